"""A map for visibility histories with dropouts (label ``"DROPOUT-BLEND"``).

With a miss rate ``p`` a visible object reads 0 in a share ``p`` of the steps, at random. Two
estimators that see the history differently each lose to the noise in their own way:

- CAL-SMA (:mod:`mappers.calibrated.cal_sma`) of the history after a moving average over ``window``
  consecutive steps (by the timeline: :func:`mappers.core.flicker.step_runs`). A miss is surrounded
  by steps that saw the object, so the average puts part of it back; a wider window blurs the
  walk's 0.2 m steps (window 3 / 5 / 9 / 15 at ``miss_rate = 0.5``: 0.064 / 0.069 / 0.094 /
  0.17 m against 0.072 unsmoothed, 10 of our layouts).
- ``covis-nonmetric`` (:mod:`mappers.masked.pair_maps`): only the order of the co-observation rates, which
  a miss rate common to all objects leaves unchanged (0.061 m, same layouts).

Both maps are anchored (the anchors held at their positions), so they are in one frame and their
mean is a map; their errors are only partly shared, and the mean beats either (0.056 m, largest
run 0.071, same layouts; at ``miss_rate = 0.2`` 0.049 against CAL-SMA's 0.053; on the 25 fresh
layouts of ``benchmarks/bench_masked_goals.py`` at 0.5: 0.069 against CAL-SMA's 0.089 and
``covis-nonmetric``'s 0.073). An object one of them leaves unplaced takes the other's position;
one whose two positions lie farther apart than the anchors' spread (a member's failure, not
noise) keeps CAL-SMA's, with a warning. When the two maps disagree as a whole (their median
distance over the objects both place above ``max_disagreement`` times the anchors' spread), the
map is CAL-SMA's alone, with a warning: ``covis-nonmetric`` has then failed, folded or flung
far, and half of it is no longer noise that the mean averages out. This holds for walk-ordered
steps (:func:`mappers.core.flicker.persistence` at least :data:`WALK_PERSISTENCE`), which CAL-SMA's
window assumes; on viewpoints drawn at random CAL-SMA is the member that fails (one synthetic
history: 0.57 m against ``covis-nonmetric``'s 0.05), and the maps are blended as before.
Measured through a 90-degree view (VIEW-BA starts from this map; mean non-anchor MPE [m] at 500
/ 1,000 / 1,500 / 2,000 steps, without the check -> with it):

- tuning histories (seeds 777 and 4242 of ``bench_online.py``, 50 layouts): VIEW-BA 0.106 /
  0.070 / 0.043 / 0.043 -> 0.074 / 0.061 / 0.042 / 0.041; the blend itself 0.197 / 0.118 / 0.068
  / 0.064 -> 0.113 / 0.096 / 0.063 / 0.058;
- unseen ones (seed 31337, 25 layouts): VIEW-BA 0.113 / 0.085 / 0.050 / 0.041 -> 0.086 / 0.055 /
  0.042 / 0.041; another simulator's (``bench_view_other_sim.py``'s world, 20 layouts, 500 /
  1,000 / 2,000): 0.114 / 0.097 / 0.084 -> 0.093 / 0.070 / 0.084;
- through a 60-degree view, where ``covis-nonmetric`` fails on most layouts (fresh seeds
  1000..1024 of ``bench_masked_goals.py``, N = 2,000): VIEW-BA 0.121 -> 0.072, the blend 0.184 ->
  0.096.

Above 0.25 CAL-SMA was the better member in 39 of 39 tuning maps, 23 of 23 unseen ones and 26 of
27 of the other simulator's (covis-nonmetric 0.29 m to 10^19 m off; the exception, both members
off by 0.4-0.5 m). Below it the members' errors are mixed, and on the MRCLAM runs (real data,
where CAL-SMA alone is by far the worse member) they disagree by 0.06-0.12, so the check leaves
those maps as they were; at 0.1 it fired there and cost 0.5 m on Dataset 1.
The median, not the mean: one object flung far is the guard above's.

A limited field of view is a dropout the mask names: an object out of view reads 0 at steps
between steps that saw it. The same blend (unobserved entries as 0) is the default for masked
visibility histories: through a 90-degree view 0.074 m (largest run 0.28) against
``covis-power``'s 0.102 (0.54) on 20 of our layouts, and 0.063 (0.115) against 0.074 (0.170) on
the 25 fresh ones of ``benchmarks/bench_masked_goals.py`` (``covis-nonmetric``: 0.085, 0.202).

*Assumes*: what CAL-SMA and ``covis-nonmetric`` assume, and that consecutive steps are close
viewpoints (the window). It was ``build_map``'s default for masked visibility histories and for
complete ones with dropouts; VIEW-BA and VIS-BA-WALK replaced it there
(:data:`mappers.defaults.DEFAULTS`). It is
VIEW-BA's start, and the masked visibility default above
:data:`mappers.defaults.SCALABLE_ABOVE_OBJECTS` objects.
"""

from __future__ import annotations

import warnings
from numbers import Real

import numpy as np
from scipy.ndimage import uniform_filter1d

from mappers.calibrated import CalibratedSMACOF
from mappers.core.flicker import persistence, step_runs
from mappers.masked.pair_maps import MaskedMapper, MaskedMapWarning

__all__ = ["WALK_PERSISTENCE", "DropoutBlend", "smooth_steps"]

WALK_PERSISTENCE = 1.5
"""The smallest :func:`mappers.core.flicker.persistence` of the zero-filled rows at which
``DROPOUT-BLEND`` takes its steps for a walk's and, when its members disagree as a whole, keeps
CAL-SMA's map. Masked walks through a 90-degree view: 1.9-3.5 (median 3.1; 225 histories of 500
to 2,000 steps), lower than complete ones (4.8-5.3: a turning view changes what is visible);
another simulator's walk 4.3-5.9; viewpoints drawn at random about 1.1."""


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


class DropoutBlend:
    """``"DROPOUT-BLEND"``: the mean of two anchored maps (module docstring).

    ``fit_transform(X, mask=None, *, sensor, anchor_ids, anchor_positions, timeline=None)``
    returns the (M, 2) map in the anchors' frame; ``maps_`` holds the two members' maps
    (``"CAL-SMA"``, ``"covis-nonmetric"``), ``disagreement_`` their median distance over the
    objects both place as a share of the anchors' spread, and ``blended_`` whether the map is
    their mean (False: CAL-SMA's alone, the steps being walk-ordered (``walk_ordered_``) and
    the disagreement above ``max_disagreement``; None disables that check).
    """

    def __init__(self, *, window: int = 3, n_neighbors: int | None = None, min_co: int = 3,
                 max_iter: int = 300, max_disagreement: float | None = 0.25,
                 random_state=0) -> None:
        smooth_steps(np.zeros((1, 1)), window)  # checks window
        if max_disagreement is not None and (
                isinstance(max_disagreement, bool) or not isinstance(max_disagreement, Real)
                or not max_disagreement > 0):
            raise ValueError(f"max_disagreement must be a number > 0 or None, got "
                             f"{max_disagreement!r}")
        self.window, self.n_neighbors, self.min_co = int(window), n_neighbors, min_co
        self.max_iter, self.random_state = max_iter, random_state
        self.max_disagreement = max_disagreement

    def fit_transform(self, X, mask=None, *, sensor: str, anchor_ids=None, anchor_positions=None,
                      timeline=None):
        if sensor != "visibility":
            raise ValueError(f"DROPOUT-BLEND maps visibility histories, got sensor {sensor!r}")
        if anchor_ids is None or anchor_positions is None:
            raise ValueError("DROPOUT-BLEND needs anchors: its two maps meet in the anchors' frame")
        X = np.asarray(X, dtype=float)
        if mask is not None:
            X = np.where(mask, X, 0.0)
        S = smooth_steps(X, self.window, timeline)
        norms = np.linalg.norm(S, axis=1, keepdims=True)
        if np.any(norms == 0):
            raise ValueError("DROPOUT-BLEND: an object is never visible (empty history row)")
        cal = CalibratedSMACOF(n_neighbors=self.n_neighbors, random_state=self.random_state)
        order = MaskedMapper("covis-nonmetric", min_co=self.min_co, max_iter=self.max_iter)
        # covis-nonmetric first: it is the one that fails on sparse data (its pairs fall apart),
        # and it finds that out before its solve, CAL-SMA only after a whole fit
        ordinal = order.fit_transform(X, mask, sensor=sensor, anchor_ids=anchor_ids,
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
            return a.copy()
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
        return Y


def _dropout_blend(window=3, n_neighbors=None, min_co=3, max_iter=300, max_disagreement=0.25,
                   random_state=0) -> DropoutBlend:
    return DropoutBlend(window=window, n_neighbors=n_neighbors, min_co=min_co, max_iter=max_iter,
                        max_disagreement=max_disagreement, random_state=random_state)
