"""CAL-SMA on a sparse graph of pairs (label ``"CAL-SMA"`` with ``sparse=True``): maps of thousands
of objects.

The same model as :mod:`mappers.calibrated.cal_sma` (CAL-SMA): a log-polynomial calibration of the
history dissimilarity into metres, fitted on neighbour pairs from the current map, alternated
with anchored weighted SMACOF. What changes is what is stored and solved (see
:mod:`mappers.smacof.sparse_stress`): dissimilarities only for pairs that share observations (or
nearest rows for dense sensors), distance targets for the symmetric kNN pairs, and the weak
"farther than the neighbourhood radius" bound only for the non-neighbour pairs that lie close
in the current map (found with a KD-tree) rather than for all M^2 pairs. The start is Landmark
MDS of the neighbour graph's geodesics, affinely placed on the anchors. Memory and time grow
about linearly with M; the measured figures are in ``benchmarks/bench_scale.py`` and the README.

Differences from CAL-SMA, and why: one deterministic start and no fold score (both need all
pairs); the repulsion covers only pairs near in the map, so the global layout rests on the
anchors: use many anchors spread over the arena (``anchors="grid"`` or ``"random"``), as any
large survey would.
"""

from __future__ import annotations

from numbers import Integral

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import validate_data

from mappers.calibrated.cal_sma import CALIBRATION_CONSTRAINTS, fit_calibration
from mappers.core.align import apply_affine, check_anchors, fit_affine
from mappers.core.estimator_params import store_params
from mappers.smacof import candidate_pairs, knn_pairs, landmark_mds, sparse_smacof

__all__ = ["SparseCalibratedSMACOF"]


def _is_binary_rows(X) -> bool:
    """Whether every stored value of each row equals the row's maximum (scaled 0/1 rows)."""
    Xs = sp.csr_array(X)
    if Xs.nnz == 0 or Xs.data.min() < 0:
        return False
    row_max = np.repeat(np.asarray(Xs.max(axis=1).todense()).ravel(), np.diff(Xs.indptr))
    nz = Xs.data != 0
    return bool(np.allclose(Xs.data[nz], row_max[nz], rtol=1e-9))


class SparseCalibratedSMACOF(TransformerMixin, BaseEstimator):
    """Calibrated anchored SMACOF over sparse pairs (CAL-SMA for large M).

    Parameters:
        n_neighbors: neighbour pairs per object with calibrated distance targets (None = 12 for
            cosine, 10 for euclidean, as CAL-SMA).
        dissimilarity: ``"auto"``, ``"cosine"`` or ``"euclidean"`` (as CAL-SMA).
        n_rounds: calibrate/re-embed rounds. max_iter, tol: Guttman updates per round.
        position_degree, dissimilarity_degree, far_weight, far_factor: as CAL-SMA.
        n_far: map neighbours per object checked against the lower bound each round.
        n_landmarks: landmarks of the Landmark-MDS start.
        random_state: seed of the first landmark.

    Attributes: embedding_ (M, 2); pairs_ (P, 2) the candidate pairs; dissimilarity_ (P,);
    neighbors_ (P,) bool; calibration_; stress_ (normalised stress of the neighbour targets);
    n_iter_; anchored_.
    """

    _parameter_constraints: dict = {
        **CALIBRATION_CONSTRAINTS,
        "dissimilarity": [StrOptions({"auto", "cosine", "euclidean"})],
        "n_far": [Interval(Integral, 0, None, closed="left")],
        "n_landmarks": [Interval(Integral, 3, None, closed="left")],
    }

    def __init__(self, *, n_neighbors=None, dissimilarity="auto", n_rounds=10, position_degree=2,
                 dissimilarity_degree=2, far_weight=0.02, far_factor=0.7, n_far=8,
                 n_landmarks=40, max_iter=50, tol=1e-5, random_state=None) -> None:
        store_params(self, locals())

    def _calibrate(self, ld, X, i, j):
        """Fit log map distance on log delta and midpoint (neighbour pairs); the targets."""
        fit = fit_calibration(ld, X, i, j, self.dissimilarity_degree, self.position_degree)
        expo = np.clip(fit.F @ fit.coef, fit.target.min() - 1.0, fit.target.max() + 1.0)
        return np.exp(expo), fit.coef

    def _far_pairs(self, X, i, j, radius):
        """Pairs near in the map (``n_far`` nearest) that are not neighbour pairs, with bounds."""
        m = X.shape[0]
        if self.n_far == 0 or self.far_weight == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
        _, idx = cKDTree(X).query(X, k=min(self.n_far + 1, m))
        a = np.repeat(np.arange(m), idx.shape[1])
        b = idx.ravel()
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        key = np.setdiff1d(np.unique(lo[lo < hi] * m + hi[lo < hi]), i * m + j)
        fi, fj = key // m, key % m
        bound = self.far_factor * np.maximum(radius[fi], radius[fj])
        dx = np.hypot(*(X[fi] - X[fj]).T)
        return fi, fj, np.maximum(dx, bound)

    def _start(self, i, j, delta, m, ids, pos, rng):
        graph = sp.csr_array((np.concatenate([delta, delta]) + 1e-12,
                              (np.concatenate([i, j]), np.concatenate([j, i]))), shape=(m, m))
        S = landmark_mds(graph, self.n_landmarks, rng)
        if ids is not None:
            try:
                S = apply_affine(S, fit_affine(S[ids], pos))
            except ValueError:
                pass
            S[ids] = pos
        return S

    def fit(self, X, y=None, *, anchor_ids=None, anchor_positions=None):
        """Map the history rows ``X`` (M, D), dense or scipy sparse; anchors as CAL-SMA."""
        self._validate_params()
        X = validate_data(self, X, accept_sparse="csr", dtype=np.float64, ensure_min_samples=3)
        m = X.shape[0]
        ids = pos = None
        if anchor_ids is not None or anchor_positions is not None:
            ids, pos = check_anchors(anchor_ids, anchor_positions, m)
        kind = self.dissimilarity
        if kind == "auto":
            kind = "cosine" if _is_binary_rows(X) else "euclidean"
        k = self.n_neighbors if self.n_neighbors is not None else (12 if kind == "cosine" else 10)
        k = min(k, m - 1)
        i, j, delta = candidate_pairs(X, kind, 3 * k)
        informative = delta < 1.0 - 1e-9 if kind == "cosine" else np.ones(delta.size, bool)
        self.dissimilarity_kind_ = kind
        return self._fit_pairs(i[informative], j[informative], delta[informative], m, k, ids, pos)

    def fit_pairs(self, i, j, delta, n_objects, *, anchor_ids=None, anchor_positions=None):
        """Map ``n_objects`` objects from dissimilarities ``delta`` of the pairs ``(i, j)``
        (i < j, each pair once; the other pairs are unknown): the same calibration and sparse
        stress as :meth:`fit`, for a dissimilarity computed elsewhere (``mappers.masked.covis_sparse``)."""
        self._validate_params()
        i, j = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
        delta = np.asarray(delta, dtype=np.float64)
        if not (i.shape == j.shape == delta.shape) or i.ndim != 1:
            raise ValueError("i, j and delta must be 1-D arrays of one length")
        if i.size and (np.any(i >= j) or i.min() < 0 or j.max() >= n_objects):
            raise ValueError(f"pairs must have 0 <= i < j < n_objects={n_objects}")
        if np.any(~np.isfinite(delta)) or np.any(delta < 0):
            raise ValueError("delta must be finite and non-negative")
        ids = pos = None
        if anchor_ids is not None or anchor_positions is not None:
            ids, pos = check_anchors(anchor_ids, anchor_positions, n_objects)
        k = min(self.n_neighbors if self.n_neighbors is not None else 12, n_objects - 1)
        self.dissimilarity_kind_ = "precomputed"
        return self._fit_pairs(i, j, delta, n_objects, k, ids, pos)

    def _fit_pairs(self, i, j, delta, m, k, ids, pos):
        if i.size == 0:
            raise ValueError("no two objects have informative histories (never sensed together)")
        loc = knn_pairs(i, j, delta, m, k)
        li, lj, ld = i[loc], j[loc], delta[loc]
        lo = max(float(ld[ld > 0].min()) if (ld > 0).any() else 1e-12, 1e-12)
        logd = np.log(np.maximum(ld, lo))
        Y = self._start(li, lj, ld, m, ids, pos, check_random_state(self.random_state))
        n_iter = 0
        for _ in range(self.n_rounds):
            Dh, coef = self._calibrate(logd, Y, li, lj)
            radius = np.zeros(m)
            np.maximum.at(radius, li, Dh)
            np.maximum.at(radius, lj, Dh)
            fi, fj, ft = self._far_pairs(Y, li, lj, radius)
            Y, _, it = sparse_smacof(
                np.concatenate([li, fi]), np.concatenate([lj, fj]), np.concatenate([Dh, ft]),
                np.concatenate([np.ones(li.size), np.full(fi.size, self.far_weight)]),
                Y, fixed=ids, max_iter=self.max_iter, tol=self.tol)
            n_iter += it
        dx = np.hypot(*(Y[li] - Y[lj]).T)
        self.embedding_ = Y
        self.pairs_ = np.column_stack([i, j])
        self.dissimilarity_ = delta
        self.neighbors_ = loc
        self.calibration_ = coef
        self.stress_ = float(np.sum((dx - Dh) ** 2) / max(np.sum(Dh**2), 1e-300))
        self.n_iter_ = n_iter
        self.anchored_ = ids is not None
        return self

    def fit_transform(self, X, y=None, *, anchor_ids=None, anchor_positions=None) -> np.ndarray:
        """Fit and return the (M, 2) embedding (world coordinates when anchors are given)."""
        return self.fit(X, anchor_ids=anchor_ids, anchor_positions=anchor_positions).embedding_

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.sparse = True
        return tags

