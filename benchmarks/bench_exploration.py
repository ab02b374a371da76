"""Map error against steps for each exploration policy of ``lfmdr_gym.POLICIES``, both sensors.

For each sensor (visibility, bearing) and each policy it walks fresh layouts (seeds never used
to tune a policy), the same layout and start pose for every policy, and maps the first 250,
500, 1,000 and 2,000 steps with the default mapper (CAL-SMA for visibility, BEARING-BA for
bearing). It prints the mean MPE over the
non-anchor objects [m] per policy and number of steps, then the goal: the best policy's map
after 500 steps at least as good as the random walk's after 2,000. ``--plot FILE`` draws the
figure (matplotlib, the ``plots`` extra).

    python benchmarks/bench_exploration.py --plot docs/exploration.png  # 25 layouts
    python benchmarks/bench_exploration.py --runs 5 --sensors visibility
    python benchmarks/bench_exploration.py --runs 6 --seed 5000 --policies rl \
        --rl-model /tmp/m.npz   # a model of one's own, on layouts for tuning
    python benchmarks/bench_exploration.py --sensors bearing \
        --policies random-walk even --env bearing_noise_deg=2   # imperfect sensing

``--env KEY=VALUE`` (repeatable) passes env keywords (noise; a limited view, whose masked
history is mapped with the masked default); the CSV does not record them.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np
from threadpoolctl import threadpool_limits

import mappers
from lfmdr_gym import POLICIES, collect, env_id_for
from lfmdr_gym.experiments.env_settings import check_env_kwargs, parse_env_kwargs
from lfmdr_gym.experiments.episodes import derived_seed, make_env
from lfmdr_gym.experiments.scoring import mpe_nonanchor

STEPS = (250, 500, 1000, 2000)


def _mpe(hist, n: int, method: str | None = None) -> tuple[float, str | None]:
    """MPE of the map of the first n steps (``method``: None for the default); NaN when no map
    can be made (fewer than 3 anchors sensed yet: a policy that has not been near three corners
    has no map to score; or, through a limited view, co-observations too few for the method:
    :class:`mappers.MappingError`), with the label of the method that made the map (None
    without one). The printout counts the layouts without a map."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            m = mappers.build_map(hist.head(n), hist.anchor_ids, hist.anchor_positions, method)
        except mappers.MappingError:
            return float("nan"), None
        except ValueError as exc:
            if "anchors remain" not in str(exc):
                raise
            return float("nan"), None
    return mpe_nonanchor(m.positions, m.unmapped, hist), m.method


def column_means(rows: np.ndarray) -> np.ndarray:
    """Per step count (column), the mean MPE over the layouts that have a map; NaN where none
    has one (through a limited view no layout has a map at 250 steps), without numpy's warning
    about an empty mean."""
    ok = np.isfinite(rows)
    count = ok.sum(axis=0)
    return np.where(count > 0, np.where(ok, rows, 0.0).sum(axis=0) / np.maximum(count, 1), np.nan)


def run(sensor: str, runs: int, seed: int, policies: list[str] | None = None,
        kwargs: dict[str, dict] | None = None, method: str | None = None,
        env_kwargs: dict | None = None, labels: set | None = None) -> dict[str, np.ndarray]:
    """Per policy, an array (runs, len(STEPS)) of MPEs. ``kwargs``: per policy, factory keywords
    (e.g. ``{"rl": {"model": "m.npz"}}`` to score a model of one's own); ``method``: map with
    this method instead of the default; ``env_kwargs``: env keywords (e.g.
    ``{"bearing_noise_deg": 2.0}``); ``labels``: a set to which the labels of the methods that
    made the maps are added (the default depends on the sensor and on whether the env masks the
    history)."""
    names = list(POLICIES) if policies is None else policies
    unknown = [n for n in names if n not in POLICIES]
    if unknown:
        raise ValueError(f"unknown policies {unknown}; registered: {list(POLICIES)}")
    out: dict[str, list] = {name: [] for name in names}
    for r in range(runs):
        s = derived_seed(seed, r)
        for name in names:
            env = make_env(env_id_for(sensor), max(STEPS), env_kwargs)
            try:
                policy = POLICIES[name](env, seed=s, **(kwargs or {}).get(name, {}))
                hist = collect(env, policy, max(STEPS), seed=s)
            finally:
                env.close()
            with threadpool_limits(limits=1):
                scored = [_mpe(hist, n, method) for n in STEPS]
            out[name].append([value for value, _ in scored])
            if labels is not None:
                labels.update(label for _, label in scored if label is not None)
    return {name: np.array(rows) for name, rows in out.items()}


def save_csv(results: dict[str, dict[str, np.ndarray]], path: str, seed: int,
             methods: dict[str, str] | None = None) -> None:
    """Tidy rows (sensor, policy, seed, layout, steps, mpe, method), written atomically;
    ``methods``: per sensor, the label(s) of the mapping method (empty when not given)."""
    import csv

    from lfmdr_gym.atomic import atomic_write

    with atomic_write(path) as fh:
        out = csv.writer(fh)
        out.writerow(["sensor", "policy", "seed", "layout", "steps", "mpe", "method"])
        for sensor, res in results.items():
            label = (methods or {}).get(sensor, "")
            for name, rows in res.items():
                for r, row in enumerate(rows):
                    for n, v in zip(STEPS, row, strict=True):
                        out.writerow([sensor, name, seed, r, n, repr(float(v)), label])


def load_csv(paths: list[str], methods: dict[str, str] | None = None
             ) -> dict[str, dict[str, np.ndarray]]:
    """The results :func:`save_csv` wrote, merged over files (policies run separately). A
    ``methods`` dict given is filled, per sensor, with the mapping methods the files record
    (joined by " / "; files written before the column existed record none)."""
    import csv

    cells: dict[str, dict[str, dict[int, dict[int, float]]]] = {}
    found: dict[str, list[str]] = {}
    for path in paths:
        with open(path, newline="", encoding="utf-8") as fh:
            for row in csv.DictReader(fh):
                per = cells.setdefault(row["sensor"], {}).setdefault(row["policy"], {})
                per.setdefault(int(row["layout"]), {})[int(row["steps"])] = float(row["mpe"])
                labels = found.setdefault(row["sensor"], [])
                for label in (row.get("method") or "").split(" / "):
                    if label and label not in labels:
                        labels.append(label)
    if methods is not None:
        methods.update({sensor: " / ".join(labels) for sensor, labels in found.items() if labels})
    return {sensor: {name: np.array([[runs[r][n] for n in STEPS] for r in sorted(runs)])
                     for name, runs in res.items()} for sensor, res in cells.items()}


def plot(results: dict[str, dict[str, np.ndarray]], path: str,
         methods: dict[str, str] | None = None) -> None:
    """MPE against steps per policy, one panel per sensor, titled with ``methods[sensor]``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lfmdr_gym.atomic import atomic_write

    fig, axes = plt.subplots(1, len(results), figsize=(4.2 * len(results), 3.4), squeeze=False)
    for ax, (sensor, res) in zip(axes[0], results.items(), strict=True):
        for name, rows in res.items():
            ax.plot(STEPS, column_means(rows), marker="o", label=name)
        label = (methods or {}).get(sensor)
        ax.set(title=f"{sensor} ({label + ', ' if label else ''}{len(rows)} layouts)", xlabel="steps",
               ylabel="mean MPE [m]", xscale="log")
        ax.set_xticks(STEPS, [str(n) for n in STEPS])
        ax.minorticks_off()
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sensors", nargs="+", default=["visibility", "bearing"])
    ap.add_argument("--runs", type=int, default=25, help="fresh layouts (one start pose each)")
    ap.add_argument("--seed", type=int, default=4711, help="never used for tuning")
    ap.add_argument("--policies", nargs="+", default=None, help="default: every registered one")
    ap.add_argument("--rl-model", default=None, metavar="FILE.npz",
                    help="score this model as the 'rl' policy (default: the shipped one)")
    ap.add_argument("--method", default=None,
                    help="map with this method (a label of mappers.METHODS) instead of the default")
    ap.add_argument("--env", action="append", default=[], metavar="KEY=VALUE",
                    help="env keyword (repeatable), e.g. bearing_noise_deg=2")
    ap.add_argument("--plot", default=None, metavar="FILE.png")
    ap.add_argument("--csv", default=None, metavar="FILE.csv", help="write the per-run MPEs")
    ap.add_argument("--load", nargs="+", default=None, metavar="FILE.csv",
                    help="print and plot these saved runs (merged) instead of running")
    args = ap.parse_args()
    try:
        env_kwargs = parse_env_kwargs(args.env)
        for sensor in args.sensors if not args.load else ():
            check_env_kwargs(sensor, env_kwargs)
    except ValueError as err:
        ap.error(f"--env: {err}")
    kwargs = {"rl": {"model": args.rl_model}} if args.rl_model else None
    if args.load:
        methods = {}
        results = load_csv(args.load, methods)
    else:
        results, methods = {}, {}
        for sensor in args.sensors:
            labels: set = set()
            results[sensor] = run(sensor, args.runs, args.seed, args.policies, kwargs, args.method,
                                  env_kwargs or None, labels)
            methods[sensor] = " / ".join(sorted(labels))
    if args.csv:
        save_csv(results, args.csv, args.seed, methods)
    for sensor, res in results.items():
        n_runs = len(next(iter(res.values())))
        print(f"\n{sensor}: mean MPE [m] over {n_runs} layouts"
              f"{f' ({methods[sensor]})' if methods.get(sensor) else ''}")
        print(f"  {'policy':14s}" + "".join(f"{n:>9d}" for n in STEPS))
        for name, rows in res.items():
            failed = np.isnan(rows).sum(axis=0)
            note = "" if not failed.any() else (
                f"   (layouts without a map: {failed.tolist()}; fewer than 3 anchors sensed, or "
                "too few co-observations for the method)")
            print(f"  {name:14s}" + "".join(f"{v:9.4f}" for v in column_means(rows)) + note)
        if "random-walk" not in res:
            continue
        target = column_means(res["random-walk"])[STEPS.index(2000)]
        best, value = min(((n, column_means(r)[STEPS.index(500)]) for n, r in res.items()),
                          key=lambda t: t[1])
        print(f"  goal: best at 500 steps ({best}, {value:.4f}) <= random walk at 2000 "
              f"({target:.4f}): {'met' if value <= target else 'NOT met'}")
    if args.plot:
        plot(results, args.plot, methods)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
