"""The map of a robot still moving: an online map updated every 10 steps.

The coverage policy explores; after every 10 steps the new columns of the history go to
``mappers.OnlineMapper``, which returns the current map. Prints the map's error as it grows.
With a limited view (``--env-kw fov_deg=90``) the history is masked: the columns go with their
mask, and the online map is VIEW-BA's, carried on between its refits.

    python examples/online_map.py [--env LFMDR-Bearing-v0] [--steps 1000]
    python examples/online_map.py --env-kw fov_deg=90 --steps 1500 --policy even
"""

from __future__ import annotations

import argparse

import numpy as np

import mappers
from lfmdr_gym import POLICIES, collect
from lfmdr_gym.experiments.env_settings import parse_env_kwargs
from lfmdr_gym.experiments.episodes import make_env


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="LFMDR-Visibility-v0")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--policy", default="coverage", choices=list(POLICIES))
    ap.add_argument("--env-kw", action="append", default=[], metavar="KEY=VALUE",
                    help="env keyword (repeatable), e.g. fov_deg=90 or bearing_noise_deg=2")
    args = ap.parse_args()
    try:
        env = make_env(args.env, args.steps, parse_env_kwargs(args.env_kw))
    except (TypeError, ValueError) as err:  # a malformed item, or one the env does not take
        ap.error(f"--env-kw: {err}")
    history = collect(env, POLICIES[args.policy](env, seed=args.seed), args.steps, seed=args.seed)
    env.close()
    # a sensing limit masks the history (noise alone reports an all-True mask: nothing to pass)
    mask = history.mask if history.partly_observed else None
    # replay the history in batches of 10 steps, as a robot would send them
    online = mappers.OnlineMapper(history.anchor_ids, history.anchor_positions,
                                  sensor=history.sensor)
    cols = history.columns_per_step
    truth = history.object_positions
    others = np.setdiff1d(np.arange(len(truth)), history.anchor_ids)
    for start in range(0, args.steps, 10):
        new = slice(start * cols, (start + 10) * cols)
        current = online.update(history.matrix[:, new], None if mask is None else mask[:, new])
        if (start + 10) % 100 == 0:
            placed = others[np.isfinite(current.positions[others, 0])]
            if placed.size == 0:  # a limited view's first steps: nothing to map yet
                why = current.warnings[0].split(" (")[0] if current.warnings else "nothing sensed"
                print(f"{start + 10:5d} steps: no map yet ({why})")
                continue
            error = mappers.mean_position_error(current.positions[placed], truth[placed])
            print(f"{start + 10:5d} steps: {placed.size} of {others.size} non-anchor objects mapped, "
                  f"MPE {error:.3f} m ({current.method})")
    for w in current.warnings:  # the last map's own notes (Map.warnings)
        print(f"warning: {w}")


if __name__ == "__main__":
    main()
