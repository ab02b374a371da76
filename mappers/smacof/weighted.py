"""Weighted SMACOF (de Leeuw 1977; paper eq. 6), which scikit-learn's ``smacof`` lacks.

scikit-learn's :func:`sklearn.manifold.smacof` minimises raw stress with equal weights only.
SMA(WGT) needs weights (w_ij = 1 for kNN pairs, else 0), and the anchored mappers
(:mod:`mappers.calibrated.cal_sma`, :mod:`mappers.masked.pair_maps`) need anchors held fixed, so the Guttman
transform is written here (other links than the identity: :mod:`mappers.smacof.variants`):

    X <- V^+ B(X) X,    V = sum_{i<j} w_ij (e_i - e_j)(e_i - e_j)^T,
    B(X)_ij = -w_ij delta_ij / d_ij(X) (i != j, d_ij > 0),   B_ii = -sum_{j != i} B_ij,

which never increases the raw stress sum_{i<j} w_ij (delta_ij - d_ij(X))^2. With equal weights
V^+ = (I - 11^T/n) / n, so the update is B(X) X / n. With fixed points a and free points f the
majoriser is minimised over X_f alone: V_ff X_f = [B(X) X]_f - V_fa X_a.
"""

from __future__ import annotations

from collections.abc import Callable
from numbers import Integral

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.metrics import pairwise_distances
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.extmath import svd_flip

from mappers.core.estimator_params import store_params
from mappers.core.graph import connected_knn_graph, warn_if_repaired
from mappers.core.iteration_params import ITERATION_CONSTRAINTS
from mappers.core.validation import check_points_or_dissimilarities

__all__ = [
    "GuttmanTransform",
    "WeightedSMACOF",
    "classical_mds",
    "euclidean_distance_matrix",
    "raw_stress",
    "squared_distance_matrix",
    "weighted_smacof",
]


def squared_distance_matrix(X: np.ndarray) -> np.ndarray:
    """(n, n) squared Euclidean distances between the rows of ``X`` (n, p), clipped at 0, no
    checks; the diagonal is left as computed (rounding-small, not set to 0)."""
    sq = np.einsum("ij,ij->i", X, X)
    D2 = np.add.outer(sq, sq)
    D2 -= 2.0 * (X @ X.T)
    return np.maximum(D2, 0.0, out=D2)


def euclidean_distance_matrix(X: np.ndarray) -> np.ndarray:
    """(n, n) Euclidean distances between the rows of ``X`` (n, p), zero diagonal, no checks.

    Plain numpy for use inside loops: sklearn's ``pairwise_distances`` validates its input on
    every call, which dominates a SMACOF iteration at n = 50.
    """
    D2 = squared_distance_matrix(X)
    np.fill_diagonal(D2, 0.0)
    return np.sqrt(D2)


def raw_stress(delta: np.ndarray, weights: np.ndarray, X: np.ndarray) -> float:
    """Raw stress sum_{i<j} w_ij (delta_ij - ||x_i - x_j||)^2 (paper eq. 6)."""
    return float(0.5 * np.sum(weights * (delta - euclidean_distance_matrix(X)) ** 2))


def classical_mds(delta: np.ndarray, n_components: int = 2) -> np.ndarray:
    """Classical (Torgerson) MDS of a distance matrix: LPCA when delta is Euclidean.

    Eigenvectors of the double-centred -delta^2/2, signs fixed with ``svd_flip``.
    """
    n = delta.shape[0]
    J = np.eye(n) - 1.0 / n
    G = -0.5 * J @ (delta**2) @ J
    w, U = np.linalg.eigh(G)
    order = np.argsort(w)[::-1][:n_components]
    U, _ = svd_flip(U[:, order], None)
    return U * np.sqrt(np.clip(w[order], 0, None))


def _check_core_inputs(delta, weights, init, fixed, fixed_positions):
    delta = np.asarray(delta, dtype=float)
    n = delta.shape[0]
    if delta.ndim != 2 or delta.shape != (n, n):
        raise ValueError(f"delta must be a square (n, n) matrix, got shape {delta.shape}")
    if not np.all(np.isfinite(delta)) or np.any(delta < 0):
        raise ValueError("delta must be finite and non-negative")
    weights = np.asarray(weights, dtype=float)
    if weights.shape != (n, n):
        raise ValueError(f"weights must have shape {(n, n)}, got {weights.shape}")
    if not np.all(np.isfinite(weights)) or np.any(weights < 0):
        raise ValueError("weights must be finite and non-negative")
    if not (np.allclose(delta, delta.T) and np.allclose(weights, weights.T)):
        raise ValueError("delta and weights must be symmetric")
    weights = weights.copy()
    np.fill_diagonal(weights, 0.0)
    X = np.array(init, dtype=float)
    if X.ndim != 2 or X.shape[0] != n or not np.all(np.isfinite(X)):
        raise ValueError(f"init must be a finite (n, p) array with n = {n}, got {X.shape}")
    free = np.ones(n, dtype=bool)
    if fixed is not None:
        fixed = np.asarray(fixed)
        if fixed.dtype == bool:
            fixed = np.flatnonzero(fixed)
        if fixed.ndim != 1 or (fixed.size and not np.issubdtype(fixed.dtype, np.integer)):
            raise ValueError("fixed must be a 1-D array of point indices (or a boolean mask)")
        if fixed.size and (fixed.min() < 0 or fixed.max() >= n or len(set(fixed)) < len(fixed)):
            raise ValueError(f"fixed indices must be distinct and in [0, {n - 1}]")
        free[fixed] = False
        if fixed_positions is not None:
            fp = np.asarray(fixed_positions, dtype=float)
            if fp.shape != (len(fixed), X.shape[1]) or not np.all(np.isfinite(fp)):
                raise ValueError(
                    f"fixed_positions must be finite with shape {(len(fixed), X.shape[1])}, "
                    f"got {fp.shape}"
                )
            X[fixed] = fp
    elif fixed_positions is not None:
        raise ValueError("fixed_positions given without fixed")
    return delta, weights, X, free


class GuttmanTransform:
    """The Guttman update for fixed weights and fixed points (module docstring), with the
    (pseudo-)inverse of V, or of V_ff with fixed points, computed once.

    :func:`weighted_smacof` takes its steps with it; the SMACOF variants
    (:mod:`mappers.smacof.variants`), whose targets change at every step while the weights do
    not, keep one instead of inverting V again per step.

    Not shared with the online CAL-SMA rounds' ``mappers.online.cal_sma._AnchoredGuttman``,
    which makes the same update another way: this one takes any non-negative weights, so V (or
    V_ff) may be singular and is pseudo-inverted, and B(X) is built as a matrix; that one relies
    on CAL-SMA's weights being positive for every pair (V_ff positive definite: a plain inverse)
    and fuses B(X) X and the stress into fewer array passes. The results agree to rounding, not
    bit for bit, and the offline maps (the paper's tables) stay on this one.

    Args:
        W: (n, n) symmetric non-negative weights, zero diagonal (checked by the caller).
        free: (n,) bool, the points that move.
        X: (n, p) configuration holding the fixed points' positions.
    """

    def __init__(self, W: np.ndarray, free: np.ndarray, X: np.ndarray) -> None:
        n = len(W)
        self.W, self.free = W, free
        V = np.diag(W.sum(axis=1)) - W
        self.all_free = bool(free.all())
        self.equal = self.all_free and np.allclose(W[~np.eye(n, dtype=bool)],
                                                   W[0, 1] if n > 1 else 0.0)
        if self.all_free and not self.equal:
            self.V_inv = np.linalg.pinv(V, hermitian=True)
        elif not self.all_free:
            # Constrained Guttman update: the majoriser is quadratic in X_f with Hessian V_ff.
            self.V_ff_inv = np.linalg.pinv(V[np.ix_(free, free)], hermitian=True)
            self.rhs_fixed = V[np.ix_(free, ~free)] @ X[~free]

    def __call__(self, wd: np.ndarray, D: np.ndarray, X: np.ndarray) -> np.ndarray:
        """One update of ``X`` given ``wd`` = W * targets and ``D``, X's distance matrix."""
        with np.errstate(divide="ignore", invalid="ignore"):
            B = -np.where(D > 0, wd / D, 0.0)
        np.fill_diagonal(B, 0.0)
        np.fill_diagonal(B, -B.sum(axis=1))
        BX = B @ X
        if self.equal:
            n, w = len(X), self.W[0, 1]
            return BX / (n * w) if w > 0 else X
        if self.all_free:
            return self.V_inv @ BX
        X_new = X.copy()
        X_new[self.free] = self.V_ff_inv @ (BX[self.free] - self.rhs_fixed)
        return X_new


def weighted_smacof(
    delta: np.ndarray,
    weights: np.ndarray,
    init: np.ndarray,
    *,
    fixed: np.ndarray | None = None,
    fixed_positions: np.ndarray | None = None,
    max_iter: int = 300,
    tol: float = 1e-6,
    callback: Callable[[int, np.ndarray, float], None] | None = None,
) -> tuple[np.ndarray, float, int]:
    """Minimise weighted raw stress by Guttman transforms from ``init``.

    Args:
        delta: (n, n) symmetric dissimilarities.
        weights: (n, n) symmetric non-negative weights (diagonal ignored).
        init: (n, p) starting configuration.
        fixed: indices (or boolean mask) of points held fixed; their positions are
            ``fixed_positions`` if given, else their rows of ``init``.
        max_iter, tol: stop after ``max_iter`` updates or when the relative stress decrease
            of one update falls below ``tol``.
        callback: called as ``callback(iteration, X, stress)`` after every update.

    Returns:
        (X, stress, n_iter): the configuration, its raw stress and the number of updates.
    """
    if max_iter < 0:
        raise ValueError(f"max_iter must be >= 0, got {max_iter}")
    delta, W, X, free = _check_core_inputs(delta, weights, init, fixed, fixed_positions)
    guttman = GuttmanTransform(W, free, X)
    wd = W * delta
    D = euclidean_distance_matrix(X)
    stress = float(0.5 * np.sum(W * (delta - D) ** 2))
    n_iter = 0
    for n_iter in range(1, max_iter + 1):  # noqa: B007 - n_iter is returned
        X_new = guttman(wd, D, X)
        D = euclidean_distance_matrix(X_new)
        X, old = X_new, stress
        stress = float(0.5 * np.sum(W * (delta - D) ** 2))
        if callback is not None:
            callback(n_iter, X, stress)
        if old <= 0 or (old - stress) <= tol * old:
            break
    return X, stress, n_iter


class WeightedSMACOF(TransformerMixin, BaseEstimator):
    """Metric MDS by SMACOF with equal (``n_neighbors=None``) or symmetric-kNN weights.

    SMA(UNWGT) is ``WeightedSMACOF()`` and SMA(WGT) is ``WeightedSMACOF(n_neighbors=K)``.

    Parameters:
        n_neighbors: None for equal weights; K for w_ij = 1 when i is among j's K nearest
            neighbours or j among i's (the graph is made connected by joining components at
            their closest pairs, with a :class:`mappers.core.graph.GraphRepairWarning`).
        init: starting configuration. ``"lpca"`` = classical MDS / linear PCA (the paper's
            start). ``"unweighted"`` (default) = the equal-weight SMACOF solution started from
            LPCA: on visibility histories the LPCA start is badly bent and kNN-weighted SMACOF
            started there stays folded, while the unweighted solution (globally rigid) does not
            fold; a folded map can even have the lower kNN stress, so stress alone cannot pick
            the start (``benchmarks/bench_mappers.py --sections smacof`` measures both; figures
            in the README). An (n, n_components) array is used as given.
        n_init: number of starts; the first is ``init``, the others random (Gaussian, scaled
            like the data). The result with the lowest weighted stress is kept.
        max_iter, tol: per start, see :func:`weighted_smacof`.
        dissimilarity: ``"euclidean"`` (rows of X are points) or ``"precomputed"`` (X is a
            symmetric distance matrix).
        n_components: dimension of the embedding.
        random_state: seed for the random starts.

    Attributes:
        embedding_ (n, n_components), stress_ (weighted raw stress), n_iter_ (updates of the
        kept start), weights_ (n, n), added_edges_ (edges added to connect the kNN graph).
    """

    _parameter_constraints: dict = {
        "n_neighbors": [Interval(Integral, 1, None, closed="left"), None],
        "init": [StrOptions({"lpca", "unweighted"}), "array-like"],
        "n_init": [Interval(Integral, 1, None, closed="left")],
        **ITERATION_CONSTRAINTS,
        "dissimilarity": [StrOptions({"euclidean", "precomputed"})],
        "n_components": [Interval(Integral, 1, None, closed="left")],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        *,
        n_neighbors: int | None = None,
        init: str | np.ndarray = "unweighted",
        n_init: int = 1,
        max_iter: int = 300,
        tol: float = 1e-6,
        dissimilarity: str = "euclidean",
        n_components: int = 2,
        random_state=None,
    ) -> None:
        store_params(self, locals())

    def _weights(self, delta: np.ndarray) -> np.ndarray:
        n = len(delta)
        if self.n_neighbors is None:
            return 1.0 - np.eye(n)
        k = min(self.n_neighbors, n - 1)
        A, _, added = connected_knn_graph(delta, k, precomputed=True)
        self.added_edges_ = added
        warn_if_repaired(added, k, stacklevel=3)
        return A.toarray()

    def fit(self, X, y=None):
        """Compute the embedding of ``X`` (points or, if precomputed, distances)."""
        X = check_points_or_dissimilarities(self, X)
        # n_jobs=1: under a parallel joblib backend (a Dask worker) sklearn would split the
        # rows into chunks, whose BLAS rounding differs: the same map must come out anywhere.
        delta = X if self.dissimilarity == "precomputed" else pairwise_distances(X, n_jobs=1)
        n = len(delta)
        self.added_edges_ = []
        W = self._weights(delta)
        self.weights_ = W
        rng = check_random_state(self.random_state)
        starts = [self._first_start(delta, W)]
        scale = np.sqrt(np.mean(delta**2) / 2) if n > 1 else 1.0
        for _ in range(self.n_init - 1):
            starts.append(
                rng.normal(scale=scale / np.sqrt(self.n_components), size=(n, self.n_components))
            )
        best = None
        for start in starts:
            Y, stress, n_iter = weighted_smacof(
                delta, W, start, max_iter=self.max_iter, tol=self.tol
            )
            if best is None or stress < best[1]:
                best = (Y, stress, n_iter)
        self.embedding_, self.stress_, self.n_iter_ = best
        return self

    def _first_start(self, delta: np.ndarray, W: np.ndarray) -> np.ndarray:
        n = len(delta)
        if isinstance(self.init, str):
            start = classical_mds(delta, self.n_components)
            if self.init == "unweighted" and self.n_neighbors is not None:
                start, _, _ = weighted_smacof(
                    delta, 1.0 - np.eye(n), start, max_iter=self.max_iter, tol=self.tol
                )
            return start
        start = np.asarray(self.init, dtype=float)
        if start.shape != (n, self.n_components):
            raise ValueError(
                f"init array must have shape {(n, self.n_components)}, got {start.shape}"
            )
        return start

    def fit_transform(self, X, y=None) -> np.ndarray:
        """Fit and return the (n, n_components) embedding."""
        return self.fit(X).embedding_
