"""MRCLAM: map every run in every mode and print MPE / MOE per run, with baselines.

    python benchmarks/bench_mrclam.py [--data DIR] [--modes visibility,bearing,range]

For each run and mode (4 corner anchors, all 5 robots, scores over the 11 non-anchor landmarks):

* ``centroid``: every landmark at the anchors' centroid;
* ``naive``: the straightforward pipeline on 1 s bins (zero-filled history, L2-normalised rows,
  unweighted SMACOF from classical MDS, affine fit to the anchors);
* ``masked-euclidean`` (bearing, range): RMS history difference over co-observed bins only,
  weighted SMACOF over the pairs that have it (the plain SPEC §7 recipe);
* ``default``: the mode's default method with its default settings;
* ``LOO``: the method with the setting chosen *without* the run (lowest mean MPE over the other
  runs in a small grid), i.e. a score on a run the setting was not tuned on.

Settings grids: covis-nonmetric (visibility, bearing): bin width {1, 2, 3, 5} s x min_co {3, 5};
range-quantile: bin width {0.25, 0.5, 1} s x quantile {0.95, 0.98, 0.99}.
"""

from __future__ import annotations

import argparse
import itertools
import time
import warnings
from pathlib import Path

import numpy as np

from lfmdr_gym.datasets.mrclam import MRCLAMDataWarning, map_mrclam_run

GRIDS = {
    "covis-nonmetric": [
        {"bin_width": bw, "min_co": mc} for bw, mc in itertools.product([1.0, 2.0, 3.0, 5.0], [3, 5])
    ],
    "range-quantile": [
        {"bin_width": bw, "quantile": q}
        for bw, q in itertools.product([0.25, 0.5, 1.0], [0.95, 0.98, 0.99])
    ],
}
DEFAULT_METHOD = {"visibility": "covis-nonmetric", "bearing": "covis-nonmetric", "range": "range-quantile"}


def _run(run_dir: Path, mode: str, method: str | None, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MRCLAMDataWarning)
        return map_mrclam_run(run_dir, mode, method=method, **kw)


def main(argv: list[str] | None = None) -> None:
    here = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=here.parent / "shared" / "data" / "mrclam")
    ap.add_argument("--modes", default="visibility,bearing,range")
    args = ap.parse_args(argv)
    runs = sorted(p for p in args.data.glob("MRCLAM_Dataset*") if p.is_dir())
    if not runs:
        raise SystemExit(f"no MRCLAM_Dataset* directories under {args.data}")
    modes = args.modes.split(",")
    t_start = time.perf_counter()
    notes: dict[str, tuple[str, ...]] = {}
    for mode in modes:
        method = DEFAULT_METHOD[mode]
        grid = GRIDS[method]
        # every setting on every run (the LOO choice needs them all)
        table = np.zeros((len(grid), len(runs)))
        for g, setting in enumerate(grid):
            for r, run in enumerate(runs):
                table[g, r] = _run(run, mode, method, **setting).mpe
        print(f"\n## mode = {mode}   (MPE [m] / MOE [%] over non-anchor landmarks)")
        head = f"{'run':<16}{'centroid':>10}{'naive 1s':>16}"
        if mode != "visibility":
            head += f"{'masked-eucl.':>16}"
        head += f"{'default':>16}{'LOO':>16}  LOO setting"
        print(head)
        sums: dict[str, list[float]] = {"centroid": [], "naive": [], "me": [], "default": [], "loo": []}
        for r, run in enumerate(runs):
            naive = _run(run, mode, "naive", bin_width=1.0)
            default = _run(run, mode, None)
            others = [k for k in range(len(runs)) if k != r]
            best = int(np.argmin(table[:, others].mean(axis=1)))
            loo = _run(run, mode, method, **grid[best])
            notes[run.name] = default.warnings
            line = f"{run.name:<16}{default.centroid_mpe:>10.2f}{naive.mpe:>9.2f}/{naive.moe:>5.1f}"
            sums["centroid"].append(default.centroid_mpe)
            sums["naive"].append(naive.mpe)
            if mode != "visibility":
                me = _run(run, mode, "masked-euclidean")
                line += f"{me.mpe:>9.2f}/{me.moe:>5.1f}"
                sums["me"].append(me.mpe)
            line += f"{default.mpe:>9.2f}/{default.moe:>5.1f}{loo.mpe:>9.2f}/{loo.moe:>5.1f}  {grid[best]}"
            sums["default"].append(default.mpe)
            sums["loo"].append(loo.mpe)
            print(line)
        for label, sel in (("mean (all)", slice(None)), ("mean (spread)", slice(0, 3))):
            if label == "mean (spread)" and len(runs) != 4:
                continue
            line = f"{label:<16}{np.mean(sums['centroid'][sel]):>10.2f}{np.mean(sums['naive'][sel]):>9.2f}{'':>6}"
            if mode != "visibility":
                line += f"{np.mean(sums['me'][sel]):>9.2f}{'':>6}"
            line += f"{np.mean(sums['default'][sel]):>9.2f}{'':>6}{np.mean(sums['loo'][sel]):>9.2f}"
            print(line)
    print("\n(mean (spread) = the three spread-out layouts DS1-3; DS6 is the clustered one)")
    print("\nwarnings per run (default method):")
    for name, ws in notes.items():
        for w in ws:
            print(f"  {name}: {w[:160]}{'...' if len(w) > 160 else ''}")
    print(f"\n[{time.perf_counter() - t_start:.0f} s]")


if __name__ == "__main__":
    main()
