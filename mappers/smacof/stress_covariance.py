"""How a weighted-stress minimiser moves when its target distances move: the implicit-function
(delta-method) response of anchored weighted SMACOF, for covariances without re-embedding.

At a minimum ``X`` of the raw stress ``sigma(X) = sum_{i<j} w_ij (d_ij(X) - t_ij)^2`` over the
free points (the anchors held), the gradient ``g(X, T)`` of the free coordinates is zero. Targets
moved by ``dT`` move the minimiser, to first order, by

    dX_f = -H_ff^-1 J dT,       H = d^2 sigma / dX^2,   J = d g / dT,

(the implicit function theorem; the delta method of statistics, e.g. van der Vaart, *Asymptotic
Statistics*, 1998, ch. 3 and 5.3). The Hessian of the stress is de Leeuw's (*Convergence of the
majorization method for multidimensional scaling*, J. Classification 5, 1988; Borg & Groenen,
*Modern Multidimensional Scaling*, 2005, §8.6): per pair, with ``u`` the unit vector from
``x_j`` to ``x_i``,

    K_ij = 2 w_ij [ (t_ij / d_ij) u u^T + (1 - t_ij / d_ij) I ],

added to the (i, i) and (j, j) blocks and subtracted from (i, j) and (j, i); and
``dg_i / dt_ij = -2 w_ij u``. Writing it here (rather than differentiating by a library) keeps
it a few vectorised numpy lines on the same arrays SMACOF uses (:mod:`mappers.smacof.weighted`).

One Hessian, factorised once, serves any number of perturbations: a resampling of the
dissimilarities (:mod:`mappers.calibrated.cal_sma_uncertainty`) costs a linear solve per
replicate instead of an embedding.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from mappers.smacof.weighted import euclidean_distance_matrix

__all__ = ["stress_hessian", "stress_response"]


def _unit_vectors(X: np.ndarray, Dx: np.ndarray) -> np.ndarray:
    """(M, M, d) unit vectors ``(x_i - x_j) / d_ij`` (zero for coincident points)."""
    diff = X[:, None, :] - X[None, :, :]
    safe = np.where(Dx > 0, Dx, 1.0)
    return np.where((Dx > 0)[..., None], diff / safe[..., None], 0.0)


def stress_hessian(X: np.ndarray, targets: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The (M d, M d) Hessian of the raw stress ``sum_{i<j} w_ij (d_ij(X) - t_ij)^2`` at ``X``
    (M, d), coordinates ordered point by point (``x_0, y_0, x_1, ...``).

    Parameters:
        X: (M, d) points. targets: (M, M) symmetric target distances ``t_ij``.
        weights: (M, M) symmetric non-negative weights ``w_ij`` (the diagonal is ignored).

    Coincident points (``d_ij = 0``) contribute nothing: the stress is not differentiable
    there, and a minimiser with two points on one another is left to the caller to refuse.
    """
    X = np.asarray(X, dtype=float)
    m, d = X.shape
    T = np.asarray(targets, dtype=float)
    W = np.array(weights, dtype=float)
    if T.shape != (m, m) or W.shape != (m, m):
        raise ValueError(f"targets and weights must be ({m}, {m}), got {T.shape} and {W.shape}")
    np.fill_diagonal(W, 0.0)
    Dx = euclidean_distance_matrix(X)
    U = _unit_vectors(X, Dx)
    W = np.where(Dx > 0, W, 0.0)
    ratio = np.where(Dx > 0, T / np.where(Dx > 0, Dx, 1.0), 0.0)
    K = 2.0 * W[..., None, None] * (ratio[..., None, None] * U[..., :, None] * U[..., None, :]
                                    + (1.0 - ratio)[..., None, None] * np.eye(d))
    H = -K.transpose(0, 2, 1, 3).copy()  # (M, d, M, d): the off-diagonal blocks -K_ij
    idx = np.arange(m)
    H[idx, :, idx, :] += K.sum(axis=1)
    return H.reshape(m * d, m * d)


def stress_response(X: np.ndarray, targets: np.ndarray, weights: np.ndarray, free: np.ndarray,
                    pairs: tuple[np.ndarray, np.ndarray], delta_targets: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """First-order moves of the minimiser ``X`` (M, d) of the weighted stress, the points not
    in ``free`` held, for each of B perturbations of some pairs' targets (module docstring).

    Parameters:
        X: (M, d) a minimiser of the stress over the ``free`` points.
        targets, weights: (M, M) the stress's targets and weights at that minimum.
        free: indices of the points that move (the others are anchors).
        pairs: ``(i, j)``, two (P,) index arrays: the pairs whose targets change (each
            unordered pair once).
        delta_targets: (B, P) the changes of those targets (``t_ij`` and ``t_ji`` alike).

    Returns:
        ``(moves, loose)``: (B, M, d) moves (zero for the held points) and an (M,) bool, True for
        free points the stress does not pin down (they lie on a direction of zero or negative
        curvature of ``H_ff``; their moves there are left out and the caller should report
        them as unbounded). The Hessian is solved by Cholesky factorisation when it is positive
        definite, else through its eigen-decomposition.
    """
    X = np.asarray(X, dtype=float)
    m, d = X.shape
    free = np.asarray(free, dtype=int)
    i, j = (np.asarray(a, dtype=int) for a in pairs)
    dT = np.asarray(delta_targets, dtype=float)
    if i.shape != j.shape or i.ndim != 1 or dT.ndim != 2 or dT.shape[1] != len(i):
        raise ValueError(f"delta_targets must be (B, P) for P = {len(i)} pairs (i, j) of equal "
                         f"length, got {dT.shape} for pairs {i.shape} and {j.shape}")
    W = np.asarray(weights, dtype=float)
    diff = X[i] - X[j]
    dist = np.linalg.norm(diff, axis=1)
    u = np.where((dist > 0)[:, None], diff / np.where(dist > 0, dist, 1.0)[:, None], 0.0)
    # gradient change: dg_i = -2 w_ij dt_ij u_ij, and the opposite at j
    force = -2.0 * (W[i, j] * dT)[:, :, None] * u[None]  # (B, P, d)
    dg = np.zeros((len(dT), m, d))
    np.add.at(dg, (slice(None), i), force)
    np.add.at(dg, (slice(None), j), -force)
    dg = dg[:, free].reshape(len(dT), -1)
    cols = (free[:, None] * d + np.arange(d)[None, :]).ravel()
    H = stress_hessian(X, targets, W)[np.ix_(cols, cols)]
    moves = np.zeros((len(dT), m, d))
    loose = np.zeros(m, dtype=bool)
    if not len(free):
        return moves, loose
    try:
        cho = scipy.linalg.cho_factor(H, lower=True)
        step = -scipy.linalg.cho_solve(cho, dg.T).T
    except np.linalg.LinAlgError:  # not positive definite: a flat or saddle direction
        ev, vec = np.linalg.eigh(0.5 * (H + H.T))
        bad = ev <= 1e-10 * max(float(np.abs(ev).max()), 1e-300)
        step = -((dg @ vec[:, ~bad]) / ev[~bad]) @ vec[:, ~bad].T
        if bad.any():
            loose[free] = np.abs(vec[:, bad]).max(axis=1).reshape(-1, d).max(axis=1) > 1e-9
    moves[:, free] = step.reshape(len(dT), -1, d)
    return moves, loose
