"""The catalog of mapping methods: label -> :class:`MethodSpec`, and how a label is resolved.

Every method, built in or registered by a user (:func:`register_method`), is a
:class:`MethodSpec` in :data:`METHODS`. A spec says what the method accepts (which sensors or
fused sets of sensors, complete and/or masked histories) and names its factory by an entry point
``"package.module:name"`` that is imported only when the method is built, as Gymnasium finds its
environments: the catalog imports no method, and no method imports the catalog back. The
pipeline, the protocol and the command line choose and check methods by the spec alone
(:func:`resolve_method`); which label is the default for which data is
:mod:`mappers.defaults`' one table.

Labels: the paper's ten keep its spellings (``LPCA`` ... ``SDE``), ours are upper case with
hyphens (``CAL-SMA``, ``COVIS-AUTO``, ``VIS-BA-WALK``); an option of a method is a parameter
(``CAL-SMA`` with ``sparse=True``), not a label. Labels of older releases resolve through
:data:`ALIASES` (with a FutureWarning) or are refused with the reason (:data:`RETIRED`: the
dead ends, whose figures are in ``docs/dead-ends.md``, and the building blocks of other methods).
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import os
import sys
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from mappers.core.errors import MappingError
from mappers.core.sensors import SENSORS, check_sensor_set, sensor_name
from mappers.defaults import DENSE_MAX_OBJECTS, choose_method

__all__ = [
    "ALIASES",
    "HISTORY_KINDS",
    "METHODS",
    "RETIRED",
    "Alias",
    "MappingError",
    "MethodSpec",
    "check_size",
    "implied_params",
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
        scalable: the parameters that switch the method to its scalable form (``{"sparse":
            True}`` for CAL-SMA), an option of one algorithm rather than a second one; with them
            ``fit_transform`` accepts a ``scipy.sparse`` X and any number of objects, whatever
            ``sparse`` and ``max_objects`` say of the default form (empty: no such form).
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
    scalable: Mapping[str, Any] = field(default_factory=dict)

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

    def with_defaults(self, params: Mapping[str, Any]) -> MethodSpec:
        """This spec with ``defaults`` updated by ``params`` (unknown names: ValueError): what
        :func:`resolve_method` returns for an old label that implies parameters, or for a
        default chosen with them (``CAL-SMA`` with ``sparse=True``)."""
        if not params:
            return self
        self.check_params(params)
        return dataclasses.replace(self, defaults={**self.defaults, **params})

    def is_scalable(self, params: Mapping[str, Any]) -> bool:
        """Whether ``params`` (the resolved parameters) select the scalable form (``scalable``)."""
        return bool(self.scalable) and all(
            k in params and params[k] == v for k, v in self.scalable.items())

    def takes_sparse(self, params: Mapping[str, Any]) -> bool:
        """Whether ``fit_transform`` takes a ``scipy.sparse`` X with these resolved parameters."""
        return self.sparse or self.is_scalable(params)

    def object_limit(self, params: Mapping[str, Any]) -> int | None:
        """The largest M the method is given with these resolved parameters (None: no limit)."""
        return None if self.is_scalable(params) else self.max_objects

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

def _params_text(params: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in params.items())


def scalable_methods(n_objects: int) -> list[str]:
    """The registered methods that map ``n_objects`` objects, each with the parameters of its
    scalable form where it needs them (``"CAL-SMA with sparse=True"``)."""
    return [label if s.max_objects is None or s.max_objects >= n_objects
            else f"{label} with {_params_text(s.scalable)}"
            for label, s in _METHODS.items()
            if s.max_objects is None or s.max_objects >= n_objects or s.scalable]


def check_size(spec: MethodSpec, n_objects: int, params: Mapping[str, Any] | None = None) -> None:
    """ValueError when ``spec`` with the resolved ``params`` does not take ``n_objects``
    objects, naming its scalable form (if it has one) and the methods that take them."""
    limit = spec.object_limit(params or {})
    if limit is not None and n_objects > limit:
        form = (f"pass {_params_text(spec.scalable)} (its scalable form) or "
                if spec.scalable else "")
        raise ValueError(
            f"method {spec.label!r} maps at most {limit} objects (it holds M x M "
            f"matrices), got {n_objects}; {form}use a scalable method: "
            f"{scalable_methods(n_objects)}"
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
    for what, names in (("defaults", spec.defaults), ("grid", spec.grid),
                        ("scalable", spec.scalable)):
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


@dataclass(frozen=True)
class Alias:
    """An old label's new spelling: the label and the parameters it stands for."""

    label: str
    params: Mapping[str, Any] = field(default_factory=dict)


_DEAD_ENDS = "docs/dead-ends.md"

ALIASES: Mapping[str, Alias] = MappingProxyType({
    "CAL-SMA-SPARSE": Alias("CAL-SMA", MappingProxyType({"sparse": True})),
    "range-quantile": Alias("RANGE-QUANTILE"),
    "covis-ensemble": Alias("COVIS-ENSEMBLE"),
    "covis-auto": Alias("COVIS-AUTO"),
    "covis-sparse": Alias("COVIS-SPARSE"),
    "dropout-blend": Alias("DROPOUT-BLEND"),
})
"""Old label -> :class:`Alias`: labels that stored results, the README or older code used and
that now have another spelling, or are one method with a parameter. :func:`resolve_method`
resolves them (in any case but the new label's own spelling) with a FutureWarning naming the
new label."""

RETIRED: Mapping[str, str] = MappingProxyType({
    "range-bounds": (
        f"a dead end (its figures: {_DEAD_ENDS}); use RANGE-QUANTILE, the same map without the "
        "field-of-view bounds; the building block stays: mappers.masked_embedding(X, mask, "
        "'range', 'range-bounds')"),
    "masked-euclidean": (
        f"a dead end (its figures: {_DEAD_ENDS}); use the masked default of the sensor "
        "(method=None: VIEW-BA, BEARING-BA or RANGE-QUANTILE); the building block stays: "
        "mappers.masked_embedding(X, mask, sensor, 'masked-euclidean')"),
    "covis-power": (
        f"a dead end as a method of its own (its figures: {_DEAD_ENDS}); use COVIS-ENSEMBLE, "
        "whose member it is (with windows=(1,), min_co=(3,) it gives covis-power's map); the "
        "building block stays: mappers.masked_embedding(X, mask, sensor, 'covis-power')"),
    "VIS-BA": (
        f"a dead end (its figures: {_DEAD_ENDS}); use VIS-BA-WALK, the same adjustment with "
        "the walk's continuity prior (with continuity=False, align=False, overrelax=0.0, "
        "grid_cells=6, prior_iters=2, model_rounds=None it gives VIS-BA's map, as does "
        "mappers.VisibilityAdjustment())"),
    "covis-nonmetric": (
        "a building block, not a method of its own: DROPOUT-BLEND's ordinal member; use "
        "DROPOUT-BLEND (visibility) or COVIS-AUTO (bearing), or call "
        "mappers.masked_embedding(X, mask, sensor, 'covis-nonmetric')"),
    "covis-angle": (
        "a building block, not a method of its own: COVIS-AUTO's branch for a local view; use "
        "COVIS-AUTO, or call mappers.masked_embedding(X, mask, 'bearing', 'covis-angle')"),
    "covis-cal": (
        "a building block, not a method of its own: COVIS-AUTO's branch for a global view; use "
        "COVIS-AUTO (bearing) or COVIS-SPARSE (visibility, bearing), or call "
        "mappers.masked.CovisCalibrated()"),
})
"""Old label -> why it is no longer a label and what to use instead: the dead ends (their
figures are in ``docs/dead-ends.md``) and the building blocks of other methods, which stay
callable in their modules. :func:`resolve_method` refuses them with that text."""

_OLD_LABELS: dict[str, str] = {k.lower(): k for k in (*ALIASES, *RETIRED)}


def _caller_level() -> int:
    """The ``stacklevel`` that names the first caller outside this package."""
    here = os.path.dirname(os.path.abspath(__file__)) + os.sep
    frame, level = sys._getframe(1), 1
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(here):
        frame, level = frame.f_back, level + 1
    return level


def _canonical(method: str) -> tuple[str | None, dict[str, Any]]:
    """The registered label ``method`` names and the parameters it implies: an exact label; an
    old label (:data:`ALIASES`, with a FutureWarning; :data:`RETIRED`: ValueError) in any case
    but its new label's own spelling; else a label matched case-insensitively (None: none)."""
    if method in _METHODS:
        return method, {}
    folded = method.strip().lower()
    registered = {k.lower(): k for k in _METHODS}.get(folded)
    old = _OLD_LABELS.get(folded)
    if old in ALIASES and registered in (None, ALIASES[old].label):
        new = ALIASES[old]
        given = f" with {_params_text(new.params)}" if new.params else ""
        warnings.warn(f"method {method!r} is now spelled {new.label!r}{given}; the old label will "
                      "stop resolving in a future release", FutureWarning,
                      stacklevel=_caller_level())
        return new.label, dict(new.params)
    if old in RETIRED and registered is None:
        raise ValueError(f"method {method!r} is no longer a label: {RETIRED[old]}")
    return registered, {}


def implied_params(spec: MethodSpec) -> dict[str, Any]:
    """The parameters :func:`resolve_method` put in ``spec``'s defaults beyond the registered
    spec's (an old label's, such as ``CAL-SMA-SPARSE``'s ``sparse=True``, or a default's): what
    to pass with ``spec.label`` to build the same method."""
    registered = _METHODS[spec.label].defaults if spec.label in _METHODS else {}
    return {k: v for k, v in spec.defaults.items() if k not in registered or registered[k] != v}


def resolve_method(method: str | None, sensor, masked: bool = False,
                   n_objects: int | None = None) -> MethodSpec:
    """The spec of ``method`` (a label, matched case-insensitively; None = the default for
    ``sensor`` — a sensor, or a fused set of them — and the kind of history, as
    :func:`mappers.defaults.choose_method` chooses it, its parameters in the spec's
    ``defaults``) if it maps such histories, else a ValueError that lists the labels which do.

    An old label resolves to its new one (:data:`ALIASES`, with a FutureWarning; parameters it
    stands for, such as ``CAL-SMA-SPARSE``'s ``sparse=True``, are in the spec's ``defaults``)
    or is refused, saying where it went and what to use instead (:data:`RETIRED`)."""
    key = check_sensor_set(sensor)
    sensor = sensor_name(key)
    kind = "masked" if masked else "complete"
    fits = methods_for(key, masked)
    if method is None:
        chosen = choose_method(key, masked=bool(masked), n_objects=n_objects)
        if chosen is None or chosen[0] not in _METHODS:
            raise ValueError(f"no default method for {kind} {sensor} histories; choose from {list(fits)}")
        label, implied = chosen
    elif not isinstance(method, str):
        raise ValueError(f"method must be a label (str) or None, got {method!r}")
    else:
        label, implied = _canonical(method)
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
    return spec.with_defaults(implied)


# The built-in methods, in table order: the paper's ten (its Table 1), ours for complete
# histories, those for masked histories, the fused ones and the viewpoint adjustments. The
# paper's keep its spellings; ours are upper case with hyphens. Older labels: ALIASES, RETIRED.
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
    MethodSpec("CAL-SMA", "mappers.calibrated.factory:_cal_sma", {},
               {"n_neighbors": [8, 10, 12, 14, 16]},
               "calibrated anchored SMACOF with fold guard; sparse=True: on sparse pairs, for "
               "thousands of objects", uses_anchors=True, scalable={"sparse": True}),
    MethodSpec("UNFOLD", "mappers.calibrated.unfolding:_unfold", {}, {},
               "classical metric unfolding of the squared range histories (range sensor only)",
               sensors=("range",), normalize=False),
    MethodSpec("RANGE-QUANTILE", "mappers.masked.pair_maps:_range_quantile",
               description="quantile of same-step range differences, anchored weighted SMACOF",
               sensors=("range",), **_MASKED),
    MethodSpec("COVIS-ENSEMBLE", "mappers.masked.ensemble:CovisEnsemble",
               description="mean of anchored co-observation maps over windows of consecutive "
                           "steps", uses_timeline=True, **_MASKED),
    MethodSpec("COVIS-AUTO", "mappers.masked.covis_auto:CovisAuto",
               description="CAL-SMA of the angle-weighted co-observation coefficient when most "
                           "pairs are seen together, else its ordinal fit",
               sensors=("bearing",), **_MASKED),
    MethodSpec("COVIS-SPARSE", "mappers.masked.covis_sparse:SparseCovis", {},
               {"n_neighbors": [8, 12, 16]},
               "CAL-SMA (sparse=True) of the co-observation coefficient on sparse co-observed "
               "pairs: masked histories of thousands of objects", sensors=_COVIS_SENSORS,
               sparse=True, max_objects=None, **_MASKED),
    MethodSpec("DROPOUT-BLEND", "mappers.masked.dropout_blend:DropoutBlend",
               description="mean of CAL-SMA on 3-step averaged rows and the ordinal "
                           "co-observation map, anchored",
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
               "bundle adjustment), anchors fixed", sensors=("bearing",), sparse=True, **_MASKED),
    MethodSpec("VIS-BA-WALK", "mappers.viewpoints.visibility:VisibilityAdjustment",
               {"continuity": True, "align": True, "overrelax": 1.0, "grid_cells": 4,
                "prior_iters": 1, "model_rounds": 2},
               {"max_rounds": [3, 5, 8], "grid_cells": [4, 6]},
               "the localisation-free visibility map refined by estimating the viewpoints "
               "(visibility bundle adjustment: a range threshold with misses) under the walk's "
               "continuity prior (the steps' viewpoints an HMM: consecutive steps close "
               "together), anchors fixed: the default for flickering visibility histories",
               sensors=("visibility",), uses_timeline=True, **_MASKED),
    MethodSpec("VIEW-BA", "mappers.viewpoints.view_cone:ViewAdjustment", {}, {},
               "a limited view's masked visibility map refined by estimating each step's "
               "viewpoint and heading from the observed sets (view-cone bundle adjustment), "
               "anchors fixed", uses_anchors=True, sensors=("visibility",), normalize=False,
               histories=("masked",), uses_timeline=True),
)
_METHODS: dict[str, MethodSpec] = {spec.label: spec for spec in _BUILTINS}
