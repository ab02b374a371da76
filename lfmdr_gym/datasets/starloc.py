"""STAR-loc: AprilTags seen by a hand-held stereo camera, read into an observation table.

The dataset (Dümbgen, Shalaby, Holmes, Cossette, Forbes, Le Ny & Barfoot, *STAR-loc: Dataset for
STereo And Range-based localization*, arXiv:2309.05518, 2023) logs, per sequence, every tag
detection (``apriltag_cal_global.csv``: the tag's centre in the left and right rectified
images) and the camera's intrinsics and baseline (``calib.json``); a Vicon survey gives the
tags' true 3-D positions (``mocap/environment_v*.csv``). The detection file also holds the
rig's true poses: they are ground truth, and this module never reads them (the CSV is read with
``usecols`` of the detection columns alone).

:func:`read_starloc` gives the observation table (one row per detection; rows of one image pair
share ``frame``): for ``sensor="range-bearing"`` the left camera's unit ray and the stereo range
(``Z = fu * b / disparity``, ``X = (u - cu) Z / fu``, ``Y = (v - cv) Z / fv``, the range the
norm of that point), for ``"bearing"`` the ray alone, for ``"visibility"`` the sightings alone.
:func:`starloc_survey` reads the survey of a sequence, :func:`starloc_anchors` picks the
benchmark's anchors and :func:`scored_tags` the tags it scores (issue 34's rule).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = [
    "DETECTION_COLUMNS",
    "STARLOC_SENSORS",
    "StarlocError",
    "read_starloc",
    "scored_tags",
    "starloc_anchors",
    "starloc_survey",
]

DETECTION_COLUMNS = ("time_s", "apriltag_id", "left_u", "left_v", "right_u", "right_v")
"""The columns of ``apriltag_cal_global.csv`` that are measurements; the others are ground truth."""

STARLOC_SENSORS = ("range-bearing", "bearing", "visibility")
"""What :func:`read_starloc` can write: stereo rays and ranges, left rays, sightings."""

_CALIB_KEYS = ("fu", "fv", "cu", "cv", "b")
_DETECTIONS = "apriltag_cal_global.csv"


class StarlocError(ValueError):
    """A STAR-loc sequence folder that cannot be read, with the file and the problem."""


def _calibration(seq: Path) -> dict[str, float]:
    path = seq / "calib.json"
    if not path.is_file():
        raise StarlocError(f"{seq}: no calib.json (the camera's fu, fv, cu, cv and baseline b): "
                           "a STAR-loc sequence folder holds it beside apriltag_cal_global.csv")
    try:
        calib = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise StarlocError(f"{path}: not valid JSON: {exc}") from exc
    missing = [k for k in _CALIB_KEYS if k not in calib]
    if missing:
        raise StarlocError(f"{path}: missing key(s) {missing} (needs {list(_CALIB_KEYS)})")
    out = {k: float(calib[k]) for k in _CALIB_KEYS}
    bad = [k for k in ("fu", "fv", "b") if not out[k] > 0]
    if bad:
        raise StarlocError(f"{path}: {bad} must be > 0, got {[out[k] for k in bad]}")
    return out


def _detections(seq: Path) -> pd.DataFrame:
    path = seq / _DETECTIONS
    if not path.is_file():
        raise StarlocError(f"{seq}: no {_DETECTIONS} (the tag detections)")
    try:  # the detection columns only: the others are ground-truth poses and pixels
        d = pd.read_csv(path, usecols=list(DETECTION_COLUMNS))
    except ValueError as exc:
        raise StarlocError(f"{path}: {exc}") from exc
    if d.empty:
        raise StarlocError(f"{path}: no detections")
    for col in DETECTION_COLUMNS:
        values = pd.to_numeric(d[col], errors="coerce")
        bad = np.flatnonzero(~np.isfinite(values.to_numpy(dtype=float)))
        if bad.size:
            raise StarlocError(f"{path}: line {bad[0] + 2}, column {col!r}: not a finite number "
                               f"({d[col].iloc[bad[0]]!r})")
    return d


def read_starloc(seq_dir: str | Path, sensor: str = "range-bearing",
                 disparity_offset: float = 0.0) -> pd.DataFrame:
    """The observation table of one STAR-loc sequence folder (see the module's docstring).

    Args:
        seq_dir: ``data/<sequence>`` of the dataset, holding ``apriltag_cal_global.csv`` and
            ``calib.json``.
        sensor: one of :data:`STARLOC_SENSORS`.
        disparity_offset: pixels the measured disparities are taken to be too large by: the
            range is ``fu * b / (disparity - disparity_offset)`` (a stereo rectification's
            constant disparity error makes the ranges off by a share that grows with them;
            :data:`lfmdr_gym.experiments.starloc.STARLOC_DISPARITY_OFFSET` says what the
            benchmark uses). 0 (default): the disparities as measured.

    Returns:
        A DataFrame with ``time`` [s], ``landmark`` (the AprilTag id, int), ``frame`` (the image
        pair, 0, 1, ... in time order) and, by ``sensor``, ``ray_x, ray_y, ray_z`` (unit, camera
        optical frame: z forward, x right, y down) and ``range`` [m]; ``attrs`` say the source,
        sequence, sensor and calibration.

    Raises:
        StarlocError (a ValueError): no ``calib.json`` or detection file, a value that is not a
        number, a disparity ``left_u - right_u <= 0`` (with the line), a tag seen twice in one
        image pair, an unknown ``sensor``.
    """
    if sensor not in STARLOC_SENSORS:
        raise StarlocError(f"sensor must be one of {list(STARLOC_SENSORS)}, got {sensor!r}")
    seq = Path(seq_dir)
    if not seq.is_dir():
        raise StarlocError(f"{seq}: not a folder")
    calib = _calibration(seq)
    d = _detections(seq)
    disparity = (d["left_u"] - d["right_u"]).to_numpy(dtype=float)
    if not np.isfinite(disparity_offset):
        raise StarlocError(f"disparity_offset must be a finite number of pixels, got "
                           f"{disparity_offset!r}")
    if sensor == "range-bearing" and np.any(disparity <= 0):
        k = int(np.flatnonzero(disparity <= 0)[0])
        raise StarlocError(f"{seq / _DETECTIONS}: line {k + 2}: disparity left_u - right_u = "
                           f"{disparity[k]:g} <= 0 (tag {int(d['apriltag_id'].iloc[k])}): a stereo "
                           "range needs a positive disparity")
    if sensor == "range-bearing" and np.any(disparity - disparity_offset <= 0):
        k = int(np.flatnonzero(disparity - disparity_offset <= 0)[0])
        raise StarlocError(f"{seq / _DETECTIONS}: line {k + 2}: disparity {disparity[k]:g} minus "
                           f"the disparity_offset {disparity_offset:g} is <= 0: no range")
    dup = d.duplicated(["time_s", "apriltag_id"])
    if dup.any():
        k = int(np.flatnonzero(dup)[0])
        raise StarlocError(f"{seq / _DETECTIONS}: line {k + 2}: tag "
                           f"{int(d['apriltag_id'].iloc[k])} seen twice in one image pair")
    time = d["time_s"].to_numpy(dtype=float)
    table = pd.DataFrame({
        "time": time,
        "landmark": d["apriltag_id"].to_numpy(dtype=np.int64),
        "frame": np.unique(time, return_inverse=True)[1].astype(np.int64),
    })
    if sensor != "visibility":
        ray = np.column_stack([(d["left_u"].to_numpy(dtype=float) - calib["cu"]) / calib["fu"],
                               (d["left_v"].to_numpy(dtype=float) - calib["cv"]) / calib["fv"],
                               np.ones(len(d))])
        norm = np.linalg.norm(ray, axis=1)
        table["ray_x"], table["ray_y"], table["ray_z"] = (ray / norm[:, None]).T
        if sensor == "range-bearing":
            # the point's Z; its norm is Z * |ray|
            depth = calib["fu"] * calib["b"] / (disparity - disparity_offset)
            table["range"] = depth * norm
    table = table.sort_values(["frame", "landmark"], kind="stable").reset_index(drop=True)
    table.attrs = {"source": "starloc", "sequence": seq.name, "sensor": sensor,
                   "calibration": calib}
    return table


def starloc_survey(seq_dir: str | Path) -> pd.DataFrame:
    """The surveyed tag positions of a sequence: ``landmark`` (AprilTag id), ``x, y, z`` [m], from
    ``mocap/environment_<version>.csv`` two folders up, the version named for the sequence in
    ``dataset_params.json``."""
    seq = Path(seq_dir)
    root = seq.resolve().parent.parent
    params_path = root / "dataset_params.json"
    if not params_path.is_file():
        raise StarlocError(f"{root}: no dataset_params.json (a STAR-loc copy has it two folders "
                           "above each sequence)")
    params = {p["name"]: p for p in json.loads(params_path.read_text(encoding="utf-8"))}
    if seq.name not in params:
        raise StarlocError(f"{params_path}: no sequence {seq.name!r}")
    path = root / "mocap" / f"environment_{params[seq.name]['landmarks']}.csv"
    env = pd.read_csv(path, usecols=["april_id", "x", "y", "z"])
    return env.rename(columns={"april_id": "landmark"})[["landmark", "x", "y", "z"]]


def starloc_anchors(table: pd.DataFrame, survey: pd.DataFrame, n: int = 6,
                    min_frames: int = 3) -> list[int]:
    """Issue 34's anchors: among the surveyed tags seen in at least ``min_frames`` image pairs,
    the lowest (least z), then ``n - 1`` times the one farthest from those picked
    (farthest-point order by the surveyed positions)."""
    seen = table.groupby("landmark")["frame"].nunique()
    pool = survey[survey["landmark"].isin(seen.index[seen >= min_frames])]
    if len(pool) < n:
        raise StarlocError(f"only {len(pool)} surveyed tags were seen in >= {min_frames} image "
                           f"pairs; {n} anchors are needed")
    xyz = pool[["x", "y", "z"]].to_numpy(dtype=float)
    picked = [int(np.argmin(xyz[:, 2]))]
    while len(picked) < n:
        dist = np.min(np.linalg.norm(xyz[:, None] - xyz[picked][None], axis=2), axis=1)
        picked.append(int(np.argmax(dist)))
    return [int(v) for v in pool["landmark"].to_numpy()[picked]]


def scored_tags(table: pd.DataFrame, survey: pd.DataFrame, anchors, min_frames: int = 3) -> list[int]:
    """The tags a STAR-loc map is scored on: surveyed, seen in at least ``min_frames`` image
    pairs, not anchors."""
    seen = table.groupby("landmark")["frame"].nunique()
    ids = set(seen.index[seen >= min_frames]) & set(survey["landmark"]) - set(anchors)
    return sorted(int(v) for v in ids)
