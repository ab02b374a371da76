"""The goals of imperfect sensing for the mappers: mean non-anchor MPE per sensor setting.

For each setting (a limited field of view, a range limit, bearing noise, visibility dropouts) it
collects ``--runs`` episodes of N steps with the random-walk agent (one seed per run: layout,
start pose and walk), applies the sensor setting, and maps each history with

- the masked default before this benchmark's methods (``covis-nonmetric``, a building block
  now: ``COVIS-ENSEMBLE`` with one ``covis-nonmetric`` member, :data:`BEFORE`; a history whose
  every entry was measured is not masked and goes to the complete default, ``CAL-SMA``), and
- the default ``build_map`` picks today (``method=None``),

printing the mean and the largest MPE over the runs [m] and the median CPU time per map.

    python benchmarks/bench_masked_goals.py                   # 25 runs from seed 1000
    python benchmarks/bench_masked_goals.py --runs 5 --seed 0 --methods COVIS-AUTO

The settings are the env's sensing keywords (``gym.make("LFMDR-Bearing-v0", fov_deg=90, ...)``):
an object is observed inside the field of view centred on the heading and within ``max_range``
(centre to centre); bearing noise is Gaussian on the angle; with ``miss_rate`` each visible entry
reads 0 with that probability and stays observed, so such a history's mask is True everywhere:
it is a complete history to the mapper, which is not told the miss rate but reads it from the
history's flicker (:mod:`mappers.core.flicker`) and then maps with ``VIS-BA-WALK``.
"""

from __future__ import annotations

import argparse
import time
import warnings

import gymnasium as gym
import numpy as np
from threadpoolctl import threadpool_limits

import lfmdr_gym  # noqa: F401 - registers the envs
import mappers
from lfmdr_gym.experiments.scoring import mpe_nonanchor
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.histories.history import History
from lfmdr_gym.histories.recording import collect

# (name, sensor, env keywords, goal mean MPE [m], figure the issue measured before [m])
SETTINGS = (
    ("bearing, 90 deg view, unlimited range, 2 deg noise", "bearing",
     dict(fov_deg=90, bearing_noise_deg=2), 0.06, 0.13),
    ("bearing, 90 deg view, max range 1.5 m, 2 deg noise", "bearing",
     dict(fov_deg=90, max_range=1.5, bearing_noise_deg=2), 0.035, 0.041),
    ("bearing, 60 deg view, max range 1.0 m, 2 deg noise", "bearing",
     dict(fov_deg=60, max_range=1.0, bearing_noise_deg=2), 0.03, 0.036),
    ("bearing, 360 deg, 30 deg noise", "bearing", dict(bearing_noise_deg=30), 0.035, 0.043),
    ("visibility, 90 deg view", "visibility", dict(fov_deg=90), 0.05, 0.071),
    ("visibility, miss rate 0.5", "visibility", dict(miss_rate=0.5), 0.055, 0.073),
    # a reference, no goal: the complete, perfect bearing history (CAL-SMA ~0.024 at N = 2000)
    ("bearing, 360 deg, perfect sensing (reference)", "bearing", {}, None, None),
)
_ONE_NONMETRIC = {"windows": (1,), "min_co": (3,), "member": "covis-nonmetric"}
BEFORE = {"visibility": ("covis-nonmetric", "COVIS-ENSEMBLE", _ONE_NONMETRIC),
          "bearing": ("covis-nonmetric", "COVIS-ENSEMBLE", _ONE_NONMETRIC)}
"""The masked defaults before: (name, label, parameters); one window of one step and one min_co
make the ensemble the map of its one member."""
TIME_GOAL = 1.0  # s per map at M = 50


def episode(sensor: str, seed: int, steps: int, **sensing) -> History:
    """One episode of ``steps`` moves (layout, start and walk from ``seed``) with the world's
    sensing keywords (``fov_deg``, ``max_range``, ``bearing_noise_deg``, ``miss_rate``, ...)."""
    env = gym.make(f"LFMDR-{sensor.capitalize()}-v0", max_episode_steps=steps, **sensing)
    return collect(env, RandomWalkPolicy.for_env(env), steps, seed=seed)


def score(hist: History, method: str | None, **params) -> tuple[float, float]:
    """(MPE over mapped non-anchor objects [m], CPU seconds) of one map (``params``: the
    method's)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.process_time()
        m = mappers.build_map(hist, hist.anchor_ids, hist.anchor_positions, method, **params)
        cpu = time.process_time() - t0
    return mpe_nonanchor(m.positions, m.unmapped, hist), cpu


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=25, help="episodes per setting (default 25)")
    ap.add_argument("--seed", type=int, default=1000, help="first seed (default 1000: fresh)")
    ap.add_argument("--steps", type=int, default=2000, help="steps per episode (default 2000)")
    ap.add_argument("--methods", nargs="*", default=None,
                    help="labels to measure besides the two defaults")
    ap.add_argument("--settings", nargs="*", type=int, default=None,
                    help="indices of the settings to run (default all)")
    args = ap.parse_args(argv)
    chosen = range(len(SETTINGS)) if args.settings is None else args.settings
    print(f"{args.runs} runs from seed {args.seed}, N = {args.steps}; MPE [m] mean / max run; "
          "CPU s per map (median, one BLAS thread)")
    with threadpool_limits(limits=1):
        for k in chosen:
            name, sensor, kw, goal, issue_before = SETTINGS[k]
            rows: dict[str, list] = {}
            for r in range(args.runs):
                seed = args.seed + r
                h = episode(sensor, seed, args.steps, **kw)
                masked = h.partly_observed
                before = BEFORE[sensor] if masked else ("CAL-SMA", "CAL-SMA", {})
                labels = {f"before ({before[0]})": before[1:], "default": (None, {})}
                for extra in args.methods or ():
                    labels[extra] = (extra, {})
                for label, (method, params) in labels.items():
                    rows.setdefault(label, []).append(score(h, method, **params))
            print(f"\n{name}: " + ("no goal" if goal is None else
                  f"goal <= {goal:.3f} m (max run <= {2 * goal:.3f}), "
                  f"issue's figure before {issue_before:.3f} m"))
            for label, vals in rows.items():
                a = np.array(vals)
                ok = goal is not None and a[:, 0].mean() <= goal and a[:, 0].max() <= 2 * goal
                print(f"  {label:32s} {a[:, 0].mean():.4f} / {a[:, 0].max():.4f}   "
                      f"{np.median(a[:, 1]):.3f} s (max {a[:, 1].max():.3f} s)  "
                      f"{'' if goal is None else 'met' if ok else 'NOT met'}")


if __name__ == "__main__":
    main()
