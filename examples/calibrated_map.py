"""CAL-SMA, the calibrated anchored mapper, on one episode per sensor.

    python examples/calibrated_map.py [--steps 2000] [--seed 0] [--plot map.png]

Collects a random-walk episode, maps it with CAL-SMA (``build_map``'s default for visibility,
and the start of its bearing default BEARING-BA) and with
SMA(WGT), the best of the paper's ten, and prints the errors and CAL-SMA's fold score (0 = no
sign of a fold; a FoldWarning is raised above ``fold_threshold``).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import lfmdr_gym  # noqa: F401  (registers the env ids)
import mappers
from lfmdr_gym import collect
from lfmdr_gym.atomic import atomic_savefig
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--plot", default=None, help="save the bearing maps to this PNG")
    args = parser.parse_args(argv)

    out: dict[str, float] = {}
    print(f"{'sensor':10s} {'method':9s} {'MPE [m]':>8s} {'MOE [%]':>8s}  fold score")
    for env_id in ("LFMDR-Visibility-v0", "LFMDR-Bearing-v0"):
        env = gym.make(env_id)
        history = collect(env, RandomWalkPolicy.for_env(env, seed=args.seed), args.steps,
                          seed=args.seed)
        env.close()
        truth, anchors = history.object_positions, history.anchor_ids
        maps = {}
        for method in ("CAL-SMA", "SMA(WGT)"):
            m = mappers.build_map(history, anchors, history.anchor_positions, method)
            maps[m.method] = m
            mpe = mappers.mean_position_error(m.positions, truth, exclude=anchors)
            moe = mappers.mean_orientation_error(m.positions, truth)
            out[f"{history.sensor}/{m.method}"] = mpe
            # the estimator itself, for its diagnostics (build_map keeps only the positions)
            note = ""
            if m.method == "CAL-SMA":
                X = history.matrix / np.linalg.norm(history.matrix, axis=1, keepdims=True)
                est = mappers.CalibratedSMACOF().fit(
                    X, anchor_ids=anchors, anchor_positions=history.anchor_positions)
                note = f"{est.fold_score_:.3f}"
            print(f"{history.sensor:10s} {m.method:9s} {mpe:8.3f} {moe:8.2f}  {note}")
            for w in m.warnings:  # what the mapper repaired or doubts (Map.warnings)
                print(f"  warning: {w}")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 2, figsize=(10, 5))
        for ax, (label, m) in zip(axes, maps.items(), strict=True):
            for t, e in zip(truth, m.positions, strict=True):
                ax.plot([t[0], e[0]], [t[1], e[1]], "r-", lw=1)
            ax.plot(*truth.T, "k.", ms=4)
            ax.plot(*history.anchor_positions.T, "bs", ms=6)
            ax.set_title(f"bearing, {label}")
            ax.set_aspect("equal")
        atomic_savefig(fig, args.plot, dpi=100)
        print(f"saved {args.plot}")
    return out


if __name__ == "__main__":
    main()
