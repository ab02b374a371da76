"""Map scores of SPEC §4: mean position error (MPE) and mean orientation error (MOE)."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

__all__ = ["mean_orientation_error", "mean_position_error"]


def _check_pair(estimate, truth, exclude) -> tuple[np.ndarray, np.ndarray]:
    est = np.asarray(estimate, dtype=float)
    tru = np.asarray(truth, dtype=float)
    if est.ndim != 2 or est.shape[1] != 2:
        raise ValueError(f"estimate must have shape (M, 2), got {est.shape}")
    if tru.shape != est.shape:
        raise ValueError(f"truth must have the shape of estimate {est.shape}, got {tru.shape}")
    keep = np.ones(len(est), dtype=bool)
    if exclude is not None:
        ex = np.asarray(list(exclude) if not isinstance(exclude, np.ndarray) else exclude)
        if ex.size:
            if not np.issubdtype(ex.dtype, np.integer):
                raise ValueError(f"exclude must hold integer object ids, got dtype {ex.dtype}")
            if ex.min() < -len(est) or ex.max() >= len(est):
                raise ValueError(f"exclude ids out of range for M={len(est)}: {ex.tolist()}")
            keep[ex] = False
    est, tru = est[keep], tru[keep]
    for name, arr in (("estimate", est), ("truth", tru)):
        bad = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
        if bad.size:
            raise ValueError(
                f"{name} has NaN/inf rows (object ids among the kept rows: {bad.tolist()[:10]}); "
                "pass them in exclude= (e.g. exclude=map.unmapped)"
            )
    return est, tru


def mean_position_error(
    estimate: np.ndarray, truth: np.ndarray, exclude: Iterable[int] | None = None
) -> float:
    """Mean Euclidean distance [m] between estimated and true positions (MPE).

    ``exclude`` lists object ids left out (e.g. the anchors, to score non-anchor objects only).
    NaN rows (unmapped objects) must be excluded explicitly: they raise ValueError.
    """
    est, tru = _check_pair(estimate, truth, exclude)
    if len(est) == 0:
        raise ValueError("no objects left to score after exclude")
    return float(np.mean(np.linalg.norm(est - tru, axis=1)))


def _signs_from(P: np.ndarray, i: int) -> np.ndarray:
    """sign((p_j - p_i) x (p_k - p_i)) for all j, k > i: an antisymmetric (n-i-1)^2 block."""
    d = P[i + 1 :] - P[i]
    cross = np.multiply.outer(d[:, 0], d[:, 1])
    cross -= cross.T  # dx_j dy_k - dy_j dx_k
    return np.sign(cross)


def mean_orientation_error(
    estimate: np.ndarray, truth: np.ndarray, exclude: Iterable[int] | None = None
) -> float:
    """Percentage of all C(M, 3) triangles whose orientation differs from the truth (MOE).

    Orientation is the sign of the triangle's signed area (anticlockwise +, clockwise -,
    degenerate 0); a triangle counts as wrong when the signs differ. Exact and vectorised:
    for each first vertex i, one (M-i-1)^2 block of signed areas over all later pairs (j, k),
    so memory stays O(M^2) (about 100 MB at M = 2000) while the work is the exact O(M^3).
    """
    est, tru = _check_pair(estimate, truth, exclude)
    n = len(est)
    if n < 3:
        raise ValueError(f"need at least 3 objects for orientation error, got {n}")
    total = n * (n - 1) * (n - 2) // 6
    wrong = 0
    for i in range(n - 2):
        # The block is antisymmetric with a zero diagonal, so every triangle (i, j, k), j < k,
        # appears twice in the mismatch count.
        wrong += int(np.count_nonzero(_signs_from(est, i) != _signs_from(tru, i))) // 2
    return 100.0 * wrong / total
