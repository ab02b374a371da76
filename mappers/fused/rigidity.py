"""Which objects a set of measured pair distances and fixed anchors pins down.

A map drawn from pair distances is only as determined as the graph of pairs: an object joined
to the rest by one distance can swing on a circle, and a cluster tied to the anchors by too few
pairs can turn. The test is infinitesimal rigidity (Asimow & Roth, *Trans. AMS* 245, 1978): at
the drawn positions, the rigidity matrix R has one row per pair (i, j), ``p_i - p_j`` in i's two
columns and ``p_j - p_i`` in j's; with the anchors' columns removed, a non-zero vector of R's
null space is a motion of the free objects that keeps every measured distance to first order,
and the objects it moves are not pinned down. Generic positions (any measured layout) make this
test exact for the graph (Gluck 1975).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import connected_components

__all__ = ["anchored_components", "flexible_objects"]


def anchored_components(weights: np.ndarray, anchors: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The connected components of the graph of pairs (``weights > 0``), each as
    ``(objects, anchors among them)``."""
    n, labels = connected_components(np.asarray(weights) > 0, directed=False)
    anchors = np.asarray(anchors)
    return [(np.flatnonzero(labels == c), anchors[labels[anchors] == c]) for c in range(n)]


def flexible_objects(
    positions: np.ndarray, weights: np.ndarray, fixed: np.ndarray, *, rtol: float = 1e-6
) -> np.ndarray:
    """Indices of the free objects that some first-order motion moves while every pair with
    ``weights > 0`` keeps its length and the ``fixed`` objects stay put.

    Args:
        positions: (n, 2) drawn positions (finite).
        weights: (n, n) symmetric; a positive entry is a measured pair.
        fixed: indices held fixed (the anchors).
        rtol: singular values below ``rtol`` times the largest count as zero.
    """
    P = np.asarray(positions, dtype=float)
    n = len(P)
    i, j = np.nonzero(np.triu(np.asarray(weights) > 0, 1))
    free = np.setdiff1d(np.arange(n), fixed)
    if free.size == 0:
        return free
    R = np.zeros((len(i), 2 * n))
    diff = P[i] - P[j]
    rows = np.arange(len(i))
    for k in range(2):
        R[rows, 2 * i + k] = diff[:, k]
        R[rows, 2 * j + k] = -diff[:, k]
    cols = np.column_stack([2 * free, 2 * free + 1]).ravel()
    R = R[:, cols]
    if len(i) == 0:
        return free
    # the null space of R is that of R^T R (2 per free object squared: far smaller than R)
    w, V = np.linalg.eigh(R.T @ R)
    motions = V[:, w <= (rtol**2) * max(w[-1], 1e-300)] if w[-1] > 0 else V
    if motions.size == 0:
        return free[:0]
    moved = np.linalg.norm(motions.reshape(len(free), 2, -1), axis=(1, 2)) > 1e-6
    return free[moved]
