"""The paper's ten dimensionality-reduction methods (Yairi 2007, §3, Table 1), registered in
:data:`mappers.catalog.METHODS` with the paper's optimum as defaults and the protocol's grids.

scikit-learn supplies PCA, kernel PCA, Isomap, LLE / Hessian LLE and the spectral embedding;
only weighted SMACOF (:mod:`mappers.smacof.weighted`) and SDE/MVU (:mod:`mappers.paper.mvu`) are ours. Thin
wrappers here add what the paper's setting needs: binary symmetric kNN weights for LEM, sign
fixing and clear errors for (Hessian) LLE.
"""

from __future__ import annotations

from numbers import Integral, Real

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.decomposition import PCA, KernelPCA
from sklearn.manifold import Isomap, SpectralEmbedding
from sklearn.manifold import LocallyLinearEmbedding as _SklearnLLE
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.extmath import svd_flip
from sklearn.utils.validation import validate_data

from mappers.core.estimator_params import store_params
from mappers.core.graph import connected_knn_graph, warn_if_repaired
from mappers.smacof import WeightedSMACOF

__all__ = ["LaplacianEigenmap", "LocallyLinear"]


def _validated_knn_input(est: BaseEstimator, X) -> np.ndarray:
    """Parameter and data checks shared by the kNN-graph estimators; returns X as float."""
    est._validate_params()
    X = validate_data(est, X, ensure_min_samples=2, dtype=float)
    if est.n_neighbors >= X.shape[0]:
        raise ValueError(
            f"n_neighbors={est.n_neighbors} must be < number of points ({X.shape[0]})"
        )
    return X


class LocallyLinear(TransformerMixin, BaseEstimator):
    """scikit-learn's LLE / Hessian LLE with fixed signs and explicit errors.

    Uses the dense eigensolver (ARPACK often fails to converge on these small, nearly
    singular problems). Hessian LLE needs n_neighbors > n_components (n_components + 3) / 2
    (K > 5 in 2-D) and its eigenproblem often fails on real histories (paper §4.4.2): both give
    a ValueError that says so instead of a bare numpy/scipy traceback.
    """

    _parameter_constraints: dict = {
        "n_neighbors": [Interval(Integral, 1, None, closed="left")],
        "method": [StrOptions({"standard", "hessian"})],
        "n_components": [Interval(Integral, 1, None, closed="left")],
        "reg": [Interval(Real, 0, None, closed="left")],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        *,
        n_neighbors: int = 8,
        method: str = "standard",
        n_components: int = 2,
        reg: float = 1e-3,
        random_state=None,
    ) -> None:
        store_params(self, locals())

    def fit(self, X, y=None):
        """Compute the embedding of ``X``."""
        X = _validated_knn_input(self, X)
        if self.method == "hessian":
            need = self.n_components * (self.n_components + 3) // 2
            if self.n_neighbors <= need:
                raise ValueError(
                    f"Hessian LLE needs n_neighbors > n_components * (n_components + 3) / 2 "
                    f"= {need}, got n_neighbors={self.n_neighbors}"
                )
        est = _SklearnLLE(
            n_neighbors=self.n_neighbors,
            n_components=self.n_components,
            method=self.method,
            reg=self.reg,
            eigen_solver="dense",
            random_state=self.random_state,
        )
        label = "Hessian LLE" if self.method == "hessian" else "LLE"
        try:
            with np.errstate(all="ignore"):
                Y = est.fit_transform(X)
        except (ValueError, np.linalg.LinAlgError, ArithmeticError) as exc:
            raise ValueError(f"{label} eigenproblem failed: {exc}") from exc
        if not np.all(np.isfinite(Y)):
            raise ValueError(f"{label} eigenproblem failed: the embedding has NaN/inf")
        sv = np.linalg.svd(Y - Y.mean(axis=0), compute_uv=False)
        if sv[0] == 0 or sv[-1] <= 1e-10 * sv[0]:
            raise ValueError(f"{label} eigenproblem failed: degenerate (rank-deficient) embedding")
        self.embedding_, _ = svd_flip(Y, None)
        self.reconstruction_error_ = est.reconstruction_error_
        return self

    def fit_transform(self, X, y=None) -> np.ndarray:
        """Fit and return the (n, n_components) embedding."""
        return self.fit(X).embedding_


class LaplacianEigenmap(TransformerMixin, BaseEstimator):
    """Laplacian eigenmap (Belkin & Niyogi 2002) with binary symmetric kNN weights (paper §4.2).

    w_ij = 1 when i is among j's K nearest neighbours or j among i's, else 0; a disconnected
    graph is joined at its closest pairs (GraphRepairWarning) since the eigenmap of a
    disconnected graph only separates the pieces. Embedding by scikit-learn's
    ``SpectralEmbedding(affinity="precomputed")`` (signs fixed there).
    """

    _parameter_constraints: dict = {
        "n_neighbors": [Interval(Integral, 1, None, closed="left")],
        "n_components": [Interval(Integral, 1, None, closed="left")],
        "random_state": ["random_state"],
    }

    def __init__(self, *, n_neighbors: int = 6, n_components: int = 2, random_state=None) -> None:
        store_params(self, locals())

    def fit(self, X, y=None):
        """Compute the embedding of ``X``."""
        X = _validated_knn_input(self, X)
        A, _, added = connected_knn_graph(X, self.n_neighbors)
        warn_if_repaired(added, self.n_neighbors)
        self.affinity_matrix_, self.added_edges_ = A, added
        est = SpectralEmbedding(
            n_components=self.n_components, affinity="precomputed", random_state=self.random_state
        )
        try:
            self.embedding_ = est.fit_transform(A)
        except (ValueError, np.linalg.LinAlgError, ArithmeticError) as exc:
            raise ValueError(f"Laplacian eigenmap eigenproblem failed: {exc}") from exc
        return self

    def fit_transform(self, X, y=None) -> np.ndarray:
        """Fit and return the (n, n_components) embedding."""
        return self.fit(X).embedding_


# --- factories: one per label, parameters named as in the paper (K, sigma2, d) ---------------


def _lpca() -> PCA:
    return PCA(n_components=2, svd_solver="full")


def _sma_unweighted(max_iter: int = 300, tol: float = 1e-6) -> WeightedSMACOF:
    # equal weights, LPCA start: the paper's SMA(UNWGT)
    return WeightedSMACOF(n_neighbors=None, init="lpca", max_iter=max_iter, tol=tol)


def _sma_weighted(
    n_neighbors: int = 5,
    init: str = "unweighted",
    n_init: int = 1,
    max_iter: int = 300,
    tol: float = 1e-6,
    random_state=None,
) -> WeightedSMACOF:
    return WeightedSMACOF(
        n_neighbors=n_neighbors,
        init=init,
        n_init=n_init,
        max_iter=max_iter,
        tol=tol,
        random_state=random_state,
    )


def _kpca_gauss(sigma2: float = 0.5) -> KernelPCA:
    if not sigma2 > 0:
        raise ValueError(f"sigma2 must be > 0, got {sigma2}")
    # k(a, b) = exp(-||a-b||^2 / (2 sigma^2)); sklearn's rbf is exp(-gamma ||a-b||^2)
    return KernelPCA(n_components=2, kernel="rbf", gamma=1.0 / (2.0 * sigma2), eigen_solver="dense")


def _kpca_poly(degree: int = 8) -> KernelPCA:
    if not (isinstance(degree, Integral) and degree >= 1):
        raise ValueError(f"degree must be a positive integer, got {degree!r}")
    # k(a, b) = (<a, b> + 1)^d
    return KernelPCA(
        n_components=2,
        kernel="poly",
        gamma=1.0,
        coef0=1.0,
        degree=int(degree),
        eigen_solver="dense",
    )


def _isomap(n_neighbors: int = 6) -> Isomap:
    return Isomap(n_neighbors=n_neighbors, n_components=2, eigen_solver="dense")


def _lle(n_neighbors: int = 8, random_state=None) -> LocallyLinear:
    return LocallyLinear(n_neighbors=n_neighbors, method="standard", random_state=random_state)


def _lem(n_neighbors: int = 6, random_state=None) -> LaplacianEigenmap:
    return LaplacianEigenmap(n_neighbors=n_neighbors, random_state=random_state)


def _hlle(n_neighbors: int = 8, random_state=None) -> LocallyLinear:
    return LocallyLinear(n_neighbors=n_neighbors, method="hessian", random_state=random_state)


def _sde(n_neighbors: int = 7, solver: str = "auto", tol: float = 1e-3, n_basis: int | None = None):
    from mappers.paper.mvu import MaximumVarianceUnfolding  # cvxpy: loaded only when SDE is built

    return MaximumVarianceUnfolding(
        n_neighbors=n_neighbors, solver=solver, tol=tol, n_basis=n_basis
    )
