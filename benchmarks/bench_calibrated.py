"""CAL-SMA against the best of the paper's ten, on the protocol's seeds and fresh ones.

For each sensor (visibility, bearing) and each seed set (the paper protocol's runs, seed 0, and
fresh runs from seeds never used to tune CAL-SMA), it collects 5 layouts x 5 start poses of
N steps with the random-walk agent and maps them with

- CAL-SMA at its defaults (``build_map(..., method="CAL-SMA")``; the complete visibility
  default, and the start of BEARING-BA, the bearing default), and
- SMA(WGT), the best of the paper's ten (kNN-weighted SMACOF from the unweighted solution),
  swept over its K grid; the K with the lowest mean MPE is reported, as the paper's tables do
  (``--all-ten`` adds the other nine at their defaults).

It prints mean / max MPE over the non-anchor objects [m], mean MOE [%], the CPU time per map
(one BLAS thread), and how many maps carried a FoldWarning, then the goals.

    python benchmarks/bench_calibrated.py               # both sensors, both seed sets
    python benchmarks/bench_calibrated.py --sensors bearing --fresh-seed 777
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from threadpoolctl import threadpool_limits

import mappers
from lfmdr_gym.experiments.protocol import ProtocolConfig, collect_episode

GOALS = {  # CAL-SMA's targets: mean MPE [m], mean MOE [%], max MPE of one run [m]
    "visibility": (0.06, 1.6, 0.12),
    "bearing": (0.033, 0.6, 0.06),
}
TIME_GOAL = 0.5  # s per map at M = 50, one core


def _score(hist, method, **params):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        t0 = time.process_time()
        m = mappers.build_map(hist, hist.anchor_ids, hist.anchor_positions, method, **params)
        cpu = time.process_time() - t0
    folded = any("FoldWarning" in w for w in m.warnings) or any(
        issubclass(w.category, mappers.FoldWarning) for w in caught
    )
    truth = hist.object_positions
    keep = np.setdiff1d(np.arange(len(truth)), [*hist.anchor_ids, *m.unmapped])
    mpe = mappers.mean_position_error(m.positions[keep], truth[keep])
    moe = mappers.mean_orientation_error(m.positions[keep], truth[keep])
    return mpe, moe, cpu, folded


def _summary(rows):
    a = np.array([r[:3] for r in rows])
    return a[:, 0].mean(), a[:, 0].max(), a[:, 1].mean(), float(np.median(a[:, 2])), sum(
        r[3] for r in rows
    )


def run(sensor: str, seed: int, layouts: int, poses: int, steps: int, all_ten: bool) -> dict:
    cfg = ProtocolConfig(sensor=sensor, layouts=layouts, poses=poses, steps=steps, seed=seed,
                         methods=("LPCA",))
    hists = [collect_episode(ep) for ep in cfg.episodes()]
    out: dict[str, tuple] = {}
    with threadpool_limits(limits=1):
        out["CAL-SMA"] = _summary([_score(h, "CAL-SMA") for h in hists])
        best = None
        for k in mappers.METHODS["SMA(WGT)"].grid["n_neighbors"]:
            s = _summary([_score(h, "SMA(WGT)", n_neighbors=k) for h in hists])
            if best is None or s[0] < best[1][0]:
                best = (k, s)
        out[f"SMA(WGT) K={best[0]} (best K)"] = best[1]
        if all_ten:
            for label in mappers.METHODS:
                if label in ("CAL-SMA", "SMA(WGT)"):
                    continue
                rows = []
                for h in hists:
                    try:
                        rows.append(_score(h, label))
                    except ValueError:  # e.g. HLLE's eigenproblem (paper: "often failed")
                        continue
                if rows:
                    out[f"{label} (default, {len(rows)} runs)"] = _summary(rows)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sensors", nargs="+", default=["visibility", "bearing"])
    ap.add_argument("--paper-seed", type=int, default=0, help="the protocol's base seed")
    ap.add_argument("--fresh-seed", type=int, default=12345, help="never used for tuning")
    ap.add_argument("--layouts", type=int, default=5)
    ap.add_argument("--poses", type=int, default=5)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--all-ten", action="store_true")
    args = ap.parse_args()
    for sensor in args.sensors:
        goal_mpe, goal_moe, goal_max = GOALS[sensor]
        for name, seed in (("paper protocol", args.paper_seed), ("fresh", args.fresh_seed)):
            res = run(sensor, seed, args.layouts, args.poses, args.steps, args.all_ten)
            print(f"\n{sensor}, {name} seeds (base seed {seed}), "
                  f"{args.layouts}x{args.poses} runs, N={args.steps}")
            print(f"  {'method':34s} {'MPE mean':>9s} {'MPE max':>8s} {'MOE %':>6s} "
                  f"{'cpu s/map':>9s} {'folds':>5s}")
            for label, (mean, mx, moe, cpu, folds) in res.items():
                print(f"  {label:34s} {mean:9.4f} {mx:8.3f} {moe:6.2f} {cpu:9.3f} {folds:5d}")
            if args.steps != 2000:
                continue  # the goals are stated for N = 2000
            mean, mx, moe, cpu, _ = res["CAL-SMA"]
            ok = mean <= goal_mpe and moe <= goal_moe and mx <= goal_max and cpu <= TIME_GOAL
            print(f"  goals (MPE <= {goal_mpe}, MOE <= {goal_moe}, max <= {goal_max}, "
                  f"<= {TIME_GOAL} s): {'met' if ok else 'NOT met'}")


if __name__ == "__main__":
    main()
