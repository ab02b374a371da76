"""Observation table <-> :class:`~lfmdr_gym.histories.history.History` (issue 33).

:func:`observations_to_history` turns a table of sightings
(:mod:`lfmdr_gym.histories.observation_table`) and an anchors table into the History every
mapper takes; :func:`history_to_observations` writes a History as such tables, and the round
trip gives back the same matrices, masks and timeline bit for bit.

Table -> History:

* **Rows (landmarks).** The landmarks listed in ``attrs["landmarks"]`` in that order, if the
  table says; else every landmark of the table and of the anchors, sorted by id. The ids are in
  ``History.meta["landmarks"]`` (integers or strings, as given): row ``i`` is landmark
  ``meta["landmarks"][i]`` (:func:`landmark_ids`).
* **Steps.** Without ``bin_width`` every frame is a step: frames are the ``frame`` numbers of each
  robot (absent: each robot's distinct times, in order), steps ordered by robot, then frame.
  With ``bin_width`` [s], each robot's rows fall into bins of that width on one grid that starts
  at the earliest time (as the MRCLAM loader bins): :mod:`lfmdr_gym.histories.binning`. The
  ``timeline`` (robot, frame or bin of each step) is set when the table has a ``robot`` column or
  is binned. Robots are taken in ``attrs["robots"]`` order if given, else sorted by id.
* **Values.** Visibility 1 where sighted (0 on a ``visible = 0`` row), bearing the circular mean
  and range the median of a cell's sightings. Bearings come from ``bearing_cos, bearing_sin``
  (exact), else ``bearing``, else rays projected to ``atan2(-ray_x, ray_z)``.
* **Mask.** A log says what was sighted, not what was looked at: the mask is True exactly on the
  sighted cells. A table whose ``attrs["complete"]`` is true (an env without sensing limits
  wrote it) instead lists every non-zero reading, every other entry being a known 0: no mask.
* **Ground truth.** ``object_positions`` from ``truth`` (NaN where it has no position; the
  anchors' positions where there is no truth); the landmarks ``truth`` lacks are listed in
  ``meta["truth_missing"]``, those it has beyond the log in ``meta["truth_unused"]``.

3-D anchors (with ``z``): a 3-D History of the table's rays and ranges, one step per frame
(:func:`lfmdr_gym.histories.ray_table.ray_table_to_history`).
"""

from __future__ import annotations

import json
import os
from typing import Any, NamedTuple

import numpy as np
import pandas as pd
import scipy.sparse as sp

from lfmdr_gym.checks import check_real
from lfmdr_gym.histories.binning import assemble, cell_values, tick_steps, time_steps
from lfmdr_gym.histories.history import History
from lfmdr_gym.histories.observation_table import (
    ObservationTableError,
    _Where,
    check_landmarks,
    checked_ids,
    normalise_ids,
    read_landmarks,
)
from lfmdr_gym.histories.ray_table import ray_table_to_history
from mappers.core.align import check_not_collinear
from mappers.core.sensors import COLUMNS_PER_STEP, sensors_of

__all__ = ["ObservationLog", "history_to_observations", "landmark_ids", "observations_to_history"]


class ObservationLog(NamedTuple):
    """A history as tables: the sightings, the anchors and the ground truth (None if unknown)."""

    observations: pd.DataFrame
    anchors: pd.DataFrame
    truth: pd.DataFrame | None


# ---------------------------------------------------------------------------- helpers
def _landmark_table(table: Any, what: str) -> pd.DataFrame:
    if isinstance(table, str | os.PathLike):
        out = read_landmarks(table, what=what)
    else:
        out = check_landmarks(table, what=what)
    return out


def _kind(ids: Any) -> str:
    return "string" if pd.Series(ids, dtype=object).map(type).eq(str).any() else "integer"


def _same_kind(parts: dict[str, Any]) -> None:
    kinds = {name: _kind(ids) for name, ids in parts.items() if len(ids)}
    if len(set(kinds.values())) > 1:
        raise ValueError(f"landmark ids must all be integers or all strings; got {kinds}")


def _sorted_ids(ids: Any) -> np.ndarray:
    arr = np.asarray(list(ids), dtype=object)
    return np.array(sorted(arr.tolist()), dtype=object)


def _positions(ids: np.ndarray, rows: list[Any]) -> np.ndarray:
    """Position of each of ``rows`` (ids) in ``ids``; -1 where absent."""
    index = {v: i for i, v in enumerate(ids.tolist())}
    return np.array([index.get(v, -1) for v in rows], dtype=np.int64)


def _sensor(table: pd.DataFrame, sensor: str | None) -> str:
    has = {"bearing": bool({"bearing", "bearing_cos", "ray_x"} & set(table.columns)),
           "range": "range" in table.columns, "visibility": True}
    if sensor is None:
        sensor = table.attrs.get("sensor")
    if sensor is None:
        sensor = ("range-bearing" if has["bearing"] and has["range"] else
                  "bearing" if has["bearing"] else "range" if has["range"] else "visibility")
    lacking = [s for s in sensors_of(sensor) if not has[s]]
    if lacking:
        raise ValueError(f"sensor {sensor!r} needs {lacking} readings, which the table lacks "
                         f"(columns: {list(table.columns)})")
    return sensor


def _bearings(table: pd.DataFrame) -> dict[str, np.ndarray]:
    """The bearing readings as ``bearing_unit`` (exact unit vectors) or ``bearing`` (angles)."""
    cols = table.columns
    if "bearing_cos" in cols:
        return {"bearing_unit": np.column_stack([table["bearing_cos"].to_numpy(np.float64),
                                                 table["bearing_sin"].to_numpy(np.float64)])}
    if "bearing" in cols:
        return {"bearing": table["bearing"].to_numpy(np.float64)}
    x, z = table["ray_x"].to_numpy(np.float64), table["ray_z"].to_numpy(np.float64)
    vertical = (x == 0) & (z == 0)
    if vertical.any():
        pos = int(np.flatnonzero(vertical)[0])
        raise ObservationTableError(
            f"row {pos}, column 'ray_x': the ray is vertical (ray_x = ray_z = 0), so it has no "
            f"bearing in the camera's horizontal plane ({int(vertical.sum())} such row(s))")
    return {"bearing": np.arctan2(-x, z)}


def _robots(table: pd.DataFrame, robot: pd.Series | None) -> tuple[np.ndarray, list[Any]]:
    """Each row's robot position (0-based) and the robot ids in position order (``robot``: the
    table's normalised robot ids, None without a robot column)."""
    if robot is None:
        return np.zeros(len(table), np.int64), [0]
    codes, uniques = pd.factorize(robot, sort=True)
    order = table.attrs.get("robots")
    if order is None:
        return codes.astype(np.int64), list(uniques)
    order = normalise_ids(pd.Series([str(v) for v in order]), "robot",
                          _Where("attrs['robots']", None)).tolist()
    pos = _positions(np.array(order, dtype=object), list(uniques))
    if (pos < 0).any():
        raise ValueError(f"robots {[u for u, p in zip(uniques, pos, strict=True) if p < 0]} are "
                         f"in the table but not in its attrs['robots'] = {order}")
    return pos[codes], order


def _empty_frames(frames: Any, robot_ids: list[Any], has_robot: bool) -> np.ndarray | None:
    """``attrs["empty_frames"]`` (frames without a sighting that are steps all the same: frame
    numbers, or [robot id, frame] pairs with a ``robot`` column) as (robot position, frame)."""
    if frames is None:
        return None
    try:
        if not has_robot:
            return np.array([[0, int(f)] for f in frames], dtype=np.int64).reshape(-1, 2)
        at = _positions(np.array(robot_ids, dtype=object), [r for r, _ in frames])
        if (at < 0).any():
            raise ValueError(f"attrs['empty_frames'] names robots not in the table: "
                             f"{sorted({r for (r, _), a in zip(frames, at, strict=True) if a < 0})}")
        return np.column_stack([at, [int(f) for _, f in frames]]).astype(np.int64).reshape(-1, 2)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"attrs['empty_frames'] must list frame numbers (with a robot column: "
                         f"[robot, frame] pairs): {exc}") from exc


def _ticks(table: pd.DataFrame, robot: np.ndarray) -> np.ndarray:
    """Each row's frame number: ``frame``, else the rank of its time among its robot's times."""
    if "frame" in table.columns:
        return table["frame"].to_numpy(np.int64)
    time = table["time"].to_numpy(np.float64)
    order = np.lexsort((time, robot))
    r, t = robot[order], time[order]
    new_robot = np.r_[True, r[1:] != r[:-1]]
    new_frame = new_robot | np.r_[True, t[1:] != t[:-1]]
    frame = np.cumsum(new_frame) - 1  # a global frame count, restarted at each robot below
    first = np.maximum.accumulate(np.where(new_robot, frame, 0))
    out = np.empty(len(time), np.int64)
    out[order] = frame - first
    return out


def _id_array(values: Any) -> np.ndarray:
    """Ids as an int64 array, or an object array of strings."""
    arr = np.asarray(list(values), dtype=object)
    if all(isinstance(v, int | np.integer) and not isinstance(v, bool) for v in arr):
        return arr.astype(np.int64)
    if all(isinstance(v, str) for v in arr):
        return arr
    raise ValueError("landmark ids must all be integers or all strings")


def _values_at(matrix: sp.csr_array, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """``matrix[row[i], col[i]]`` for every i (0 where nothing is stored), without densifying."""
    coo = sp.csr_array(matrix)
    coo.sum_duplicates()
    coo = coo.tocoo()
    ncols = matrix.shape[1]
    key = coo.row.astype(np.int64) * ncols + coo.col
    order = np.argsort(key, kind="stable")
    key, data = key[order], coo.data[order]
    want = row.astype(np.int64) * ncols + col
    at = np.minimum(np.searchsorted(key, want), max(len(key) - 1, 0))
    found = (key[at] == want) if len(key) else np.zeros(len(want), bool)
    return np.where(found, data[at] if len(key) else 0.0, 0.0).astype(np.float64)


# ------------------------------------------------------------------------ table -> History
def _row_ids(declared: Any, seen_ids: np.ndarray, codes: np.ndarray,
             anchor_ids: list[Any]) -> tuple[np.ndarray, np.ndarray]:
    """The history's landmark ids (row order) and each table row's history row: the table's
    ``attrs["landmarks"]`` when it declares them, else the sighted and anchor ids sorted. Every
    anchor must be among the landmarks the log knows."""
    if declared is not None:
        # read as a CSV's ids are (the JSON "7" or 7 is landmark 7, "007" a string)
        ids = np.asarray(normalise_ids(pd.Series([str(v) for v in declared]), "landmark",
                                       _Where("attrs['landmarks']", None)).tolist(), dtype=object)
        listed = set(ids.tolist())
        if len(listed) != len(ids):
            raise ValueError("the table's attrs['landmarks'] lists a landmark twice")
        outside = [v for v in seen_ids.tolist() if v not in listed]
        if outside:
            raise ValueError(f"landmarks {outside[:10]} are in the table but not in its "
                             f"attrs['landmarks']")
    else:
        ids = _sorted_ids(set(seen_ids.tolist()) | set(anchor_ids))
    li = _positions(ids, seen_ids.tolist())[codes]
    # anchors: in the log (their count and shape are checked by the caller)
    known = set(ids.tolist()) if declared is not None else set(seen_ids.tolist())
    absent = [a for a in anchor_ids if a not in known]
    if absent:
        raise ValueError(f"anchors {absent} are never sighted in the log (landmarks sighted: "
                         f"{_sorted_ids(seen_ids)[:20].tolist()}{' ...' if len(seen_ids) > 20 else ''})")
    return ids, li


def _steps(table: pd.DataFrame, attrs: dict[str, Any], robot: np.ndarray, robot_ids: list[Any],
           bin_width: float | None, drop_empty_bins: bool) -> Any:
    """The history's steps: per-robot time bins of ``bin_width`` seconds, else one per frame
    (with the frames the table declares empty)."""
    if bin_width is not None:
        check_real("bin_width", bin_width, low=0.0, low_open=True)
        return time_steps(robot, table["time"].to_numpy(np.float64), len(robot_ids), bin_width,
                          drop_empty_bins=drop_empty_bins)
    extra = _empty_frames(attrs.get("empty_frames"), robot_ids, "robot" in table.columns)
    return tick_steps(robot, _ticks(table, robot), len(robot_ids), extra=extra)


def _truth_positions(truth: pd.DataFrame | None,
                     ids: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    """The (M, 2) true positions (NaN: unknown; for scoring only) and the meta entries naming
    the landmarks the truth misses and the truth rows no landmark uses."""
    positions = np.full((len(ids), 2), np.nan)
    if truth is None:
        return positions, {}
    at = _positions(ids, truth["landmark"].tolist())
    positions[at[at >= 0]] = truth[["x", "y"]].to_numpy(np.float64)[at >= 0]
    have = set(truth["landmark"].tolist())
    return positions, {"truth_missing": [v for v in ids.tolist() if v not in have],
                       "truth_unused": [v for v, p in zip(truth["landmark"], at, strict=True)
                                        if p < 0]}


def observations_to_history(
    table: pd.DataFrame,
    anchors: pd.DataFrame | str | os.PathLike,
    *,
    truth: pd.DataFrame | str | os.PathLike | None = None,
    sensor: str | None = None,
    bin_width: float | None = None,
    drop_empty_bins: bool = True,
    sparse: bool | None = None,
) -> History:
    """The :class:`History` of an observation table (the module docstring says how).

    Args:
        table: the sightings (:func:`~lfmdr_gym.histories.observation_table.read_observations`).
        anchors: table (or file) ``landmark, x, y`` of the anchors: at least 3, not collinear,
            each in the log.
        truth: table (or file) of true landmark positions, for scoring only; None: unknown.
        sensor: the history's sensor or fused set (``"visibility"``, ``"bearing"``, ``"range"``,
            ``"range-bearing"``, ``"visibility-bearing"``); None: ``attrs["sensor"]``, else the
            readings the table has (range and bearing: ``"range-bearing"``; none: visibility).
        bin_width: [s] per-robot time bins; None: one step per frame.
        drop_empty_bins: with ``bin_width``, drop bins in which a robot saw nothing.
        sparse: scipy sparse matrices and masks; None: when a dense matrix would be large
            (:func:`~lfmdr_gym.histories.binning.assemble`).

    Row ``i`` of the history is landmark ``meta["landmarks"][i]``. Bad input raises
    :class:`~lfmdr_gym.histories.observation_table.ObservationTableError` (a ValueError).
    """
    landmark, robot_col = checked_ids(table)
    if not len(table):
        raise ValueError("the observation table has no rows: nothing was sighted")
    anchors = _landmark_table(anchors, "anchors")
    truth = None if truth is None else _landmark_table(truth, "truth")
    if "z" in anchors.columns:  # 3-D: rays (and ranges) of one camera
        if bin_width is not None:
            raise ValueError("a 3-D log maps one step per frame: bin_width is for 2-D logs")
        return ray_table_to_history(table, anchors, truth, sensor)  # (checked above)
    name = _sensor(table, sensor)
    parts = sensors_of(name)
    attrs = dict(table.attrs)
    codes, seen_ids = pd.factorize(landmark)
    seen_ids = np.asarray(seen_ids, dtype=object)
    anchor_ids = anchors["landmark"].tolist()
    _same_kind({"the table": seen_ids, "the anchors": anchor_ids,
                **({} if truth is None else {"the truth": truth["landmark"].tolist()})})
    ids, li = _row_ids(attrs.get("landmarks"), seen_ids, codes, anchor_ids)
    anchor_pos = anchors[["x", "y"]].to_numpy(np.float64)
    check_not_collinear(anchor_pos, "anchor positions")
    robot, robot_ids = _robots(table, robot_col)
    steps = _steps(table, attrs, robot, robot_ids, bin_width, drop_empty_bins)
    n_steps, m = steps.n_steps, len(ids)
    readings: dict[str, Any] = {}
    if "bearing" in parts:
        readings.update(_bearings(table))
    if "range" in parts:
        readings["range_"] = table["range"].to_numpy(np.float64)
    if "visibility" in parts and "visible" in table.columns:
        readings["visible"] = table["visible"].to_numpy() == 1
    cells = cell_values(parts, li, steps.step, (m, n_steps), **readings)
    complete = bool(attrs.get("complete", False))
    built = {s: assemble(cells, s, masked=not complete, sparse=sparse) for s in parts}
    positions, meta_truth = _truth_positions(truth, ids)
    anchor_rows = _positions(ids, anchor_ids)
    if truth is None:
        positions[anchor_rows] = anchor_pos
    timeline = steps.timeline if ("robot" in table.columns or bin_width is not None) else None
    meta = {"source": attrs.get("source", "observation table"), "sensor": name,
            "landmarks": ids.tolist(), "anchor_landmarks": anchor_ids,
            "robots": list(robot_ids) if "robot" in table.columns else None,
            "bin_width": None if bin_width is None else float(bin_width),
            "rows": int(len(table)), "complete": complete, **meta_truth,
            # History.meta is JSON (History.save): an attrs value JSON cannot hold (a Path, say)
            # is kept as its text
            "table_attrs": json.loads(json.dumps(attrs, default=str))}
    if len(parts) == 1:
        matrix, mask = built[name]
    else:
        matrix = {s: built[s][0] for s in parts}
        mask = None if complete else {s: built[s][1] for s in parts}
    return History(sensor=name, matrix=matrix, object_positions=positions,
                   anchor_ids=anchor_rows, anchor_positions=anchor_pos, mask=mask, meta=meta,
                   timeline=timeline)


def landmark_ids(history: History) -> np.ndarray:
    """The landmark id of each row of a history made by :func:`observations_to_history` (or
    anything that keeps ``meta["landmarks"]``); else the row numbers."""
    ids = history.meta.get("landmarks")
    if ids is None or len(ids) != history.n_objects:
        return np.arange(history.n_objects)
    return np.asarray(ids, dtype=object if any(isinstance(v, str) for v in ids) else np.int64)


# ------------------------------------------------------------------------ History -> table
def _entries(history: History) -> tuple[sp.csr_array, bool]:
    """The (M, N) entries to write: the observed ones (a masked history) or those with a non-zero
    reading (complete), and whether the history is masked."""
    parts = history.parts or {history.sensor: history}
    masked = any(p.masked for p in parts.values())
    step_sets = []
    for s, p in parts.items():
        c = COLUMNS_PER_STEP[s]
        if masked:
            if not p.masked:
                raise ValueError(f"a {history.sensor} history whose {s} part has no mask while "
                                 "another has one cannot be written as one table")
            grid = p.sparse_mask
        else:
            grid = p.sparse != 0
        cols = [sp.csr_array(grid[:, k::c]) for k in range(c)]
        if any((cols[0] != other).nnz for other in cols[1:]):
            raise ValueError(f"the {s} mask differs between the columns of one step; a table "
                             "holds one reading per landmark and step")
        step_sets.append(cols[0].astype(bool))
    if masked and any((step_sets[0] != other).nnz for other in step_sets[1:]):
        raise ValueError(f"the sensors of this {history.sensor} history observed different "
                         "entries; a table holds one set of observed entries per landmark and step")
    grid = step_sets[0]
    for other in step_sets[1:]:
        grid = grid + other
    return sp.csr_array(grid, dtype=bool), masked


def _robot_frames(history: History) -> tuple[np.ndarray, np.ndarray, list[Any]]:
    """Each step's robot number and frame, and the robots' ids: from the history's timeline
    (which must be in (robot, tick) order without repeats), else one robot whose frames are the
    step numbers."""
    n = history.n_steps
    if history.timeline is None:
        return np.zeros(n, np.int64), np.arange(n, dtype=np.int64), []
    tl = history.timeline
    order_ok = np.all((tl[1:, 0] > tl[:-1, 0]) |
                      ((tl[1:, 0] == tl[:-1, 0]) & (tl[1:, 1] > tl[:-1, 1])))
    if not order_ok:
        raise ValueError("the history's steps are not in (robot, tick) order without repeats;"
                         " a table's frames would reorder them")
    robot_of, frame_of = tl[:, 0], tl[:, 1]
    # robot ids: the history's own (meta["robots"], as a loader or this module keeps them) if
    # they name every robot of the timeline, else the timeline's robot numbers
    named = history.meta.get("robots")
    n_robots = int(robot_of.max()) + 1 if n else 0
    robot_ids = (list(named) if isinstance(named, list) and len(named) >= n_robots
                 and len(set(map(str, named))) == len(named) else list(range(n_robots)))
    return robot_of, frame_of, (_id_array(robot_ids).tolist() if robot_ids else [])


def _readings(history: History, row: np.ndarray, step: np.ndarray) -> dict[str, np.ndarray]:
    """The table's reading columns of the entries (``row``, ``step``), per sensor of the
    history: ``visible`` (only if some observed entry reads 0), ``bearing`` with its exact
    ``bearing_cos, bearing_sin``, ``range``."""
    out: dict[str, np.ndarray] = {}
    parts = history.parts or {history.sensor: history}
    for s, p in parts.items():
        data = p.sparse
        if s == "visibility":
            v = _values_at(data, row, step)
            if not np.isin(v, (0.0, 1.0)).all():
                raise ValueError("visibility readings must be 0 or 1")
            if (v == 0).any():
                out["visible"] = v.astype(np.int8)
        elif s == "bearing":
            c, sn = _values_at(data, row, 2 * step), _values_at(data, row, 2 * step + 1)
            if np.any((c == 0) & (sn == 0)):
                raise ValueError("an observed bearing reads (0, 0) (an object at the robot's "
                                 "centre): it has no direction to write")
            out["bearing"] = np.arctan2(sn, c)
            out["bearing_cos"], out["bearing_sin"] = c, sn
        else:
            out["range"] = _values_at(data, row, step)
    return out


def history_to_observations(history: History, *, landmarks: Any = None) -> ObservationLog:
    """Write a :class:`History` as an observation table, its anchors and its ground truth.

    One row per observed entry (a masked history) or per entry with a non-zero reading (a
    complete one: ``attrs["complete"] = True``, every other entry a known 0). Columns: ``time``
    and ``frame`` (the step, or with a timeline its tick; ``time`` = that number, as the history
    keeps no clock), ``robot`` (the timeline's robot), ``landmark``, and per sensor ``visible``
    (visibility, if any observed entry reads 0), ``bearing`` with ``bearing_cos, bearing_sin``
    (the exact unit vector), ``range``. ``attrs`` keeps the sensor, the landmark ids, the robots
    and the steps without a row, so :func:`observations_to_history` gives the same matrices,
    masks and timeline back. Robot poses are not written, nor the values of unobserved entries
    of a masked history (no mapper reads them; they come back as 0, as every recorder and loader
    writes them).

    Args:
        history: any single-sensor or fused History.
        landmarks: an id per row (default ``meta["landmarks"]`` if it fits, else 0..M-1).
    """
    m, n = history.n_objects, history.n_steps
    ids = _id_array(landmark_ids(history) if landmarks is None else landmarks)
    if len(ids) != m or len(set(ids.tolist())) != m:
        raise ValueError(f"landmarks must be {m} distinct ids (one per row), got {len(ids)}")
    robot_of, frame_of, robot_ids = _robot_frames(history)
    grid, masked = _entries(history)
    coo = grid.tocoo()
    order = np.lexsort((coo.row, coo.col))  # step by step, landmarks in row order
    row, step = coo.row[order].astype(np.int64), coo.col[order].astype(np.int64)
    out: dict[str, Any] = {"time": frame_of[step].astype(np.float64)}
    if history.timeline is not None:
        out["robot"] = _id_array(robot_ids)[robot_of[step]]
    out["frame"] = frame_of[step]
    out["landmark"] = ids[row]
    out.update(_readings(history, row, step))
    table = pd.DataFrame(out)
    has_rows = np.zeros(n, bool)
    has_rows[step] = True
    empty = np.flatnonzero(~has_rows)
    table.attrs = {
        "source": "lfmdr history", "sensor": history.sensor, "complete": not masked,
        "landmarks": ids.tolist(),
        **({"robots": robot_ids} if history.timeline is not None and n else {}),
        **({"empty_frames": ([[robot_ids[robot_of[t]], int(frame_of[t])] for t in empty]
                             if history.timeline is not None else frame_of[empty].tolist())}
           if len(empty) else {}),
    }
    anchors = pd.DataFrame({"landmark": ids[history.anchor_ids],
                            "x": history.anchor_positions[:, 0],
                            "y": history.anchor_positions[:, 1]})
    known = np.all(np.isfinite(history.object_positions), axis=1)
    truth = None
    if known.any():
        truth = pd.DataFrame({"landmark": ids[known], "x": history.object_positions[known, 0],
                              "y": history.object_positions[known, 1]})
    return ObservationLog(table, anchors, truth)
