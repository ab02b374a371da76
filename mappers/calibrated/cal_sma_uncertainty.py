"""CAL-SMA's position covariances at a fraction of a map's cost: a block jackknife over the
history's steps, each replicate carried to the map by the stress minimiser's linear response
instead of a new embedding.

A CAL-SMA map (:mod:`mappers.calibrated.cal_sma`) is the anchored minimiser of the weighted
stress of calibrated targets ``t_ij = exp(sum_p a_p (log delta_ij)^p + c + b . phi(mid_ij))``
on neighbour pairs (and a weak lower bound on the others). Its sampling spread comes from the
dissimilarities ``delta`` (``1 - cos`` of the visibility rows), which are sums over the steps.
So:

1. the steps are cut into ``nb = ceil(N / L)`` consecutive blocks of ``L = ceil(sqrt(N))``
   steps (consecutive steps of a walk see nearly the same scene), and each block's Gram matrix
   of the rows is taken once; deleting block ``b`` gives the replicate's ``delta_b`` by a
   subtraction (the delete-one-block jackknife: Künsch, *Ann. Statist.* 17, 1989, §3; Efron &
   Tibshirani, *An Introduction to the Bootstrap*, 1993, ch. 11);
2. the replicate's targets are the map's calibration applied to ``delta_b`` (coefficients and
   midpoints held: the calibration is a smooth fit of hundreds of pairs), on the map's
   neighbour pairs;
3. the map's move is the first-order response of the stress minimiser to the targets' change
   (:func:`mappers.smacof.stress_covariance.stress_response`: the implicit function theorem,
   de Leeuw's stress Hessian, the anchors held) — one factorisation, one solve per block;
4. the jackknife covariance ``(nb - 1) / nb sum_b (dX_b - mean)(dX_b - mean)^T`` of the moves.

What the linearisation leaves out — new neighbour pairs, a refitted calibration, the
dissimilarity's bias (a history dissimilarity is not a distance) — is not in the spread; the
caller (:mod:`mappers.covariances`) widens it by a factor chosen on one simulator and confirmed
on another (docs/guide/uncertainty.md).
"""

from __future__ import annotations

import math

import numpy as np

from mappers.calibrated.cal_sma import CalibratedSMACOF, fit_calibration, log_floor
from mappers.core.threads import thread_limit
from mappers.smacof import euclidean_distance_matrix, stress_response

__all__ = ["has_linear_jackknife", "jackknife_targets", "linear_jackknife_covariances"]


def _one_thread():
    """BLAS and OpenMP held to one thread: the jackknife's products and its factorisation are
    small (a few hundred rows), and threads competing for a shared machine's cores made them
    ten times slower (measured at 300 objects)."""
    return thread_limit(1)


def has_linear_jackknife(est) -> bool:
    """Whether the fitted estimator ``est`` is a map the linearised jackknife covers: the dense,
    anchored CAL-SMA of ``1 - cos`` dissimilarities (visibility histories)."""
    return (isinstance(est, CalibratedSMACOF) and getattr(est, "anchored_", False)
            and getattr(est, "dissimilarity_kind_", None) == "cosine")


def _block_grams(X: np.ndarray, n_steps: int, i: np.ndarray, j: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The Gram matrix of the rows of ``X`` (M, n_steps * per_step) over each block of
    ``ceil(sqrt(n_steps))`` consecutive steps (the last may be shorter), at the pairs
    ``(i, j)`` and on the diagonal: ``(nb, P)`` and ``(nb, M)`` (never an (nb, M, M) array)."""
    per_step = X.shape[1] // n_steps
    block = max(1, math.ceil(math.sqrt(n_steps)))
    edges = np.unique(np.minimum(np.arange(0, n_steps + block, block), n_steps) * per_step)
    steps = np.ascontiguousarray(X.T)  # a block of columns as contiguous rows: BLAS's matmul
    at_pairs, diag = [], []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        G = steps[a:b].T @ steps[a:b]
        at_pairs.append(G[i, j])
        diag.append(np.diag(G).copy())
    return np.array(at_pairs), np.array(diag)


def _cosine_logs(G_pairs: np.ndarray, diag: np.ndarray, i: np.ndarray, j: np.ndarray,
                 floor: float) -> np.ndarray:
    """``log max(1 - cos, floor)`` at the pairs ``(i, j)`` from Gram entries (..., P) and
    diagonals (..., M) (an empty row: cosine 0)."""
    norm = np.sqrt(np.where(diag > 0, diag, 1.0))
    cos = np.clip(G_pairs / (norm[..., i] * norm[..., j]), -1.0, 1.0)
    return np.log(np.maximum(1.0 - cos, floor))


def jackknife_targets(est: CalibratedSMACOF, X: np.ndarray, n_steps: int
                      ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray],
                                 np.ndarray, np.ndarray]:
    """The stress CAL-SMA's map minimises and its block-jackknife replicates' target changes
    (steps 1 and 2 of the module docstring).

    Parameters:
        est: the fitted CAL-SMA (:func:`has_linear_jackknife`).
        X: (M, n_steps * per_step) the history rows it was fitted on (any positive row
            scaling: ``1 - cos`` ignores it).
        n_steps: the history's steps.

    Returns:
        ``(T, W, pairs, dt, few)``: the (M, M) targets and weights of the stress whose
        minimiser the map is, CAL-SMA's last re-embedding (neighbour pairs with weight 1 and
        their calibrated targets; the other pairs with CAL-SMA's far weight and the target
        ``max(distance, bound)``: a weak spring that keeps a loosely tied object where it
        is), the neighbour pairs ``(i, j)`` (each once), their (nb, P) target changes in the
        nb delete-one-block replicates, and an (M,) bool, True for objects seen in fewer than
        two blocks.
    """
    if not has_linear_jackknife(est):
        raise ValueError("the linearised jackknife needs a fitted, anchored CAL-SMA of "
                         "visibility (1 - cos) dissimilarities")
    X = np.asarray(X, dtype=float)
    Y = est.embedding_
    m = len(Y)
    if X.shape[0] != m or n_steps < 1 or X.shape[1] % n_steps:
        raise ValueError(f"X must be ({m}, n_steps * per_step) for n_steps = {n_steps}, "
                         f"got {X.shape}")
    loc = est.neighbors_
    floor = log_floor(est.dissimilarity_[loc])
    i, j = np.nonzero(np.triu(loc, 1))
    L0 = np.log(np.maximum(est.dissimilarity_[i, j], floor))
    fit = fit_calibration(L0, Y, i, j, est.dissimilarity_degree, est.position_degree)
    lo, hi = fit.target.min() - 1.0, fit.target.max() + 1.0  # CAL-SMA's clip (_calibrate)
    expo0 = fit.F @ fit.coef
    a = fit.coef[:est.dissimilarity_degree]

    Gk, diag_k = _block_grams(X, n_steps, i, j)
    G, diag = Gk.sum(axis=0), diag_k.sum(axis=0)
    L_full = _cosine_logs(G, diag, i, j, floor)
    Lb = _cosine_logs(G[None] - Gk, diag[None] - diag_k, i, j, floor)  # block b deleted
    few = np.sum(diag_k > 0, axis=0) < 2
    # a replicate without any sighting of an object leaves that object's pairs as they were
    # (the object itself gets no covariance: ``few``)
    empty = (diag[None] - diag_k) <= 0
    Lb = np.where(empty[:, i] | empty[:, j], L_full[None], Lb)
    dL = Lb - L_full  # (nb, pairs)
    change = sum(a[p - 1] * ((L0 + dL) ** p - L0**p) for p in range(1, len(a) + 1))
    t0 = np.exp(np.clip(expo0, lo, hi))
    dt = np.exp(np.clip(expo0 + change, lo, hi)) - t0

    T = np.zeros((m, m))
    T[i, j] = T[j, i] = t0
    R = T.max(axis=1)
    bound = est.far_factor * np.maximum(R[:, None], R[None, :])
    far = ~loc
    np.fill_diagonal(far, False)
    W = np.where(loc, 1.0, np.where(far, est.far_weight, 0.0))
    T = np.where(far, np.maximum(euclidean_distance_matrix(Y), bound), T)
    return T, W, (i, j), dt, few


def linear_jackknife_covariances(est: CalibratedSMACOF, X: np.ndarray, n_steps: int,
                                 anchors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CAL-SMA's (M, 2, 2) position covariances in the estimator's frame (module docstring),
    not yet widened.

    Parameters:
        est, X, n_steps: as for :func:`jackknife_targets`.
        anchors: indices (rows of ``X``) of the anchors, held.

    Returns:
        ``(cov, few)``: the covariances (zero for the anchors, ``inf`` on the diagonal of
        objects the stress does not pin down) and an (M,) bool, True for objects seen in fewer
        than two blocks (the jackknife cannot measure their spread: NaN covariance).
    """
    with _one_thread():
        T, W, pairs, dt, few = jackknife_targets(est, X, n_steps)
        m, nb = len(T), len(dt)
        free = np.setdiff1d(np.arange(m), anchors)
        moves, loose = stress_response(est.embedding_, T, W, free, pairs, dt)
    dev = moves - moves.mean(axis=0)
    cov = np.einsum("bmi,bmj->mij", dev, dev) * (nb - 1) / nb
    cov[loose] = np.diag([np.inf, np.inf])
    cov[few] = np.nan
    cov[np.asarray(anchors, dtype=int)] = 0.0
    return cov, few
