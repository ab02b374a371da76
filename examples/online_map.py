"""The map of a robot still moving: an online map updated every 10 steps.

The coverage policy explores; after every 10 steps the new columns of the history go to
``mappers.OnlineMapper``, which returns the current map. Prints the map's error as it grows.

    PYTHONPATH=. python examples/online_map.py [--env LFMDR-Bearing-v0] [--steps 1000]
"""

from __future__ import annotations

import argparse

import numpy as np

import mappers
from lfmdr_gym import POLICIES, collect
from lfmdr_gym.experiments.episodes import make_env


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="LFMDR-Visibility-v0")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    env = make_env(args.env, args.steps)
    history = collect(env, POLICIES["coverage"](env, seed=args.seed), args.steps, seed=args.seed)
    env.close()
    # replay the history in batches of 10 steps, as a robot would send them
    online = mappers.OnlineMapper(history.anchor_ids, history.anchor_positions,
                                  sensor=history.sensor)
    cols = history.columns_per_step
    truth = history.object_positions
    others = np.setdiff1d(np.arange(len(truth)), history.anchor_ids)
    for start in range(0, args.steps, 10):
        current = online.update(history.matrix[:, start * cols:(start + 10) * cols])
        if (start + 10) % 100 == 0:
            placed = others[np.isfinite(current.positions[others, 0])]
            error = mappers.mean_position_error(current.positions[placed], truth[placed])
            print(f"{start + 10:5d} steps: {placed.size} of {others.size} non-anchor objects mapped, "
                  f"MPE {error:.3f} m")


if __name__ == "__main__":
    main()
