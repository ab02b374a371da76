"""STAR-loc: map every sequence from its detections alone, per sensor, and print the non-anchor
MPE against the tag survey (issue 34).

    python benchmarks/bench_starloc.py [--data DIR] [--sensors range-bearing,bearing,visibility]
        [--out docs/results/starloc/starloc.csv]
        [--figure docs/guide/starloc_3d.png --figure-sequence loop-2d_s3]
        [--visibility-method COVIS-3D-MEDIAN [--visibility-params '{"window": 10}']]

Anchors: six surveyed tags seen in >= 3 image pairs (the lowest, then farthest-point order);
scored: the other tags seen in >= 3 image pairs; ``mapped`` is the share of them placed (a tag
left unmapped is missing from the MPE, and at least 90 % should be mapped); ``mappable`` the
share of them that a chain of sightings links to three anchors not on one line, the most any map
can place (:mod:`mappers.spatial.anchored`). Also the baseline of every tag at the anchors'
centroid. Sensors: ``range-bearing`` the stereo camera (left rays
and stereo ranges, SPATIAL-BA), ``bearing`` the left camera's rays (SPATIAL-BA), ``visibility``
the sightings (COVIS-3D); the parameters are :data:`lfmdr_gym.experiments.starloc.STARLOC_PARAMS`.
``--visibility-method`` maps the sightings with another 3-D method instead (e.g. the opt-in
``COVIS-3D-MEDIAN``, or ``FRUSTUM-BA-WALK`` given its camera as ``--visibility-params`` JSON).
Goals on setup s3: stereo <= 0.05 m, bearing <= 0.10 m, visibility <= 1.0 m. The data:
``<repo>/../shared/data/starloc`` (its README; never copied into the repository).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
import warnings
from pathlib import Path

import numpy as np

from lfmdr_gym.atomic import atomic_write_text
from lfmdr_gym.datasets.starloc import (
    read_starloc,
    scored_tags,
    starloc_anchors,
    starloc_survey,
)
from lfmdr_gym.experiments.figures import plot_views_3d
from lfmdr_gym.experiments.starloc import map_starloc

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "data" / "starloc"
FIELDS = ["sequence", "setup", "sensor", "mapped_by", "mpe", "mapped", "n_scored", "centroid_mpe",
          "cpu_s", "mappable"]


def centroid_mpe(seq: Path) -> float:
    """The MPE of every scored tag put at the anchors' centroid."""
    table, survey = read_starloc(seq, "visibility"), starloc_survey(seq)
    anchors = starloc_anchors(table, survey)
    xyz = survey.set_index("landmark")[["x", "y", "z"]]
    centre = xyz.loc[anchors].to_numpy(dtype=float).mean(axis=0)
    scored = xyz.loc[scored_tags(table, survey, anchors)].to_numpy(dtype=float)
    return float(np.linalg.norm(scored - centre, axis=1).mean())


def draw_views(seq: Path, path: Path) -> None:
    """Three orthographic views (top, front, side) of the stereo map of ``seq`` against the tag
    survey, anchors marked, saved to ``path`` (PNG;
    :func:`lfmdr_gym.experiments.figures.plot_views_3d`)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = map_starloc(seq, "range-bearing")
    xyz = starloc_survey(seq).set_index("landmark")[["x", "y", "z"]]
    tags = sorted(r.positions)
    est = np.array([r.positions[t] for t in tags])
    tru = xyz.loc[tags].to_numpy(dtype=float)
    plot_views_3d(est, tru, np.flatnonzero(np.isin(tags, r.anchors)), path,
                  title=f"STAR-loc {r.sequence}: SPATIAL-BA from the stereo detections, "
                        f"MPE {r.mpe:.3f} m over {r.n_scored} tags ({r.mapped:.0%} mapped)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--sensors", default="range-bearing,bearing,visibility")
    parser.add_argument("--out", type=Path, default=None, help="write the rows as CSV here")
    parser.add_argument("--figure", type=Path, default=None,
                        help="draw three orthographic views of one sequence's stereo map here")
    parser.add_argument("--figure-sequence", default="loop-2d_s3")
    parser.add_argument("--no-table", action="store_true", help="only draw the figure")
    parser.add_argument("--visibility-method", default=None,
                        help="map the sightings with this 3-D method (default: the default)")
    parser.add_argument("--visibility-params", type=json.loads, default={},
                        help="JSON object of that method's parameters")
    args = parser.parse_args(argv)
    if args.visibility_params and args.visibility_method is None:
        parser.error("--visibility-params needs --visibility-method")
    if not isinstance(args.visibility_params, dict):
        parser.error("--visibility-params must be a JSON object")
    params = {"visibility": {"method": args.visibility_method, **args.visibility_params}} \
        if args.visibility_method is not None else {}
    if args.figure is not None:
        draw_views(args.data / "data" / args.figure_sequence, args.figure)
        print(f"wrote {args.figure}")
        if args.no_table:
            return 0
    folders = sorted(p for p in (args.data / "data").iterdir() if p.is_dir()) \
        if (args.data / "data").is_dir() else []
    if not folders:
        print(f"no STAR-loc sequences under {args.data / 'data'}", file=sys.stderr)
        return 1
    rows = []
    print(f"{'sequence':18s} {'sensor':14s} {'MPE [m]':>8s} {'mapped':>7s} {'scored':>6s} "
          f"{'centroid':>8s} {'CPU [s]':>7s} {'mappable':>8s}")
    for seq in folders:
        base = centroid_mpe(seq)
        for sensor in args.sensors.split(","):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # the map's notes: unmapped tags counted
                    r = map_starloc(seq, sensor, params.get(sensor))
            except ValueError as exc:  # a sequence too short to map: a row that says so
                print(f"{seq.name:18s} {sensor:14s} failed: {exc}", flush=True)
                rows.append({"sequence": seq.name, "setup": seq.name.rsplit("_", 1)[-1],
                             "sensor": sensor, "mapped_by": "failed", "mpe": "nan", "mapped": "0",
                             "n_scored": "", "centroid_mpe": f"{base:.4f}", "cpu_s": "",
                             "mappable": ""})
                continue
            rows.append({"sequence": r.sequence, "setup": r.sequence.rsplit("_", 1)[-1],
                         "sensor": sensor, "mapped_by": r.method, "mpe": f"{r.mpe:.4f}",
                         "mapped": f"{r.mapped:.3f}", "n_scored": r.n_scored,
                         "centroid_mpe": f"{base:.4f}", "cpu_s": f"{r.cpu_seconds:.2f}",
                         "mappable": f"{r.mappable:.4f}"})
            print(f"{r.sequence:18s} {sensor:14s} {r.mpe:8.3f} {r.mapped:7.0%} {r.n_scored:6d} "
                  f"{base:8.3f} {r.cpu_seconds:7.2f} {r.mappable:8.0%}", flush=True)
    if args.out is not None:
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=FIELDS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(args.out, buf.getvalue())
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
