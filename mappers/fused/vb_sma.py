"""Visibility + bearing in one map (label ``"VB-SMA"``): the paper's open question (§6), "how to
integrate different information sources ... when both visibility and bearing measurements are
available".

The two histories of one walk are joined object by object: each sensor's row is divided by its
norm (paper eq. 7, per sensor), the bearing part is weighted by ``bearing_weight``, and the
joined rows are mapped by CAL-SMA (:mod:`mappers.calibrated.cal_sma`) with its Euclidean history
dissimilarity. The squared dissimilarity of two objects is then the sum of the sensors' squared
row distances,

    delta_ij^2 = ||v_i - v_j||^2 + w^2 ||b_i - b_j||^2 = 2 (1 - cos(V_i, V_j)) + w^2 ||b_i - b_j||^2,

so visibility, which separates near objects sharply but saturates beyond the visual range,
and bearing, which grows smoothly with distance over the whole arena, both shape the map.

That map is then blended with CAL-SMA's map of the bearing rows alone, both held to the same
anchors: ``(1 - s) * fused + s * bearing-only`` with ``s = bearing_share``. The two maps' errors
are largely independent, so the blend keeps most of the fused map's gain and loses little on
the walks where the joined rows mislead (``s`` chosen on tuning seeds:
``docs/fused-sensing.md#vb-smas-worst-run-a-blend-not-a-switch``). ``bearing_share=0`` is the
fused map alone.

Last (``refine=True``, the default since BEARING-BA became the bearing default), the blend is the
start map of a bearing-only bundle adjustment of the bearing part (:mod:`mappers.viewpoints.bearing`,
``start_positions`` = the blend): each step's viewpoint is estimated and the map refined until it
explains the bearings, which visibility bits cannot do to millimetres: without it a fused
history mapped far worse than its bearing half alone (``docs/fused-sensing.md``, "After
BEARING-BA"). ``refine=False`` is the paper-era VB-SMA (the blend alone).

References: Yairi (2007) for the rows and their normalisation (eq. 7); de Leeuw (1977) for the
anchored SMACOF; Triggs et al. (2000) for the bundle adjustment.
"""

from __future__ import annotations

from numbers import Real

import numpy as np
from sklearn.utils._param_validation import Interval, StrOptions

from mappers.calibrated import CalibratedSMACOF
from mappers.core.validation import check_fused_input
from mappers.viewpoints import BearingAdjustment

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
        bearing_share: share ``s`` in [0, 1) of the bearing-only map in the blend (0: the fused
            map alone).
        refine: refine the blend by bearing-only bundle adjustment of the bearing part
            (:class:`mappers.viewpoints.bearing.BearingAdjustment` with its defaults; False: the
            paper-era VB-SMA).
        The other parameters are CAL-SMA's (:class:`mappers.calibrated.cal_sma.CalibratedSMACOF`),
        for both its maps (the joined rows' and the bearing rows').

    Fitted attributes beyond CAL-SMA's: ``fused_embedding_`` (the joined rows' map) and
    ``bearing_embedding_`` (the bearing rows' map; None when ``bearing_share`` is 0);
    ``blend_embedding_`` their blend; ``adjustment_`` the fitted
    :class:`~mappers.viewpoints.bearing.BearingAdjustment` (None when ``refine`` is False);
    ``embedding_`` is the refined blend (the blend when ``refine`` is False or the adjustment
    kept its start).
    """

    _parameter_constraints: dict = {**CalibratedSMACOF._parameter_constraints,
                                    "dissimilarity": [StrOptions({"auto", "cosine", "euclidean"})],
                                    "bearing_weight": [Interval(Real, 0, None, closed="neither")],
                                    "bearing_share": [Interval(Real, 0, 1, closed="left")],
                                    "refine": ["boolean"]}

    def __init__(self, *, bearing_weight: float = 3.0, bearing_share: float = 0.3,
                 refine: bool = True, n_neighbors: int | None = None, dissimilarity: str = "auto",
                 n_rounds: int = 20, position_degree: int = 2, dissimilarity_degree: int = 2,
                 far_weight: float = 0.02, far_factor: float = 0.7, n_init: int = 4,
                 fold_threshold: float = 0.05, init: np.ndarray | None = None,
                 max_iter: int = 100, tol: float = 1e-6, random_state=None) -> None:
        super().__init__(n_neighbors=n_neighbors, dissimilarity=dissimilarity, n_rounds=n_rounds,
                         position_degree=position_degree,
                         dissimilarity_degree=dissimilarity_degree, far_weight=far_weight,
                         far_factor=far_factor, n_init=n_init, fold_threshold=fold_threshold,
                         init=init, max_iter=max_iter, tol=tol, random_state=random_state)
        self.bearing_weight = bearing_weight
        self.bearing_share = bearing_share
        self.refine = refine

    def fit(self, X, y=None, *, masks=None, anchor_ids=None, anchor_positions=None):
        """Map the fused histories ``X`` ({"visibility": (M, N), "bearing": (M, 2N)}; complete:
        ``masks`` must be None or all None)."""
        self._validate_params()
        check_fused_input(self, X, ("visibility", "bearing"))
        if masks and any(m is not None for m in masks.values()):
            raise ValueError("VB-SMA maps complete histories only: masks must be None")
        Z = joined_rows(X["visibility"], X["bearing"], self.bearing_weight)
        super().fit(Z, anchor_ids=anchor_ids, anchor_positions=anchor_positions)
        self.fused_embedding_ = self.embedding_
        self.bearing_embedding_ = None
        if self.bearing_share > 0:
            B = np.asarray(X["bearing"], dtype=float)
            norm = np.linalg.norm(B, axis=1, keepdims=True)
            if not np.all(norm > 0):
                raise ValueError("VB-SMA blends in the bearing-only map, which needs every "
                                 "object's bearing history; some are empty (bearing_share=0 "
                                 "maps the joined rows alone)")
            alone = CalibratedSMACOF(**{name: getattr(self, name)
                                        for name in CalibratedSMACOF._get_param_names()})
            self.bearing_embedding_ = alone.fit_transform(B / norm, anchor_ids=anchor_ids,
                                                          anchor_positions=anchor_positions)
            s = self.bearing_share
            self.embedding_ = (1.0 - s) * self.fused_embedding_ + s * self.bearing_embedding_
        self.blend_embedding_ = self.embedding_
        self.adjustment_ = None
        if self.refine:
            self.adjustment_ = BearingAdjustment()
            self.embedding_ = self.adjustment_.fit_transform(
                X["bearing"], anchor_ids=anchor_ids, anchor_positions=anchor_positions,
                start_positions=self.blend_embedding_)
        return self

    def fit_transform(self, X, y=None, *, masks=None, anchor_ids=None, anchor_positions=None):
        """Fit and return the (M, 2) map in world coordinates."""
        return self.fit(X, masks=masks, anchor_ids=anchor_ids,
                        anchor_positions=anchor_positions).embedding_


def _vb_sma(bearing_weight: float = 3.0, bearing_share: float = 0.3, refine: bool = True,
            n_neighbors: int | None = None, random_state=None) -> VisibilityBearingSMACOF:
    return VisibilityBearingSMACOF(bearing_weight=bearing_weight, bearing_share=bearing_share,
                                   refine=refine, n_neighbors=n_neighbors,
                                   random_state=random_state)
