"""Weighted isotonic regression of distances on dissimilarities, as non-metric SMACOF needs it.

:func:`isotonic_fit` gives the values of scikit-learn's
``IsotonicRegression(increasing=True).fit_transform(x, y, sample_weight=w)`` (tied inputs share
the weighted mean of their targets, then the pool-adjacent-violators fit of
:func:`scipy.optimize.isotonic_regression`, read back at each input by linear interpolation
between the fit's knots), computed the same way, operation for operation. Non-metric SMACOF
(:func:`mappers.smacof.variants.nonmetric_smacof`) calls it once per iteration on a few hundred
to a few thousand pairs; there scikit-learn's estimator spent about nine tenths of its time on
checking its input and building an interpolator object, hence this function (the regression
itself is scipy's).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import isotonic_regression

from mappers.smacof import isotonic_kernels

__all__ = ["isotonic_fit"]

TIE_RESOLUTION = np.finfo(np.float64).resolution
"""Inputs closer than this to the first of their run are one input (scikit-learn's rule)."""


def isotonic_fit(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The non-decreasing function of ``x`` closest to ``y`` in ``w``-weighted least squares,
    evaluated at each ``x`` (1-D float arrays of one length, ``w > 0``, all finite).

    Equal inputs are one point whose target is their weighted mean (Kruskal 1964's secondary
    approach to ties); the fit between the distinct inputs is linear, as scikit-learn's
    :class:`sklearn.isotonic.IsotonicRegression` interpolates it, and so are the values returned
    (the same to the last bit, which its test checks).
    """
    order = np.lexsort((y, x))
    ux, uy, uw = isotonic_kernels.merge_ties(x[order], y[order], w[order], TIE_RESOLUTION)
    fit = np.asarray(isotonic_regression(uy, weights=uw, increasing=True).x, dtype=float)
    if fit.size == 1:
        return np.repeat(fit, x.size)
    # the knots: the first, the last, and each point whose fit differs from a neighbour's
    keep = np.ones(fit.size, dtype=bool)
    keep[1:-1] = (fit[1:-1] != fit[:-2]) | (fit[1:-1] != fit[2:])
    # read back at each input between the knots, as scipy.interpolate.interp1d(kind="linear")
    # does for it: by numpy.interp
    return np.interp(x, ux[keep], fit[keep])
