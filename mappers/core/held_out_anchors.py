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
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from mappers.core.uncertainty import chi2_quantile

__all__ = ["held_out_factor"]


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
