"""Pair statistics of what was observed together: the raw material of the masked mappers.

A masked history (a limited field of view, occlusion, a range limit, real cameras) says, per
step, which objects were sensed and what was measured. Objects sensed in the same step were seen
from one viewpoint, so their pair carries information that no zero-filled history keeps: how
often they are co-observed (visibility, any sensor) and, for ranges, bounds from the triangle
inequality. Each function takes the per-step view of :func:`mappers.core.sensors.step_observations`.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

__all__ = [
    "angle_covisibility_dissimilarity",
    "co_observation_components",
    "co_observation_counts",
    "covisibility_dissimilarity",
    "masked_euclidean_dissimilarity",
    "pair_components",
    "range_pair_bounds",
    "range_pair_distances",
]


def co_observation_counts(seen: np.ndarray) -> np.ndarray:
    """(M, M) number of steps in which both objects were sensed (diagonal: each one's count)."""
    S = np.asarray(seen, dtype=float)
    return S @ S.T


def _pairs_seen_together(seen: np.ndarray, min_pairs: int):
    """``(i, j, steps)`` for each pair i < j sensed together in at least ``min_pairs`` steps
    (``steps``: the boolean step mask of those co-observations)."""
    M = seen.shape[0]
    for i in range(M):
        for j in range(i + 1, M):
            both = seen[i] & seen[j]
            if both.sum() >= min_pairs:
                yield i, j, both


# ---------------------------------------------------------------------- dissimilarities
def covisibility_dissimilarity(seen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``-log`` of the Ochiai co-observation coefficient, and the co-observation counts.

    Returns ``(delta, C)``; pairs never seen together get ``delta = -log(1e-6)``.
    """
    C = co_observation_counts(seen)
    n = np.diag(C).copy()
    with np.errstate(divide="ignore", invalid="ignore"):
        och = C / np.sqrt(np.outer(n, n))
    och = np.nan_to_num(och, nan=0.0)
    delta = -np.log(np.clip(och, 1e-6, 1.0))
    np.fill_diagonal(delta, 0.0)
    return delta, C


def angle_covisibility_dissimilarity(
    seen: np.ndarray, angles: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``-log`` of the angle-weighted Ochiai coefficient of bearing histories, and the counts.

    ``G_ij = sum_t cos(b_i(t) - b_j(t))`` over the steps that sensed both (bearings ``angles``
    [rad]), ``delta_ij = -log(max(G_ij, 0) / sqrt(n_i n_j))`` with ``n_i`` the steps that sensed
    i: the Ochiai coefficient of :func:`covisibility_dissimilarity` in which a co-observation
    counts by how close the two bearings were (1 in the same direction, 0 at right angles).
    It is the cosine of the zero-filled (cos, sin) rows, so on a complete history it is the
    paper's L2-normalised comparison (eq. 7). Returns ``(delta, C)``; pairs never seen together
    (or with ``G_ij <= 0``) get ``delta = -log(1e-6)``.
    """
    S = np.asarray(seen, dtype=float)
    a = np.where(seen, angles, 0.0)
    c, s = np.cos(a) * S, np.sin(a) * S
    C = S @ S.T
    G = np.maximum(c @ c.T + s @ s.T, 0.0)
    n = np.diag(C).copy()
    with np.errstate(divide="ignore", invalid="ignore"):
        och = np.nan_to_num(G / np.sqrt(np.outer(n, n)), nan=0.0)
    delta = -np.log(np.clip(och, 1e-6, 1.0))
    np.fill_diagonal(delta, 0.0)
    return delta, C


def range_pair_distances(
    ranges: np.ndarray, seen: np.ndarray, *, quantile: float = 0.98, min_pairs: int = 5
) -> tuple[np.ndarray, np.ndarray]:
    """Distance estimates from same-step ranges: the ``quantile`` of ``|r_i - r_j|``.

    Returns ``(delta, counts)``; ``delta`` is 0 where ``counts < min_pairs`` (missing).
    """
    if not 0 < quantile <= 1:
        raise ValueError(f"quantile must be in (0, 1], got {quantile}")
    if min_pairs < 1:
        raise ValueError(f"min_pairs must be >= 1, got {min_pairs}")
    M = seen.shape[0]
    delta = np.zeros((M, M))
    counts = co_observation_counts(seen)
    for i, j, both in _pairs_seen_together(seen, min_pairs):
        delta[i, j] = delta[j, i] = np.quantile(np.abs(ranges[i, both] - ranges[j, both]), quantile)
    counts[counts < min_pairs] = 0
    np.fill_diagonal(counts, 0)
    return delta, counts


def range_pair_bounds(
    ranges: np.ndarray, seen: np.ndarray, *, fov: float = 1.22, upper_quantile: float = 0.02,
    min_pairs: int = 5,
) -> np.ndarray:
    """Upper bounds on pair distances from same-step ranges and a field of view ``fov`` [rad]:
    the ``upper_quantile`` of ``sqrt(r_i^2 + r_j^2 - 2 r_i r_j cos(fov))``; inf where missing."""
    if not 0 < fov <= np.pi:
        raise ValueError(f"fov must be in (0, pi] radians, got {fov}")
    if not 0 <= upper_quantile <= 1:
        raise ValueError(f"upper_quantile must be in [0, 1], got {upper_quantile}")
    M = seen.shape[0]
    upper = np.full((M, M), np.inf)
    for i, j, both in _pairs_seen_together(seen, min_pairs):
        ri, rj = ranges[i, both], ranges[j, both]
        u = np.sqrt(np.maximum(ri**2 + rj**2 - 2 * ri * rj * np.cos(fov), 0.0))
        upper[i, j] = upper[j, i] = np.quantile(u, upper_quantile)
    np.fill_diagonal(upper, 0.0)
    return upper


def masked_euclidean_dissimilarity(
    values: np.ndarray, seen: np.ndarray, sensor: str, *, min_pairs: int = 5
) -> tuple[np.ndarray, np.ndarray]:
    """RMS difference of two histories over the steps that observed both (bearing: chord
    ``|e^{ib_i} - e^{ib_j}|``). Returns ``(delta, counts)``, counts 0 where missing."""
    M = seen.shape[0]
    delta = np.zeros((M, M))
    counts = co_observation_counts(seen)
    for i, j, both in _pairs_seen_together(seen, min_pairs):
        a, b = values[i, both], values[j, both]
        diff2 = 2 - 2 * np.cos(a - b) if sensor == "bearing" else (a - b) ** 2
        delta[i, j] = delta[j, i] = np.sqrt(np.mean(diff2))
    counts[counts < min_pairs] = 0
    np.fill_diagonal(counts, 0)
    return delta, counts


# ---------------------------------------------------------------------------- groups
def pair_components(weights: np.ndarray) -> list[list[int]]:
    """Connected components (lists of row indices) of the graph of pairs with weight > 0."""
    n, labels = connected_components(csr_matrix(weights > 0), directed=False)
    return [np.flatnonzero(labels == k).tolist() for k in range(n)]


def co_observation_components(seen: np.ndarray, min_co: int = 3) -> list[list[int]]:
    """Connected components (object indices) of the graph joining objects sensed together in
    at least ``min_co`` steps."""
    C = co_observation_counts(seen)
    np.fill_diagonal(C, 0)
    return pair_components(C >= min_co)
