"""The checks an estimator applies to the history it is fitted on, as scikit-learn's own do.

Every estimator of :mod:`mappers` takes an (M objects, D columns) history as ``X`` and, when it
maps masked histories, a boolean ``mask`` and the ``sensor`` as fit inputs. These helpers check
them with :func:`sklearn.utils.validation.validate_data` (which also records ``n_features_in_``)
so that a bad input gives scikit-learn's messages; fused histories (a mapping sensor -> matrix)
are checked for their keys only, their matrices by the estimator that reads them.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np
import scipy.sparse as sp
from sklearn.utils.validation import check_symmetric, validate_data

from mappers.core.sensors import SENSORS, check_sensor, infer_sensor

__all__ = [
    "check_fit",
    "check_fused_input",
    "check_history",
    "check_no_bools",
    "check_points_or_dissimilarities",
    "check_views",
]


def check_history(estimator, X, y=None, *, mask=None, sensor: str | None = None,
                  sensors: Iterable[str] = SENSORS, accept_sparse: bool = False,
                  min_objects: int = 3):
    """``(X, mask, sensor)`` for ``estimator.fit``: ``X`` a float64 (M, D) array with M >=
    ``min_objects`` (a scipy sparse one kept sparse when ``accept_sparse``); ``mask`` None or a
    boolean array of X's shape (True = observed; a scipy sparse mask with a sparse X); the
    observed entries finite (the others may hold anything); ``sensor`` as given, or inferred
    from the observed entries (:func:`mappers.core.sensors.infer_sensor`), and one of
    ``sensors`` (a ValueError naming the estimator and what it maps). ``y``, which the
    estimators ignore as scikit-learn's unsupervised ones do, is refused when it looks like a
    mask given in its place (``fit(X, mask)``: the mask is a keyword argument)."""
    if y is not None and np.shape(y) == np.shape(X) and len(np.shape(y)) == 2:
        raise ValueError("y has the shape of X: pass a mask as mask=..., fit's second "
                         "positional argument is y (ignored)")
    # a dense history with a mask: the unobserved entries may hold anything (NaN)
    X = validate_data(estimator, X, accept_sparse="csr" if accept_sparse else False,
                      dtype=np.float64, ensure_min_samples=min_objects,
                      ensure_all_finite=mask is None or sp.issparse(X))
    if mask is not None:
        if sp.issparse(mask) and not sp.issparse(X):
            mask = mask.toarray()
        dtype = mask.dtype if sp.issparse(mask) else np.asarray(mask).dtype
        if dtype != np.bool_:
            raise ValueError(f"mask must be a boolean array (True = observed), got dtype {dtype}")
        mask = mask if sp.issparse(mask) else np.asarray(mask)
        if mask.shape != X.shape:
            raise ValueError(f"mask must have the shape of X {X.shape}, got {mask.shape}")
        if not sp.issparse(X) and not np.all(np.isfinite(X[mask])):
            raise ValueError("X contains NaN or inf in observed entries")
    if sensor is None:
        sensor = infer_sensor(X) if sp.issparse(X) else infer_sensor(X, mask)
    check_sensor(sensor)
    sensors = tuple(sensors)
    if sensor not in sensors:
        raise ValueError(f"{type(estimator).__name__} maps {' and '.join(sensors)} histories, "
                         f"got sensor {sensor!r}")
    return X, mask, sensor


def check_fused_input(estimator, X, sensors: Iterable[str]) -> None:
    """ValueError unless ``X`` is fused histories holding ``sensors``: a mapping sensor -> (M,
    columns) matrix (:mod:`mappers.core.fused_histories`), not one array."""
    sensors = sorted(sensors)
    if not isinstance(X, Mapping) or not set(sensors) <= set(X):
        got = (f"a mapping with the keys {sorted(X)}" if isinstance(X, Mapping)
               else type(X).__name__)
        raise ValueError(f"{type(estimator).__name__} maps fused histories: X must be a mapping "
                         f"sensor -> history matrix with the keys {sensors}, got {got}")


def check_no_bools(estimator, *names: str) -> None:
    """ValueError for a parameter among ``names`` given as a bool: scikit-learn's numeric
    ``Interval`` constraints take True for 1, and a count or a threshold given as True is a
    mistake."""
    for name in names:
        value = getattr(estimator, name)
        if isinstance(value, bool | np.bool_):
            raise ValueError(f"the {name!r} parameter of {type(estimator).__name__} must be a "
                             f"number, got {value!r}")


def check_fit(estimator, X, y=None, *, bools: Iterable[str] = (), **history):
    """``(X, mask, sensor)``: the preamble of a masked estimator's ``fit`` in one call, in this
    order: its parameters (``estimator._validate_params()``), none of ``bools`` given as a bool
    (:func:`check_no_bools`), and the history (:func:`check_history` with ``history``'s keyword
    arguments: mask, sensor, sensors, accept_sparse, min_objects)."""
    estimator._validate_params()
    check_no_bools(estimator, *bools)
    return check_history(estimator, X, y, **history)


def check_views(estimator, X, mask=None) -> np.ndarray:
    """``X`` as a float64 (M, D) array with M >= 3 for a viewpoint adjustment's ``fit`` (as
    :func:`sklearn.utils.validation.validate_data`); with a mask the unobserved entries may hold
    anything (NaN), without one every entry must be finite."""
    return validate_data(estimator, X, dtype=np.float64, ensure_min_samples=3,
                         ensure_all_finite=mask is None)


def check_points_or_dissimilarities(estimator, X) -> np.ndarray:
    """The preamble of the ``fit`` of an embedding with a ``dissimilarity`` parameter: its
    parameters (``estimator._validate_params()``), then ``X`` as a float (n, d) array of n >= 2
    points (:func:`sklearn.utils.validation.validate_data`) or, when ``estimator.dissimilarity``
    is ``"precomputed"``, a symmetric (:func:`sklearn.utils.validation.check_symmetric`, which
    returns it symmetrised) and non-negative (n, n) matrix of dissimilarities."""
    estimator._validate_params()
    X = validate_data(estimator, X, ensure_min_samples=2, dtype=float)
    if estimator.dissimilarity == "precomputed":
        X = check_symmetric(X, raise_exception=True)
        if np.any(X < 0):
            raise ValueError("precomputed dissimilarities must be non-negative")
    return X
