"""A map for visibility histories with dropouts (label ``"DROPOUT-BLEND"``).

With a miss rate ``p`` a visible object reads 0 in a share ``p`` of the steps, at random. Two
anchored maps that each lose to this noise in their own way are averaged:

- CAL-SMA (:mod:`mappers.calibrated.cal_sma`) of the history after a moving average over
  ``window`` consecutive steps (by the timeline: :func:`mappers.core.flicker.step_runs`): a miss
  is surrounded by steps that saw the object, so the average puts part of it back, and a wider
  window blurs the walk's steps;
- ``covis-nonmetric`` (:mod:`mappers.masked.pair_maps`): only the order of the co-observation
  rates, which a miss rate common to all objects leaves unchanged.

Both hold the anchors at their positions, so they share one frame, and their errors are only
partly shared: their mean beats either. An object one of them leaves unplaced takes the other's
position; one whose two positions lie farther apart than the anchors' spread (a member's
failure, not noise) keeps CAL-SMA's, with a warning. When the two maps disagree as a whole
(their median distance over the objects both place above ``max_disagreement`` times the anchors'
spread; the median, not the mean: one object flung far is the guard above's), the map is
CAL-SMA's alone, with a warning: ``covis-nonmetric`` has then failed, and half of it is no
longer noise that the mean averages out. That check holds for walk-ordered steps
(:func:`mappers.core.flicker.persistence` at least :data:`WALK_PERSISTENCE`), which CAL-SMA's
window assumes; on viewpoints drawn at random CAL-SMA is the member that fails, and the maps are
blended as they are.

A limited field of view is a dropout the mask names (an object out of view reads 0 at steps
between steps that saw it), so the same blend, unobserved entries as 0, maps masked visibility
histories. It is VIEW-BA's start and the masked visibility default above
:data:`mappers.defaults.SCALABLE_ABOVE_OBJECTS` objects (:data:`mappers.defaults.DEFAULTS`).
What each choice was measured on: ``docs/imperfect-sensing.md#dropout-blend``.

*Assumes*: what CAL-SMA and ``covis-nonmetric`` assume, and that consecutive steps are close
viewpoints (the window).

References: Yairi (2007) for the history rows; de Leeuw (1977) for the anchored SMACOF of both
members; Kruskal (1964) for the ordinal fit of ``covis-nonmetric``.
"""

from __future__ import annotations

import warnings
from numbers import Integral, Real

import numpy as np
from scipy.ndimage import uniform_filter1d
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval

from mappers.calibrated import CalibratedSMACOF
from mappers.core.estimator_params import store_params
from mappers.core.flicker import persistence, step_runs
from mappers.core.validation import check_fit
from mappers.masked.pair_maps import MaskedMapper, MaskedMapWarning

__all__ = ["WALK_PERSISTENCE", "DropoutBlend", "smooth_steps"]

WALK_PERSISTENCE = 1.5  # between walks and random viewpoints: docs/imperfect-sensing.md#dropout-blend
"""The smallest :func:`mappers.core.flicker.persistence` of the zero-filled rows at which
``DROPOUT-BLEND`` takes its steps for a walk's and, when its members disagree as a whole, keeps
CAL-SMA's map."""


def smooth_steps(X, window: int, timeline=None) -> np.ndarray:
    """``X`` (M, N) with each row replaced by its moving average over ``window`` consecutive
    steps of each run (:func:`mappers.core.flicker.step_runs`; the ends repeat the edge step)."""
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1:
        raise ValueError(f"window must be an integer >= 1, got {window!r}")
    X = np.asarray(X, dtype=float)
    out = X.copy()
    for run in step_runs(X.shape[1], timeline):
        out[:, run] = uniform_filter1d(X[:, run], int(window), axis=1, mode="nearest")
    return out


class DropoutBlend(TransformerMixin, BaseEstimator):
    """``"DROPOUT-BLEND"``: the mean of two anchored maps (module docstring).

    Parameters:
        window: steps of the moving average of CAL-SMA's rows.
        n_neighbors, random_state: CAL-SMA's.
        min_co, max_iter: ``covis-nonmetric``'s.
        max_disagreement: the members' median distance, as a share of the anchors' spread,
            above which a walk's map is CAL-SMA's alone (None: never).

    ``fit(X, mask=None, *, sensor=None, anchor_ids, anchor_positions, timeline=None)`` maps a
    visibility history in the anchors' frame (the anchors are needed: the two maps meet there).

    Attributes:
        embedding_ (M, 2); maps_ the two members' maps (``"CAL-SMA"``, ``"covis-nonmetric"``);
        disagreement_ their median distance over the objects both place as a share of the
        anchors' spread; walk_ordered_ whether the steps are walk-ordered
        (:data:`WALK_PERSISTENCE`); blended_ whether the map is their mean (False: CAL-SMA's
        alone, the steps being walk-ordered and the disagreement above ``max_disagreement``);
        n_features_in_.
    """

    _parameter_constraints: dict = {
        "window": [Interval(Integral, 1, None, closed="left")],
        "n_neighbors": [Interval(Integral, 2, None, closed="left"), None],
        "min_co": [Interval(Integral, 1, None, closed="left")],
        "max_iter": [Interval(Integral, 1, None, closed="left")],
        "max_disagreement": [Interval(Real, 0, None, closed="neither"), None],
        "random_state": ["random_state"],
    }

    def __init__(self, *, window: int = 3, n_neighbors: int | None = None, min_co: int = 3,
                 max_iter: int = 300, max_disagreement: float | None = 0.25,
                 random_state=0) -> None:
        store_params(self, locals())

    def fit(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
            anchor_positions=None, timeline=None):
        """Map the visibility history ``X`` (M, N) (``mask`` True where observed)."""
        X, mask, sensor = check_fit(self, X, y, bools=("window", "min_co", "max_disagreement"),
                                    mask=mask, sensor=sensor, sensors=("visibility",))
        if anchor_ids is None or anchor_positions is None:
            raise ValueError("DROPOUT-BLEND needs anchors: its two maps meet in the anchors' frame")
        if mask is not None:
            X = np.where(mask, X, 0.0)
        S = smooth_steps(X, self.window, timeline)
        norms = np.linalg.norm(S, axis=1, keepdims=True)
        if np.any(norms == 0):
            raise ValueError("DROPOUT-BLEND: an object is never visible (empty history row)")
        cal = CalibratedSMACOF(n_neighbors=self.n_neighbors, random_state=self.random_state)
        order = MaskedMapper(method="covis-nonmetric", min_co=self.min_co, max_iter=self.max_iter)
        # covis-nonmetric first: it is the one that fails on sparse data (its pairs fall apart),
        # and it finds that out before its solve, CAL-SMA only after a whole fit
        ordinal = order.fit_transform(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                                      anchor_positions=anchor_positions)
        self.maps_ = {
            "CAL-SMA": cal.fit_transform(S / norms, anchor_ids=anchor_ids,
                                         anchor_positions=anchor_positions),
            "covis-nonmetric": ordinal,
        }
        a, b = self.maps_.values()
        pos = np.asarray(anchor_positions, dtype=float)
        spread = float(np.sqrt(np.mean(np.sum((pos - pos.mean(axis=0)) ** 2, axis=1))))
        gap = np.linalg.norm(a - b, axis=1)
        both = ~np.isnan(gap)  # placed by both (an infinite gap counts: a member flung away)
        self.disagreement_ = float(np.median(gap[both]) / spread) if both.any() else float("nan")
        # CAL-SMA is the member trusted only where its window is sound: on walk-ordered steps
        # (on viewpoints drawn at random the averaged rows mix unrelated steps, and it is the
        # member that fails)
        self.walk_ordered_ = bool(persistence(X, timeline) >= WALK_PERSISTENCE)
        self.blended_ = not (self.max_disagreement is not None and self.walk_ordered_
                             and self.disagreement_ > self.max_disagreement)
        if not self.blended_:
            # covis-nonmetric has failed as a whole (folded, or flung far on sparse data): its
            # half of a mean would be an error, not noise to average out. CAL-SMA is the member
            # kept: it guards itself against folds (mappers.calibrated.cal_sma.fold_score)
            warnings.warn(f"DROPOUT-BLEND: the CAL-SMA and covis-nonmetric maps disagree by "
                          f"{self.disagreement_:.2f} of the anchors' spread (median; above "
                          f"max_disagreement = {self.max_disagreement:g}): the map is CAL-SMA's",
                          MaskedMapWarning, stacklevel=2)
            self.embedding_ = a.copy()
            return self
        Y = np.where(np.isnan(a), b, np.where(np.isnan(b), a, 0.5 * (a + b)))
        # covis-nonmetric's lower bounds can fling a weakly tied object kilometres away on very
        # sparse data (N = 300 at miss_rate 0.7); an object whose two positions lie farther
        # apart than the anchors' spread keeps CAL-SMA's
        apart = np.zeros(len(gap), dtype=bool)
        apart[both] = gap[both] > spread
        if apart.any():
            Y[apart] = a[apart]
            warnings.warn(f"DROPOUT-BLEND: objects {np.flatnonzero(apart).tolist()} lie farther "
                          f"apart in the two maps than the anchors' spread ({spread:.2f} m); "
                          "they keep the CAL-SMA position", MaskedMapWarning, stacklevel=2)
        self.embedding_ = Y
        return self

    def fit_transform(self, X, y=None, *, mask=None, sensor: str | None = None, anchor_ids=None,
                      anchor_positions=None, timeline=None):
        """Fit and return the (M, 2) map in the anchors' frame."""
        return self.fit(X, mask=mask, sensor=sensor, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions, timeline=timeline).embedding_


