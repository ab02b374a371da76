"""VIS-BA against the visibility default: mean non-anchor MPE, start map vs refined map.

For each setting (complete perfect visibility, ``miss_rate=0.5``, a 90-degree view) it collects
``--runs`` episodes of N steps with the random-walk agent (one seed per run, as
``benchmarks/bench_masked_goals.py``), maps each history with ``build_map``'s default and with
VIS-BA, the visibility adjustment with independent steps (a dead end, no longer a label:
``docs/dead-ends.md``; here ``"VIS-BA-WALK"`` with the walk's options off, :data:`INDEPENDENT`;
its CPU time includes drawing its start map: the default's, or the map of the default it
replaced when the default adjusts viewpoints), and prints the mean and the largest MPE over
the runs [m] and the median CPU time per map. ``--walk`` adds VIS-BA with the walk's continuity
prior, ``"VIS-BA-WALK"`` itself (its start: the default's map, or the map of the default it
replaced: ``DROPOUT-BLEND`` for a masked history, CAL-SMA for a flickering or perfect one). The
rows keep the names of the stored tables (``docs/results/vis_ba_*.csv``).

    python benchmarks/bench_visibility_adjustment.py --runs 20 --seed 100   # tuning
    python benchmarks/bench_visibility_adjustment.py --runs 25 --seed 1000  # fresh
"""

from __future__ import annotations

import argparse
import csv

import numpy as np
from bench_masked_goals import episode, score
from threadpoolctl import threadpool_limits

from lfmdr_gym.atomic import atomic_write

INDEPENDENT = {"continuity": False, "align": False, "overrelax": 0.0, "grid_cells": 6,
               "prior_iters": 2, "model_rounds": None}
"""VIS-BA-WALK's options off, VisibilityAdjustment's own defaults: VIS-BA, steps independent."""

SETTINGS = (
    ("visibility, perfect (360 deg)", {}),
    ("visibility, miss rate 0.5", dict(miss_rate=0.5)),
    ("visibility, 90 deg view", dict(fov_deg=90)),
)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=25, help="episodes per setting (default 25)")
    ap.add_argument("--seed", type=int, default=1000, help="first seed (default 1000: fresh)")
    ap.add_argument("--steps", type=int, default=2000, help="steps per episode (default 2000)")
    ap.add_argument("--settings", nargs="*", type=int, default=None,
                    help="indices of the settings to run (default all)")
    ap.add_argument("--csv", default=None, help="write one row per run and method here")
    ap.add_argument("--walk", action="store_true",
                    help="also VIS-BA with the walk's continuity prior (VIS-BA-WALK)")
    args = ap.parse_args(argv)
    chosen = range(len(SETTINGS)) if args.settings is None else args.settings
    print(f"{args.runs} runs from seed {args.seed}, N = {args.steps}; MPE [m] mean / max run; "
          "CPU s per map (median, one BLAS thread)")
    lines = [("setting", "seed", "method", "mpe", "cpu_s")]
    runs = {"default (start)": (None, {}), "VIS-BA": ("VIS-BA-WALK", INDEPENDENT),
            "VIS-BA + walk": ("VIS-BA-WALK", {})}  # row -> (method, its parameters)
    with threadpool_limits(limits=1):
        for k in chosen:
            name, kw = SETTINGS[k]
            rows: dict[str, list] = {"default (start)": [], "VIS-BA": []}
            if args.walk:
                rows["VIS-BA + walk"] = []
            for r in range(args.runs):
                h = episode("visibility", args.seed + r, args.steps, **kw)
                for label in rows:
                    method, params = runs[label]
                    rows[label].append(score(h, method, **params))
                    mpe, cpu = rows[label][-1]
                    lines.append((name, args.seed + r, label, f"{mpe:.6f}", f"{cpu:.4f}"))
            print(f"\n{name}")
            for label, vals in rows.items():
                a = np.array(vals)
                print(f"  {label:18s} {a[:, 0].mean():.4f} / {a[:, 0].max():.4f}   "
                      f"{np.median(a[:, 1]):.2f} s (max {a[:, 1].max():.2f} s)")
            a, b = np.array(rows["default (start)"]), np.array(rows["VIS-BA"])
            print(f"  VIS-BA better in {int(np.sum(b[:, 0] < a[:, 0]))} of {len(a)} runs")
    if args.csv:
        with atomic_write(args.csv) as f:
            csv.writer(f).writerows(lines)


if __name__ == "__main__":
    main()
