"""Symmetric k-nearest-neighbour graphs, made connected when they fall apart.

Graph-based mappers (LEM, weighted SMACOF, SDE) need one connected neighbourhood graph: on a
disconnected graph their solutions are undefined (LEM, SDE) or the pieces drift apart (SMACOF).
The repair used everywhere is the one Isomap uses in scikit-learn: join the components by their
closest pairs of points, one edge at a time, and report how many edges were added.

Two neighbour rules live here. The paper's methods use scikit-learn's kNN graph
(:func:`symmetric_knn_graph`) on the history rows. CAL-SMA (:mod:`mappers.calibrated.cal_sma`) needs
neighbours among *informative* pairs only: a dissimilarity at its saturation value (two objects
never sensed together) says "far", not how far, so :func:`knn_mask` leaves such pairs out and
breaks ties by index. The two rules differ only where distances tie, which saturated pairs do.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components
from sklearn.metrics import pairwise_distances
from sklearn.neighbors import kneighbors_graph

__all__ = [
    "GraphRepairWarning",
    "connect_components",
    "connected_knn_graph",
    "informative_pairs",
    "knn_mask",
    "symmetric_knn_graph",
    "warn_if_repaired",
]


class GraphRepairWarning(UserWarning):
    """The kNN graph was disconnected and edges were added between its closest components."""


def symmetric_knn_graph(
    X: np.ndarray, n_neighbors: int, *, precomputed: bool = False
) -> csr_matrix:
    """Binary symmetric kNN graph: i ~ j when j is among i's K nearest or i among j's.

    ``X`` is (n, d) points, or an (n, n) distance matrix when ``precomputed``.
    """
    n = X.shape[0]
    if not 1 <= n_neighbors < n:
        raise ValueError(f"n_neighbors must be in [1, {n - 1}] for {n} points, got {n_neighbors}")
    metric = "precomputed" if precomputed else "euclidean"
    A = kneighbors_graph(X, n_neighbors, mode="connectivity", metric=metric, include_self=False,
                         n_jobs=1)
    A = A.maximum(A.T).tocsr()
    A.data[:] = 1.0
    return A


def connect_components(
    A: csr_matrix, distances: np.ndarray
) -> tuple[csr_matrix, list[tuple[int, int]]]:
    """Join the components of graph ``A`` by their closest pairs under ``distances`` (n, n).

    Returns the connected binary graph and the list of added edges (empty if ``A`` was
    connected). Repeatedly links the component of the first point to its nearest other
    component, so at most (components - 1) edges are added.
    """
    A = A.tolil(copy=True)
    added: list[tuple[int, int]] = []
    n_comp, labels = connected_components(A, directed=False)
    while n_comp > 1:
        inside = labels == labels[0]
        sub = distances[np.ix_(inside, ~inside)]
        a, b = np.unravel_index(np.argmin(sub), sub.shape)
        i, j = int(np.flatnonzero(inside)[a]), int(np.flatnonzero(~inside)[b])
        A[i, j] = A[j, i] = 1.0
        added.append((i, j))
        n_comp, labels = connected_components(A, directed=False)
    return A.tocsr(), added


def connected_knn_graph(
    X: np.ndarray, n_neighbors: int, *, precomputed: bool = False
) -> tuple[csr_matrix, np.ndarray, list[tuple[int, int]]]:
    """Symmetric kNN graph made connected; returns (graph, distance matrix, added edges)."""
    D = np.asarray(X, dtype=float) if precomputed else pairwise_distances(X, n_jobs=1)
    A = symmetric_knn_graph(D, n_neighbors, precomputed=True)
    A, added = connect_components(A, D)
    return A, D, added


def warn_if_repaired(added: list[tuple[int, int]], n_neighbors: int, *, stacklevel: int = 2) -> None:
    """Raise a :class:`GraphRepairWarning` when ``added`` (from :func:`connect_components`) is
    not empty; ``stacklevel`` counts from the caller, as in :func:`warnings.warn`."""
    if added:
        warnings.warn(
            f"kNN graph (K={n_neighbors}) was disconnected: joined its components by "
            f"{len(added)} closest-pair edge(s)",
            GraphRepairWarning,
            stacklevel=stacklevel + 1,
        )


def knn_mask(delta: np.ndarray, valid: np.ndarray, k: int) -> np.ndarray:
    """(n, n) bool symmetric kNN mask in ``delta`` among the ``valid`` pairs (ties: lower index
    first). Unlike :func:`symmetric_knn_graph` it never picks an uninformative pair."""
    m = len(delta)
    d = np.where(valid, delta, np.inf)
    np.fill_diagonal(d, np.inf)
    k = min(k, m - 1)
    order = np.argsort(d, axis=1, kind="stable")[:, :k]
    A = np.zeros((m, m), dtype=bool)
    A[np.repeat(np.arange(m), k), order.ravel()] = True
    A &= valid
    return A | A.T


def informative_pairs(delta: np.ndarray) -> np.ndarray:
    """Pairs whose dissimilarity is informative: below the saturation value (never co-sensed)."""
    top = delta.max()
    valid = delta < top * (1.0 - 1e-9) if top > 0 else np.zeros_like(delta, dtype=bool)
    np.fill_diagonal(valid, False)
    return valid
