"""The catalog of mapping methods: label -> :class:`MethodSpec`, and how a label is resolved.

Every method, built in or registered by a user (:func:`register_method`), is a
:class:`MethodSpec` in :data:`METHODS`. A spec says what the method accepts (which sensors or
fused sets of sensors, complete and/or masked histories) and names its factory by an entry point
``"package.module:name"`` that is imported only when the method is built, as Gymnasium finds its
environments: the catalog imports no method, and no method imports the catalog back. The
pipeline, the protocol and the command line choose and check methods by the spec alone
(:func:`resolve_method`); which label is the default for which data is
:mod:`mappers.defaults`' one table.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from mappers.core.errors import MappingError
from mappers.core.sensors import SENSORS, check_sensor_set, sensor_name
from mappers.defaults import DENSE_MAX_OBJECTS, choose_method

__all__ = [
    "HISTORY_KINDS",
    "METHODS",
    "MappingError",
    "MethodSpec",
    "check_size",
    "methods_for",
    "register_method",
    "resolve_method",
]

HISTORY_KINDS: tuple[str, ...] = ("complete", "masked")
"""``"complete"``: every entry is a measurement (a 0 is "not visible"); ``"masked"``: a boolean
mask says which entries the sensor measured, the others are unknown."""


@dataclass(frozen=True)
class MethodSpec:
    """One mapping method: its label, how to build it, its parameters and what it accepts.

    ``factory(**params)`` returns an object with ``fit_transform(X, **inputs) -> (M, 2)``; the
    parameters it accepts are the names in its signature (:attr:`parameters`). ``factory`` is a
    callable or an entry point ``"package.module:name"``, imported on first use (as Gymnasium
    finds environments), so that the catalog imports no method. What
    ``build_map`` passes as ``inputs`` follows from the flags below.

    Attributes:
        defaults: the default of each parameter (the paper's optimum for its methods).
        grid: the parameter grid the protocol sweeps.
        uses_anchors: the estimator takes ``anchor_ids`` (rows of X) and ``anchor_positions``
            and holds them fixed, so its embedding is already in world coordinates.
        sensors: the sensors whose histories it maps (None: any single sensor). An entry that
            is a frozenset of sensors (e.g. ``frozenset({"range", "bearing"})``) means fused
            histories of exactly that set: ``build_map`` then hands ``fit_transform`` the
            mapping sensor -> matrix as X and ``masks`` keyed alike (None values: complete).
        normalize: whether ``build_map`` divides each row by its norm first (paper eq. 7) unless
            told otherwise; False for methods whose model needs the raw values (UNFOLD).
        histories: the kinds of history it maps (:data:`HISTORY_KINDS`). A method that maps
            masked histories receives ``mask`` (None for a complete history) and ``sensor``.
        uses_timeline: the estimator takes ``timeline`` ((N, 2) ints: robot and tick of each
            step, or None for one robot stepping once per tick) to group consecutive steps.
        sparse: ``fit_transform`` accepts a ``scipy.sparse`` X, so ``build_map`` hands compact
            histories over without building the dense matrix.
        max_objects: the largest M the method is given (None: no limit); ``build_map`` refuses
            more with an error naming the scalable methods.
    """

    label: str
    factory: Callable[..., Any] | str
    defaults: Mapping[str, Any] = field(default_factory=dict)
    grid: Mapping[str, Sequence[Any]] = field(default_factory=dict)
    description: str = ""
    uses_anchors: bool = False
    sensors: tuple[str | frozenset[str], ...] | None = None
    normalize: bool = True
    histories: tuple[str, ...] = ("complete",)
    uses_timeline: bool = False
    sparse: bool = False
    max_objects: int | None = DENSE_MAX_OBJECTS

    def load(self) -> Callable[..., Any]:
        """The factory itself: ``factory``, or the object its entry point names (imported on
        first use; an entry point that does not resolve is a ValueError naming it)."""
        return _load(self.factory, self.label)

    @property
    def parameters(self) -> tuple[str, ...]:
        """Names of the keyword parameters ``factory`` accepts."""
        sig = inspect.signature(self.load())
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

    def resolved_params(self, params: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """Every parameter's value: the factory's own defaults, updated by ``defaults`` and then
        by ``params`` (unknown names: ValueError)."""
        params = dict(params or {})
        self.check_params(params)
        own = {name: p.default for name, p in inspect.signature(self.load()).parameters.items()
               if p.default is not inspect.Parameter.empty}
        return {**own, **self.defaults, **params}

    def build(self, **params: Any) -> Any:
        """The estimator with ``defaults`` updated by ``params`` (unknown names: ValueError)."""
        return self.load()(**self.resolved_params(params))

    @property
    def takes_masks(self) -> bool:
        return "masked" in self.histories

    def accepts(self, sensor: str | frozenset[str], masked: bool) -> bool:
        """Whether the method maps ``sensor`` histories (a sensor, or a fused set of them) of
        that kind (masked or complete)."""
        kind = "masked" if masked else "complete"
        return _maps(self, check_sensor_set(sensor)) and kind in self.histories

    @property
    def fused(self) -> bool:
        """Whether the method maps fused histories (a mapping sensor -> matrix)."""
        return self.sensors is not None and any(not isinstance(s, str) for s in self.sensors)


def _maps(spec: MethodSpec, key: str | frozenset[str]) -> bool:
    """Whether ``spec`` takes histories of ``key`` (a sensor or a frozenset of them); a spec
    without ``sensors`` takes any single sensor."""
    if spec.sensors is None:
        return isinstance(key, str)
    return key in spec.sensors


_LOADED: dict[str, Callable[..., Any]] = {}


def _load(factory: Callable[..., Any] | str, label: str) -> Callable[..., Any]:
    if not isinstance(factory, str):
        return factory
    if factory not in _LOADED:
        module, _, name = factory.partition(":")
        try:
            _LOADED[factory] = getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError) as exc:
            raise ValueError(f"method {label!r}: entry point {factory!r} does not resolve: "
                             f"{exc}") from exc
    return _LOADED[factory]


class _Registry(Mapping[str, MethodSpec]):
    """Read-only view of the registered methods, in registration order (use register_method)."""

    def __getitem__(self, label: str) -> MethodSpec:
        return _METHODS[label]

    def __iter__(self) -> Iterator[str]:
        return iter(list(_METHODS))

    def __len__(self) -> int:
        return len(_METHODS)

    def __repr__(self) -> str:
        return f"METHODS({list(self)})"


METHODS: Mapping[str, MethodSpec] = _Registry()
"""Label -> :class:`MethodSpec`, in registration order (read-only view; use register_method)."""

def check_size(spec: MethodSpec, n_objects: int) -> None:
    """ValueError when ``spec`` does not take ``n_objects`` objects, naming the methods that do."""
    if spec.max_objects is not None and n_objects > spec.max_objects:
        scalable = [label for label, s in METHODS.items()
                    if s.max_objects is None or s.max_objects >= n_objects]
        raise ValueError(
            f"method {spec.label!r} maps at most {spec.max_objects} objects (it holds M x M "
            f"matrices), got {n_objects}; use a scalable method: {scalable}"
        )


def register_method(spec: MethodSpec, *, replace: bool = False) -> MethodSpec:
    """Add ``spec`` to :data:`METHODS` (ValueError if the label exists, unless ``replace``)."""
    if not isinstance(spec, MethodSpec):
        raise ValueError(f"spec must be a MethodSpec, got {type(spec).__name__}")
    if not isinstance(spec.label, str) or not spec.label:
        raise ValueError("spec.label must be a non-empty string")
    if not (callable(spec.factory) or (isinstance(spec.factory, str) and ":" in spec.factory)):
        raise ValueError(f"spec.factory of {spec.label!r} is neither callable nor an entry "
                         "point 'package.module:name'")
    if spec.label in _METHODS and not replace:
        raise ValueError(f"method {spec.label!r} is already registered (pass replace=True)")
    if spec.sensors is not None and not _valid_sensors(spec.sensors):
        raise ValueError(
            f"{spec.label!r}: sensors must be None or a non-empty tuple of {SENSORS} and of "
            f"frozensets of two or more of them (fused histories), got {spec.sensors!r}"
        )
    if (isinstance(spec.histories, str) or not spec.histories
            or not set(spec.histories) <= set(HISTORY_KINDS)):
        raise ValueError(
            f"{spec.label!r}: histories must be a non-empty tuple of {HISTORY_KINDS}, "
            f"got {spec.histories!r}"
        )
    for what, names in (("defaults", spec.defaults), ("grid", spec.grid)):
        unknown = sorted(set(names) - set(spec.parameters))
        if unknown:
            raise ValueError(f"{spec.label!r}: {what} name(s) {unknown} not accepted by factory")
    _METHODS[spec.label] = spec
    return spec


def _valid_sensors(sensors: object) -> bool:
    if isinstance(sensors, str) or not isinstance(sensors, tuple) or not sensors:
        return False
    return all(
        (isinstance(s, str) and s in SENSORS)
        or (isinstance(s, frozenset) and len(s) >= 2 and s <= set(SENSORS))
        for s in sensors
    )


def methods_for(sensor=None, masked: bool | None = None) -> tuple[str, ...]:
    """Labels of the registered methods that map ``sensor`` histories (a sensor, a fused set of
    them, or None: any) of that kind (None: any)."""
    key = None if sensor is None else check_sensor_set(sensor)
    return tuple(
        label for label, spec in _METHODS.items()
        if (key is None or _maps(spec, key))
        and (masked is None or ("masked" if masked else "complete") in spec.histories)
    )


def resolve_method(method: str | None, sensor, masked: bool = False,
                   n_objects: int | None = None) -> MethodSpec:
    """The spec of ``method`` (a label, matched case-insensitively; None = the default for
    ``sensor`` — a sensor, or a fused set of them — and the kind of history, as
    :func:`mappers.defaults.choose_method` chooses it) if it maps such
    histories, else a ValueError that lists the labels which do."""
    key = check_sensor_set(sensor)
    sensor = sensor_name(key)
    kind = "masked" if masked else "complete"
    fits = methods_for(key, masked)
    if method is None:
        method = choose_method(key, masked=bool(masked), n_objects=n_objects)
        if method is None or method not in _METHODS:
            raise ValueError(f"no default method for {kind} {sensor} histories; choose from {list(fits)}")
    if not isinstance(method, str):
        raise ValueError(f"method must be a label (str) or None, got {method!r}")
    label = method if method in _METHODS else {k.lower(): k for k in _METHODS}.get(method.strip().lower())
    if label is None:
        raise ValueError(f"unknown method {method!r}; methods for {kind} {sensor} histories: {list(fits)}")
    spec = _METHODS[label]
    if not _maps(spec, key):
        takes = "single-sensor" if spec.sensors is None else " and ".join(
            sensor_name(s) for s in spec.sensors)
        raise ValueError(
            f"method {label!r} maps {takes} histories only: it does not map "
            f"{sensor} histories; methods for {kind} {sensor} histories: {list(fits)}"
        )
    if kind not in spec.histories:
        raise ValueError(
            f"method {label!r} does not map {kind} {sensor} histories; methods that do: {list(fits)}"
        )
    return spec


# The built-in methods, in table order: the paper's ten (its Table 1), ours for complete
# histories, those for masked histories, the fused ones and the viewpoint adjustments.
# The paper's grids (K 4..10, sigma^2 in {0.25, 0.5, 1, 2}, d in {2, 4, 8}), widened where our
# first full protocol run put the best value on the grid's edge (HLLE at K = 10, KPCA(GAUS) at
# sigma^2 = 2): a best parameter on an edge says the grid was too narrow, not where the optimum is.
_K_GRID = [4, 5, 6, 7, 8, 9, 10, 11, 12]
_MASKED = {"uses_anchors": True, "normalize": False, "histories": ("complete", "masked")}
_COVIS_SENSORS = ("visibility", "bearing")
_BUILTINS: tuple[MethodSpec, ...] = (
    MethodSpec("LPCA", "mappers.paper.methods:_lpca", {}, {}, "linear PCA / classical MDS"),
    MethodSpec("SMA(UNWGT)", "mappers.paper.methods:_sma_unweighted", {}, {},
               "SMACOF, equal weights, LPCA start"),
    MethodSpec("SMA(WGT)", "mappers.paper.methods:_sma_weighted", {"n_neighbors": 5},
               {"n_neighbors": _K_GRID},
               "SMACOF, symmetric kNN weights, started from the SMA(UNWGT) solution"),
    MethodSpec("KPCA(GAUS)", "mappers.paper.methods:_kpca_gauss", {"sigma2": 0.5},
               {"sigma2": [0.25, 0.5, 1.0, 2.0, 4.0, 8.0]}, "kernel PCA, Gaussian kernel"),
    MethodSpec("KPCA(POLY)", "mappers.paper.methods:_kpca_poly", {"degree": 8},
               {"degree": [2, 4, 8]}, "kernel PCA, polynomial kernel"),
    MethodSpec("ISOMAP", "mappers.paper.methods:_isomap", {"n_neighbors": 6},
               {"n_neighbors": _K_GRID}, "Isomap"),
    MethodSpec("LLE", "mappers.paper.methods:_lle", {"n_neighbors": 8},
               {"n_neighbors": _K_GRID}, "locally linear embedding"),
    MethodSpec("LEM", "mappers.paper.methods:_lem", {"n_neighbors": 6},
               {"n_neighbors": _K_GRID}, "Laplacian eigenmap, binary kNN weights"),
    # Hessian LLE needs K > 5 in 2-D, so its grid starts at 6 (K = 4, 5 would always fail).
    MethodSpec("HLLE", "mappers.paper.methods:_hlle", {"n_neighbors": 8},
               {"n_neighbors": [k for k in _K_GRID if k > 5]}, "Hessian LLE"),
    MethodSpec("SDE", "mappers.paper.methods:_sde", {"n_neighbors": 7},
               {"n_neighbors": _K_GRID}, "semidefinite embedding / maximum variance unfolding"),
    MethodSpec("CAL-SMA", "mappers.calibrated.cal_sma:_cal_sma", {},
               {"n_neighbors": [8, 10, 12, 14, 16]}, "calibrated anchored SMACOF with fold guard",
               uses_anchors=True),
    MethodSpec("UNFOLD", "mappers.calibrated.unfolding:_unfold", {}, {},
               "classical metric unfolding of the squared range histories (range sensor only)",
               sensors=("range",), normalize=False),
    MethodSpec("CAL-SMA-SPARSE", "mappers.calibrated.cal_sma_sparse:_cal_sma_sparse", {},
               {"n_neighbors": [8, 10, 12, 14, 16]},
               "CAL-SMA on sparse pairs: scales to thousands of objects", uses_anchors=True,
               sensors=("visibility", "bearing"), sparse=True, max_objects=None),
    MethodSpec("range-quantile", "mappers.masked.pair_maps:_range_quantile",
               description="quantile of same-step range differences, anchored weighted SMACOF",
               sensors=("range",), **_MASKED),
    MethodSpec("range-bounds", "mappers.masked.pair_maps:_range_bounds",
               description="range-quantile with field-of-view upper bounds", sensors=("range",),
               **_MASKED),
    MethodSpec("covis-nonmetric", "mappers.masked.pair_maps:_covis_nonmetric",
               description="ordinal SMACOF of -log co-observation rates, anchored", **_MASKED),
    MethodSpec("covis-power", "mappers.masked.pair_maps:_covis_power",
               description="power-link SMACOF of -log co-observation rates, anchored", **_MASKED),
    MethodSpec("covis-angle", "mappers.masked.pair_maps:_covis_angle",
               description="ordinal SMACOF of -log angle-weighted co-observation rates, anchored",
               sensors=("bearing",), **_MASKED),
    MethodSpec("masked-euclidean", "mappers.masked.pair_maps:_masked_euclidean",
               description="RMS history difference over co-observed steps, weighted SMACOF",
               **_MASKED),
    MethodSpec("covis-ensemble", "mappers.masked.ensemble:CovisEnsemble",
               description="mean of anchored co-observation maps over windows of consecutive "
                           "steps", uses_timeline=True, **_MASKED),
    MethodSpec("covis-cal", "mappers.masked.covis_auto:CovisCalibrated",
               description="CAL-SMA of 1 - (angle-weighted) co-observation rates, anchored",
               sensors=_COVIS_SENSORS, **_MASKED),
    MethodSpec("covis-auto", "mappers.masked.covis_auto:CovisAuto",
               description="covis-cal when most pairs are seen together, else covis-angle",
               sensors=("bearing",), **_MASKED),
    MethodSpec("covis-sparse", "mappers.masked.covis_sparse:SparseCovis", {},
               {"n_neighbors": [8, 12, 16]},
               "covis-cal's model on sparse co-observed pairs: masked histories of thousands of "
               "objects", sensors=_COVIS_SENSORS, sparse=True, max_objects=None, **_MASKED),
    MethodSpec("dropout-blend", "mappers.masked.dropout_blend:DropoutBlend",
               description="mean of CAL-SMA on 3-step averaged rows and covis-nonmetric, anchored",
               sensors=("visibility",), uses_timeline=True, **_MASKED),
    MethodSpec("LOC-SMA", "mappers.fused.loc_sma:_loc_sma", {},
               {"min_count": [1, 3, 10], "trim": [None, 3.0]},
               "anchored weighted SMACOF of law-of-cosines distances, refined by range-and-bearing "
               "bundle adjustment (fused range + bearing; refine=None: the law-of-cosines map "
               "alone)", sensors=(frozenset({"range", "bearing"}),), **_MASKED),
    MethodSpec("VB-SMA", "mappers.fused.vb_sma:_vb_sma", {},
               {"bearing_weight": [1.0, 2.0, 3.0, 4.0], "bearing_share": [0.0, 0.2, 0.3, 0.5]},
               "CAL-SMA of joined visibility and bearing histories, blended with the bearing-only "
               "map, refined by bearing-only bundle adjustment (fused; refine=False: the "
               "paper-era blend)", uses_anchors=True,
               sensors=(frozenset({"visibility", "bearing"}),), normalize=False),
    # BEARING-BA's and VIEW-BA's defaults were chosen on tuning layouts
    # (docs/imperfect-sensing.md): no sweep.
    MethodSpec("BEARING-BA", "mappers.viewpoints.bearing:BearingAdjustment", {}, {},
               "the bearing default's map refined by estimating the viewpoints (bearing-only "
               "bundle adjustment), anchors fixed", sensors=("bearing",), **_MASKED),
    MethodSpec("VIS-BA", "mappers.viewpoints.visibility:VisibilityAdjustment", {},
               {"max_rounds": [3, 5, 8], "grid_cells": [6, 8]},
               "the visibility default's map refined by estimating the viewpoints (visibility "
               "bundle adjustment: a range threshold with misses), anchors fixed",
               sensors=("visibility",), uses_timeline=True, **_MASKED),
    MethodSpec("VIS-BA-WALK", "mappers.viewpoints.visibility:VisibilityAdjustment",
               {"continuity": True, "align": True, "overrelax": 1.0, "grid_cells": 4,
                "prior_iters": 1, "model_rounds": 2},
               {"max_rounds": [3, 5, 8], "grid_cells": [4, 6]},
               "VIS-BA with the walk's continuity prior (the steps' viewpoints an HMM: "
               "consecutive steps close together): the default for flickering visibility "
               "histories", sensors=("visibility",), uses_timeline=True, **_MASKED),
    MethodSpec("VIEW-BA", "mappers.viewpoints.view_cone:ViewAdjustment", {}, {},
               "a limited view's masked visibility map refined by estimating each step's "
               "viewpoint and heading from the observed sets (view-cone bundle adjustment), "
               "anchors fixed", uses_anchors=True, sensors=("visibility",), normalize=False,
               histories=("masked",), uses_timeline=True),
)
_METHODS: dict[str, MethodSpec] = {spec.label: spec for spec in _BUILTINS}
