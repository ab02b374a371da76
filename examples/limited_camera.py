"""A limited camera: 90-degree view, 1.5 m range, 2-degree bearing noise; its masked history
and its map.

The paper's robot sees every object's bearing at every step. A real camera sees the few
objects in front of it, near enough, with some noise. The env reports which objects it measured
(``obs["observed"]``); ``collect`` turns that into the history's mask and ``build_map`` maps a
masked history with the default for masked histories.

    python examples/limited_camera.py [--steps 2000] [--seed 3] [--out limited_camera.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym

import lfmdr_gym  # noqa: F401  (registers the env ids)
import mappers
from lfmdr_gym import History, collect
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy

CAMERA = {"fov_deg": 90.0, "max_range": 1.5, "bearing_noise_deg": 2.0}


def main(argv: list[str] | None = None) -> History:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--out", default="limited_camera.png", help="the map figure")
    args = parser.parse_args(argv)

    env = gym.make("LFMDR-Bearing-v0", **CAMERA)
    obs, _ = env.reset(seed=args.seed)
    print(f"camera {CAMERA}: at the start it measures {int(obs['observed'].sum())} of "
          f"{len(obs['observed'])} objects")
    history = collect(env, RandomWalkPolicy.for_env(env), args.steps, seed=args.seed)
    env.close()
    per_step = history.mask[:, ::2]  # one flag per object and step (bearing: cos, sin columns)
    print(history)
    print(f"observed: {100 * history.mask.mean():.1f} % of the entries, "
          f"{per_step.sum(axis=0).mean():.1f} objects per step; "
          f"never observed: {int((~per_step.any(axis=1)).sum())} objects")

    # The mapper gets the history (matrix and mask) and the anchors; the truth only scores.
    result = mappers.build_map(history, history.anchor_ids, history.anchor_positions)
    skip = sorted({*history.anchor_ids.tolist(), *result.unmapped})
    mpe = mappers.mean_position_error(result.positions, history.object_positions, exclude=skip)
    print(f"{result.method}: MPE {mpe:.3f} m (mapped non-anchor objects), "
          f"unmapped {list(result.unmapped)}")
    for w in result.warnings:  # what the mapper repaired or doubts (Map.warnings)
        print(f"warning: {w}")

    from lfmdr_gym.experiments.figures import plot_map

    path = plot_map(result.positions, history, Path(args.out),
                    title=f"90 deg camera, 1.5 m range, 2 deg noise: {result.method}, "
                          f"MPE {mpe:.3f} m", notes=result.warnings)
    print(f"wrote {path}")
    return history


if __name__ == "__main__":
    main()
