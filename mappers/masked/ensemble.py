"""The covisibility ensemble (label ``"COVIS-ENSEMBLE"``): the mean of anchored co-observation
maps over several windows of consecutive steps.

Two landmarks caught in one camera frame are close; caught within a few seconds of each other,
while the camera sweeps, they are still likely close, and the window decides how far "close"
reaches. A single co-observation map moves with the window, and on real runs the window best on
one run is not on another, while the mean of the maps over a fixed spread of windows needs no
choice of one. All members hold the anchors fixed, so they share the anchors'
frame and their mean is a map. It adds no information to its members: it removes the choice of
one setting. *Assumes* what its members assume (:mod:`mappers.masked.pair_maps`).

Windows are counted in ticks of the history's *timeline*: an (N, 2) integer array giving, for
each step (column group), the robot that took it and the tick of its clock (e.g. the index of a
0.5 s bin); steps of one robot falling in the same ``tick // window`` are merged. Without a
timeline the history is one robot stepping once per tick.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from numbers import Integral, Real
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval, StrOptions

from mappers.core.estimator_params import store_params
from mappers.core.sensors import check_timeline, step_observations
from mappers.core.validation import check_history
from mappers.masked.pair_maps import MaskedMap, MaskedMapWarning, masked_embedding

__all__ = ["CovisEnsemble", "ensemble_embedding", "window_steps"]

MEMBERS = ("covis-power", "covis-nonmetric")


def window_steps(seen: np.ndarray, window: int, timeline: np.ndarray | None = None) -> np.ndarray:
    """(M, W) bool: objects sensed within each window of ``window`` ticks of one robot.

    Windows are ordered robot by robot, then in time; windows with no step are absent.
    """
    seen = np.asarray(seen, dtype=bool)
    n = seen.shape[1]
    if timeline is None:
        robot, tick = np.zeros(n, dtype=np.int64), np.arange(n, dtype=np.int64)
    else:
        robot, tick = check_timeline(timeline, n).T
    key = robot * (int(tick.max(initial=0)) // window + 1) + tick // window
    used, inv = np.unique(key, return_inverse=True)
    merge = csr_matrix((np.ones(n), (np.arange(n), np.asarray(inv).ravel())), shape=(n, len(used)))
    return (merge.T @ seen.T.astype(float)).T > 0


def ensemble_embedding(
    histories: Sequence[tuple[np.ndarray, np.ndarray | None]],
    sensor: str,
    method: str | None = None,
    *,
    anchor_ids: np.ndarray,
    anchor_positions: np.ndarray,
    param_sets: Sequence[dict[str, Any]] = ({},),
    max_iter: int = 300,
) -> MaskedMap:
    """Mean of :func:`~mappers.masked.pair_maps.masked_embedding` maps over several histories of the same
    objects and several parameter sets, anchors held fixed (all maps are then in their frame).

    Args:
        histories: ``(X, mask)`` pairs, e.g. one run at several windows (same objects, same rows).
        sensor, method: as for :func:`~mappers.masked.pair_maps.masked_embedding` (one method for all).
        anchor_ids, anchor_positions: required: without fixed anchors the members' frames differ.
        param_sets: parameter overrides; every history is mapped with every set.

    Returns a :class:`~mappers.masked.pair_maps.MaskedMap` whose ``positions`` are the mean of the members'
    (an object unmapped in any member is unmapped), ``delta``/``weights`` the members' means,
    ``components`` those of the member with the most components, ``warnings`` the union, and
    ``params`` ``{"members": [...params of each member...]}``.
    """
    if anchor_ids is None or anchor_positions is None:
        raise ValueError("ensemble_embedding needs anchor_ids and anchor_positions (a common frame)")
    if len(histories) == 0:
        raise ValueError("histories must hold at least one (X, mask) pair")
    if len(param_sets) == 0:
        raise ValueError("param_sets must hold at least one parameter dict")
    members = [
        masked_embedding(X, mask, sensor, method, anchor_ids=anchor_ids,
                         anchor_positions=anchor_positions, max_iter=max_iter, **ps)
        for X, mask in histories for ps in param_sets
    ]
    shapes = {m.positions.shape for m in members}
    if len(shapes) != 1:
        raise ValueError(f"histories must describe the same objects, got maps of shapes {shapes}")
    positions = np.mean([m.positions for m in members], axis=0)  # NaN anywhere -> NaN
    msgs: list[str] = []
    for m in members:
        msgs.extend(w for w in m.warnings if w not in msgs)
    return MaskedMap(
        positions=positions,
        method=members[0].method,
        params={"members": [dict(m.params) for m in members]},
        delta=np.mean([m.delta for m in members], axis=0),
        weights=np.mean([m.weights for m in members], axis=0),
        components=max(members, key=lambda m: len(m.components)).components,
        unmapped=tuple(int(i) for i in np.flatnonzero(np.isnan(positions).any(axis=1))),
        warnings=tuple(msgs),
    )


class CovisEnsemble(TransformerMixin, BaseEstimator):
    """``"COVIS-ENSEMBLE"``: the mean of anchored co-observation maps over windows of steps.

    Parameters:
        windows: the windows [ticks] the history is merged over, one member map each.
        min_co: the members' ``min_co``, one member map each (with each window).
        member: ``"covis-power"`` or ``"covis-nonmetric"``.
        power: covis-power's exponent (None: its default; only with ``member="covis-power"``).
        max_iter: the members' SMACOF updates.

    Uses only the pattern of what was observed, so any sensor's history serves.
    ``fit(X, mask=None, *, sensor=None, anchor_ids, anchor_positions, timeline=None)`` needs the
    anchors: the members meet in their frame.

    Attributes:
        embedding_ (M, 2) (NaN rows: unmapped); result_ the :class:`MaskedMap` of the mean (its
        notes issued as :class:`MaskedMapWarning`); n_features_in_.
    """

    _parameter_constraints: dict = {
        "windows": ["array-like", Interval(Integral, 1, None, closed="left")],
        "min_co": ["array-like", Interval(Integral, 1, None, closed="left")],
        "member": [StrOptions(set(MEMBERS))],
        "power": [Interval(Real, 0, None, closed="neither"), None],
        "max_iter": [Interval(Integral, 1, None, closed="left")],
    }

    def __init__(self, *, windows: Sequence[int] = (2, 3, 4, 6, 8, 10),
                 min_co: Sequence[int] = (3, 5), member: str = "covis-power",
                 power: float | None = None, max_iter: int = 300) -> None:
        store_params(self, locals())

    def fit(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
            anchor_positions=None, timeline=None):
        """Map the history ``X`` (M, D) (``mask`` True where observed) with the anchors."""
        self._validate_params()
        windows = tuple(int(w) for w in np.atleast_1d(self.windows))
        min_co = tuple(int(m) for m in np.atleast_1d(self.min_co))
        if not windows or min(windows) < 1 or not min_co:
            raise ValueError(f"windows must be positive integers and min_co non-empty, got "
                             f"windows={self.windows!r}, min_co={self.min_co!r}")
        if self.power is not None and self.member != "covis-power":
            raise ValueError("power applies to member='covis-power' only")
        X, mask, sensor = check_history(self, X, y, mask=mask, sensor=sensor)
        seen, _ = step_observations(X, mask, sensor)
        extra = {} if self.power is None else {"power": float(self.power)}
        hists = [(window_steps(seen, w, timeline).astype(float), None) for w in windows]
        self.result_ = ensemble_embedding(
            hists, "visibility", self.member, anchor_ids=anchor_ids,
            anchor_positions=anchor_positions, max_iter=self.max_iter,
            param_sets=[{"min_co": m, **extra} for m in min_co],
        )
        for msg in self.result_.warnings:
            warnings.warn(msg, MaskedMapWarning, stacklevel=2)
        self.embedding_ = self.result_.positions
        return self

    def fit_transform(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
                      anchor_positions=None, timeline=None) -> np.ndarray:
        """Fit and return the (M, 2) map (NaN rows: unmapped)."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions, timeline=timeline).embedding_
