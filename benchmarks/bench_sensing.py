"""Map error against imperfect sensing: bearing noise, field of view, max range, miss rate.

The paper's sensors are perfect; its §5.1 names noise and missing observations as the open
question. This sweep walks the random-walk agent through ``--runs`` fresh layouts (one start
pose each, N = ``--steps``) per sensing setting (:mod:`lfmdr_gym.sim.sensing_limits`) and maps every
history with each method that accepts it: the methods for masked histories and, when the
history is complete (noise alone), the sensor's default for complete ones. Five panels, each
varying one setting from the paper's world:

- bearing, noise 0-30 deg (full view, unlimited range);
- bearing, field of view 360-60 deg (2 deg noise);
- bearing, max range 2.0-0.75 m (full view, 2 deg noise);
- visibility, field of view 360-60 deg;
- visibility, miss rate 0-0.7.

Every setting of a run shares its layout and start pose, so the curves compare like with like.
Writes ``sensing.csv`` (one row per setting, run and method: mean non-anchor MPE [m], unmapped
objects, seconds per map) and ``sensing.png`` (mean non-anchor MPE with the spread over runs)
into ``--out``, and prints the table of means.

    python benchmarks/bench_sensing.py --jobs 2               # docs/results/sensing
    python benchmarks/bench_sensing.py --runs 2 --steps 1000 --out /tmp/sensing
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from joblib import Parallel, delayed
from threadpoolctl import threadpool_limits

from lfmdr_gym.atomic import atomic_write
from lfmdr_gym.experiments.episodes import Episode, collect_episode, derived_seed
from lfmdr_gym.experiments.scoring import evaluate

# panel -> (sensor, the setting varied, its values, the settings held fixed)
PANELS: dict[str, tuple[str, str, tuple[Any, ...], dict[str, Any]]] = {
    "bearing noise [deg]": ("bearing", "bearing_noise_deg", (0, 2, 5, 10, 20, 30), {}),
    "bearing field of view [deg] (2 deg noise)": (
        "bearing", "fov_deg", (360, 180, 90, 60), {"bearing_noise_deg": 2}),
    "bearing max range [m] (2 deg noise)": (
        "bearing", "max_range", (None, 2.0, 1.5, 1.0, 0.75), {"bearing_noise_deg": 2}),
    "visibility field of view [deg]": ("visibility", "fov_deg", (360, 180, 90, 60), {}),
    "visibility miss rate": ("visibility", "miss_rate", (0.0, 0.1, 0.3, 0.5, 0.7), {}),
}
# COVIS-ENSEMBLE groups consecutive steps and takes tens of seconds per map at N = 2000: too
# slow for a sweep of hundreds of maps; name it with --methods to include it.
SLOW = ("COVIS-ENSEMBLE",)
FIELDS = ("panel", "sensor", "setting", "value", "env_kwargs", "run", "method", "kind",
          "mpe_nonanchor", "unmapped", "seconds", "error", "default")


def _methods(sensor: str, masked: bool, chosen: list[str] | None) -> list[str]:
    """The methods that map this history: every masked-capable one (they take complete
    histories too) and, for a complete history, CAL-SMA (the localisation-free pipeline for
    complete histories) and the sensor's default for complete ones, if another."""
    from mappers import DEFAULT_METHODS, methods_for

    fits = list(methods_for(sensor, True))
    if not masked:
        for label in dict.fromkeys(("CAL-SMA", DEFAULT_METHODS[(sensor, False)])):
            if label not in fits:
                fits.insert(0, label)
    if chosen is None:
        return [m for m in fits if m not in SLOW]
    return [m for m in fits if m.lower() in {c.lower() for c in chosen}]


def _task(panel: str, value: Any, run: int, steps: int, seed: int,
          chosen: list[str] | None) -> list[dict[str, Any]]:
    sensor, setting, _, fixed = PANELS[panel]
    kwargs = {**fixed, **({} if value is None else {setting: value})}
    from lfmdr_gym import env_id_for

    episode = Episode(env_id_for(sensor), run, 0, derived_seed(seed, run), derived_seed(seed, run, 0),
                      steps, tuple(sorted(kwargs.items())))
    with threadpool_limits(1):  # one BLAS thread per map, as the protocol
        history = collect_episode(episode)
        masked = history.partly_observed
        from mappers import default_method

        default = default_method(history)  # what build_map picks (a flickering history: dropouts)
        methods = _methods(sensor, masked, chosen)
        if chosen is None and default not in methods:
            methods.insert(0, default)
        rows = []
        for method in methods:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.perf_counter()
                result = evaluate(history, method)
            rows.append({
                "panel": panel, "sensor": sensor, "setting": setting,
                "value": "none" if value is None else value, "env_kwargs": json.dumps(kwargs),
                "run": run, "method": method, "kind": "masked" if masked else "complete",
                "mpe_nonanchor": result["mpe_nonanchor"], "unmapped": result["unmapped"],
                "seconds": time.perf_counter() - t0, "error": result["error"],
                "default": default,
            })
    return rows


def _is_default(row: dict[str, Any]) -> bool:
    """Whether ``row``'s method is the one ``build_map`` picks for its history by default."""
    from mappers import DEFAULT_METHODS

    if row.get("default"):  # recorded since the flicker routing (mappers.core.flicker)
        return row["method"] == row["default"]
    return row["method"] == DEFAULT_METHODS[(row["sensor"], row["kind"] == "masked")]


def _spread(rows, panel, labels, keep) -> tuple[list[float], list[float], list[float]]:
    """Mean, min and max of the non-anchor MPE over runs, per value of ``panel``."""
    mean, lo, hi = [], [], []
    for v in labels:
        e = np.array([r["mpe_nonanchor"] for r in rows
                      if r["panel"] == panel and r["value"] == v and keep(r)], dtype=float)
        e = e[np.isfinite(e)]
        mean.append(e.mean() if e.size else np.nan)
        lo.append(e.min() if e.size else np.nan)
        hi.append(e.max() if e.size else np.nan)
    return mean, lo, hi


def _plot(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # each row its own scale: bearing maps reach 1e-9 m (BEARING-BA), visibility maps 0.03 m
    fig, grid = plt.subplots(2, 3, figsize=(13.5, 7.6), sharey="row")
    axes = grid.ravel()
    axes[-1].set_axis_off()
    for ax, (panel, (_, _, values, _)) in zip(axes, PANELS.items(), strict=False):
        labels = ["none" if v is None else v for v in values]
        x = np.arange(len(values))
        methods = list(dict.fromkeys(r["method"] for r in rows if r["panel"] == panel))
        for method in methods:
            mean, lo, hi = _spread(rows, panel, labels, lambda r, m=method: r["method"] == m)
            line, = ax.plot(x, mean, "o-", label=method)
            ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.12)
        mean, _, _ = _spread(rows, panel, labels, _is_default)
        ax.plot(x, mean, "k--", lw=1.2, label="default (build_map)")
        ax.set_xticks(x, [str(v) for v in labels])
        ax.set_title(panel, fontsize=9)
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    for ax in grid[:, 0]:
        ax.set_ylabel("non-anchor MPE [m]: mean, band min-max")
    fig.tight_layout()
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)


def _write_csv(rows: list[dict[str, Any]], path: Path) -> None:
    with atomic_write(path) as fh:
        writer = csv.DictWriter(fh, fieldnames=FIELDS, lineterminator="\n")
        writer.writeheader()
        for r in rows:
            writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def _print_table(rows: list[dict[str, Any]]) -> None:
    for panel in PANELS:
        print(f"\n{panel}: mean non-anchor MPE [m] (max over runs), median seconds per map")
        methods = list(dict.fromkeys(r["method"] for r in rows if r["panel"] == panel))
        for v in dict.fromkeys(r["value"] for r in rows if r["panel"] == panel):
            cells = []
            for m in methods:
                sel = [r for r in rows if r["panel"] == panel and r["method"] == m and r["value"] == v]
                e = np.array([r["mpe_nonanchor"] for r in sel], dtype=float)
                if not sel:
                    continue
                sec = np.median([r["seconds"] for r in sel])
                if np.isnan(e).all():
                    cells.append(f"{m} failed in all {e.size} runs")
                    continue
                cells.append(f"{m} {np.nanmean(e):.3f} ({np.nanmax(e):.3f}) {sec:.1f}s"
                             + (f" [{int(np.isnan(e).sum())} failed]" if np.isnan(e).any() else ""))
            print(f"  {v!s:>6}: " + "; ".join(cells))


def _read_csv(path: Path) -> list[dict[str, Any]]:
    """The rows of a ``sensing.csv`` written by this script (for --replot)."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        r["value"] = "none" if r["value"] == "none" else float(r["value"])
        for key in ("mpe_nonanchor", "seconds"):
            r[key] = float(r[key])
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=5, help="layouts (one start pose each) per setting")
    p.add_argument("--steps", type=int, default=2000, help="episode length N")
    p.add_argument("--seed", type=int, default=2026, help="base seed of the layouts (fresh: "
                   "not the protocol's 0)")
    p.add_argument("--methods", nargs="+", default=None,
                   help=f"methods to draw, among those that accept each history (default: all "
                        f"but {', '.join(SLOW)})")
    p.add_argument("--panels", nargs="+", default=None, choices=list(PANELS), metavar="PANEL",
                   help="panels to run (default: all)")
    p.add_argument("--jobs", type=int, default=1, help="worker processes")
    p.add_argument("--out", default="docs/results/sensing", help="output directory")
    p.add_argument("--replot", action="store_true",
                   help="only redraw sensing.png and reprint the table from --out/sensing.csv")
    args = p.parse_args()
    if args.replot:
        rows = _read_csv(Path(args.out) / "sensing.csv")
        _plot(rows, Path(args.out) / "sensing.png")
        _print_table(rows)
        return
    if args.runs < 1 or args.steps < 1:
        p.error("--runs and --steps must be positive")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    panels = args.panels or list(PANELS)
    tasks = [(panel, v, run) for panel in panels for v in PANELS[panel][2] for run in range(args.runs)]
    t0 = time.perf_counter()
    results = Parallel(n_jobs=args.jobs, return_as="generator_unordered")(
        delayed(_task)(panel, v, run, args.steps, args.seed, args.methods) for panel, v, run in tasks)
    rows = []
    for done, task_rows in enumerate(results, 1):
        rows.extend(task_rows)
        print(f"\r{done}/{len(tasks)} histories mapped", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    order = {(panel, v, run): i for i, (panel, v, run) in enumerate(tasks)}
    methods = {m: i for i, m in enumerate(dict.fromkeys(r["method"] for r in rows))}
    rows.sort(key=lambda r: (order[(r["panel"], None if r["value"] == "none" else r["value"],
                                    r["run"])], methods[r["method"]]))
    _write_csv(rows, out / "sensing.csv")
    if set(panels) == set(PANELS):
        _plot(rows, out / "sensing.png")
    _print_table(rows)
    print(f"\n{len(rows)} maps of {len(tasks)} histories in {time.perf_counter() - t0:.0f} s; "
          f"wrote {out / 'sensing.csv'}" + (f" and {out / 'sensing.png'}" if set(panels) == set(PANELS) else ""))


if __name__ == "__main__":
    main()
