"""An observation table (issue 33's contract) of 3-D sightings -> the histories 3-D maps take.

One row per sighting with ``time``, ``landmark``, optional ``frame`` (else rows of one ``time``
are one frame) and, by the sensor, ``ray_x, ray_y, ray_z`` (any length) and ``range``. Out come
the landmark ids (rows of the histories, sorted), a 3-D bearing history (M, 3N) of unit rays
(:mod:`mappers.spatial.rays`), a range history (M, N) (0 where none) and the visibility
history (M, N) of 0/1, with one column per frame in time order. One robot; the table's
``robot`` column, if any, must hold one value.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pandas as pd

from lfmdr_gym.histories.history import History

__all__ = ["RayHistories", "ray_histories", "ray_table_to_history"]


class RayHistories(NamedTuple):
    """``ids`` (M,) landmark ids; ``rays`` (M, 3N) or None; ``ranges`` (M, N) or None;
    ``visibility`` (M, N) 0/1."""

    ids: np.ndarray
    rays: np.ndarray | None
    ranges: np.ndarray | None
    visibility: np.ndarray


def ray_histories(table: pd.DataFrame) -> RayHistories:
    """The histories of a table of 3-D sightings (see the module's docstring). ValueError naming
    the column: a missing ``time``/``landmark``, a ray of length 0 or not finite, a range that
    is not > 0, a landmark seen twice in one frame, several robots."""
    for col in ("time", "landmark"):
        if col not in table.columns:
            raise ValueError(f"the observation table has no {col!r} column")
    if "robot" in table.columns and table["robot"].nunique() > 1:
        raise ValueError("ray_histories maps one robot's table; the 'robot' column holds "
                         f"{table['robot'].nunique()} robots")
    frame_key = table["frame"] if "frame" in table.columns else table["time"]
    frames, col = np.unique(frame_key.to_numpy(), return_inverse=True)
    ids, row = np.unique(table["landmark"].to_numpy(), return_inverse=True)
    m, n = ids.size, frames.size
    if pd.DataFrame({"r": row, "c": col}).duplicated().any():
        k = int(np.flatnonzero(pd.DataFrame({"r": row, "c": col}).duplicated())[0])
        raise ValueError(f"row {k}: landmark {table['landmark'].iloc[k]!r} seen twice in one frame")
    vis = np.zeros((m, n))
    vis[row, col] = 1.0
    rays = ranges = None
    ray_cols = ["ray_x", "ray_y", "ray_z"]
    if set(ray_cols) <= set(table.columns):
        r = table[ray_cols].to_numpy(dtype=float)
        length = np.linalg.norm(r, axis=1)
        bad = np.flatnonzero(~(np.isfinite(length) & (length > 0)))
        if bad.size:
            raise ValueError(f"row {bad[0]}: the ray (ray_x, ray_y, ray_z) = {r[bad[0]].tolist()} "
                             "has length 0 or is not finite")
        rays = np.zeros((m, 3 * n))
        for k in range(3):
            rays[row, 3 * col + k] = r[:, k] / length
    if "range" in table.columns:
        if rays is None:
            raise ValueError("the table has ranges but no rays (ray_x, ray_y, ray_z)")
        d = table["range"].to_numpy(dtype=float)
        bad = np.flatnonzero(~(np.isfinite(d) & (d > 0)))
        if bad.size:
            raise ValueError(f"row {bad[0]}: range {d[bad[0]]!r} is not a positive number")
        ranges = np.zeros((m, n))
        ranges[row, col] = d
    return RayHistories(ids, rays, ranges, vis)


def _positions_3d(ids: np.ndarray, table: pd.DataFrame | None) -> np.ndarray:
    """(M, 3) positions of the landmarks ``ids`` from a ``landmark, x, y, z`` table (NaN where
    it has none)."""
    out = np.full((len(ids), 3), np.nan)
    if table is None:
        return out
    at = {v: k for k, v in enumerate(table["landmark"].tolist())}
    xyz = table[["x", "y", "z"]].to_numpy(dtype=float)
    for i, landmark in enumerate(ids.tolist()):
        if landmark in at:
            out[i] = xyz[at[landmark]]
    return out


def ray_table_to_history(table: pd.DataFrame, anchors: pd.DataFrame,
                         truth: pd.DataFrame | None = None, sensor: str | None = None) -> History:
    """A 3-D :class:`History` (positions (M, 3); see :func:`ray_histories`) of a table of 3-D
    sightings, with the anchors of a checked ``landmark, x, y, z`` table.

    ``sensor``: ``"range-bearing"`` (rays and ranges, fused), ``"bearing"`` (rays, 3 columns per
    step) or ``"visibility"``; None: the most the table has. The history is masked where a
    landmark was not sighted; row ``i`` is landmark ``meta["landmarks"][i]``. ValueError: an
    anchor absent from the log, fewer than 4 anchors, a sensor the table cannot give.
    """
    if "z" not in anchors.columns:
        raise ValueError("3-D anchors need a z column (landmark, x, y, z)")
    h = ray_histories(table)
    if sensor is None:
        sensor = ("range-bearing" if h.ranges is not None else
                  "bearing" if h.rays is not None else "visibility")
    if sensor not in ("range-bearing", "bearing", "visibility"):
        raise ValueError(f"a 3-D log maps as 'range-bearing', 'bearing' or 'visibility', got "
                         f"{sensor!r}")
    if sensor != "visibility" and h.rays is None:
        raise ValueError(f"sensor {sensor!r} needs rays (ray_x, ray_y, ray_z); the table has none")
    if sensor == "range-bearing" and h.ranges is None:
        raise ValueError("sensor 'range-bearing' needs a range column; the table has none")
    row = {v: k for k, v in enumerate(h.ids.tolist())}
    absent = [a for a in anchors["landmark"].tolist() if a not in row]
    if absent:
        raise ValueError(f"anchors {absent} are never sighted in the log")
    if len(anchors) < 4:
        raise ValueError(f"a 3-D map needs at least 4 anchors (not on one plane), got {len(anchors)}")
    seen = h.visibility > 0
    rays_mask = np.repeat(seen, 3, axis=1)
    if sensor == "range-bearing":
        matrix: object = {"range": h.ranges, "bearing": h.rays}
        mask: object = {"range": seen, "bearing": rays_mask}
    else:
        matrix = h.rays if sensor == "bearing" else h.visibility
        mask = rays_mask if sensor == "bearing" else None
    anchor_ids = np.array([row[a] for a in anchors["landmark"].tolist()], dtype=np.int64)
    anchor_xyz = anchors[["x", "y", "z"]].to_numpy(dtype=float)
    positions = _positions_3d(h.ids, truth)
    no_truth = np.isnan(positions[anchor_ids]).any(axis=1)
    positions[anchor_ids[no_truth]] = anchor_xyz[no_truth]
    meta = {"landmarks": h.ids.tolist(), "source": table.attrs.get("source", "observation table")}
    return History(sensor=sensor, matrix=matrix, object_positions=positions,
                   anchor_ids=anchor_ids, anchor_positions=anchor_xyz, mask=mask, meta=meta)
