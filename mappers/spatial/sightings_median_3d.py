"""COVIS-3D-MEDIAN: a 3-D map from ordered sightings alone, the geometric median of four maps.

Each of four maps of the same sightings is biased its own way, so each object is put at the
geometric median of its positions in them (as ``COVIS-ENSEMBLE(combine="median")`` does in 2-D,
:func:`mappers.masked.geometric_median`). Each map is a weighted SMACOF (de Leeuw 1977) with the
anchors held at their positions (Borg & Groenen, *Modern Multidimensional Scaling*, 2005,
sec. 8.4), of targets that are a dissimilarity times one scale fitted on the anchors' pairs
(:func:`mappers.spatial.covisibility_3d.anchor_scale`), started as COVIS-3D is:

1. and 2. **second order over windows** of 10 and of 20 steps: the sightings merged over sliding
   windows of consecutive steps (an object seen in any of them; a hand-held camera's
   consecutive frames overlap), then the cosine dissimilarity of two objects' rows of Ochiai
   coefficients (objects seen with the same others are near one another, even when never seen
   together: every pair gets a target). Weights ``1 / max(target, MIN_TARGET)**2`` (near pairs
   count most, as in Sammon's mapping).
3. **geodesic**: shortest paths on the graph of the pairs seen together, an edge's length the
   square root of its ``-log`` Ochiai coefficient (a landmark Isomap: Tenenbaum, de Silva &
   Langford, Science 290, 2000). Weights: the square root of the steps that saw both for pairs
   seen together, the least of those for the others.
4. **frame gap**: from each sighting of one object, the number of steps to the nearest sighting
   of the other; the mean of ``log(1 + gap)`` over the first object's sightings, the smaller of
   the two directions (objects seen soon after one another are near). Sammon weights as 1.

The steps must be in the order they were taken (windows and gaps read neighbouring columns).
The four were chosen among 119 medians of one to five of seven maps (with COVIS-3D, a harmonic
map and windows of 3) on three STAR-loc sequences (``python
benchmarks/bench_starloc_sightings.py --subsets``).

Better than COVIS-3D on STAR-loc's setup s3, not on every other sequence nor in
``LFMDR-Camera3D-v0`` (figures: the 3-D guide and docs/dead-ends.md, ``python
benchmarks/bench_starloc.py --sensors visibility --visibility-method COVIS-3D-MEDIAN``), so it
is opt-in (``method="COVIS-3D-MEDIAN"``), not the default.
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

__all__ = ["SightingsMedian3D", "frame_gap_embedding", "frame_gaps", "geodesic_embedding",
           "second_order_dissimilarity", "second_order_embedding", "window_sightings"]

MIN_TARGET = 0.3
"""Metres: the Sammon weights are ``1 / max(target, MIN_TARGET)**2``, so that a pair with a
target near 0 does not take all the weight."""


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


def second_order_dissimilarity(seen: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """``(D, och)``: the second-order dissimilarity (M, M) of the ordered sightings ``seen``
    (M, N) merged over sliding windows of ``window`` steps — one minus the cosine of two objects'
    rows of Ochiai coefficients — and those coefficients (1 on the diagonal)."""
    delta, counts = covisibility_dissimilarity(window_sightings(seen, window))
    och = np.exp(-delta) * (counts > 0)
    np.fill_diagonal(och, 1.0)
    rows = och / np.linalg.norm(och, axis=1, keepdims=True)
    D = np.clip(1.0 - rows @ rows.T, 0.0, None)
    np.fill_diagonal(D, 0.0)
    return D, och


def second_order_embedding(seen: np.ndarray, ids: np.ndarray, pos: np.ndarray, window: int,
                           max_iter: int) -> np.ndarray:
    """(M, 3): a second-order member of the module's docstring on the ordered sightings
    ``seen`` (M, N)."""
    D, och = second_order_dissimilarity(seen, window)
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


def frame_gaps(seen: np.ndarray) -> np.ndarray:
    """(M, M): for objects i, j of the ordered sightings ``seen`` (M, N; each object seen at
    least once), the mean over the steps that saw i of ``log(1 + steps to the nearest step that
    saw j)``, then the smaller of (i, j) and (j, i); 0 on the diagonal."""
    seen = np.asarray(seen, dtype=bool)
    if not seen.any(axis=1).all():
        raise ValueError("frame_gaps needs every object seen at least once")
    n = seen.shape[1]
    steps = np.arange(n, dtype=float)
    # the step of the last sighting at or before each step, and of the next at or after it
    before = np.maximum.accumulate(np.where(seen, steps, -np.inf), axis=1)
    after = np.minimum.accumulate(np.where(seen, steps, np.inf)[:, ::-1], axis=1)[:, ::-1]
    gap = np.minimum(steps - before, after - steps)  # (M, N): steps to j's nearest sighting
    G = (seen @ np.log1p(gap).T) / seen.sum(axis=1, keepdims=True)
    G = np.minimum(G, G.T)
    np.fill_diagonal(G, 0.0)
    return G


def frame_gap_embedding(seen: np.ndarray, start: np.ndarray, ids: np.ndarray, pos: np.ndarray,
                        max_iter: int) -> np.ndarray:
    """(M, 3): member 4 of the module's docstring on the ordered sightings ``seen`` (M, N),
    from ``start`` (M, 3)."""
    G = frame_gaps(seen)
    T = anchor_scale(G, ids, pos) * G
    W = 1.0 / np.maximum(T, MIN_TARGET) ** 2
    np.fill_diagonal(W, 0.0)
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
    median of four anchored embeddings (see the module's docstring).

    Args:
        windows: the steps merged by each second-order member (10 and 20: see the module's
            docstring; a window longer than the history is cut to its length).
        max_iter: SMACOF updates at most, per member.

    ``members_`` (K, M, 3) holds the members' maps in the order second-order (one per window),
    geodesic, frame gap. Objects that no chain of sightings within the shortest window links to
    an anchor are NaN; the geodesic member places only those linked by pairs seen in one step
    (and none when fewer than two anchors are), the others take the median of the rest.
    """

    def __init__(self, *, windows: tuple[int, ...] = (10, 20), max_iter: int = 300):
        self.windows = windows
        self.max_iter = max_iter

    def fit(self, X, y=None, *, anchor_ids=None, anchor_positions=None, mask=None):
        """Map the ordered visibility history ``X`` (M, N) (``mask`` True where observed)."""
        X = check_views(self, X, mask)
        if anchor_ids is None or anchor_positions is None:
            raise ValueError("COVIS-3D-MEDIAN needs anchors: anchor_ids and anchor_positions "
                             "(A, 3)")
        if not np.all((X == 0) | (X == 1) | (mask is not None and ~np.asarray(mask, bool))):
            raise ValueError("COVIS-3D-MEDIAN maps visibility histories: an (M, N) array of 0/1")
        windows = [int(w) for w in np.atleast_1d(self.windows)]
        if not windows or min(windows) < 1:
            raise ValueError(f"windows must be one or more step counts >= 1, got {self.windows!r}")
        seen = X > 0 if mask is None else (X > 0) & np.asarray(mask, dtype=bool)
        ids, pos = check_anchors_3d(anchor_ids, anchor_positions, X.shape[0], fit="affine")
        windows = [min(w, seen.shape[1]) for w in windows]
        delta, counts = covisibility_dissimilarity(seen)
        near = _linked_to_anchors(counts, ids)  # by pairs seen in one step
        wide = _linked_to_anchors(  # by pairs seen within the shortest window of steps
            covisibility_dissimilarity(window_sightings(seen, min(windows)))[1], ids)
        if not wide[ids].all():
            raise ValueError(f"anchors {ids[~wide[ids]].tolist()} were never seen with another "
                             "object: COVIS-3D-MEDIAN cannot place them")
        members = np.full((len(windows) + 2, X.shape[0], 3), np.nan)
        sub = np.flatnonzero(wide)
        local = np.searchsorted(sub, ids)
        for k, w in enumerate(windows):
            members[k, sub] = second_order_embedding(seen[sub], local, pos, w, self.max_iter)
        if np.count_nonzero(near[ids]) >= 2:  # the anchors linked this way give the scale
            near_sub = np.flatnonzero(near)
            members[-2, near_sub] = geodesic_embedding(
                delta[np.ix_(near_sub, near_sub)], counts[np.ix_(near_sub, near_sub)],
                np.searchsorted(near_sub, ids[near[ids]]), pos[near[ids]], self.max_iter)
        och = np.where(counts > 0, np.exp(-delta), 0.0)[np.ix_(sub, sub)]
        members[-1, sub] = frame_gap_embedding(seen[sub], anchor_mean_start(och, local, pos),
                                               local, pos, self.max_iter)
        out = np.full((X.shape[0], 3), np.nan)
        placed = np.isfinite(members[:, :, 0])
        # each object at the median of the members that placed it
        for which in np.unique(placed[:, wide], axis=1).T:
            rows = np.flatnonzero(wide & np.all(placed == which[:, None], axis=0))
            out[rows] = geometric_median(members[which][:, rows])
        out[ids] = pos
        self.members_ = members
        self.embedding_ = out
        return self
