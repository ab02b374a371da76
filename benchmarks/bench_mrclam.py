"""MRCLAM: map every run with every sensor and print MPE / MOE per run, with baselines.

    python benchmarks/bench_mrclam.py [--data DIR] [--sensors visibility,bearing,range,range-bearing]
        [--candidates COVIS-ENSEMBLE,RANGE-QUANTILE]

For each run and sensor (4 corner anchors, all 5 robots, scores over the 11 non-anchor landmarks):

* ``centroid``: every landmark at the anchors' centroid;
* ``naive``: the straightforward pipeline on 1 s bins (zero-filled history, L2-normalised rows,
  unweighted SMACOF from classical MDS, affine fit to the anchors);
* ``masked-euclidean`` (bearing, range): RMS history difference over co-observed bins only,
  weighted SMACOF over the pairs that have it (the masked form of the paper's recipe; a dead
  end, docs/dead-ends.md, registered here for this table only);
* each masked method (mappers/masked/pair_maps.py) that suits the sensor, with its default
  settings: ``covis-nonmetric`` at one bin width (a building block: ``COVIS-ENSEMBLE`` with one
  ``covis-nonmetric`` member), ``RANGE-QUANTILE`` and ``range-bounds`` (a dead end, registered
  here for this table only);
* ``<method> LOO``: the method with the setting chosen *without* the run (lowest mean MPE over
  the other runs in a small grid), i.e. a score on a run the setting was not tuned on.

* ``COVIS-ENSEMBLE/nonmetric``: the mean of the covis-nonmetric maps over bin widths
  {1, 1.5, 2, 3, 4, 5} s x min_co {3, 5} (anchors fixed, one frame);
* ``COVIS-ENSEMBLE`` (visibility, bearing; the default of both on logged runs): the same with
  covis-power members (metric link distance = a * (-log co-observation rate) ** 0.5; a run whose
  usable pairs fall apart keeps the covis-nonmetric members, with a warning).

Settings grids: covis-nonmetric (visibility, bearing): bin width {1, 2, 3, 5} s x min_co {3, 5};
COVIS-ENSEMBLE/nonmetric: the set of bin widths, {1, 2, 3, 5} / {1, 1.5, 2, 3, 4, 5} /
{0.5, ..., 8} s; COVIS-ENSEMBLE: power {0.35, 0.5, 0.7, 1}; RANGE-QUANTILE: bin width
{0.25, 0.5, 1} s x quantile {0.95, 0.98, 0.99}; range-bounds: the same x slack {0.5, 1}.
LOC-SMA (range-bearing, the default of both measurements fused): bin width {0.25, 0.5} s x
min_count {3, 10} x trim {None (weighted median), 3}.
What was tried for bearings and lost is in docs/bearing-on-real-data.md.
"""

from __future__ import annotations

import argparse
import itertools
import time
import warnings
from pathlib import Path

import numpy as np

from lfmdr_gym.datasets.mrclam import DEFAULT_BIN_WIDTH, MRCLAMDataWarning
from lfmdr_gym.experiments.mrclam import map_mrclam_run
from mappers import MethodSpec, register_method

# The dead ends of the table, no longer labels of the catalog (docs/dead-ends.md): their building
# blocks registered here, for this benchmark only, with the specs they had.
_MASKED = {"uses_anchors": True, "normalize": False, "histories": ("complete", "masked")}
DEAD_ENDS = {
    "masked-euclidean": MethodSpec("MASKED-EUCLIDEAN", "mappers.masked.pair_maps:_masked_euclidean",
                                   **_MASKED),
    "range-bounds": MethodSpec("RANGE-BOUNDS", "mappers.masked.pair_maps:_range_bounds",
                               sensors=("range",), **_MASKED),
}

GRIDS = {
    "covis-nonmetric": [
        {"bin_width": bw, "min_co": mc} for bw, mc in itertools.product([1.0, 2.0, 3.0, 5.0], [3, 5])
    ],
    "RANGE-QUANTILE": [
        {"bin_width": bw, "quantile": q}
        for bw, q in itertools.product([0.25, 0.5, 1.0], [0.95, 0.98, 0.99])
    ],
    "range-bounds": [
        {"bin_width": bw, "quantile": q, "slack": sl}
        for bw, q, sl in itertools.product([0.25, 0.5, 1.0], [0.95, 0.98, 0.99], [0.5, 1.0])
    ],
    "COVIS-ENSEMBLE": [{"power": pw} for pw in (0.35, 0.5, 0.7, 1.0)],
    "COVIS-ENSEMBLE/nonmetric": [
        {"bin_widths": bws}
        for bws in [(1.0, 2.0, 3.0, 5.0), (1.0, 1.5, 2.0, 3.0, 4.0, 5.0),
                    (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 8.0)]
    ],
    "masked-euclidean": [],
    "LOC-SMA": [
        {"bin_width": bw, "min_count": mc, "trim": tr}
        for bw, mc, tr in itertools.product([0.25, 0.5], [3, 10], [None, 3.0])
    ],
}
CANDIDATES = {
    "visibility": ["covis-nonmetric", "COVIS-ENSEMBLE/nonmetric", "COVIS-ENSEMBLE"],
    "bearing": ["masked-euclidean", "covis-nonmetric", "COVIS-ENSEMBLE/nonmetric",
                "COVIS-ENSEMBLE"],
    "range": ["masked-euclidean", "RANGE-QUANTILE", "range-bounds"],
    "range-bearing": ["LOC-SMA"],
}


def _run(run_dir: Path, sensor: str, method: str | None, **kw):
    if method == "COVIS-ENSEMBLE/nonmetric":
        method, kw = "COVIS-ENSEMBLE", {**kw, "member": "covis-nonmetric"}
    elif method == "covis-nonmetric":  # the building block at one bin width: one member
        width, min_co = kw.pop("bin_width", DEFAULT_BIN_WIDTH[sensor]), kw.pop("min_co", 3)
        method = "COVIS-ENSEMBLE"
        kw = {**kw, "member": "covis-nonmetric", "bin_widths": (width,), "min_co": min_co}
    elif method in DEAD_ENDS:
        method = register_method(DEAD_ENDS[method], replace=True).label
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MRCLAMDataWarning)
        return map_mrclam_run(run_dir, sensor, method=method, **kw)


def main(argv: list[str] | None = None) -> None:
    here = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=here.parent / "shared" / "data" / "mrclam")
    ap.add_argument("--sensors", "--modes", default="visibility,bearing,range,range-bearing")
    ap.add_argument("--candidates", default=None,
                    help="comma-separated subset of the method columns (default: all)")
    args = ap.parse_args(argv)
    runs = sorted(p for p in args.data.glob("MRCLAM_Dataset*") if p.is_dir())
    if not runs:
        raise SystemExit(f"no MRCLAM_Dataset* directories under {args.data}")
    t_start = time.perf_counter()
    notes: dict[str, list[str]] = {}
    for sensor in args.sensors.split(","):
        cols: list[tuple[str, list]] = []  # (label, per-run results)
        if sensor != "range-bearing":  # the naive pipeline maps one sensor
            cols.append(("naive 1s", [_run(run, sensor, "naive", bin_width=1.0) for run in runs]))
        chosen: dict[str, list[str]] = {}
        wanted = CANDIDATES[sensor] if args.candidates is None else [
            c for c in CANDIDATES[sensor] if c in args.candidates.split(",")]
        for method in wanted:
            default = [_run(run, sensor, method) for run in runs]
            cols.append((method, default))
            grid = GRIDS[method]
            if not grid:
                continue
            table = np.array([[_run(run, sensor, method, **g).mpe for run in runs] for g in grid])
            loo, picks = [], []
            for r, run in enumerate(runs):
                others = [k for k in range(len(runs)) if k != r]
                best = int(np.argmin(table[:, others].mean(axis=1)))
                loo.append(_run(run, sensor, method, **grid[best]))
                picks.append(", ".join(f"{k}={v}" for k, v in grid[best].items()))
            cols.append((f"{method} LOO", loo))
            chosen[method] = picks
        for run, res in zip(runs, cols[-1][1], strict=True):
            notes.setdefault(run.name, [])
            for w in res.warnings:
                if w not in notes[run.name]:
                    notes[run.name].append(w)
        print(f"\n## sensor = {sensor}   MPE [m] / MOE [%] over the 11 non-anchor landmarks")
        print(f"{'run':<16}{'centroid':>9}" + "".join(f"{label:>30}" for label, _ in cols))
        for r, run in enumerate(runs):
            line = f"{run.name:<16}{cols[0][1][r].centroid_mpe:>9.2f}"
            line += "".join(f"{res[r].mpe:>23.2f} /{res[r].moe:>5.1f}" for _, res in cols)
            print(line)
        groups = [("mean (all)", list(range(len(runs))))]
        spread = [k for k, run in enumerate(runs) if not run.name.endswith("Dataset6")]
        if len(spread) != len(runs):
            groups.append(("mean (DS1-3)", spread))
        for label, idx in groups:
            line = f"{label:<16}{np.mean([cols[0][1][k].centroid_mpe for k in idx]):>9.2f}"
            line += "".join(f"{np.mean([res[k].mpe for k in idx]):>23.2f} /{np.mean([res[k].moe for k in idx]):>5.1f}" for _, res in cols)
            print(line)
        for method, picks in chosen.items():
            print(f"LOO settings chosen for {method}: " + "; ".join(
                f"{run.name[-1]}: {p}" for run, p in zip(runs, picks, strict=True)))
    print("\nwarnings per run:")
    for name, ws in notes.items():
        for w in ws:
            print(f"  {name}: {w[:200]}{'...' if len(w) > 200 else ''}")
    print(f"\n[{time.perf_counter() - t_start:.0f} s]")


if __name__ == "__main__":
    main()
