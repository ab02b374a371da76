"""Map a real robot run (UTIAS MRCLAM) without localisation, and score it against motion capture.

    python examples/mrclam_map.py [RUN_DIR] [--sensor range] [--out DIR]

RUN_DIR defaults to ../shared/data/mrclam/MRCLAM_Dataset2 next to the repository. Prints what the
loader filtered, any data warnings, and MPE / MOE over the non-anchor landmarks; with --out it
writes map.csv (subject, x, y) and map.png.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

from lfmdr_gym.datasets import MRCLAMDataWarning
from lfmdr_gym.experiments.mrclam import map_mrclam_run

DEFAULT_RUN = Path(__file__).resolve().parents[1].parent / "shared/data/mrclam/MRCLAM_Dataset2"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", nargs="?", type=Path, default=DEFAULT_RUN)
    ap.add_argument("--sensor", default="range",
                    choices=["visibility", "bearing", "range", "range-bearing"])
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    if not args.run_dir.is_dir():
        raise SystemExit(f"no MRCLAM run at {args.run_dir} (pass RUN_DIR)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MRCLAMDataWarning)  # they are in result.warnings
        result = map_mrclam_run(args.run_dir, args.sensor, out=args.out)
    rep = result.report
    print(f"{result.run}: kept {rep.landmark_rows} landmark rows; dropped {rep.robot_rows} robot "
          f"sightings, {rep.unknown_barcode_rows} unknown barcodes, {rep.repeat_rows} exact repeats")
    for w in result.warnings:
        print(f"warning: {w}")
    print(f"{args.sensor} / {result.method} {result.params}, anchors {result.anchor_subjects}")
    print(f"MPE {result.mpe:.3f} m, MOE {result.moe:.2f} % over non-anchor landmarks "
          f"(anchors' centroid: {result.centroid_mpe:.2f} m)")
    if result.csv_path:
        print(f"wrote {result.csv_path} and {result.png_path}")


if __name__ == "__main__":
    main()
