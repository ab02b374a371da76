"""Co-observation maps for masked histories: calibrated when the view is global, ordinal when it
is local (label ``"COVIS-AUTO"``; its calibrated branch :class:`CovisCalibrated`, ``covis-cal``,
is a building block).

A limited field of view with no range limit sees most pairs of landmarks together some time:
the co-observation coefficient (the Ochiai coefficient of :mod:`mappers.masked.coobservation`,
angle-weighted for bearings) then grows smoothly with proximity for every pair, as a complete
history's row similarity does, and CAL-SMA's calibration (:mod:`mappers.calibrated.cal_sma`: a smooth
log-link fitted on neighbour pairs, anchors held fixed) turns it into distances. With a range
limit most pairs are never seen together: the coefficient is informative only at short range,
its link to distance changes with the horizon, and only its order is trusted (the ordinal
``covis-nonmetric`` / ``covis-angle`` of :mod:`mappers.masked.pair_maps`, with lower bounds for the pairs
never seen together).

``covis-cal``, :class:`CovisCalibrated` (visibility, bearing; a building block)
    CAL-SMA on ``1 - och_ij`` and on ``-log och_ij`` (precomputed; pairs seen together in fewer
    than ``min_co`` steps at the saturation value: never neighbours, only "far"), and the mean
    of the two anchored maps. The two differ only by a monotone transform, which the calibration
    absorbs, but they start from different places and settle in different local optima; their
    mean has the variance of neither (``links`` picks one or both). *Assumes*: what CAL-SMA
    assumes of a history dissimilarity: a smooth, monotone link to distance that varies slowly
    over the arena.

``"COVIS-AUTO"`` (bearing)
    ``covis-cal`` when the share of pairs (of sensed objects) seen together in fewer than
    ``min_co`` steps is at most ``local_share``, else the ordinal ``covis-angle``. The share is
    read from the data; the chosen branch is in ``branch_``. *Assumes*: what the chosen branch
    assumes. (Visibility is always local, the sensor sees only nearby objects: ``covis-cal`` or
    ``covis-nonmetric`` directly.)
"""

from __future__ import annotations

import warnings
from numbers import Integral, Real

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval

from mappers.calibrated import CalibratedSMACOF
from mappers.core.estimator_params import store_params
from mappers.core.sensors import step_observations
from mappers.core.validation import check_fit
from mappers.masked.coobservation import (
    angle_covisibility_dissimilarity,
    covisibility_dissimilarity,
)
from mappers.masked.pair_maps import MaskedMapWarning, masked_embedding

__all__ = ["CovisAuto", "CovisCalibrated", "co_observation_coefficient"]

_SENSORS = ("visibility", "bearing")


def co_observation_coefficient(X, mask, sensor: str) -> tuple[np.ndarray, np.ndarray]:
    """``(och, C)``: the (angle-weighted, for bearing) Ochiai coefficient in [0, 1] of each pair
    and the number of steps that sensed both (diagonal: each object's count)."""
    if sensor not in _SENSORS:
        raise ValueError(f"sensor must be one of {list(_SENSORS)}, got {sensor!r}")
    seen, values = step_observations(X, mask, sensor)
    if sensor == "bearing":
        delta, C = angle_covisibility_dissimilarity(seen, values)
    else:
        delta, C = covisibility_dissimilarity(seen)
    och = np.where(delta >= -np.log(1e-6), 0.0, np.exp(-delta))
    np.fill_diagonal(och, 1.0)
    return och, C


def _links(links) -> tuple[str, ...]:
    links = (links,) if isinstance(links, str) else tuple(links)
    if not links or not set(links) <= {"linear", "log"}:
        raise ValueError(f"links must be a non-empty tuple of 'linear' and 'log', got {links!r}")
    return links


class CovisCalibrated(TransformerMixin, BaseEstimator):
    """``covis-cal``: CAL-SMA on ``1 -`` the co-observation coefficient (module docstring); the
    global branch of ``COVIS-AUTO``, called directly (no longer a label of its own).

    Parameters:
        min_co: a pair seen together in fewer steps is only "far" (never a neighbour target).
        n_neighbors: CAL-SMA's neighbour pairs per object (None: CAL-SMA's own default).
        links: ``"linear"`` (``1 - och``) and/or ``"log"`` (``-log och``): the mean of their maps.
        random_state: CAL-SMA's seed.

    ``fit(X, mask=None, *, sensor=None, anchor_ids=None, anchor_positions=None)`` maps a
    visibility or bearing history (the sensor inferred when not given), in the anchors' frame
    when anchors are given (without anchors the links' frames differ, so give one link only).

    Attributes:
        embedding_ (M, 2); cals_ the fitted :class:`~mappers.calibrated.cal_sma.CalibratedSMACOF`
        per link (``fold_score_``, ``folded_``, ...); n_features_in_.
    """

    _parameter_constraints: dict = {
        "min_co": [Interval(Integral, 1, None, closed="left")],
        "n_neighbors": [Interval(Integral, 2, None, closed="left"), None],
        "links": [str, tuple, list],
        "random_state": ["random_state"],
    }

    def __init__(self, *, min_co: int = 3, n_neighbors: int | None = 12,
                 links: tuple[str, ...] = ("linear", "log"), random_state=0) -> None:
        store_params(self, locals())

    def fit(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
            anchor_positions=None):
        """Map the history ``X`` (M, D) (``mask`` True where observed; None: complete)."""
        X, mask, sensor = check_fit(self, X, y, bools=("min_co",), mask=mask, sensor=sensor,
                                    sensors=_SENSORS)
        links = _links(self.links)
        och, C = co_observation_coefficient(X, mask, sensor)
        far = C < self.min_co
        np.fill_diagonal(far, False)
        self.cals_ = []
        for link in links:
            D = 1.0 - och if link == "linear" else -np.log(np.maximum(och, 1e-6))
            D[far] = D.max()  # the saturation value: "far", never a neighbour target
            np.fill_diagonal(D, 0.0)
            cal = CalibratedSMACOF(dissimilarity="precomputed", n_neighbors=self.n_neighbors,
                                   random_state=self.random_state)
            self.cals_.append(cal.fit(D, anchor_ids=anchor_ids, anchor_positions=anchor_positions))
        self.embedding_ = np.mean([cal.embedding_ for cal in self.cals_], axis=0)
        return self

    def fit_transform(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
                      anchor_positions=None):
        """Fit and return the (M, 2) map."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions).embedding_


NEIGHBORS = 12
"""``COVIS-AUTO``'s default neighbour pairs per object. Not a fixed parameter default: build_map
refuses an ``n_neighbors`` of M or more, and the masked bearing default (BEARING-BA from
COVIS-AUTO) failed for 12 objects or fewer (issue 35); CAL-SMA takes at most M - 1."""


class CovisAuto(TransformerMixin, BaseEstimator):
    """``"COVIS-AUTO"``: ``covis-cal`` for a global view, the ordinal map for a local one
    (module docstring).

    Parameters:
        min_co: as ``covis-cal``'s, and the count below which a pair is "not seen together".
        local_share: the largest share of pairs not seen together for which ``covis-cal`` maps.
        n_neighbors: ``covis-cal``'s (None: :data:`NEIGHBORS`, which CAL-SMA lowers to M - 1
            for fewer objects; a number given is checked against the objects mapped).
        random_state: ``covis-cal``'s.
        max_iter: ``covis-angle``'s SMACOF updates.

    ``fit(X, mask=None, *, sensor=None, anchor_ids=None, anchor_positions=None)`` maps a bearing
    history.

    Attributes:
        embedding_ (M, 2); branch_ the label used; local_share_ the measured share of pairs (of
        sensed objects) seen together in fewer than ``min_co`` steps; n_features_in_.
    """

    _parameter_constraints: dict = {
        "min_co": [Interval(Integral, 1, None, closed="left")],
        "local_share": [Interval(Real, 0, 1, closed="both")],
        "n_neighbors": [Interval(Integral, 2, None, closed="left"), None],
        "max_iter": [Interval(Integral, 1, None, closed="left")],
        "random_state": ["random_state"],
    }

    def __init__(self, *, min_co: int = 3, local_share: float = 0.1, n_neighbors: int | None = None,
                 max_iter: int = 300, random_state=0) -> None:
        store_params(self, locals())

    def fit(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
            anchor_positions=None):
        """Map the bearing history ``X`` (M, 2N) (``mask`` True where observed)."""
        X, mask, sensor = check_fit(self, X, y, bools=("min_co",), mask=mask, sensor=sensor,
                                    sensors=("bearing",))
        _, C = co_observation_coefficient(X, mask, sensor)
        sensed = np.diag(C) > 0
        Cs = C[np.ix_(sensed, sensed)]
        off = ~np.eye(len(Cs), dtype=bool)
        self.local_share_ = float(np.mean(Cs[off] < self.min_co)) if off.any() else 1.0
        if self.local_share_ <= self.local_share:
            self.branch_ = "covis-cal"
            k = NEIGHBORS if self.n_neighbors is None else self.n_neighbors
            est = CovisCalibrated(min_co=self.min_co, n_neighbors=k, random_state=self.random_state)
            self.embedding_ = est.fit_transform(X, mask=mask, sensor=sensor,
                                                anchor_ids=anchor_ids,
                                                anchor_positions=anchor_positions)
            return self
        self.branch_ = "covis-angle"
        result = masked_embedding(X, mask, sensor, self.branch_, anchor_ids=anchor_ids,
                                  anchor_positions=anchor_positions, max_iter=self.max_iter,
                                  min_co=self.min_co)
        for msg in result.warnings:
            warnings.warn(msg, MaskedMapWarning, stacklevel=2)
        self.embedding_ = result.positions
        return self

    def fit_transform(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
                      anchor_positions=None):
        """Fit and return the (M, 2) map (NaN rows: unmapped)."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions).embedding_
