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

import numpy as np

from mappers.calibrated import CalibratedSMACOF
from mappers.core.sensors import step_observations
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


def _check_min_co(min_co) -> int:
    if isinstance(min_co, bool) or not isinstance(min_co, (int, np.integer)) or min_co < 1:
        raise ValueError(f"min_co must be an integer >= 1, got {min_co!r}")
    return int(min_co)


class CovisCalibrated:
    """``covis-cal``: CAL-SMA on ``1 -`` the co-observation coefficient (module docstring); the
    global branch of ``COVIS-AUTO``, called directly (no longer a label of its own).

    ``fit_transform(X, mask=None, *, sensor, anchor_ids=None, anchor_positions=None)`` returns
    the (M, 2) map (in the anchors' frame when anchors are given: without anchors the members'
    frames differ, so give one link only); ``cals_`` are the fitted
    :class:`~mappers.calibrated.cal_sma.CalibratedSMACOF` per link (``fold_score_``, ``folded_``, ...).
    """

    def __init__(self, *, min_co: int = 3, n_neighbors: int = 12,
                 links: tuple[str, ...] = ("linear", "log"), random_state=0) -> None:
        self.min_co = _check_min_co(min_co)
        links = (links,) if isinstance(links, str) else tuple(links)
        if not links or not set(links) <= {"linear", "log"}:
            raise ValueError(f"links must be a non-empty tuple of 'linear' and 'log', got {links!r}")
        self.n_neighbors, self.links, self.random_state = n_neighbors, links, random_state

    def fit_transform(self, X, mask=None, *, sensor: str, anchor_ids=None, anchor_positions=None):
        och, C = co_observation_coefficient(X, mask, sensor)
        far = C < self.min_co
        np.fill_diagonal(far, False)
        self.cals_ = []
        for link in self.links:
            D = 1.0 - och if link == "linear" else -np.log(np.maximum(och, 1e-6))
            D[far] = D.max()  # the saturation value: "far", never a neighbour target
            np.fill_diagonal(D, 0.0)
            cal = CalibratedSMACOF(dissimilarity="precomputed", n_neighbors=self.n_neighbors,
                                   random_state=self.random_state)
            self.cals_.append(cal.fit(D, anchor_ids=anchor_ids, anchor_positions=anchor_positions))
        return np.mean([cal.embedding_ for cal in self.cals_], axis=0)


class CovisAuto:
    """``"COVIS-AUTO"``: ``covis-cal`` for a global view, the ordinal map for a local one
    (module docstring). ``branch_`` is the branch used (``"covis-cal"`` or ``"covis-angle"``),
    ``local_share_`` the measured share of pairs seen together in fewer than ``min_co`` steps."""

    def __init__(self, *, min_co: int = 3, local_share: float = 0.1, n_neighbors: int = 12,
                 max_iter: int = 300, random_state=0) -> None:
        self.min_co = _check_min_co(min_co)
        if not 0.0 <= local_share <= 1.0:
            raise ValueError(f"local_share must be in [0, 1], got {local_share!r}")
        self.local_share = float(local_share)
        self.n_neighbors, self.max_iter, self.random_state = n_neighbors, max_iter, random_state

    def fit_transform(self, X, mask=None, *, sensor: str, anchor_ids=None, anchor_positions=None):
        if sensor != "bearing":
            raise ValueError(f"COVIS-AUTO maps bearing histories, got sensor {sensor!r}")
        _, C = co_observation_coefficient(X, mask, sensor)
        sensed = np.diag(C) > 0
        Cs = C[np.ix_(sensed, sensed)]
        off = ~np.eye(len(Cs), dtype=bool)
        self.local_share_ = float(np.mean(Cs[off] < self.min_co)) if off.any() else 1.0
        if self.local_share_ <= self.local_share:
            self.branch_ = "covis-cal"
            est = CovisCalibrated(min_co=self.min_co, n_neighbors=self.n_neighbors,
                                  random_state=self.random_state)
            return est.fit_transform(X, mask, sensor=sensor, anchor_ids=anchor_ids,
                                     anchor_positions=anchor_positions)
        self.branch_ = "covis-angle"
        result = masked_embedding(X, mask, sensor, self.branch_, anchor_ids=anchor_ids,
                                  anchor_positions=anchor_positions, max_iter=self.max_iter,
                                  min_co=self.min_co)
        for msg in result.warnings:
            warnings.warn(msg, MaskedMapWarning, stacklevel=2)
        return result.positions


def _covis_cal(min_co=3, n_neighbors=12, links=("linear", "log"),
               random_state=0) -> CovisCalibrated:
    return CovisCalibrated(min_co=min_co, n_neighbors=n_neighbors, links=links,
                           random_state=random_state)


def _covis_auto(min_co=3, local_share=0.1, n_neighbors=12, max_iter=300,
                random_state=0) -> CovisAuto:
    return CovisAuto(min_co=min_co, local_share=local_share, n_neighbors=n_neighbors,
                     max_iter=max_iter, random_state=random_state)
