"""MOE benchmark: the exact O(M^2 log M) mean_orientation_error against the O(M^3) brute force.

Run from the project root:

    python benchmarks/bench_scores.py                    # M = 200, 500, 1000, 2000
    python benchmarks/bench_scores.py --sizes 500 4000 --max-brute 1000 --repeats 5

Layouts: uniform random truth in the unit square, estimate = truth + N(0, 0.05^2) noise (a
typical map), plus an integer-grid truth with a rounded noisy estimate (many exactly collinear
triples, the degenerate case). Both functions must give the identical MOE; the brute force is
skipped above --max-brute. The machine is shared: times are medians, compare ratios rather
than absolute figures.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from threadpoolctl import threadpool_limits

from mappers.core.scores import _moe_bruteforce, mean_orientation_error


def brute_moe(est: np.ndarray, truth: np.ndarray) -> float:
    """The previous mean_orientation_error, minus its input checks."""
    n = len(est)
    return 100.0 * _moe_bruteforce(est, truth) / (n * (n - 1) * (n - 2) // 6)


def layout(kind: str, m: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    if kind == "random":
        truth = rng.uniform(size=(m, 2))
        return truth + 0.05 * rng.normal(size=(m, 2)), truth
    side = int(np.ceil(np.sqrt(m)))
    truth = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:m]
    truth = truth.astype(float)
    return np.round(truth + 0.5 * rng.normal(size=truth.shape)), truth


def timed(fn, est, truth, repeats: int) -> tuple[float, float]:
    times, value = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        value = fn(est, truth)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), value


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", nargs="+", type=int, default=[200, 500, 1000, 2000])
    p.add_argument("--layouts", nargs="+", default=["random", "grid"], choices=["random", "grid"])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--max-brute", type=int, default=2000, help="largest M for the brute force")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    rng = np.random.default_rng(args.seed)
    mismatches = 0
    with threadpool_limits(limits=1):  # the machine is shared; one BLAS thread is steadier
        for kind in args.layouts:
            print(f"\n## {kind} layout: median of {args.repeats} runs")
            print(f"{'M':>5s} {'fast s':>9s} {'brute s':>9s} {'speed-up':>9s} {'MOE %':>10s}  same")
            for m in args.sizes:
                est, truth = layout(kind, m, rng)
                t_fast, v_fast = timed(mean_orientation_error, est, truth, args.repeats)
                if m <= args.max_brute:
                    t_brute, v_brute = timed(brute_moe, est, truth, args.repeats)
                    same = v_fast == v_brute
                    mismatches += not same
                    print(f"{m:5d} {t_fast:9.3f} {t_brute:9.3f} {t_brute / t_fast:8.1f}x "
                          f"{v_fast:10.6f}  {'yes' if same else f'NO (brute {v_brute!r})'}")
                else:
                    print(f"{m:5d} {t_fast:9.3f} {'-':>9s} {'-':>9s} {v_fast:10.6f}  -")
    if mismatches:
        raise SystemExit(f"{mismatches} size(s) where the fast MOE differs from the brute force")


if __name__ == "__main__":
    main()
