"""Fused sensing in simulation: each sensor alone and fused, non-anchor MPE and time per map.

    python benchmarks/bench_fusion_sim.py [--runs 25] [--steps 2000] [--seed0 9000]
        [--sections camera60,camera360,camera-env,vis-bearing]

Every run is one random walk in ``LFMDR-Bearing-v0`` (50 objects, 2.5 m arena, 4 corner
anchors), seeds ``seed0, seed0 + 1, ...`` (fresh: never used to choose a setting). From that
walk's true poses and layout:

* ``camera60``: a camera with a 60-degree field of view and a 1 m range limit, bearing noise
  2 deg and range noise 2 cm (Gaussian), mapped fused (``LOC-SMA``) and by range alone
  (``RANGE-QUANTILE``, masked) and by bearing alone (``BEARING-BA``, masked) — the conditions
  of a real robot's camera;
* ``camera360``: a 360-degree view without range limit, 5 deg / 5 cm noise, fused vs range
  alone (``UNFOLD``) and bearing alone (``BEARING-BA``);
* ``camera-env``: a walk of ``LFMDR-Camera-v0`` itself (the MRCLAM camera's field of view,
  range limit and noise, line of sight on; :data:`lfmdr_gym.sim.camera.CAMERA_PRESET`), its fused
  history mapped as collected (``LOC-SMA``) and each of its parts alone (masked defaults:
  ``RANGE-QUANTILE`` for range, ``BEARING-BA`` for bearing);
* ``vis-bearing``: the walk's own bearing history and the visibility bits of the same poses
  (:func:`lfmdr_gym.sim.sensors.visibility`, the env's defaults), each alone (its default:
  ``CAL-SMA`` for visibility, ``BEARING-BA`` for bearing) and fused (``VB-SMA``, and VB-SMA without
  its blend with the bearing-only map, ``bearing_share=0``); the ratio fused / better-alone per run,
  for both; ``vis-bearing paper`` is VB-SMA without its bundle adjustment (``refine=False``, the
  blend alone);
* ``vis-bearing-noisy`` (not in the default sections): the same with 10 degrees of Gaussian
  noise on the bearings, where the better single sensor is not exact.

In the range-bearing sections the fused column is the default, ``LOC-SMA`` refined by a
bundle adjustment with range and angle residuals (``refine="range-bearing"``); ``LOC-SMA alone``
is the law-of-cosines map without it (``refine=None``, the default before), ``LOC-SMA+BA`` the
map refined by the bearing-only adjustment (``refine="bearing"``).

Prints mean / median / max MPE [m] per column and the median wall-clock and CPU time per map
[s] (on a busy machine the CPU time is the fairer figure: the mappers run on one thread).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np

import lfmdr_gym  # noqa: F401  (registers the env ids)
from lfmdr_gym import collect
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.sim.sensors import visibility
from mappers import build_map, mean_position_error

# the geometry of a camera on known poses is the tests' synthetic walk's (tests/synthetic_walk.py)
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from synthetic_walk import sensed  # noqa: E402


def simulate_camera(history, fov_deg: float, max_range: float | None, sigma_bearing_deg: float,
                    sigma_range: float, rng: np.random.Generator):
    """Range and bearing histories (and masks) of a camera on the walk of ``history``.

    From the true robot poses and object centres: an object is sensed when it lies within
    ``fov_deg / 2`` of the heading and nearer than ``max_range`` (None: any distance); no
    occlusion. Readings get independent Gaussian noise: ``sigma_range`` [m] on the range,
    ``sigma_bearing_deg`` on the bearing (a negative range is reflected). Returns ``({"range": R, "bearing": B}, masks)`` in the
    layout of :mod:`mappers.core.sensors` (unsensed entries 0 and False).
    """
    P, poses = history.object_positions, history.robot_poses
    r, theta, seen = sensed(P, poses, fov_deg, max_range)
    r = np.abs(r + rng.normal(0.0, sigma_range, r.shape))  # a range is a distance
    theta = theta + rng.normal(0.0, math.radians(sigma_bearing_deg), theta.shape)
    R = np.where(seen, r, 0.0)
    B = np.zeros((len(P), 2 * poses.shape[0]))
    B[:, 0::2], B[:, 1::2] = np.where(seen, np.cos(theta), 0.0), np.where(seen, np.sin(theta), 0.0)
    return {"range": R, "bearing": B}, {"range": seen, "bearing": np.repeat(seen, 2, axis=1)}


def visibility_history(history, radius: float, visual_angle: float) -> np.ndarray:
    """(M, N) visibility bits of the walk's poses (:func:`lfmdr_gym.sim.sensors.visibility`, with
    occlusion), as ``LFMDR-Visibility-v0`` would have sensed them."""
    return np.stack([visibility(pose, history.object_positions, radius, visual_angle)
                     for pose in history.robot_poses], axis=1).astype(float)


def _score(history, histories, method=None, mask=None, sensor=None,
           **params) -> tuple[float, float, float]:
    t, cpu = time.perf_counter(), time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = build_map(histories, history.anchor_ids, history.anchor_positions, method,
                      mask=mask, sensor=sensor, **params)
    dt, dcpu = time.perf_counter() - t, time.process_time() - cpu
    exclude = sorted({*history.anchor_ids.tolist(), *m.unmapped})
    return mean_position_error(m.positions, history.object_positions, exclude=exclude), dt, dcpu


def run_one(seed: int, steps: int, sections: list[str]) -> dict[str, tuple[float, float, float]]:
    """Every column's (MPE, wall seconds, CPU seconds) on the walk of ``seed``."""
    env = gym.make("LFMDR-Bearing-v0")
    history = collect(env, RandomWalkPolicy.for_env(env, seed=seed), steps, seed=seed)
    radius, visual_angle = env.unwrapped.world.object_radius, math.radians(env.unwrapped.visual_angle_deg)
    env.close()
    rng = np.random.default_rng(seed)
    out: dict[str, tuple[float, float]] = {}
    if "camera60" in sections:
        fused, masks = simulate_camera(history, 60.0, 1.0, 2.0, 0.02, rng)
        out["cam60 range-bearing"] = _score(history, fused, mask=masks)
        out["cam60 range"] = _score(history, fused["range"], mask=masks["range"], sensor="range")
        out["cam60 bearing"] = _score(history, fused["bearing"], mask=masks["bearing"],
                                      sensor="bearing")
        out["cam60 LOC-SMA+BA"] = _score(history, fused, mask=masks, refine="bearing")
        out["cam60 LOC-SMA alone"] = _score(history, fused, mask=masks, refine=None)
    if "camera360" in sections:
        fused, masks = simulate_camera(history, 360.0, None, 5.0, 0.05, rng)
        out["cam360 range-bearing"] = _score(history, fused)
        out["cam360 range"] = _score(history, fused["range"], sensor="range")
        out["cam360 bearing"] = _score(history, fused["bearing"], sensor="bearing")
        out["cam360 LOC-SMA+BA"] = _score(history, fused, refine="bearing")
        out["cam360 LOC-SMA alone"] = _score(history, fused, refine=None)
    if "camera-env" in sections:
        env = gym.make("LFMDR-Camera-v0", max_episode_steps=steps)
        cam = collect(env, RandomWalkPolicy.for_env(env, seed=seed), steps, seed=seed)
        env.close()
        out["camera-env range-bearing"] = _score(cam, cam)
        out["camera-env range"] = _score(cam, cam.parts["range"])
        out["camera-env bearing"] = _score(cam, cam.parts["bearing"])
        out["camera-env LOC-SMA+BA"] = _score(cam, cam, refine="bearing")
        out["camera-env LOC-SMA alone"] = _score(cam, cam, refine=None)
    if "vis-bearing" in sections:
        vis = visibility_history(history, radius, visual_angle)
        out["visibility"] = _score(history, vis, sensor="visibility")
        out["bearing"] = _score(history, history.matrix, sensor="bearing")
        both = {"visibility": vis, "bearing": history.matrix}
        out["visibility-bearing"] = _score(history, both)
        out["vis-bearing unblended"] = _score(history, both, bearing_share=0.0)
        out["vis-bearing paper"] = _score(history, both, refine=False)
    if "vis-bearing-noisy" in sections:  # the same, bearings with 10 degrees of noise
        vis = visibility_history(history, radius, visual_angle)
        B = np.asarray(history.matrix, dtype=float)
        noise = np.random.default_rng([seed, 10])  # whatever the other sections drew
        theta = np.arctan2(B[:, 1::2], B[:, 0::2]) + noise.normal(0.0, math.radians(10.0),
                                                                  (B.shape[0], B.shape[1] // 2))
        noisy = np.empty_like(B)
        noisy[:, 0::2], noisy[:, 1::2] = np.cos(theta), np.sin(theta)
        out["noisy visibility"] = _score(history, vis, sensor="visibility")
        out["noisy bearing"] = _score(history, noisy, sensor="bearing")
        both = {"visibility": vis, "bearing": noisy}
        out["noisy vis-bearing"] = _score(history, both)
        out["noisy vis-bearing paper"] = _score(history, both, refine=False)
    return out


def _ratios(rows, fused_col, a, b, label):
    """The fused map's MPE over the better single sensor's: of the means, and per run."""
    better = np.array([min(r[a][0], r[b][0]) for r in rows])
    fused = np.array([r[fused_col][0] for r in rows])
    ratio = fused / better
    print(f"{label} / better alone: mean of MPEs {fused.mean() / better.mean():.3f}, per run "
          f"mean {ratio.mean():.3f}, median {np.median(ratio):.3f}, max {ratio.max():.3f}; "
          f"fused - better: mean {np.mean(fused - better):+.2e} m, max {np.max(fused - better):+.2e} m")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=25)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--seed0", type=int, default=9000)
    ap.add_argument("--sections", default="camera60,camera360,camera-env,vis-bearing")
    args = ap.parse_args(argv)
    sections = args.sections.split(",")
    rows = [run_one(args.seed0 + k, args.steps, sections) for k in range(args.runs)]
    print(f"{args.runs} runs, N = {args.steps}, seeds {args.seed0}..{args.seed0 + args.runs - 1}")
    print(f"{'column':<24}{'mean MPE':>10}{'median':>10}{'max':>10}{'time/map':>10}{'CPU/map':>10}")
    for col in rows[0]:
        e, t, cpu = (np.array([r[col][k] for r in rows]) for k in range(3))
        print(f"{col:<24}{e.mean():>10.4f}{np.median(e):>10.4f}{e.max():>10.4f}"
              f"{np.median(t):>9.3f}s{np.median(cpu):>9.3f}s")
    if "vis-bearing" in sections:
        for col in ("visibility-bearing", "vis-bearing unblended", "vis-bearing paper"):
            _ratios(rows, col, "visibility", "bearing", col)
    if "vis-bearing-noisy" in sections:
        for col in ("noisy vis-bearing", "noisy vis-bearing paper"):
            _ratios(rows, col, "noisy visibility", "noisy bearing", col)

if __name__ == "__main__":
    main()
