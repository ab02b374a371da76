"""``lfmdr map`` (a saved history or an observation log) and ``lfmdr convert`` (a dataset or a
ROS bag to an observation table): parse, call one library function, print.

Kept apart from :mod:`lfmdr_gym.cli`, which registers them, so no module grows past its limit.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path
from typing import Any

from lfmdr_gym.cli_common import (
    add_command,
    add_method_options,
    positive_int,
    print_warnings,
)

__all__ = ["add_convert", "add_map"]

_TABLE_ONLY = ("anchors", "truth", "sensor", "bin_width", "frame")


def _positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds (a positive number), got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected seconds (a positive number), got {value}")
    return value


# --------------------------------------------------------------------------------- lfmdr map
_UNCERTAINTY_KINDS = ("model", "jackknife", "bootstrap", "anchors", "floor")


def _uncertainty_kind(text: str) -> str:
    if text not in _UNCERTAINTY_KINDS:
        raise argparse.ArgumentTypeError(f"{text!r} is not a kind of uncertainty; choose one of "
                                         f"{', '.join(_UNCERTAINTY_KINDS)} (or give "
                                         "--uncertainty alone)")
    return text


def add_map(sub: Any) -> None:
    """``lfmdr map HISTORY.npz`` or ``lfmdr map LOG.csv|LOG.parquet --anchors A.csv``."""
    from mappers.core.sensors import FUSED_SENSORS, SENSORS

    p = add_command(
        sub, "map", "map a saved history (.npz) or an observation log (.csv/.parquet); scores "
                    "when the ground truth is known",
        "Map a saved history with one method; print MPE and MOE when the file holds every "
        "object's true position; write map.csv and map.png into --out.",
        "An observation log (a CSV or Parquet table of sightings: time, landmark, [robot], "
        "[frame], and any of bearing, ray_x/ray_y/ray_z, range; see docs/guide/your-robot.md) "
        "is mapped with the anchors of --anchors (a table landmark,x,y): writes map.csv "
        "(landmark, x, y, anchor, mapped), map.json and map.yaml (a tag map for other tools) "
        "and map.png, and with --truth scores.json. The files of one run are written as a "
        "set: on any error --out is left as it was.",
    )
    p.add_argument("history", metavar="LOG",
                   help="a history saved by lfmdr collect/run (.npz), or an observation table "
                        "(.csv, .parquet)")
    add_method_options(p, "the default for the history's sensor and kind, as build_map chooses")
    p.add_argument("--steps", type=positive_int, default=None,
                   help="map only the first N steps (default: all)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="output directory (default: next to the history, named after it)")
    p.add_argument("--uncertainty", nargs="?", const=True, default=False, type=_uncertainty_kind,
                   metavar="KIND",
                   help="give each landmark a covariance: cov_* columns in map.csv (and a "
                        "covariance in map.json / map.yaml), 95 %% ellipses in map.png. KIND: "
                        f"{', '.join(_UNCERTAINTY_KINDS)}; alone: the method's own with the "
                        "systematic floor where it has a model (build_map's uncertainty=True; "
                        "docs/guide/uncertainty.md)")
    log = p.add_argument_group("observation logs (.csv, .parquet)")
    log.add_argument("--anchors", default=None, metavar="A.csv",
                     help="landmarks of known position, a table landmark,x,y (at least 3, not "
                          "collinear, each sighted in the log); required for a log")
    log.add_argument("--truth", default=None, metavar="T.csv",
                     help="true positions (landmark,x,y) to score the map; landmarks it lacks "
                          "are not scored, and the scores say which")
    log.add_argument("--sensor", default=None, choices=(*SENSORS, *FUSED_SENSORS),
                     help="which measurements to map (default: the log's, fused when it has "
                          "several)")
    log.add_argument("--bin", dest="bin_width", type=_positive_seconds, default=None,
                     metavar="SECONDS",
                     help="time bins of each robot's frames, in seconds (default: one step per "
                          "frame)")
    log.add_argument("--frame", default="map", metavar="NAME",
                     help="name of the anchors' frame, written in map.json and map.yaml")
    p.set_defaults(handler=_cmd_map)


def _cmd_map(args: argparse.Namespace) -> int:
    from lfmdr_gym.experiments.map_log import is_observation_log

    if is_observation_log(args.history):
        return _cmd_map_log(args)
    given = [f"--{name.replace('_width', '')}" for name in _TABLE_ONLY
             if getattr(args, name) not in (None, "map")]
    if given:
        raise ValueError(f"{', '.join(given)} apply to an observation log (.csv, .parquet); "
                         f"{args.history} is a saved history, which holds its anchors")
    return _cmd_map_history(args)


def _cmd_map_history(args: argparse.Namespace) -> int:
    from lfmdr_gym.experiments.mapping import map_history_file
    from lfmdr_gym.experiments.params import method_label

    info = map_history_file(args.history, args.method, params=args.param,
                            n_steps=args.steps, out=args.out, uncertainty=args.uncertainty)
    m = info["map"]
    print(f"{info['history']!r}: {method_label(info['method'], info['param'])}")
    if m.unmapped:
        print(f"unmapped objects: {list(m.unmapped)}")
    print_warnings(m.warnings)
    if "mpe" in info:
        moe = "MOE" if m.positions.shape[1] == 2 else "tetrahedron orientation error"
        print(f"MPE {info['mpe']:.4f} m (non-anchor {info['mpe_nonanchor']:.4f} m), "
              f"{moe} {info['moe']:.2f} %")
    else:
        print("no ground truth in the file: not scored")
    print(f"wrote {info['out'] / 'map.csv'} and {info['figure']}")
    return 0


def _number(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _cmd_map_log(args: argparse.Namespace) -> int:
    from lfmdr_gym.experiments.map_log import map_observation_log
    from lfmdr_gym.experiments.params import method_label

    if args.anchors is None:
        raise ValueError(f"{args.history} is an observation log: give its anchors with "
                         "--anchors A.csv (a table landmark,x,y)")
    out = args.out if args.out is not None else Path(args.history).with_suffix("")
    run = map_observation_log(args.history, args.anchors, truth=args.truth, sensor=args.sensor,
                              bin_width=args.bin_width, method=args.method, params=args.param,
                              n_steps=args.steps, out=out, frame=args.frame,
                              uncertainty=args.uncertainty)
    h = run.history
    print(f"{args.history}: {h.n_objects} landmarks, {h.n_steps} steps ({h.sensor}), "
          f"{method_label(run.method, run.param)}")
    unmapped = [run.landmarks[i] for i in run.map.unmapped]
    if unmapped:
        print(f"unmapped landmarks: {unmapped}")
    print_warnings(run.notes)
    s = run.scores
    if s is not None:
        print(f"MPE {_number(s['mpe'], 4)} m (non-anchor {_number(s['mpe_nonanchor'], 4)} m), "
              f"MOE {_number(s['moe'], 2)} % over {s['n_scored']} landmarks of the truth")
        if s["missing_from_truth"]:
            print(f"not scored, missing from {args.truth}: {s['missing_from_truth']}")
    print("wrote " + ", ".join(str(p) for p in run.files.files))
    return 0


# ----------------------------------------------------------------------------- lfmdr convert
def add_convert(sub: Any) -> None:
    """``lfmdr convert {mrclam,starloc,rosbag} SRC --out obs.csv|obs.parquet``."""
    p = add_command(
        sub, "convert", "turn an MRCLAM run, a STAR-loc sequence or a ROS bag into an observation table",
        "Write the sightings of a dataset as an observation table (CSV or Parquet, by the "
        "suffix of --out), the log `lfmdr map LOG --anchors A.csv` maps; written atomically.",
    )
    kinds = p.add_subparsers(dest="source", metavar="SOURCE", required=True)
    m = add_command(
        kinds, "mrclam", "an MRCLAM run directory (landmark sightings of every robot)",
        "The robots' logged sightings of an UTIAS MRCLAM run (time, robot, landmark, range, "
        "bearing), filtered as lfmdr mrclam filters them; with --landmarks, the landmarks' "
        "motion-capture positions as a table landmark,x,y (for --anchors / --truth).",
    )
    m.add_argument("src", metavar="RUN_DIR", help="an MRCLAM run directory (MRCLAM_DatasetN)")
    m.add_argument("--groundtruth-fixes", choices=["known", "detect", "none"], default="known",
                   help="as for lfmdr mrclam: which documented ground-truth errors to fix")
    m.add_argument("--landmarks", default=None, metavar="L.csv",
                   help="also write the landmarks' ground truth here (for --truth)")
    m.add_argument("--anchors", default=None, metavar="A.csv",
                   help="also write the anchors lfmdr mrclam uses here (the 4 landmarks nearest "
                        "the corners of their bounding box; for --anchors)")
    _add_table_out(m)
    m.set_defaults(handler=_cmd_convert_mrclam)
    r = add_command(
        kinds, "rosbag", "a ROS 1 or ROS 2 bag of AprilTag detections",
        "AprilTag detections of one topic of a ROS 1 bag or a ROS 2 bag (sqlite3, MCAP), read "
        "with the rosbags library (pip install 'lfmdr[ros]'; no ROS install).",
    )
    t = add_command(
        kinds, "starloc", "a STAR-loc sequence folder (AprilTags seen by a stereo camera, 3-D)",
        "The AprilTag detections of one STAR-loc sequence (data/<sequence>: "
        "apriltag_cal_global.csv and calib.json; the pose columns, ground truth, are never "
        "read): stereo gives a ray and a range per sighting, --sensor bearing the left camera's "
        "rays, visibility the sightings alone. With --landmarks, the tags' surveyed positions "
        "(landmark,x,y,z); with --anchors, the benchmark's six anchors (the lowest tag seen in "
        ">= 3 image pairs, then farthest-point order).",
    )
    t.add_argument("src", metavar="SEQ_DIR", help="a STAR-loc sequence folder (data/<sequence>)")
    t.add_argument("--sensor", choices=["range-bearing", "bearing", "visibility"],
                   default="range-bearing", help="what each sighting keeps")
    t.add_argument("--landmarks", default=None, metavar="L.csv",
                   help="also write the tags' surveyed positions here (for --truth)")
    t.add_argument("--anchors", default=None, metavar="A.csv",
                   help="also write the six anchors of the STAR-loc benchmark here")
    t.add_argument("--disparity-offset", type=float, default=0.0, metavar="PX",
                   help="pixels the disparities are too large by: range = fu b / (disparity - "
                        "PX) (default 0; the STAR-loc benchmark uses 0.5)")
    _add_table_out(t)
    t.set_defaults(handler=_cmd_convert_starloc)
    from lfmdr_gym.datasets import rosbag  # (imports rosbags only when it reads a bag)

    rosbag.add_arguments(r)
    _add_table_out(r)
    r.set_defaults(handler=_cmd_convert_rosbag)


def _add_table_out(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, metavar="OBS.csv|OBS.parquet",
                   help="observation table to write (CSV or Parquet by its suffix)")


def _cmd_convert_mrclam(args: argparse.Namespace) -> int:
    from lfmdr_gym.datasets.mrclam import MRCLAMDataWarning, read_run
    from lfmdr_gym.datasets.mrclam_table import (
        mrclam_anchors,
        mrclam_landmarks,
        mrclam_observations,
    )
    from lfmdr_gym.histories.observation_table import write_landmarks, write_observations

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MRCLAMDataWarning)  # they are in run.report.warnings
        run = read_run(args.src, groundtruth_fixes=args.groundtruth_fixes)
    table = mrclam_observations(run)
    print_warnings(run.report.warnings)
    written = [write_observations(table, args.out)]
    if args.landmarks is not None:
        written.append(write_landmarks(mrclam_landmarks(run), args.landmarks, what="truth"))
    if args.anchors is not None:
        written.append(write_landmarks(mrclam_anchors(run), args.anchors, what="anchors"))
    print(f"{run.name}: {len(table)} sightings of {table['landmark'].nunique()} landmarks by "
          f"{table['robot'].nunique()} robots; wrote " + ", ".join(map(str, written)))
    return 0


def _cmd_convert_starloc(args: argparse.Namespace) -> int:
    from lfmdr_gym.datasets.starloc import read_starloc, starloc_anchors, starloc_survey
    from lfmdr_gym.histories.observation_table import write_landmarks, write_observations

    table = read_starloc(args.src, args.sensor, args.disparity_offset)
    survey = starloc_survey(args.src) if (args.landmarks or args.anchors) else None
    written = [write_observations(table, args.out)]
    if args.landmarks is not None:
        written.append(write_landmarks(survey, args.landmarks, what="truth"))
    if args.anchors is not None:
        ids = starloc_anchors(table, survey)
        anchors = survey.set_index("landmark").loc[ids].reset_index()
        written.append(write_landmarks(anchors, args.anchors, what="anchors"))
    print(f"{table.attrs['sequence']}: {len(table)} sightings of {table['landmark'].nunique()} "
          f"tags in {table['frame'].nunique()} image pairs; wrote " + ", ".join(map(str, written)))
    return 0


def _cmd_convert_rosbag(args: argparse.Namespace) -> int:
    from lfmdr_gym.datasets import rosbag
    from lfmdr_gym.histories.observation_table import write_observations

    table = rosbag.run(args)
    write_observations(table, args.out)
    print(f"{args.src} {args.topic}: {len(table)} sightings of {table['landmark'].nunique()} "
          f"landmarks; wrote {args.out}")
    return 0
