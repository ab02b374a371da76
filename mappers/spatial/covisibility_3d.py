"""COVIS-3D: a 3-D map from sightings alone (visibility), by co-observation.

Objects seen together often are near one another (the paper's premise): the ``-log`` of the
Ochiai coefficient of two objects' sightings (:func:`mappers.masked.covisibility_dissimilarity`)
is embedded in three dimensions by weighted SMACOF (de Leeuw, 1977) with the anchors held fixed
at their positions (a constrained Guttman update, Borg & Groenen, *Modern Multidimensional
Scaling*, 2005, sec. 8.4; as ``COVIS-ENSEMBLE``'s members do in 2-D), so the map is in the
anchors' frame with no fit afterwards:

- targets: the dissimilarities times one scale, the least-squares fit of the anchors' true
  distances on their dissimilarities (a link through zero); pairs never seen together get the
  largest dissimilarity seen ("far") with a weight of 5 % of the least weight;
- weights: the square root of the number of steps that saw both (as ``covis-nonmetric``);
- start: each object at the mean of the anchors weighted by its Ochiai coefficient with each
  (an anchor at its position), a point set that spans space whenever the anchors do.

Why not the earlier unanchored embedding followed by an affine fit: classical MDS of these
dissimilarities often has a negative third eigenvalue, so the start is planar, and a Guttman
update never leaves the span of its start; the anchors' images then lay on one plane and the
affine fit was refused (2 layouts of 25 in ``benchmarks/bench_camera3d.py``), or the map came
out flattened. Fixed anchors span space by themselves.
"""

from __future__ import annotations

import numpy as np
from sklearn.base import BaseEstimator

from mappers.core.align_3d import check_anchors_3d
from mappers.core.embedding_transformer import EmbeddingTransformer
from mappers.core.validation import check_views
from mappers.masked import covisibility_dissimilarity
from mappers.smacof import weighted_smacof

__all__ = ["CoVisibility3D"]

FAR_WEIGHT = 0.05
"""Weight of a pair never seen together (target: the largest dissimilarity seen), relative to
the least weight of a pair seen together."""


def anchor_mean_start(similarity: np.ndarray, ids: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """(M, 3): each object at the mean of the anchors' positions weighted by its
    ``similarity`` (M, M) with each anchor (all anchors equally when it has none), anchors at
    their positions."""
    S = np.asarray(similarity, dtype=float)[:, ids]
    S = np.where(S.sum(axis=1, keepdims=True) > 0, S, 1.0)
    S[ids] = np.eye(len(ids))
    return S @ pos / S.sum(axis=1, keepdims=True)


def anchor_scale(delta: np.ndarray, ids: np.ndarray, pos: np.ndarray) -> float:
    """Least-squares scale ``s`` of ``s * delta ~ distance`` over the anchors' pairs."""
    iu = np.triu_indices(len(ids), 1)
    dist = np.linalg.norm(pos[:, None] - pos[None], axis=2)[iu]
    dd = delta[np.ix_(ids, ids)][iu]
    if not np.any(dd > 0):
        raise ValueError("the anchors' co-observation dissimilarities are all 0: no scale")
    return float(dist @ dd / (dd @ dd))


class CoVisibility3D(EmbeddingTransformer, BaseEstimator):
    """Visibility histories (M, N) of 0/1 -> (M, 3) world positions (see the module's
    docstring); ``max_iter`` SMACOF updates at most. Objects never seen with another are NaN."""

    def __init__(self, *, max_iter: int = 300):
        self.max_iter = max_iter

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
        C = counts.astype(float).copy()
        np.fill_diagonal(C, 0.0)
        ok = C.sum(axis=1) > 0
        if not ok[ids].all() or np.count_nonzero(ok) < 4:
            raise ValueError(f"anchors {ids[~ok[ids]].tolist()} were never seen with another "
                             "object: COVIS-3D cannot place them")
        sub = np.flatnonzero(ok)
        local = np.searchsorted(sub, ids)
        Cs = C[np.ix_(sub, sub)]
        together = Cs > 0
        D = np.where(together, delta[np.ix_(sub, sub)], delta[np.ix_(sub, sub)][together].max())
        W = np.sqrt(Cs)
        W = np.where(together, W, FAR_WEIGHT * W[together].min())
        np.fill_diagonal(W, 0.0)
        start = anchor_mean_start(np.where(together, np.exp(-D), 0.0), local, pos)
        Y, _, _ = weighted_smacof(anchor_scale(D, local, pos) * D, W, start, fixed=local,
                                  fixed_positions=pos, max_iter=self.max_iter)
        out = np.full((X.shape[0], 3), np.nan)
        out[sub] = Y
        self.embedding_ = out
        return self
