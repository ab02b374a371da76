"""COVIS-3D: a 3-D map from sightings alone (visibility), by co-observation.

Objects seen together often are near one another (the paper's premise): the ``-log`` of the
Ochiai coefficient of two objects' sightings (:func:`mappers.masked.covisibility_dissimilarity`)
is embedded in three dimensions by weighted SMACOF (de Leeuw, 1977; pairs weighted by how often
they were seen together, started from classical MDS), and a 3-D affine map onto the anchors
(four or more, not on one plane) makes it metric (:func:`mappers.core.align_3d.fit_affine_3d`).
"""

from __future__ import annotations

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin

from mappers.core.align_3d import apply_affine_3d, check_anchors_3d, fit_affine_3d
from mappers.core.validation import check_views
from mappers.masked import covisibility_dissimilarity
from mappers.smacof import classical_mds, weighted_smacof

__all__ = ["CoVisibility3D"]


class CoVisibility3D(TransformerMixin, BaseEstimator):
    """Visibility histories (M, N) of 0/1 -> (M, 3) world positions (see the module's
    docstring); ``max_iter`` SMACOF updates at most. Objects never seen with another are NaN."""

    def __init__(self, *, max_iter: int = 300):
        self.max_iter = max_iter

    def fit_transform(self, X, y=None, *, anchor_ids=None, anchor_positions=None,
                      mask=None) -> np.ndarray:
        """Fit and return ``embedding_`` (M, 3)."""
        return self.fit(X, y, anchor_ids=anchor_ids, anchor_positions=anchor_positions,
                        mask=mask).embedding_

    def fit(self, X, y=None, *, anchor_ids=None, anchor_positions=None, mask=None):
        """Map the visibility history ``X`` (M, N) (``mask`` True where observed) in 3-D."""
        X = check_views(self, X, mask)
        if anchor_ids is None or anchor_positions is None:
            raise ValueError("COVIS-3D needs anchors: anchor_ids and anchor_positions (A, 3)")
        if not np.all((X == 0) | (X == 1) | (mask is not None and ~np.asarray(mask, bool))):
            raise ValueError("COVIS-3D maps visibility histories: an (M, N) array of 0/1")
        seen = X > 0 if mask is None else (X > 0) & np.asarray(mask, dtype=bool)
        ids, pos = check_anchors_3d(anchor_ids, anchor_positions, X.shape[0], fit="affine")
        delta, counts = covisibility_dissimilarity(seen)
        W = counts.astype(float).copy()
        np.fill_diagonal(W, 0.0)
        ok = W.sum(axis=1) > 0
        if not ok[ids].all() or np.count_nonzero(ok) < 4:
            raise ValueError(f"anchors {ids[~ok[ids]].tolist()} were never seen with another "
                             "object: COVIS-3D cannot place them")
        sub = np.flatnonzero(ok)
        D, Ws = delta[np.ix_(sub, sub)], W[np.ix_(sub, sub)]
        D = np.where(Ws > 0, D, D[Ws > 0].max())  # pairs never seen together: the farthest seen
        Ws = np.where(Ws > 0, Ws, 0.05 * Ws[Ws > 0].min())
        Y, _, _ = weighted_smacof(D, Ws, classical_mds(D, 3), max_iter=self.max_iter)
        local = np.searchsorted(sub, ids)
        T = fit_affine_3d(Y[local], pos)
        out = np.full((X.shape[0], 3), np.nan)
        out[sub] = apply_affine_3d(Y, T)
        self.embedding_ = out
        return self
