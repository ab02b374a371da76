"""Semidefinite embedding / maximum variance unfolding (Weinberger et al. 2005), with cvxpy.

    maximise trace(K)  s.t.  K PSD,  sum(K) = 0,
                             K_ii + K_jj - 2 K_ij = ||x_i - x_j||^2  for every edge of the
                             symmetric kNN graph (made connected),

and the embedding is the top eigenvectors of K scaled by the square roots of their eigenvalues.
scikit-learn has no MVU, so it is written here.

Formulation and solver: the distance constraints are one sparse linear map on vec(K), built
from index arrays (no per-edge Python loop). The time goes into the solver's dense PSD cone, not
into compiling. The default is the first-order solver SCS at a moderate tolerance (distances
rescaled so the mean squared edge length is 1, ``scale=1``), which lands on the interior-point
solution (CLARABEL) within millimetres after the anchor fit, several times faster
(``benchmarks/bench_mappers.py --sections sde``; figures in the README). The fast MVU of
Weinberger et al. (2007) (``n_basis=m``: K = Q L Q^T with Q the m bottom non-constant
eigenvectors of the graph Laplacian, constraints as a quadratic penalty) is offered for large M;
it is less accurate, so it is not the default.
"""

from __future__ import annotations

from numbers import Integral, Real

import cvxpy as cp
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import laplacian
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.extmath import svd_flip

from mappers.core.estimator_params import store_params
from mappers.core.graph import connected_knn_graph, warn_if_repaired
from mappers.core.validation import check_points_or_dissimilarities

__all__ = ["MaximumVarianceUnfolding", "mvu_constraint_matrix"]


def mvu_constraint_matrix(ei: np.ndarray, ej: np.ndarray, n: int) -> sp.csr_matrix:
    """Sparse (edges, n*n) map taking vec(K) (row-major) to K_ii + K_jj - K_ij - K_ji."""
    m = len(ei)
    rows = np.tile(np.arange(m), 4)
    cols = np.concatenate([ei * n + ei, ej * n + ej, ei * n + ej, ej * n + ei])
    vals = np.repeat([1.0, 1.0, -1.0, -1.0], m)
    return sp.csr_matrix((vals, (rows, cols)), shape=(m, n * n))


class MaximumVarianceUnfolding(TransformerMixin, BaseEstimator):
    """SDE / MVU embedding: unfold the kNN graph as far as its edge lengths allow.

    Parameters:
        n_neighbors: K of the symmetric kNN graph (joined at closest pairs if disconnected,
            with a :class:`mappers.core.graph.GraphRepairWarning`); clipped to n - 1.
        n_components: embedding dimension.
        solver: "auto" (SCS for the exact SDP, CLARABEL for the small fast-MVU problem) or a
            cvxpy SDP solver name ("CLARABEL" gives the exact SDP to high accuracy, several
            times slower than SCS).
        tol: solver tolerance (SCS eps_abs = eps_rel; CLARABEL gap/feasibility tolerances),
            relative to distances scaled to unit mean squared edge length.
        max_iters: iteration cap for SCS (ignored by CLARABEL).
        n_basis: None for the exact SDP; m for fast MVU (Weinberger et al. 2007) in the span of
            the m bottom non-constant Laplacian eigenvectors, constraints as a penalty.
        penalty: weight of the mean squared constraint violation in the fast-MVU objective.
        dissimilarity: "euclidean" (rows of X are points) or "precomputed" (X is distances).

    Attributes:
        embedding_, kernel_ (n, n) learned Gram matrix, eigenvalues_ (top n_components),
        graph_ (sparse kNN graph used), added_edges_, solver_status_.
    """

    _parameter_constraints: dict = {
        "n_neighbors": [Interval(Integral, 1, None, closed="left")],
        "n_components": [Interval(Integral, 1, None, closed="left")],
        "solver": [str],
        "tol": [Interval(Real, 0, None, closed="neither")],
        "max_iters": [Interval(Integral, 1, None, closed="left")],
        "n_basis": [Interval(Integral, 1, None, closed="left"), None],
        "penalty": [Interval(Real, 0, None, closed="neither")],
        "dissimilarity": [StrOptions({"euclidean", "precomputed"})],
    }

    def __init__(
        self,
        *,
        n_neighbors: int = 7,
        n_components: int = 2,
        solver: str = "auto",
        tol: float = 1e-3,
        max_iters: int = 20000,
        n_basis: int | None = None,
        penalty: float = 1e3,
        dissimilarity: str = "euclidean",
    ) -> None:
        store_params(self, locals())

    def _solve(self, problem: cp.Problem) -> None:
        solver = self.solver.upper()
        if solver == "AUTO":
            solver = "SCS" if self.n_basis is None else "CLARABEL"
        if solver not in cp.installed_solvers():
            raise ValueError(
                f"solver {self.solver!r} is not installed; have {cp.installed_solvers()}"
            )
        if solver == "SCS":
            # scale=1 (SCS's initial dual scaling; default 0.1): with our unit-mean edge lengths
            # it took 200-250 iterations instead of 500-825 at M = 50, and the map moved 1-3 mm
            # from the interior-point solution instead of 3-6 mm.
            opts = {
                "eps_abs": self.tol, "eps_rel": self.tol, "max_iters": self.max_iters, "scale": 1.0,
            }
        elif solver == "CLARABEL":
            opts = {"tol_gap_abs": self.tol, "tol_gap_rel": self.tol, "tol_feas": self.tol}
        else:
            opts = {}
        try:
            problem.solve(solver=solver, **opts)
        except cp.error.SolverError as exc:
            if solver != "CLARABEL":
                raise ValueError(f"MVU: solver {solver} failed: {exc}") from exc
            # Clarabel can stop with NumericalError near a tight tolerance on some CPUs (the
            # same problem solves elsewhere); shorter interior-point steps (default 0.99 of
            # the way to the cone boundary) get through, so retry once with them.
            try:
                problem.solve(solver=solver, max_step_fraction=0.9, **opts)
            except cp.error.SolverError as again:
                raise ValueError(f"MVU: solver {solver} failed: {again}") from again
        self.solver_status_ = problem.status
        if problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
            raise ValueError(f"MVU: solver {solver} ended with status {problem.status!r}")

    def fit(self, X, y=None):
        """Learn the kernel and the embedding of ``X`` (points, or distances if precomputed)."""
        X = check_points_or_dissimilarities(self, X)
        n = X.shape[0]
        k = min(self.n_neighbors, n - 1)
        A, D, added = connected_knn_graph(X, k, precomputed=self.dissimilarity == "precomputed")
        warn_if_repaired(added, k)
        self.graph_, self.added_edges_ = A, added
        ei, ej = sp.triu(A, 1).nonzero()
        d2 = D[ei, ej] ** 2
        scale = float(d2.mean()) if d2.size and d2.mean() > 0 else 1.0
        d2 = d2 / scale  # unit mean squared edge: tolerances mean the same for any data
        if self.n_basis is None:
            K = cp.Variable((n, n), PSD=True)
            # vec() is row-major ("C") to match mvu_constraint_matrix
            constraints = [
                cp.sum(K) == 0,
                mvu_constraint_matrix(ei, ej, n) @ cp.vec(K, order="C") == d2,
            ]
            self._solve(cp.Problem(cp.Maximize(cp.trace(K)), constraints))
            kernel = K.value
        else:
            m = min(self.n_basis, n - 1)
            # Bottom non-constant Laplacian eigenvectors: smooth on the graph and orthogonal to
            # the ones vector, so K = Q L Q^T is centred by construction.
            _, V = np.linalg.eigh(laplacian(A.astype(float)).toarray())
            Q = V[:, 1 : m + 1]
            q = Q[ei] - Q[ej]
            L = cp.Variable((m, m), PSD=True)
            lin = np.einsum("ea,eb->eab", q, q).reshape(len(ei), m * m)
            resid = lin @ cp.vec(L, order="C") - d2
            objective = cp.trace(L) - self.penalty * cp.sum_squares(resid) / max(len(ei), 1)
            self._solve(cp.Problem(cp.Maximize(objective)))
            kernel = Q @ L.value @ Q.T
        kernel = scale * 0.5 * (kernel + kernel.T)
        w, U = np.linalg.eigh(kernel)
        order = np.argsort(w)[::-1][: self.n_components]
        U, _ = svd_flip(U[:, order], None)
        self.kernel_ = kernel
        self.eigenvalues_ = w[order]
        self.embedding_ = U * np.sqrt(np.clip(w[order], 0.0, None))
        return self

    def fit_transform(self, X, y=None) -> np.ndarray:
        """Fit and return the (n, n_components) embedding."""
        return self.fit(X).embedding_
