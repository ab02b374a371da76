"""Quickstart: one episode of the paper's random walk, recorded, saved, mapped and scored.

    python examples/quickstart.py [--steps 2000] [--seed 0] [--out history.npz]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import lfmdr_gym  # noqa: F401  (registers LFMDR-Visibility-v0, LFMDR-Bearing-v0, LFMDR-Range-v0)
import mappers
from lfmdr_gym import History, collect
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy


def main(argv: list[str] | None = None) -> History:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="LFMDR-Visibility-v0")
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="history.npz")
    args = parser.parse_args(argv)

    env = gym.make(args.env)  # the world: 50 cylinders in a 2.5 m arena, a disc robot
    policy = RandomWalkPolicy.for_env(env)  # the paper's agent, matched to the env's geometry
    history = collect(env, policy, args.steps, seed=args.seed)  # one seed fixes everything
    env.close()
    path = history.save(args.out)

    seen = (history.matrix != 0).any(axis=1) if history.sensor == "visibility" else None
    print(history)
    print(f"matrix {history.matrix.shape} ({history.sensor}); anchors {history.anchor_ids.tolist()}")
    print(f"blocked moves: {history.meta['blocked_moves']} of {history.n_steps}")
    if seen is not None:
        print(f"objects seen at least once: {int(seen.sum())} of {history.n_objects}")
    print(f"saved to {path}; reload with History.load({str(path)!r})")
    assert np.array_equal(History.load(path).matrix, history.matrix)

    # The mapper sees the histories and the anchors only; ground truth is used to score.
    # Pass the History itself, not history.matrix: build_map then also reads its sensor, its
    # mask (what a limited sensor did not see) and its timeline.
    for method in ("SMA(WGT)", None):  # None: the default for this kind of history
        result = mappers.build_map(
            history, history.anchor_ids, history.anchor_positions, method=method
        )
        mpe = mappers.mean_position_error(
            result.positions, history.object_positions, exclude=history.anchor_ids
        )
        moe = mappers.mean_orientation_error(result.positions, history.object_positions)
        print(f"{result.method:>10}: MPE {mpe:.3f} m (non-anchor objects), MOE {moe:.2f} %")
        for w in result.warnings:  # what the mapper repaired or doubts (Map.warnings)
            print(f"{'':>10}  warning: {w}")
    return history


if __name__ == "__main__":
    main()
