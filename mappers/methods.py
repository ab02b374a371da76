"""The paper's ten DR methods (SPEC §3) as a registry of scikit-learn-style estimators.

``METHODS`` maps a label to a :class:`MethodSpec`: ``spec.factory(**params)`` builds an
estimator whose ``fit_transform(X)`` returns the (M, 2) embedding; ``spec.defaults`` are the
paper's optimum for visibility; ``spec.grid`` is the parameter grid of the protocol. New methods
(yours, or the calibrated mapper of :mod:`mappers.calibrated`) join through
:func:`register_method`.

scikit-learn supplies PCA, kernel PCA, Isomap, LLE / Hessian LLE and the spectral embedding;
only weighted SMACOF (:mod:`mappers.smacof`) and SDE/MVU (:mod:`mappers.mvu`) are ours. Thin
wrappers here add what the paper's setting needs: binary symmetric kNN weights for LEM, sign
fixing and clear errors for (Hessian) LLE.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from numbers import Integral, Real
from types import MappingProxyType
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.decomposition import PCA, KernelPCA
from sklearn.manifold import Isomap, SpectralEmbedding
from sklearn.manifold import LocallyLinearEmbedding as _SklearnLLE
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.extmath import svd_flip
from sklearn.utils.validation import validate_data

from mappers.graph import connected_knn_graph, warn_if_repaired
from mappers.mvu import MaximumVarianceUnfolding
from mappers.smacof import WeightedSMACOF

__all__ = [
    "DEFAULT_METHODS",
    "METHODS",
    "LaplacianEigenmap",
    "LocallyLinear",
    "MappingError",
    "MethodSpec",
    "register_method",
]

# The paper's grids (K 4..10, sigma^2 in {0.25, 0.5, 1, 2}, d in {2, 4, 8}), widened where our
# first full protocol run put the best value on the grid's edge (HLLE at K = 10, KPCA(GAUS) at
# sigma^2 = 2): a best parameter on an edge says the grid was too narrow, not where the optimum is.
K_GRID: tuple[int, ...] = (4, 5, 6, 7, 8, 9, 10, 11, 12)
SIGMA2_GRID: tuple[float, ...] = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
DEGREE_GRID: tuple[int, ...] = (2, 4, 8)


class MappingError(ValueError):
    """A method could not embed the data (eigenproblem failure, solver failure, ...)."""


SENSORS: tuple[str, ...] = ("visibility", "bearing", "range")
"""The kinds of history: one 0/1 column per step, (cos, sin) per step, or one range per step."""


@dataclass(frozen=True)
class MethodSpec:
    """One mapping method: its label, how to build it, its default parameters and grid.

    ``factory(**params)`` must return an object with ``fit_transform(X) -> (M, 2)``; the
    parameters it accepts are the names in its signature (see :attr:`parameters`).
    """

    label: str
    factory: Callable[..., Any]
    defaults: Mapping[str, Any] = field(default_factory=dict)
    grid: Mapping[str, Sequence[Any]] = field(default_factory=dict)
    description: str = ""
    # True when the estimator takes the anchors itself, as
    # ``fit_transform(X, anchor_ids=..., anchor_positions=...)`` (ids index the rows of X), and
    # holds them fixed; build_map then passes them and the affine fit is the identity.
    uses_anchors: bool = False
    # The sensors whose histories the method maps (None: any). build_map refuses the others, and
    # the protocol leaves the method out of the tables of other sensors.
    sensors: tuple[str, ...] | None = None
    # Whether build_map divides each history by its norm first (paper eq. 7) unless told not to;
    # False for methods whose model needs the raw values (UNFOLD: distances).
    normalize: bool = True

    @property
    def parameters(self) -> tuple[str, ...]:
        """Names of the keyword parameters ``factory`` accepts."""
        sig = inspect.signature(self.factory)
        return tuple(
            name
            for name, p in sig.parameters.items()
            if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        )

    def check_params(self, params: Mapping[str, Any]) -> None:
        """ValueError naming any key of ``params`` that ``factory`` does not accept."""
        unknown = sorted(set(params) - set(self.parameters))
        if unknown:
            raise ValueError(
                f"unknown parameter(s) {unknown} for method {self.label!r}; "
                f"it accepts {list(self.parameters)}"
            )

    def build(self, **params: Any) -> Any:
        """The estimator with ``defaults`` updated by ``params`` (unknown names: ValueError)."""
        self.check_params(params)
        return self.factory(**{**self.defaults, **params})


_METHODS: dict[str, MethodSpec] = {}
METHODS: Mapping[str, MethodSpec] = MappingProxyType(_METHODS)
"""Label -> :class:`MethodSpec`, in registration order (read-only view; use register_method)."""


def register_method(spec: MethodSpec, *, replace: bool = False) -> MethodSpec:
    """Add ``spec`` to :data:`METHODS` (ValueError if the label exists, unless ``replace``)."""
    if not isinstance(spec, MethodSpec):
        raise ValueError(f"spec must be a MethodSpec, got {type(spec).__name__}")
    if not isinstance(spec.label, str) or not spec.label:
        raise ValueError("spec.label must be a non-empty string")
    if not callable(spec.factory):
        raise ValueError(f"spec.factory of {spec.label!r} is not callable")
    if spec.label in _METHODS and not replace:
        raise ValueError(f"method {spec.label!r} is already registered (pass replace=True)")
    if spec.sensors is not None and (
        isinstance(spec.sensors, str) or not spec.sensors or not set(spec.sensors) <= set(SENSORS)
    ):
        raise ValueError(
            f"{spec.label!r}: sensors must be None or a non-empty tuple of {SENSORS}, "
            f"got {spec.sensors!r}"
        )
    for what, names in (("defaults", spec.defaults), ("grid", spec.grid)):
        unknown = sorted(set(names) - set(spec.parameters))
        if unknown:
            raise ValueError(f"{spec.label!r}: {what} name(s) {unknown} not accepted by factory")
    _METHODS[spec.label] = spec
    return spec


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
        self.n_neighbors = n_neighbors
        self.method = method
        self.n_components = n_components
        self.reg = reg
        self.random_state = random_state

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
        self.n_neighbors = n_neighbors
        self.n_components = n_components
        self.random_state = random_state

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


def _sde(
    n_neighbors: int = 7, solver: str = "auto", tol: float = 1e-3, n_basis: int | None = None
) -> MaximumVarianceUnfolding:
    return MaximumVarianceUnfolding(
        n_neighbors=n_neighbors, solver=solver, tol=tol, n_basis=n_basis
    )


for _spec in (
    MethodSpec("LPCA", _lpca, {}, {}, "linear PCA / classical MDS"),
    MethodSpec("SMA(UNWGT)", _sma_unweighted, {}, {}, "SMACOF, equal weights, LPCA start"),
    MethodSpec(
        "SMA(WGT)",
        _sma_weighted,
        {"n_neighbors": 5},
        {"n_neighbors": list(K_GRID)},
        "SMACOF, symmetric kNN weights, started from the SMA(UNWGT) solution",
    ),
    MethodSpec(
        "KPCA(GAUS)",
        _kpca_gauss,
        {"sigma2": 0.5},
        {"sigma2": list(SIGMA2_GRID)},
        "kernel PCA, Gaussian kernel",
    ),
    MethodSpec(
        "KPCA(POLY)",
        _kpca_poly,
        {"degree": 8},
        {"degree": list(DEGREE_GRID)},
        "kernel PCA, polynomial kernel",
    ),
    MethodSpec("ISOMAP", _isomap, {"n_neighbors": 6}, {"n_neighbors": list(K_GRID)}, "Isomap"),
    MethodSpec(
        "LLE", _lle, {"n_neighbors": 8}, {"n_neighbors": list(K_GRID)}, "locally linear embedding"
    ),
    MethodSpec(
        "LEM",
        _lem,
        {"n_neighbors": 6},
        {"n_neighbors": list(K_GRID)},
        "Laplacian eigenmap, binary kNN weights",
    ),
    MethodSpec(
        # Hessian LLE needs K > 5 in 2-D, so its grid starts at 6 (K = 4, 5 would always fail).
        "HLLE",
        _hlle,
        {"n_neighbors": 8},
        {"n_neighbors": [k for k in K_GRID if k > 5]},
        "Hessian LLE",
    ),
    MethodSpec(
        "SDE",
        _sde,
        {"n_neighbors": 7},
        {"n_neighbors": list(K_GRID)},
        "semidefinite embedding / maximum variance unfolding",
    ),
):
    register_method(_spec)
del _spec

DEFAULT_METHODS: dict[str, str] = {
    # CAL-SMA is registered by mappers/calibrated.py, which ``import mappers`` always loads
    "visibility": "CAL-SMA",
    "bearing": "CAL-SMA",
    # UNFOLD is registered by mappers/unfolding.py, which ``import mappers`` always loads
    "range": "UNFOLD",
}
"""Method build_map uses when none is given, per sensor. Measured on simulated random-walk
histories (lfmdr_gym, M = 50, N = 2000, non-anchor MPE): CAL-SMA beats the paper's ten for
visibility and bearing (``benchmarks/bench_calibrated.py``; see :mod:`mappers.calibrated`).
For range, classical metric unfolding (UNFOLD, :mod:`mappers.unfolding`) is exact on complete
range histories (the squared ranges, double-centred, are rank 2), where SMA(WGT), the best of
the paper's ten on range (0.195 m, 5 layouts, default parameters; ``benchmarks/bench_mappers.py
--sections methods``), and CAL-SMA (0.18 m) are not (``--sections range``); SMA(WGT) is also
best of the ten for bearing (0.051 m) and second for visibility (0.134 m, behind HLLE's
0.114 m, which the paper reports "often failed to run")."""
