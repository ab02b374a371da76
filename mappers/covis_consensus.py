"""Two co-observation maps that check each other (label ``"covis-consensus"``).

Through a limited field of view (visibility, 90 degrees: an object is in view in a quarter of
the steps) the masked maps fail in two different ways:

- ``covis-power`` (:mod:`mappers.masked`: a power link fitted to the co-observation rates,
  started from the ordinal ``covis-nonmetric`` map) is the more precise when its ordinal start
  is right, and fails when it is not (0.39, 0.54 and 0.14 m on 3 of 20 of our layouts, where
  the ordinal fit settles in a wrong layout; the same happens started from a good map).
- ``covis-cal`` (:mod:`mappers.covis_calibrated`: CAL-SMA of the coefficients) never failed
  that way on our layouts (largest run 0.095 m) but is less precise (mean 0.073 against 0.057
  on the 17 layouts where ``covis-power`` did not fail).

Both are anchored, so they are in one frame and their disagreement, the mean distance between
an object's two positions, is measured from the data alone: 0.03–0.09 m where ``covis-power`` was
right, 0.15–0.54 m where it failed (20 layouts). So: ``covis-power``'s map when the two agree
within ``max_disagreement`` times the anchors' spread (RMS distance from their centroid: 1.3 m
in the 2.5 m arena, so 0.09 is 0.12 m), else ``covis-cal``'s. ``choice_`` says which, and
``disagreement_`` by how much [m].

*Assumes*: what the chosen member assumes, and that the two members fail independently (a
layout on which both fail the same way is not caught).
"""

from __future__ import annotations

import numpy as np

from mappers.covis_calibrated import CovisCalibrated
from mappers.masked import MaskedMapper
from mappers.registry import MethodSpec

__all__ = ["CovisConsensus"]


class CovisConsensus:
    """``"covis-consensus"`` (module docstring): ``fit_transform(X, mask=None, *, sensor,
    anchor_ids, anchor_positions)`` returns the (M, 2) map in the anchors' frame; ``maps_`` holds
    both members' maps, ``choice_`` the label used, ``disagreement_`` [m]."""

    def __init__(self, *, max_disagreement: float = 0.09, min_co: int = 3, n_neighbors: int = 12,
                 max_iter: int = 300, random_state=0) -> None:
        if not (isinstance(max_disagreement, (int, float)) and max_disagreement > 0):
            raise ValueError(f"max_disagreement must be a number > 0, got {max_disagreement!r}")
        self.max_disagreement = float(max_disagreement)
        self.min_co, self.n_neighbors = min_co, n_neighbors
        self.max_iter, self.random_state = max_iter, random_state

    def fit_transform(self, X, mask=None, *, sensor: str, anchor_ids=None, anchor_positions=None):
        if anchor_ids is None or anchor_positions is None:
            raise ValueError("covis-consensus needs anchors: its two maps meet in the anchors' frame")
        ids = np.asarray(anchor_ids)
        pos = np.asarray(anchor_positions, dtype=float)
        kw = dict(sensor=sensor, anchor_ids=ids, anchor_positions=pos)
        self.maps_ = {
            "covis-power": MaskedMapper("covis-power", min_co=self.min_co,
                                        max_iter=self.max_iter).fit_transform(X, mask, **kw),
            "covis-cal": CovisCalibrated(min_co=self.min_co, n_neighbors=self.n_neighbors,
                                         random_state=self.random_state).fit_transform(X, mask, **kw),
        }
        a, b = self.maps_["covis-power"], self.maps_["covis-cal"]
        rows = np.setdiff1d(np.flatnonzero(np.isfinite(a).all(1) & np.isfinite(b).all(1)), ids)
        spread = float(np.sqrt(np.mean(np.sum((pos - pos.mean(axis=0)) ** 2, axis=1))))
        self.disagreement_ = (float(np.mean(np.linalg.norm(a[rows] - b[rows], axis=1)))
                              if rows.size else float("inf"))
        agree = self.disagreement_ <= self.max_disagreement * spread
        self.choice_ = "covis-power" if agree else "covis-cal"
        return self.maps_[self.choice_]


def _covis_consensus(max_disagreement=0.09, min_co=3, n_neighbors=12, max_iter=300,
                     random_state=0) -> CovisConsensus:
    return CovisConsensus(max_disagreement=max_disagreement, min_co=min_co,
                          n_neighbors=n_neighbors, max_iter=max_iter, random_state=random_state)


SPEC = MethodSpec(
    "covis-consensus", _covis_consensus,
    description="covis-power's map when it agrees with covis-cal's, else covis-cal's",
    sensors=("visibility", "bearing"), uses_anchors=True, normalize=False,
    histories=("complete", "masked"),
)
