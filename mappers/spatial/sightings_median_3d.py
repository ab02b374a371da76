"""COVIS-3D-MEDIAN: a 3-D map from sightings alone, the geometric median of three embeddings.

Each of three maps of the same co-observation is biased its own way, so each object is put at the
geometric median of its three positions (as ``COVIS-ENSEMBLE(combine="median")`` does in 2-D,
:func:`mappers.masked.ensemble.geometric_median`). All three hold the anchors at their positions:

1. **harmonic**: each object at the mean of the objects seen with it, weighted by their Ochiai
   co-observation coefficient; with the anchors held this is one linear system, the harmonic
   function of the co-observation graph (Zhu, Ghahramani & Lafferty, "Semi-supervised learning
   using Gaussian fields and harmonic functions", ICML 2003). It cannot leave the anchors' hull.
2. **second order over windows**: the sightings merged over ``window`` consecutive steps (an
   object seen in any of them; a hand-held camera's consecutive frames overlap), then the cosine
   dissimilarity of two objects' rows of Ochiai coefficients (objects seen with the same others
   are near one another, even if never seen together: it gives every pair a target). Targets:
   that dissimilarity times one scale fitted on the anchors' pairs; weights ``1 / max(target,
   MIN_TARGET)**2`` (near pairs count most, as in Sammon's mapping); weighted SMACOF (de Leeuw
   1977) with the anchors held (Borg & Groenen 2005, sec. 8.4).
3. **geodesic**: shortest paths on the graph of the pairs seen together, an edge's length the
   square root of its ``-log`` Ochiai coefficient (a landmark Isomap, Tenenbaum, de Silva &
   Langford, Science 2000), times one scale fitted on the anchors' pairs; weights the square
   root of the steps that saw both for pairs seen together, the least of those for the others;
   weighted SMACOF with the anchors held.

The steps must be in the order they were taken (the windows merge neighbouring columns).

Measured on STAR-loc (``python benchmarks/bench_starloc.py --visibility-method
COVIS-3D-MEDIAN``; docs/dead-ends.md): 1.7-2.2 m on setup s3 against COVIS-3D's 2.2-2.9 m,
not under the 1.0 m goal, and worse than COVIS-3D on 5 of 13 sequences; so it is opt-in
(``method="COVIS-3D-MEDIAN"``), not the default.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import connected_components, shortest_path
from sklearn.base import BaseEstimator

from mappers.core.align_3d import check_anchors_3d
from mappers.core.embedding_transformer import EmbeddingTransformer
from mappers.core.validation import check_views
from mappers.masked import covisibility_dissimilarity, geometric_median
from mappers.smacof import weighted_smacof
from mappers.spatial.covisibility_3d import anchor_mean_start, anchor_scale

__all__ = ["SightingsMedian3D", "geodesic_embedding", "harmonic_embedding",
           "second_order_embedding", "window_sightings"]

MIN_TARGET = 0.3
"""Metres: the second-order member's weights are ``1 / max(target, MIN_TARGET)**2``, so that a
pair with a target near 0 does not take all the weight."""


def window_sightings(seen: np.ndarray, window: int) -> np.ndarray:
    """(M, N - window + 1) bool: object i seen in any of the steps ``j .. j + window - 1``
    (column j) of the ordered sightings ``seen`` (M, N); ``window`` 1 gives ``seen`` back.
    Sliding windows, one per step: :func:`mappers.masked.window_steps` tiles the steps into
    disjoint windows instead, so two sightings a step apart across a tile's edge never meet."""
    seen = np.asarray(seen, dtype=bool)
    if window < 1:
        raise ValueError(f"window must be >= 1 step, got {window}")
    if window > seen.shape[1]:
        raise ValueError(f"window of {window} steps is longer than the {seen.shape[1]} steps")
    csum = np.concatenate([np.zeros((seen.shape[0], 1)), np.cumsum(seen, axis=1)], axis=1)
    j = np.arange(seen.shape[1] - window + 1)
    return (csum[:, j + window] - csum[:, j]) > 0


def harmonic_embedding(similarity: np.ndarray, ids: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """(M, d): the anchors ``ids`` at ``pos`` (A, d), every other object at the
    ``similarity``-weighted (M, M, symmetric, >= 0) mean of the others: the harmonic solution
    ``L_ff X_f = -L_fa pos`` of the graph Laplacian. Every object must be linked to an anchor
    by a chain of positive similarities (ValueError otherwise: the system is singular)."""
    S = np.asarray(similarity, dtype=float).copy()
    np.fill_diagonal(S, 0.0)
    L = np.diag(S.sum(axis=1)) - S
    free = np.setdiff1d(np.arange(S.shape[0]), ids)
    out = np.empty((S.shape[0], pos.shape[1]))
    out[ids] = pos
    try:
        out[free] = np.linalg.solve(L[np.ix_(free, free)], -L[np.ix_(free, ids)] @ pos)
    except np.linalg.LinAlgError as exc:
        raise ValueError("some objects are not linked to an anchor by sightings: no harmonic "
                         "map") from exc
    return out


def second_order_embedding(seen: np.ndarray, ids: np.ndarray, pos: np.ndarray, window: int,
                           max_iter: int) -> np.ndarray:
    """(M, 3): member 2 of the module's docstring on the ordered sightings ``seen`` (M, N)."""
    delta, counts = covisibility_dissimilarity(window_sightings(seen, window))
    och = np.exp(-delta) * (counts > 0)
    np.fill_diagonal(och, 1.0)
    rows = och / np.linalg.norm(och, axis=1, keepdims=True)
    D = np.clip(1.0 - rows @ rows.T, 0.0, None)
    np.fill_diagonal(D, 0.0)
    T = anchor_scale(D, ids, pos) * D
    W = 1.0 / np.maximum(T, MIN_TARGET) ** 2
    np.fill_diagonal(W, 0.0)
    Y, _, _ = weighted_smacof(T, W, anchor_mean_start(och, ids, pos), fixed=ids,
                              fixed_positions=pos, max_iter=max_iter)
    return Y


def geodesic_embedding(delta: np.ndarray, counts: np.ndarray, ids: np.ndarray, pos: np.ndarray,
                       max_iter: int) -> np.ndarray:
    """(M, 3): member 3 of the module's docstring, from the ``-log`` Ochiai ``delta`` and the
    co-observation ``counts`` (M, M; every object seen with another). Pairs that no chain of
    sightings links (two groups, each with anchors) get no weight."""
    together = counts > 0
    np.fill_diagonal(together, False)
    # 1e-9: a pair seen in every step of both has delta 0, which csgraph would read as no edge
    G = shortest_path(np.where(together, np.sqrt(delta) + 1e-9, 0.0), directed=False)
    linked = np.isfinite(G)
    G = np.where(linked, G, 0.0)
    T = anchor_scale(G, ids, pos) * G
    W = np.sqrt(np.where(together, counts, 0.0).astype(float))
    W = np.where(together, W, np.where(linked, W[together].min(), 0.0))
    np.fill_diagonal(W, 0.0)
    start = anchor_mean_start(np.where(together, np.exp(-delta), 0.0), ids, pos)
    Y, _, _ = weighted_smacof(T, W, start, fixed=ids, fixed_positions=pos, max_iter=max_iter)
    return Y


def _linked_to_anchors(counts: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """(M,) bool: the objects that a chain of pairs with positive ``counts`` (M, M) links to one
    of the anchors ``ids`` (an anchor counts when it is seen with another object)."""
    C = np.asarray(counts) > 0
    np.fill_diagonal(C, False)
    _, label = connected_components(C, directed=False)
    linked = C.any(axis=1)
    return np.isin(label, label[ids[linked[ids]]]) & linked


class SightingsMedian3D(EmbeddingTransformer, BaseEstimator):
    """Ordered visibility histories (M, N) of 0/1 -> (M, 3) world positions, the geometric
    median of three anchored embeddings (see the module's docstring).

    Args:
        window: steps merged by the second-order member (10: chosen on STAR-loc's eight_s3,
            grid_s3 and loop-2d-fast_s3 among 1, 3, 10 and 20).
        max_iter: SMACOF updates at most, per member.

    Objects never seen with another, or not linked to the anchors by sightings, are NaN.
    """

    def __init__(self, *, window: int = 10, max_iter: int = 300):
        self.window = window
        self.max_iter = max_iter

    def fit(self, X, y=None, *, anchor_ids=None, anchor_positions=None, mask=None):
        """Map the ordered visibility history ``X`` (M, N) (``mask`` True where observed)."""
        X = check_views(self, X, mask)
        if anchor_ids is None or anchor_positions is None:
            raise ValueError("COVIS-3D-MEDIAN needs anchors: anchor_ids and anchor_positions "
                             "(A, 3)")
        if not np.all((X == 0) | (X == 1) | (mask is not None and ~np.asarray(mask, bool))):
            raise ValueError("COVIS-3D-MEDIAN maps visibility histories: an (M, N) array of 0/1")
        seen = X > 0 if mask is None else (X > 0) & np.asarray(mask, dtype=bool)
        ids, pos = check_anchors_3d(anchor_ids, anchor_positions, X.shape[0], fit="affine")
        window = min(self.window, seen.shape[1])
        delta, counts = covisibility_dissimilarity(seen)
        near = _linked_to_anchors(counts, ids)  # by pairs seen in one step
        wide = _linked_to_anchors(covisibility_dissimilarity(window_sightings(seen, window))[1],
                                  ids)  # by pairs seen within a window of steps
        if not wide[ids].all():
            raise ValueError(f"anchors {ids[~wide[ids]].tolist()} were never seen with another "
                             "object: COVIS-3D-MEDIAN cannot place them")
        members = np.full((3, X.shape[0], 3), np.nan)
        if np.count_nonzero(near[ids]) >= 2:  # the anchors linked this way give the scale
            sub = np.flatnonzero(near)
            local = np.searchsorted(sub, ids[near[ids]])
            d_sub, c_sub = delta[np.ix_(sub, sub)], counts[np.ix_(sub, sub)]
            members[0, sub] = harmonic_embedding(np.where(c_sub > 0, np.exp(-d_sub), 0.0),
                                                 local, pos[near[ids]])
            members[2, sub] = geodesic_embedding(d_sub, c_sub, local, pos[near[ids]],
                                                 self.max_iter)
        sub = np.flatnonzero(wide)
        members[1, sub] = second_order_embedding(seen[sub], np.searchsorted(sub, ids), pos,
                                                 window, self.max_iter)
        out = np.full((X.shape[0], 3), np.nan)
        placed = np.isfinite(members[:, :, 0])
        # each object at the median of the members that placed it (all three, or the
        # second-order member alone where only windows of steps link it to the anchors)
        for which in np.unique(placed[:, wide], axis=1).T:
            rows = np.flatnonzero(wide & np.all(placed == which[:, None], axis=0))
            out[rows] = geometric_median(members[which][:, rows])
        out[ids] = pos
        self.members_ = members
        self.embedding_ = out
        return self
