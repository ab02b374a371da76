"""A coverage-seeking exploration policy: run straight, bounce off obstacles ("run and tumble").

The paper's random walk turns by up to 45 degrees every step, so the robot diffuses. This
policy is the ballistic alternative: it keeps its heading (with a little jitter) while the way
ahead is clear and, when an obstacle comes within reach, tumbles: it keeps turning toward the
side with more room until it finds a heading with room to run. Whether straight runs pay off
depends on the clutter: in the default 50-object arena, where runs are short, it does not beat
the random walk. Measured with the script below (seeds 0-2, 2000 steps, same layout and start):
both end up visiting 99-100 % of the arena's 0.25 m cells, but after 200 steps this policy has
visited 59-68 % against 75-79 %, and it is blocked on 25-35 % of its moves against 19-22 %.
Treat it as a template for your own policy, not as a better default.

It uses only the observation's proximity ring (no pose), meets the policy contract (a callable
with ``reset(seed=None)``, answering single or batched observations) and so plugs into
``collect``. Run it as a script to compare the two policies on one layout:

    PYTHONPATH=. python examples/coverage_policy.py [--steps 2000] [--seed 0]
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

import lfmdr_gym  # noqa: F401  (registers the ids)
from lfmdr_gym.history import History, collect
from lfmdr_gym.policies import RandomWalkPolicy


class CoveragePolicy:
    """Run straight while there is room; bounce (turn one way until clear) when there is not.

    Args:
        max_turn, step_length, robot_radius, obstacle_radius: the robot's geometry, as for
            :class:`~lfmdr_gym.policies.RandomWalkPolicy` (whose collision check is reused).
        jitter: largest random heading change on a straight run [rad].
        room: extra free distance [m] beyond one step that a run needs ahead.
        seed: seed of the policy's own generator (also settable with :meth:`reset`).
    """

    def __init__(self, max_turn: float = math.pi / 4, step_length: float = 0.2,
                 robot_radius: float = 0.05, obstacle_radius: float = 0.024, *,
                 jitter: float = 0.1, room: float = 0.15, seed: int | None = None) -> None:
        if not 0 <= jitter <= max_turn:
            raise ValueError(f"jitter must lie in [0, max_turn={max_turn}], got {jitter!r}")
        if room < 0:
            raise ValueError(f"room must be non-negative, got {room!r}")
        self.check = RandomWalkPolicy(max_turn, step_length, robot_radius,
                                      obstacle_radius=obstacle_radius, plan_ahead=False)
        self.jitter = jitter
        self.room = room
        self.rng = np.random.default_rng(seed)
        self._tumble: np.ndarray | None = None  # per row: 0 running, +-1 turning that way

    @classmethod
    def for_env(cls, env: Any, **kwargs: Any) -> CoveragePolicy:
        """Matched to ``env``'s geometry, read as :meth:`RandomWalkPolicy.for_env` does."""
        ref = RandomWalkPolicy.for_env(env)
        geometry = {"max_turn": ref.max_turn, "step_length": ref.step_length,
                    "robot_radius": ref.robot_radius, "obstacle_radius": ref.obstacle_radius}
        return cls(**{**geometry, **kwargs})

    def reset(self, seed: int | None = None) -> None:
        self._tumble = None
        if seed is not None:
            self.rng = np.random.default_rng(seed)

    def __call__(self, observation: Mapping[str, Any]) -> np.ndarray:
        prox = np.asarray(observation["proximity"], dtype=np.float64)
        single = prox.ndim == 1
        prox = np.atleast_2d(prox)
        batch = prox.shape[0]
        if self._tumble is None or self._tumble.shape != (batch,):
            self._tumble = np.zeros(batch)
        c = self.check
        need = c.step_length + c.margin + self.room
        # candidates: a jittered straight run, then turns of growing size to either side
        fan = np.linspace(0.0, c.max_turn, 9)[1:]
        actions = np.empty(batch, dtype=np.float32)
        for i in range(batch):
            run = self.rng.uniform(-self.jitter, self.jitter)
            if self._tumble[i] == 0 and c.clearance(prox[i:i + 1], np.array([[run]]))[0, 0] >= need:
                actions[i] = run
                continue
            if self._tumble[i] == 0:  # start a tumble toward the side with more room
                n = prox.shape[1]
                left, right = prox[i, 1:n // 2].sum(), prox[i, n // 2 + 1:].sum()
                side = np.sign(left - right) or self.rng.choice([-1.0, 1.0])
                self._tumble[i] = side
            turns = self._tumble[i] * fan
            room = c.clearance(prox[i:i + 1], turns[None])[0]
            if (room >= need).any():  # the smallest turn that opens a run ends the tumble
                actions[i] = turns[(room >= need).argmax()]
                self._tumble[i] = 0.0
            elif (room >= need - self.room).any():  # a safe step, still turning
                actions[i] = turns[room.argmax()]
            else:
                actions[i] = turns[-1]
        return actions[:1].copy() if single else actions.reshape(batch, 1)


def arena_coverage(history: History, arena_size: float = 2.5, cell: float = 0.25) -> float:
    """Share of the arena's ``cell``-sized squares the robot's centre entered (ground truth)."""
    n = int(round(arena_size / cell))
    ij = np.floor((history.robot_poses[:, :2] + arena_size / 2) / cell).astype(int)
    ij = np.clip(ij, 0, n - 1)
    return len({(a, b) for a, b in ij}) / (n * n)


def summary(name: str, history: History) -> str:
    seen = int((history.matrix != 0).any(axis=1).sum())
    return (f"{name:<16s} blocked {history.meta['blocked_moves']:>4d}/{history.n_steps}  "
            f"objects seen {seen:>2d}/{history.n_objects}  "
            f"arena cells visited {arena_coverage(history):.0%}")


def main(argv: list[str] | None = None) -> dict[str, History]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="save the coverage history here (.npz)")
    args = parser.parse_args(argv)

    env = gym.make("LFMDR-Visibility-v0")
    out = {
        "coverage": collect(env, CoveragePolicy.for_env(env), args.steps, seed=args.seed),
        "random walk": collect(env, RandomWalkPolicy.for_env(env), args.steps, seed=args.seed),
    }
    env.close()
    print(f"LFMDR-Visibility-v0, seed {args.seed}, {args.steps} steps (same layout and start)")
    for name, history in out.items():
        print(summary(name, history))
    for n in (50, 200):
        if n <= args.steps:
            cells = {name: f"{arena_coverage(h.head(n)):.0%}" for name, h in out.items()}
            print(f"after {n} steps, arena cells visited: {cells}")
    if args.out:
        print(f"saved {out['coverage'].save(args.out)}")
    return out


if __name__ == "__main__":
    main()
