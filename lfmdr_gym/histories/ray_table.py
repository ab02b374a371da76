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

__all__ = ["RayHistories", "ray_histories"]


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
