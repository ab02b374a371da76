"""Variants of weighted SMACOF with other links between dissimilarity and distance.

:func:`mappers.smacof.weighted.weighted_smacof` fits distances to dissimilarities (a metric, identity
link). The mappers of masked histories need three other links, none of which scikit-learn's MDS
offers together with weights and fixed points, hence these loops around one Guttman step
(de Leeuw 1977; Borg & Groenen, *Modern Multidimensional Scaling*, 2005, ch. 8-9):

- ordinal (:func:`nonmetric_smacof`): only the order of the dissimilarities is trusted;
  disparities by isotonic regression (Kruskal 1964);
- power (:func:`power_link_smacof`): distance = a * dissimilarity ** power, one scale refitted;
- interval (:func:`bounded_smacof`): each distance must lie in [lower, upper].

Pairs can be *censored*: known only to be at least as far as every measured pair.
"""

from __future__ import annotations

import numpy as np

from mappers.smacof.isotonic import isotonic_fit
from mappers.smacof.weighted import GuttmanTransform, euclidean_distance_matrix, weighted_smacof

__all__ = ["bounded_smacof", "nonmetric_smacof", "power_link_smacof"]


def _start(init: np.ndarray, fixed, fixed_positions) -> tuple[np.ndarray, float]:
    """The start with the fixed points in place, and the fixed points' diameter (0 if < 2)."""
    X = np.array(init, dtype=float)
    if fixed is not None and fixed_positions is not None:
        X[np.asarray(fixed)] = fixed_positions
    span = 0.0
    if fixed is not None and len(np.atleast_1d(fixed)) > 1:
        F = X[np.asarray(fixed)]
        span = float(np.max(np.linalg.norm(F[:, None] - F[None], axis=2)))
    return X, span


def nonmetric_smacof(
    delta: np.ndarray,
    weights: np.ndarray,
    init: np.ndarray,
    *,
    censored: np.ndarray | None = None,
    fixed: np.ndarray | None = None,
    fixed_positions: np.ndarray | None = None,
    max_iter: int = 300,
    tol: float = 1e-6,
) -> np.ndarray:
    """Non-metric (ordinal) weighted SMACOF, optionally with fixed points and lower bounds.

    Each iteration fits disparities by isotonic regression of the current distances on
    ``delta`` (pairs with weight > 0 and not ``censored``), sets each censored pair's
    disparity to its current distance clipped to [t, u] (t = largest fitted disparity: a
    censored pair is at least as far as any measured one; u = max(2 t, 1.5 x the fixed points'
    diameter) only stops a point held by nothing but lower bounds from drifting away), then takes one Guttman step of
    :func:`mappers.smacof.weighted.weighted_smacof`. sklearn's non-metric MDS has neither weights nor
    fixed points nor bounds, hence this loop. Without fixed points the disparities are scaled
    to a constant weighted sum of squares (Kruskal's normalisation).
    """
    delta = np.asarray(delta, dtype=float)
    W = np.asarray(weights, dtype=float).copy()
    np.fill_diagonal(W, 0.0)
    n = len(delta)
    iu = np.triu_indices(n, 1)
    cens = np.zeros((n, n), bool) if censored is None else np.asarray(censored, bool)
    w = W[iu]
    obs = (w > 0) & ~cens[iu]
    cen = (w > 0) & cens[iu]
    if obs.sum() < 2:
        raise ValueError("nonmetric_smacof needs at least 2 measured (weighted, uncensored) pairs")
    X, span = _start(init, fixed, fixed_positions)
    guttman = _guttman(W, X, fixed)
    scale = np.sqrt(np.sum(w[obs | cen]))
    x_obs, w_obs = delta[iu][obs], w[obs]
    for _ in range(max_iter):
        d = np.linalg.norm(X[iu[0]] - X[iu[1]], axis=1)
        dh = np.zeros_like(d)
        dh[obs] = isotonic_fit(x_obs, d[obs], w_obs)
        if cen.any():
            t = dh[obs].max()
            dh[cen] = np.clip(d[cen], t, max(2 * t, 1.5 * span))
        if fixed is None:
            norm = np.sqrt(np.sum(w * dh**2))
            if norm > 0:
                dh *= scale / norm
        T = np.zeros((n, n))
        T[iu] = dh
        T = T + T.T
        X, converged = _guttman_step(guttman, T, X, tol)
        if converged:
            break
    return X


def power_link_smacof(
    delta: np.ndarray,
    weights: np.ndarray,
    init: np.ndarray,
    *,
    power: float = 0.5,
    censored: np.ndarray | None = None,
    fixed: np.ndarray | None = None,
    fixed_positions: np.ndarray | None = None,
    n_rounds: int = 60,
    steps_per_round: int = 5,
) -> tuple[np.ndarray, float]:
    """Weighted SMACOF on targets ``a * delta**power`` with the scale ``a`` re-fitted each round.

    Each round sets ``a`` to the weighted least-squares fit of the current distances on
    ``delta**power`` over the measured (weighted, uncensored) pairs, gives each censored pair
    the target ``clip(d, t, max(2 t, 1.5 x fixed points' diameter))`` (t = largest measured
    target: a lower bound, as in :func:`nonmetric_smacof`), then takes ``steps_per_round``
    Guttman steps of :func:`mappers.smacof.weighted.weighted_smacof`. Returns ``(X, a)``. A monotone
    link with one free exponent instead of the isotonic one of :func:`nonmetric_smacof`
    (sklearn's MDS has neither weights, fixed points nor a parametric link).
    """
    if not power > 0:
        raise ValueError(f"power must be > 0, got {power}")
    if n_rounds < 1 or steps_per_round < 1:
        raise ValueError("n_rounds and steps_per_round must be >= 1")
    delta = np.asarray(delta, dtype=float)
    W = np.asarray(weights, dtype=float).copy()
    np.fill_diagonal(W, 0.0)
    n = len(delta)
    cens = np.zeros((n, n), bool) if censored is None else np.asarray(censored, bool)
    meas = (W > 0) & ~cens
    if meas.sum() < 4:
        raise ValueError("power_link_smacof needs at least 2 measured (weighted, uncensored) pairs")
    X, span = _start(init, fixed, fixed_positions)
    dp = np.maximum(delta, 0.0) ** power
    a = 1.0
    for _ in range(n_rounds):
        D = np.linalg.norm(X[:, None] - X[None], axis=2)
        den = np.sum(W[meas] * dp[meas] ** 2)
        a = float(np.sum(W[meas] * D[meas] * dp[meas]) / den) if den > 0 else 1.0
        T = a * dp
        t = T[meas].max()
        T = np.where(cens, np.clip(D, t, max(2 * t, 1.5 * span)), T)
        np.fill_diagonal(T, 0.0)
        X, _, _ = weighted_smacof(T, W, X, fixed=fixed, max_iter=steps_per_round, tol=0.0)
    return X, a


def bounded_smacof(
    lower: np.ndarray,
    upper: np.ndarray,
    weights: np.ndarray,
    init: np.ndarray,
    *,
    fixed: np.ndarray | None = None,
    fixed_positions: np.ndarray | None = None,
    max_iter: int = 500,
    tol: float = 1e-7,
) -> np.ndarray:
    """Weighted SMACOF on distance *intervals*: each iteration's target for a pair is its current
    distance clipped to ``[lower, upper]`` (zero stress inside the interval), then one Guttman
    step of :func:`mappers.smacof.weighted.weighted_smacof` (box-constrained stress; sklearn has none)."""
    lower = np.asarray(lower, dtype=float)
    upper = np.maximum(np.asarray(upper, dtype=float), lower)
    X, _ = _start(init, fixed, fixed_positions)
    guttman = _guttman(weights, X, fixed)
    for _ in range(max_iter):
        D = np.linalg.norm(X[:, None] - X[None], axis=2)
        T = np.clip(D, lower, upper)
        np.fill_diagonal(T, 0.0)
        X, converged = _guttman_step(guttman, T, X, tol)
        if converged:
            break
    return X



def _guttman(weights, X, fixed) -> GuttmanTransform:
    """The Guttman update for these weights (diagonal ignored) and fixed points, inverted once
    for all the steps of a loop below."""
    W = np.asarray(weights, dtype=float).copy()
    np.fill_diagonal(W, 0.0)
    free = np.ones(len(W), dtype=bool)
    fixed = np.asarray([] if fixed is None else fixed)
    if fixed.size:
        free[fixed] = False  # indices or a boolean mask
    return GuttmanTransform(W, free, X)


def _guttman_step(guttman: GuttmanTransform, targets, X, tol):
    """One Guttman transform towards ``targets``, and whether it moved the map by less than
    ``tol`` of its extent.

    The update is :func:`mappers.smacof.weighted.weighted_smacof`'s (the same
    :class:`~mappers.smacof.weighted.GuttmanTransform`); only the stopping rule differs: the
    targets change at every step here, so the stress of one step's targets says nothing about
    convergence, and the map's movement is watched instead."""
    X_new = guttman(guttman.W * targets, euclidean_distance_matrix(X), X)
    return X_new, np.abs(X_new - X).max() <= tol * max(np.abs(X_new).max(), 1e-12)
