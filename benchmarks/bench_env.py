"""Steps per second of the LFMDR environments, driven by the random-walk agent.

Prints medians over several repeats (single process) for:

* ``LFMDR-Visibility-v0`` at M = 50 (default arena) and at M = 500 in an arena enlarged to the
  same object density (side 2.5 * sqrt(10) m), with the RandomWalkPolicy (policy time included)
  and with a fixed action (env alone);
* ``LFMDR-Visibility-v0`` at M = 10,000 (arena side 2.5 * sqrt(200) m), with the agent: a step
  touches only nearby objects (a cell grid), so the ratio to M = 50 should stay near 1;
* ``LFMDR-Bearing-v0`` at M = 50;
* a straightforward pure-numpy simulation of the same world written below (move checked against
  every object, visibility with occlusion tested object by object), for the ratio.

* ``collect`` (the recorder) at M = 50 with the agent: the env loop plus what recording costs.

Goal (issue #13): >= 12,000 steps/s at M = 50 with the agent, and >= 2.5 x the reference world
measured in the same run. Every run is timed twice: wall-clock time and the process's CPU time
(``time.process_time``). On a machine shared with other work, wall time also counts the time
the process waited for a core, so the CPU-time rates are the fairer absolute figures; the ratios
are computed per repeat (each repeat runs every case once, round robin) and their median printed.

    python benchmarks/bench_env.py            # full run (1-3 minutes)
    python benchmarks/bench_env.py --quick    # fewer steps and repeats
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import gymnasium as gym
import numpy as np

import lfmdr_gym  # noqa: F401  (registers the ids)
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.histories.recording import collect

ARENA = 2.5
BIG_ARENA = 2.5 * math.sqrt(10.0)  # 10x the area for 10x the objects: same density
HUGE_ARENA = 2.5 * math.sqrt(200.0)  # M = 10,000 at the same density


class ReferenceWorld:
    """The paper's world simulated the plain way, as a yardstick (no pymunk, no cleverness).

    Same geometry as the env's defaults: square arena, cylinders of 48 mm laid out by rejection
    sampling with 0.15 m clearances, a 0.05 m disc robot that turns, then advances 0.2 m unless it
    would touch an object or a wall (it stops short), then observes visibility (visual angle
    > 5 degrees and line of sight clear of every other cylinder) or bearing, plus a ring of 32
    proximity rays.
    """

    def __init__(self, n_objects: int = 50, arena_size: float = ARENA, sensor: str = "visibility",
                 seed: int = 0) -> None:
        self.rng = np.random.default_rng(seed)
        self.half = arena_size / 2
        self.r = 0.024
        self.robot_radius = 0.05
        self.step_length = 0.2
        self.min_angle = math.radians(5.0)
        self.sensor = sensor
        self.ray_angles = 2 * np.pi * np.arange(32) / 32  # the env's default ray count
        self.proximity_range = 0.5
        pts: list[np.ndarray] = []
        lim = self.half - 0.15 - self.r
        while len(pts) < n_objects:
            p = self.rng.uniform(-lim, lim, 2)
            if all(np.hypot(*(p - q)) >= 0.15 + 2 * self.r for q in pts):
                pts.append(p)
        self.objects = np.array(pts)
        while True:
            p = self.rng.uniform(-self.half + 0.1, self.half - 0.1, 2)
            if np.min(np.hypot(*(self.objects - p).T)) > self.r + self.robot_radius + 0.05:
                break
        self.pose = np.array([p[0], p[1], self.rng.uniform(-np.pi, np.pi)])

    def _free_travel(self, p: np.ndarray, e: np.ndarray) -> float:
        """Distance the robot centre can move from p along unit e before touching anything."""
        rr = self.r + self.robot_radius
        d = self.objects - p
        b = d @ e
        c = np.einsum("ij,ij->i", d, d) - rr * rr
        disc = b * b - c
        ok = (disc >= 0) & (b > 0)
        t_obj = np.where(ok, b - np.sqrt(np.where(ok, disc, 0.0)), np.inf)
        lim = self.half - self.robot_radius
        t_wall = np.inf
        for k in range(2):
            if e[k] > 1e-12:
                t_wall = min(t_wall, (lim - p[k]) / e[k])
            elif e[k] < -1e-12:
                t_wall = min(t_wall, (-lim - p[k]) / e[k])
        return float(min(t_obj.min(initial=np.inf), t_wall))

    def step(self, turn: float) -> tuple[dict[str, np.ndarray], bool]:
        x, y, h = self.pose
        h = (h + turn + np.pi) % (2 * np.pi) - np.pi
        e = np.array([math.cos(h), math.sin(h)])
        travel = self._free_travel(self.pose[:2], e)
        blocked = travel < self.step_length
        move = min(self.step_length, max(travel - 1e-6, 0.0))
        self.pose = np.array([x + move * e[0], y + move * e[1], h])
        return self.observe(), blocked

    def observe(self) -> dict[str, np.ndarray]:
        p, h = self.pose[:2], self.pose[2]
        d = self.objects - p
        dist = np.hypot(d[:, 0], d[:, 1])
        if self.sensor == "bearing":
            ang = np.arctan2(d[:, 1], d[:, 0]) - h
            reading = np.stack([np.cos(ang), np.sin(ang)], axis=1).astype(np.float32)
        else:
            visible = 2 * np.arcsin(np.minimum(self.r / dist, 1.0)) > self.min_angle
            for j in np.flatnonzero(visible):  # occlusion, the plain way: every other cylinder
                u = d[j] / dist[j]
                along = d @ u
                perp = np.abs(d[:, 0] * u[1] - d[:, 1] * u[0])
                blocking = (along > 0) & (along < dist[j]) & (perp < self.r)
                blocking[j] = False
                if blocking.any():
                    visible[j] = False
            reading = visible.astype(np.int8)
        # proximity: each ray against every cylinder and the walls
        angles = h + self.ray_angles
        rays = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        b = rays @ d.T  # (rays, objects)
        c = np.einsum("ij,ij->i", d, d) - self.r * self.r
        disc = b * b - c[None, :]
        hit = np.where((disc >= 0) & (b > 0), b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
        with np.errstate(divide="ignore"):
            tx = np.where(rays[:, 0] > 0, (self.half - p[0]) / rays[:, 0],
                          (-self.half - p[0]) / rays[:, 0])
            ty = np.where(rays[:, 1] > 0, (self.half - p[1]) / rays[:, 1],
                          (-self.half - p[1]) / rays[:, 1])
        prox = np.minimum(np.minimum(hit.min(axis=1), np.abs(tx)), np.abs(ty))
        prox = np.minimum(prox, self.proximity_range).astype(np.float32)
        return {self.sensor: reading, "proximity": prox}


def _clocks() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def _since(start: tuple[float, float]) -> tuple[float, float]:
    wall, cpu = _clocks()
    return wall - start[0], cpu - start[1]


def env_runner(env_id: str, n_steps: int, *, policy: bool, **kwargs):
    """A function timing one episode of ``n_steps`` (reset excluded); returns (wall, CPU) seconds."""
    env = gym.make(env_id, max_episode_steps=n_steps, **kwargs)
    agent = RandomWalkPolicy.for_env(env, seed=0)
    fixed = np.array([0.1], dtype=np.float32)
    seeds = iter(range(10_000))

    def run() -> tuple[float, float]:
        obs, _ = env.reset(seed=next(seeds))
        agent.reset(seed=0)
        t0 = _clocks()
        if policy:
            for _ in range(n_steps):
                obs, *_ = env.step(agent(obs))
        else:
            for _ in range(n_steps):
                env.step(fixed)
        return _since(t0)

    return run


def collect_runner(env_id: str, n_steps: int):
    """Times ``collect`` of one episode of ``n_steps`` (its reset included)."""
    env = gym.make(env_id, max_episode_steps=n_steps)
    agent = RandomWalkPolicy.for_env(env)
    seeds = iter(range(10_000))

    def run() -> tuple[float, float]:
        t0 = _clocks()
        collect(env, agent, n_steps, seed=next(seeds))
        return _since(t0)

    return run


def policy_runner(n_steps: int):
    """Times the agent alone on the observations of a recorded random-walk episode."""
    env = gym.make("LFMDR-Visibility-v0", max_episode_steps=n_steps)
    agent = RandomWalkPolicy.for_env(env, seed=0)
    obs, _ = env.reset(seed=0)
    recorded = []
    for _ in range(n_steps):
        obs, *_ = env.step(agent(obs))
        recorded.append(obs)
    env.close()

    def run() -> tuple[float, float]:
        agent.reset(seed=1)
        t0 = _clocks()
        for o in recorded:
            agent(o)
        return _since(t0)

    return run


def reference_runner(n_steps: int, *, n_objects: int, arena_size: float,
                     sensor: str = "visibility"):
    agent = RandomWalkPolicy(seed=0)
    seeds = iter(range(10_000))

    def run() -> tuple[float, float]:
        world = ReferenceWorld(n_objects, arena_size, sensor, seed=next(seeds))
        obs = world.observe()
        agent.reset(seed=0)
        t0 = _clocks()
        for _ in range(n_steps):
            obs, _ = world.step(float(agent(obs)[0]))
        return _since(t0)

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000, help="steps per repeat (M = 50)")
    parser.add_argument("--repeats", type=int, default=7, help="repeats; the median is printed")
    parser.add_argument("--quick", action="store_true", help="500 steps x 3 repeats")
    args = parser.parse_args()
    steps, repeats = (500, 3) if args.quick else (args.steps, args.repeats)
    big_steps = max(steps // 4, 100)
    big = {"n_objects": 500, "arena_size": BIG_ARENA}

    cases = {  # label -> (runner, steps per run)
        "vis50": ("LFMDR-Visibility-v0, M=50, RandomWalkPolicy",
                  env_runner("LFMDR-Visibility-v0", steps, policy=True), steps),
        "vis50_env": ("LFMDR-Visibility-v0, M=50, fixed action (env alone)",
                      env_runner("LFMDR-Visibility-v0", steps, policy=False), steps),
        "policy": ("RandomWalkPolicy alone, on a recorded episode (calls/s)",
                   policy_runner(steps), steps),
        "bear50": ("LFMDR-Bearing-v0, M=50, RandomWalkPolicy",
                   env_runner("LFMDR-Bearing-v0", steps, policy=True), steps),
        "vis500": (f"LFMDR-Visibility-v0, M=500, arena {BIG_ARENA:.2f} m, RandomWalkPolicy",
                   env_runner("LFMDR-Visibility-v0", big_steps, policy=True, **big), big_steps),
        "vis500_env": ("LFMDR-Visibility-v0, M=500, fixed action (env alone)",
                       env_runner("LFMDR-Visibility-v0", big_steps, policy=False, **big),
                       big_steps),
        "vis10k": (f"LFMDR-Visibility-v0, M=10000, arena {HUGE_ARENA:.1f} m, RandomWalkPolicy",
                   env_runner("LFMDR-Visibility-v0", big_steps, policy=True, n_objects=10_000,
                              arena_size=HUGE_ARENA), big_steps),
        "ref50": ("reference numpy world, M=50, visibility, RandomWalkPolicy",
                  reference_runner(steps, n_objects=50, arena_size=ARENA), steps),
        "ref500": ("reference numpy world, M=500, visibility, RandomWalkPolicy",
                   reference_runner(big_steps, **big), big_steps),
        "collect50": ("collect, LFMDR-Visibility-v0, M=50, RandomWalkPolicy (records the history)",
                      collect_runner("LFMDR-Visibility-v0", steps), steps),
    }
    # Round robin: every repeat runs every case once, so a burst of load from other processes
    # on this shared machine hits all cases alike and the ratios stay meaningful.
    rates: dict[str, dict[str, list[float]]] = {"wall": {k: [] for k in cases},
                                                "cpu": {k: [] for k in cases}}
    for _ in range(repeats):
        for key, (_, run, n) in cases.items():
            wall, cpu = run()
            rates["wall"][key].append(n / wall)
            rates["cpu"][key].append(n / cpu)

    def med(clock: str, key: str) -> float:
        return statistics.median(rates[clock][key])

    def ratio(clock: str, a: str, b: str) -> float:
        return statistics.median(x / y for x, y in zip(rates[clock][a], rates[clock][b],
                                                        strict=True))

    print(f"median steps/s over {repeats} repeats ({steps} steps at M=50, {big_steps} at M=500 "
          "and M=10000); wall clock | CPU time")
    for key, (label, _, _) in cases.items():
        print(f"  {label:<80s} {med('wall', key):>9,.0f} | {med('cpu', key):>9,.0f}")
    for clock in ("wall", "cpu"):
        print(f"  [{clock}] env / reference (per-repeat ratio, median): "
              f"M=50 {ratio(clock, 'vis50', 'ref50'):.2f}x, M=500 {ratio(clock, 'vis500', 'ref500'):.2f}x; "
              f"collect / reference at M=50 {ratio(clock, 'collect50', 'ref50'):.2f}x; "
              f"M=10000 / M=50 with the agent {ratio(clock, 'vis10k', 'vis50'):.2f} (goal >= 0.5)")
    for clock in ("wall", "cpu"):
        rate, r = med(clock, "vis50"), ratio(clock, "vis50", "ref50")
        goal = "meets" if rate >= 12_000 and r >= 2.5 else "misses"
        print(f"  [{clock}] goal >= 12,000 steps/s and >= 2.5x the reference at M=50 with the "
              f"agent: {goal} ({rate:,.0f} steps/s, {r:.2f}x)")


if __name__ == "__main__":
    main()
