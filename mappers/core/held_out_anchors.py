"""A check of a map's covariances by its own anchors, and the factor that makes them honest.

The anchors are the only objects whose true positions a map is given, so they are the only
calibration set a logged run has. Each anchor in turn is left out (the map made again from the
other anchors, the held-out anchor mapped like any other object), and its squared Mahalanobis
distance ``q_j = e_jᵀ C_j⁻¹ e_j`` (``e_j`` the held-out anchor's error, ``C_j`` its covariance in
that map) is what the map's covariances claim against what the map does.

If the covariances were right, each ``q_j`` would follow χ²(d) and their sum ``T`` χ²(A d) for
``A`` held-out anchors. That is the *global test* of the variance factor of geodesy's
adjustment theory (Koch, *Parameter Estimation and Hypothesis Testing in Linear Models*, 2nd ed.,
1999, §4.3; Teunissen, *Testing Theory*, 2000): ``T`` above the χ²(A d) ``level`` quantile says
the errors are larger than the model's noise — on logged runs, systematic errors (a sensor's
bias, a landmark's offset) that neither the residuals nor a resampling of the readings see.
The model is then scaled by the estimated variance factor ``k = T / (A d)`` (the variance
component of Koch §3.5, and the cross-validation estimate of the prediction error, Stone 1974),
widened for the few anchors it comes from: with ``e ~ N(0, k C)`` for a new object, independent
of the anchors, ``eᵀ C⁻¹ e / k̂`` follows ``d F(d, A d)``, so the region that holds ``level`` is
``eᵀ C⁻¹ e ≤ k̂ d F_level(d, A d)`` — the factor on the covariances is
``k̂ d F_level(d, A d) / χ²_level(d)`` (as the bootstrap's Hotelling factor,
:func:`mappers.core.uncertainty.sample_size_factor`). This is split conformal calibration with
the anchors as the calibration set (Vovk, Gammerman & Shafer, *Algorithmic Learning in a Random
World*, 2005; Angelopoulos & Bates, *A Gentle Introduction to Conformal Prediction*, 2021) in its
parametric form: with four anchors the empirical quantile of four scores is no quantile at all,
so the scores' mean is taken and its spread accounted for by the F law.

When the test passes, the factor is 1: the model is kept as it is (a simulated history whose
noise the model describes keeps its calibration).

:func:`held_out_floor` reads the same held-out anchors another way, the one ``uncertainty=True``
uses for a method with an adjustment: the anchors' errors beyond their covariances as an
*additive*, isotropic variance ``σ²`` (a systematic error the same size wherever a landmark is,
however many readings it has), not a factor on the model (which leaves the landmarks with many
readings, whose model ellipses are small, as overconfident as before).
"""

from __future__ import annotations

import numpy as np
from scipy import optimize, stats

from mappers.core.uncertainty import chi2_quantile, mahalanobis_squared

__all__ = ["held_out_factor", "held_out_floor"]


def held_out_factor(q: np.ndarray, d: int, level: float = 0.95) -> tuple[float, float]:
    """``(factor, k)`` for the held-out anchors' squared Mahalanobis distances ``q`` (A,) in
    ``d`` dimensions (module docstring): ``k = sum(q) / (A d)`` the estimated variance factor,
    ``factor`` what to multiply the covariances by (1 when ``sum(q)`` is within the χ²(A d)
    ``level`` quantile). ValueError without a finite ``q``; an infinite ``q`` (an anchor off its
    covariance's support) gives an infinite factor."""
    q = np.asarray(q, dtype=float)
    q = q[~np.isnan(q)]
    if not q.size:
        raise ValueError("no held-out anchor has a finite position and covariance")
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    a = q.size
    total = float(np.sum(q))
    k = total / (a * d)
    if total <= stats.chi2.ppf(level, a * d):
        return 1.0, k
    return k * d * float(stats.f.ppf(level, d, a * d)) / chi2_quantile(d, level), k


def held_out_floor(errors: np.ndarray, covariances: np.ndarray,
                   level: float = 0.95) -> tuple[float, int]:
    """``(variance, A)``: the isotropic variance per axis to add to every non-anchor object's
    covariance, estimated from held-out anchors' errors ``errors`` (A, d) (mapped position minus
    known position) under their covariances ``covariances`` (A, d, d) in the maps without them;
    ``A`` the anchors used (rows with a finite error and covariance).

    ``σ²`` solves ``Σ_j e_jᵀ (C_j + σ² I)⁻¹ e_j = A d`` (0 when the anchors' squared Mahalanobis
    distances already sum to at most ``A d``): the moment estimate of an additive variance
    component (Koch, *Parameter Estimation and Hypothesis Testing in Linear Models*, 2nd ed.,
    1999, §3.6; the "additive" systematic part of an error budget), its left side falling in
    ``σ²``, so the root is unique. It is widened for the few anchors it comes from by
    ``d F_level(d, A d) / χ²_level(d)`` (1.49 for four anchors in 2-D, 1.21 for six in 3-D): a new
    object's error over ``σ̂`` follows ``d F(d, A d)`` where the floor dominates (as
    :func:`held_out_factor`'s widening). No constant is tuned. ValueError with fewer than two
    usable anchors or ``level`` outside (0, 1). The root is found by ``scipy.optimize.brentq``
    on a bracket doubled from the anchors' mean squared error per axis."""
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    e = np.asarray(errors, dtype=float)
    c = np.asarray(covariances, dtype=float)
    if e.ndim != 2 or c.shape != (*e.shape, e.shape[1]):
        raise ValueError(f"errors (A, d) and covariances (A, d, d) expected, got {e.shape} "
                         f"and {c.shape}")
    ok = np.all(np.isfinite(e), axis=1) & np.all(np.isfinite(c), axis=(1, 2))
    e, c = e[ok], c[ok]
    a, d = e.shape
    if a < 2:
        raise ValueError(f"a floor from held-out anchors needs at least two of them with a "
                         f"finite error and covariance, got {a}")
    eye = np.eye(d)

    def excess(s2: float) -> float:
        return float(np.sum(mahalanobis_squared(e, c + s2 * eye))) - a * d

    if excess(0.0) <= 0:
        return 0.0, a
    hi = max(float(np.sum(e * e)) / (a * d), np.finfo(float).tiny)
    while excess(hi) > 0:  # (sum_j |e_j|^2 / hi <= A d once hi >= mean |e|^2 / d: a few steps)
        hi *= 2.0
    s2 = optimize.brentq(excess, 0.0, hi, xtol=1e-300, rtol=1e-12)
    return s2 * d * float(stats.f.ppf(level, d, a * d)) / chi2_quantile(d, level), a
