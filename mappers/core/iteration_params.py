"""The stopping rule of an iterative fit as scikit-learn parameter constraints.

An estimator that iterates (SMACOF's Guttman updates, Levenberg-Marquardt steps) takes
``max_iter``, the most iterations (an integer >= 1), and ``tol``, the relative improvement below
which it stops (a number >= 0). An estimator that alternates in rounds (a bundle adjustment's
rounds of viewpoints, then landmarks) takes ``max_rounds`` and ``tol`` in the same sense.
scikit-learn validates an estimator's parameters against its ``_parameter_constraints``
(``sklearn.utils._param_validation``); these are those entries, written once for every such
estimator: spread one into the dict, ``{**ITERATION_CONSTRAINTS, ...}`` or
``{**ROUND_CONSTRAINTS, ...}``.
"""

from __future__ import annotations

from numbers import Integral, Real

from sklearn.utils._param_validation import Interval

__all__ = ["ITERATION_CONSTRAINTS", "ROUND_CONSTRAINTS"]

ITERATION_CONSTRAINTS: dict = {
    "max_iter": [Interval(Integral, 1, None, closed="left")],
    "tol": [Interval(Real, 0, None, closed="left")],
}
"""``max_iter`` an integer >= 1, ``tol`` a number >= 0."""

ROUND_CONSTRAINTS: dict = {
    "max_rounds": ITERATION_CONSTRAINTS["max_iter"],
    "tol": ITERATION_CONSTRAINTS["tol"],
}
"""``max_rounds`` an integer >= 1, ``tol`` a number >= 0."""
