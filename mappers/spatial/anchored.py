"""Which objects the sightings can place at all: those linked by a chain of sightings to three
anchors not on one line.

Two objects seen in one step are linked; the links split the objects into groups (the connected
components of the co-sighting graph; SciPy's ``connected_components``). Nothing a step sees
ties its group to another group, so each group's sightings are explained equally well when the
whole group (objects and the steps that saw them) is moved by any rigid motion (any similarity,
for rays alone). The anchors fix that motion only in a group that holds three of them not on one
line: with two, the group still turns freely about the line through them; with one, about that
point; with none, it is anywhere. No method, however started, places the objects of the other
groups from their sightings alone (a motion model or odometry would link the steps; the project
maps without them).

The condition is necessary, not sufficient: inside a group, parts joined by fewer than three
shared objects can still turn against one another. It is an upper bound on what a map can
place, and it names the objects it must leave out.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix, issparse
from scipy.sparse.csgraph import connected_components

__all__ = ["ANCHOR_LINE_RTOL", "anchored_objects"]

ANCHOR_LINE_RTOL = 1e-6
"""Anchors lie on one line when the second singular value of their centred positions is below
this share of the first (the tolerance :func:`mappers.core.align_3d.check_not_collinear_3d`
refuses anchors with)."""


def _off_line(points: np.ndarray) -> bool:
    if len(points) < 3:
        return False
    s = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return bool(s[0] > 0 and s[1] > ANCHOR_LINE_RTOL * s[0])


def anchored_objects(seen, anchor_ids, anchor_positions) -> np.ndarray:
    """(M,) bool: the objects whose group of co-sighted objects (see the module's docstring)
    holds three anchors not on one line; the others cannot be placed from the sightings.

    Args:
        seen: (M, N) sightings, nonzero where object i was seen at step j (a dense array or a
            SciPy sparse matrix; only which entries are nonzero counts).
        anchor_ids: (A,) rows of the anchors.
        anchor_positions: (A, 2) or (A, 3) their positions (2-D: three anchors not on one line
            fix a planar similarity alike).
    """
    S = csr_matrix(seen) if issparse(seen) else None
    if S is None:
        arr = np.asarray(seen)
        if arr.ndim != 2:
            raise ValueError(f"seen must be an (M, N) matrix of sightings, got shape {arr.shape}")
        S = csr_matrix(np.isfinite(arr) & (arr != 0))
    m = S.shape[0]
    ids = np.asarray(anchor_ids)
    pos = np.asarray(anchor_positions, dtype=float)
    if ids.ndim != 1 or not np.issubdtype(ids.dtype, np.integer) or (
            ids.size and (ids.min() < 0 or ids.max() >= m)):
        raise ValueError(f"anchor_ids must be a 1-D array of integer rows in [0, {m}), got "
                         f"{anchor_ids!r}")
    if pos.ndim != 2 or pos.shape[0] != ids.size or pos.shape[1] not in (2, 3):
        raise ValueError(f"anchor_positions must be ({ids.size}, 2) or ({ids.size}, 3), got "
                         f"shape {pos.shape}")
    if not np.all(np.isfinite(pos)):
        raise ValueError("anchor_positions contain NaN or inf")
    S.data = np.ones_like(S.data, dtype=float)
    S.eliminate_zeros()
    # objects linked when seen in one step: S S^T is nonzero exactly there (and on the diagonal)
    link = coo_matrix(S @ S.T)
    _, group = connected_components(link, directed=False)
    out = np.zeros(m, dtype=bool)
    for g in np.unique(group[ids]):
        mine = group[ids] == g
        if _off_line(pos[mine]):
            out[group == g] = True
    return out
