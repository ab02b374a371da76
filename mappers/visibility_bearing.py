"""Visibility + bearing in one map (label ``"VB-SMA"``): the paper's open question (§6), "how to
integrate different information sources ... when both visibility and bearing measurements are
available".

The two histories of one walk are joined object by object: each sensor's row is divided by its
norm (paper eq. 7, per sensor), the bearing part is weighted by ``bearing_weight``, and the
joined rows are mapped by CAL-SMA (:mod:`mappers.calibrated`) with its Euclidean history
dissimilarity. The squared dissimilarity of two objects is then the sum of the sensors' squared
row distances,

    delta_ij^2 = ||v_i - v_j||^2 + w^2 ||b_i - b_j||^2 = 2 (1 - cos(V_i, V_j)) + w^2 ||b_i - b_j||^2,

so visibility, which separates near objects sharply but saturates beyond the visual range,
and bearing, which grows smoothly with distance over the whole arena, both shape the map.
"""

from __future__ import annotations

from numbers import Real

import numpy as np
from sklearn.utils._param_validation import Interval

from mappers.calibrated import CalibratedSMACOF
from mappers.registry import MethodSpec

__all__ = ["VisibilityBearingSMACOF", "joined_rows"]


def joined_rows(visibility: np.ndarray, bearing: np.ndarray, bearing_weight: float) -> np.ndarray:
    """(M, N + 2N) rows ``[v / ||v||, w b / ||b||]`` (an all-zero row part stays zero)."""
    parts = []
    for X, w in ((visibility, 1.0), (bearing, bearing_weight)):
        X = np.asarray(X, dtype=float)
        norm = np.linalg.norm(X, axis=1, keepdims=True)
        parts.append(w * X / np.where(norm > 0, norm, 1.0))
    return np.hstack(parts)


class VisibilityBearingSMACOF(CalibratedSMACOF):
    """CAL-SMA of joined visibility and bearing histories (see the module docstring).

    Parameters:
        bearing_weight: weight ``w`` of the bearing rows against the visibility rows.
        The other parameters are CAL-SMA's (:class:`mappers.calibrated.CalibratedSMACOF`).
    """

    _parameter_constraints: dict = {**CalibratedSMACOF._parameter_constraints,
                                    "bearing_weight": [Interval(Real, 0, None, closed="neither")]}

    def __init__(self, *, bearing_weight: float = 3.0, n_neighbors: int | None = None,
                 n_rounds: int = 20, position_degree: int = 2, fold_threshold: float = 0.05,
                 random_state=None) -> None:
        super().__init__(n_neighbors=n_neighbors, n_rounds=n_rounds,
                         position_degree=position_degree, fold_threshold=fold_threshold,
                         random_state=random_state)
        self.bearing_weight = bearing_weight

    def fit(self, X, y=None, *, masks=None, anchor_ids=None, anchor_positions=None):
        """Map the fused histories ``X`` ({"visibility": (M, N), "bearing": (M, 2N)}; complete:
        ``masks`` must be None or all None)."""
        if masks and any(m is not None for m in masks.values()):
            raise ValueError("VB-SMA maps complete histories only: masks must be None")
        self._validate_params()
        Z = joined_rows(X["visibility"], X["bearing"], self.bearing_weight)
        return super().fit(Z, anchor_ids=anchor_ids, anchor_positions=anchor_positions)

    def fit_transform(self, X, y=None, *, masks=None, anchor_ids=None, anchor_positions=None):
        """Fit and return the (M, 2) map in world coordinates."""
        return self.fit(X, masks=masks, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions).embedding_


def _vb_sma(bearing_weight: float = 3.0, n_neighbors: int | None = None,
            random_state=None) -> VisibilityBearingSMACOF:
    return VisibilityBearingSMACOF(bearing_weight=bearing_weight, n_neighbors=n_neighbors,
                                   random_state=random_state)


SPEC = MethodSpec(
    "VB-SMA",
    _vb_sma,
    {},
    {"bearing_weight": [1.0, 2.0, 3.0, 4.0]},
    "CAL-SMA of joined visibility and bearing histories (fused)",
    uses_anchors=True,
    sensors=(frozenset({"visibility", "bearing"}),),
    normalize=False,
)
