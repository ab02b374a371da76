"""The online map against rebuilding it: cost per update and accuracy as the run grows.

For each sensor (visibility, bearing) it collects fresh layouts (seeds never used to tune
anything) with the random walk, feeds :class:`mappers.OnlineMapper` (default method: CAL-SMA
for visibility, BEARING-BA for bearing, both updated incrementally) the columns of 10 new steps
at a time and prints, over the runs:

- the CPU time of one update, median and mean (the mean includes the occasional full refits),
  against ``build_map`` on the whole history at N steps (one BLAS thread), and their ratio;
- the MPE of the online map at 500, 1,000, 1,500 and N steps over the offline map's of the
  same steps (mean and max of the ratio), and both mean MPEs [m].

The offline map is ``build_map``'s default for bearing (BEARING-BA), and the online map's own
method for visibility (CAL-SMA, the default for perfect visibility). ``--env`` passes env
keywords (imperfect sensing, e.g. ``bearing_noise_deg=2``; masked histories are fed with their
masks, an all-True mask, as noise alone gives, as a complete history; with a limited view, e.g.
``fov_deg=90``, both maps are the masked default's, VIEW-BA, which the online mapper carries on
between its refits). A bad ``--env`` item is refused with the experiments' own message.

    python benchmarks/bench_online.py                  # 25 layouts per sensor
    python benchmarks/bench_online.py --runs 5 --sensors bearing
    python benchmarks/bench_online.py --runs 8 --seed 777 --warm-rounds 2   # variants
    python benchmarks/bench_online.py --runs 8 --seed 777 --warm-tol 1e-6 --fold-check-every 1
    python benchmarks/bench_online.py --runs 8 --sensors bearing --env bearing_noise_deg=2
    python benchmarks/bench_online.py --runs 8 --sensors visibility --env fov_deg=90
    python benchmarks/bench_online.py --sensors visibility --env fov_deg=90 --reference-lag 100

``--reference-lag K`` also maps offline K steps before each checkpoint and prints that map's mean
MPE over the checkpoint's: how far the reference itself moves in K steps (for VIEW-BA through a
90-degree view, ``--reference-lag 10`` moves the mean over the 25 layouts by up to 12 %, further
than the final goal's 1.05: ``docs/online-and-exploration.md``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from threadpoolctl import threadpool_limits

import mappers
from lfmdr_gym.experiments.env_settings import check_env_kwargs, parse_env_kwargs
from lfmdr_gym.experiments.protocol import ProtocolConfig, collect_episode
from lfmdr_gym.experiments.scoring import mpe_nonanchor
from mappers.core.sensors import COLUMNS_PER_STEP

GOAL_SPEEDUP, GOAL_FINAL, GOAL_CHECKPOINT = 20.0, 1.05, 1.1


def _mpe(result, hist) -> float:
    """NaN when nothing is mapped yet (a limited view's first steps)."""
    return mpe_nonanchor(result.positions, result.unmapped, hist)


def one_run(hist, steps: int, batch: int, checkpoints: tuple[int, ...], lag: int = 0,
            **online) -> dict:
    """One layout: update times, and the online and offline MPEs at each checkpoint; with
    ``lag`` > 0 also the offline map's MPE ``lag`` steps before each checkpoint (``lagged``)."""
    c = COLUMNS_PER_STEP[hist.sensor]
    om = mappers.OnlineMapper(hist.anchor_ids, hist.anchor_positions, sensor=hist.sensor, **online)
    times, ratios, online, offline, lagged = [], [], [], [], []
    reference = None  # bearing: build_map's default (BEARING-BA); visibility: the online method
    X = hist.matrix
    # an env with noise only reports an all-True mask: a complete history
    mask = hist.mask if hist.partly_observed else None

    def offline_map(n: int, method):
        cols = n * c
        return mappers.build_map(X[:, :cols], hist.anchor_ids, hist.anchor_positions, method,
                                 sensor=hist.sensor, mask=None if mask is None else mask[:, :cols])

    def offline_mpe(n: int) -> float:
        try:
            return _mpe(offline_map(n, reference), hist)
        except ValueError:  # too few steps to map (a limited view at 500 steps): no ratio
            return np.nan

    for s in range(0, steps, batch):
        cols = slice(s * c, (s + batch) * c)
        t0 = time.process_time()
        current = om.update(X[:, cols], None if mask is None else mask[:, cols])
        times.append(time.process_time() - t0)
        if hist.sensor != "bearing":
            reference = current.method
        if s + batch in checkpoints:
            online.append(_mpe(current, hist))
            offline.append(offline_mpe(s + batch))
            if lag:
                lagged.append(offline_mpe(s + batch - lag))
            ratios.append(online[-1] / offline[-1])
    t0 = time.process_time()
    try:
        offline_map(steps, reference)
        rebuild = time.process_time() - t0
    except ValueError:  # no map of the N steps (a limited view, a short run): no time to compare
        rebuild = np.nan
    return {"median": np.median(times), "mean": np.mean(times), "rebuild": rebuild,
            "ratios": ratios, "online": online, "offline": offline, "lagged": lagged,
            "refits": om.n_full_fits, "fold_refits": om.n_fold_refits, "growth": om.refit_growth}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sensors", nargs="+", default=["visibility", "bearing"])
    ap.add_argument("--runs", type=int, default=25, help="fresh layouts (one start pose each)")
    ap.add_argument("--seed", type=int, default=31337, help="never used for tuning")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--batch", type=int, default=10, help="new steps per update")
    ap.add_argument("--warm-rounds", type=int, default=1, help="OnlineMapper's warm_rounds")
    ap.add_argument("--refit-growth", type=float, default=None,
                    help="OnlineMapper's refit_growth (default: its own, 4, or 1.25 for VIEW-BA)")
    ap.add_argument("--warm-tol", type=float, default=1e-4, help="OnlineMapper's warm_tol")
    ap.add_argument("--fold-check-every", type=int, default=5,
                    help="OnlineMapper's fold_check_every")
    ap.add_argument("--bundle-every", type=int, default=5, help="OnlineMapper's bundle_every")
    ap.add_argument("--bundle-rounds", type=int, default=1, help="OnlineMapper's bundle_rounds")
    ap.add_argument("--env", action="append", default=[], metavar="KEY=VALUE",
                    help="env keyword (repeatable), e.g. bearing_noise_deg=2")
    ap.add_argument("--reference-lag", type=int, default=0, metavar="K",
                    help="also map offline K steps before each checkpoint and print that map's "
                         "MPE over the checkpoint's: how far the offline reference itself moves")
    args = ap.parse_args()
    if not 0 <= args.reference_lag < 500:
        ap.error(f"--reference-lag must be in [0, 500), got {args.reference_lag}")
    try:
        env = parse_env_kwargs(args.env) or None
        masked = {sensor: check_env_kwargs(sensor, env)[1] for sensor in args.sensors}
    except ValueError as err:
        ap.error(f"--env: {err}")
    checkpoints = tuple(n for n in (500, 1000, 1500) if n < args.steps) + (args.steps,)
    for sensor in args.sensors:
        # a limited view or range masks the history: the protocol checks its method against that
        method = mappers.resolve_method(None, sensor, masked=masked[sensor]).label
        cfg = ProtocolConfig(sensor=sensor, layouts=args.runs, poses=1, steps=args.steps,
                             seed=args.seed, methods=(method,), env_kwargs=env)
        with threadpool_limits(limits=1):
            rows = [one_run(collect_episode(ep), args.steps, args.batch, checkpoints,
                            lag=args.reference_lag, warm_rounds=args.warm_rounds,
                            refit_growth=args.refit_growth, warm_tol=args.warm_tol,
                            fold_check_every=args.fold_check_every,
                            bundle_every=args.bundle_every, bundle_rounds=args.bundle_rounds)
                    for ep in cfg.episodes()]
        med = np.median([r["median"] for r in rows])
        mean = np.mean([r["mean"] for r in rows])
        rebuild = np.nanmedian([r["rebuild"] for r in rows])  # NaN: no layout had a map at N
        R = np.array([r["ratios"] for r in rows])  # NaN where the offline map could not be made
        print(f"\n{sensor}: {len(rows)} fresh layouts (seed {args.seed}), updates of {args.batch} "
              f"steps, N = {args.steps}, warm_rounds {args.warm_rounds}, refit_growth "
              f"{rows[0]['growth']:g}, warm_tol {args.warm_tol:g}, fold_check_every "
              f"{args.fold_check_every}, bundle_every {args.bundle_every}, bundle_rounds "
              f"{args.bundle_rounds}{f', env {env}' if env else ''}")
        print(f"  rebuild at N: {rebuild * 1e3:.1f} ms;  update: median {med * 1e3:.2f} ms "
              f"({rebuild / med:.1f}x cheaper), mean incl. refits {mean * 1e3:.2f} ms "
              f"({rebuild / mean:.1f}x); full refits per run {np.mean([r['refits'] for r in rows]):.1f} "
              f"({np.mean([r['fold_refits'] for r in rows]):.1f} of them after a fold check)")
        lag = args.reference_lag
        print(f"  {'steps':>6s} {'online MPE':>10s} {'offline MPE':>11s} {'ratio mean':>10s} "
              f"{'ratio max':>9s}" + (f" {f'offline N-{lag} / N':>17s}" if lag else ""))
        ratios = []  # of the mean MPEs, where both maps exist
        for j, n in enumerate(checkpoints):
            ok = [r for r in rows if np.isfinite(r["ratios"][j])]  # both maps made
            on = np.mean([r["online"][j] for r in ok]) if ok else np.nan
            off = np.mean([r["offline"][j] for r in ok]) if ok else np.nan
            ratios.append(on / off)
            moved = ""
            if lag:  # the offline map K steps before over the checkpoint's, where all three exist
                both = [r for r in ok if np.isfinite(r["lagged"][j])]
                before = np.mean([r["lagged"][j] for r in both]) if both else np.nan
                at = np.mean([r["offline"][j] for r in both]) if both else np.nan
                moved = f" {before / at:17.3f}" if both else f" {'-':>17s}"
            print(f"  {n:6d} {on:10.4g} {off:11.4g} {on / off:10.3f} "
                  f"{np.nanmax(R[:, j]):9.3f}{moved}"
                  f"{'' if len(ok) == len(rows) else f'  ({len(rows) - len(ok)} runs without both maps)'}")
        final, mids = ratios[-1], ratios[:-1]
        mid_goal = ("no checkpoint before N" if not mids
                    else "met" if max(mids) <= GOAL_CHECKPOINT else "NOT met")
        print(f"  goals: update >= {GOAL_SPEEDUP:.0f}x cheaper (median: "
              f"{'met' if rebuild / med >= GOAL_SPEEDUP else 'NOT met'}; mean: "
              f"{'met' if rebuild / mean >= GOAL_SPEEDUP else 'NOT met'}), final MPE <= "
              f"{GOAL_FINAL} x offline ({'met' if final <= GOAL_FINAL else 'NOT met'}), checkpoints "
              f"<= {GOAL_CHECKPOINT} x ({mid_goal})")


if __name__ == "__main__":
    main()
