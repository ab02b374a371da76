"""The one registry of mapping methods: label -> :class:`MethodSpec`, and the default per input.

Every method — the paper's ten (:mod:`mappers.methods`), CAL-SMA (:mod:`mappers.calibrated`),
UNFOLD (:mod:`mappers.unfolding`), the methods for masked histories (:mod:`mappers.masked`,
:mod:`mappers.ensemble`, :mod:`mappers.covis_calibrated`), the bearing default BEARING-BA
(:mod:`mappers.bearing_adjustment`), VIS-BA (:mod:`mappers.visibility_adjustment`: a visibility
map refined by estimating the viewpoints; with the walk's continuity prior, VIS-BA-WALK, the
default for flickering visibility histories), the masked visibility default VIEW-BA
(:mod:`mappers.view_adjustment`: the viewpoints and headings of a limited view) and any a user
registers —
is a :class:`MethodSpec` in :data:`METHODS`. A spec says what the method accepts (which sensors
or fused sets of sensors, complete and/or masked histories); the pipeline, the protocol and the
command line choose and check methods by the spec alone (:func:`resolve_method`). Fused methods
— LOC-SMA (:mod:`mappers.range_bearing`) for range + bearing, VB-SMA
(:mod:`mappers.visibility_bearing`) for visibility + bearing — are registered like the others,
keyed by their frozenset of sensors.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from mappers.sensors import SENSORS, check_sensor_set, sensor_name

__all__ = [
    "DEFAULT_METHODS",
    "DROPOUT_DEFAULTS",
    "DENSE_MAX_OBJECTS",
    "SCALABLE_ABOVE_OBJECTS",
    "SCALABLE_DEFAULTS",
    "check_size",
    "HISTORY_KINDS",
    "METHODS",
    "MappingError",
    "MethodSpec",
    "methods_for",
    "register_method",
    "resolve_method",
]

DENSE_MAX_OBJECTS = 5000
"""Largest M a method holding (M, M) matrices is given by default (:attr:`MethodSpec.max_objects`):
one such float64 matrix is 200 MB there and the paper's methods hold several."""

SCALABLE_ABOVE_OBJECTS = 500
"""Above this many objects ``build_map`` picks the scalable default (:data:`SCALABLE_DEFAULTS`)
when no method is named: dense CAL-SMA takes about 40 s at M = 1,000, its sparse form 2 s."""

HISTORY_KINDS: tuple[str, ...] = ("complete", "masked")
"""``"complete"``: every entry is a measurement (a 0 is "not visible"); ``"masked"``: a boolean
mask says which entries the sensor measured, the others are unknown."""


class MappingError(ValueError):
    """A method could not embed the data (eigenproblem failure, solver failure, ...)."""


@dataclass(frozen=True)
class MethodSpec:
    """One mapping method: its label, how to build it, its parameters and what it accepts.

    ``factory(**params)`` returns an object with ``fit_transform(X, **inputs) -> (M, 2)``; the
    parameters it accepts are the names in its signature (:attr:`parameters`). What
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
    factory: Callable[..., Any]
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

    def resolved_params(self, params: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """Every parameter's value: the factory's own defaults, updated by ``defaults`` and then
        by ``params`` (unknown names: ValueError)."""
        params = dict(params or {})
        self.check_params(params)
        own = {name: p.default for name, p in inspect.signature(self.factory).parameters.items()
               if p.default is not inspect.Parameter.empty}
        return {**own, **self.defaults, **params}

    def build(self, **params: Any) -> Any:
        """The estimator with ``defaults`` updated by ``params`` (unknown names: ValueError)."""
        return self.factory(**self.resolved_params(params))

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


_METHODS: dict[str, MethodSpec] = {}
_BUILTINS_LOADED = False


def _load_builtins() -> None:
    """Register the built-in methods once, in table order: the paper's ten (its Table 1), ours
    for complete histories, then those for masked histories. Done on first use of the registry,
    so that ``import mappers`` (and the world, which imports the sensor vocabulary) stays light."""
    global _BUILTINS_LOADED
    if _BUILTINS_LOADED:
        return
    _BUILTINS_LOADED = True
    from mappers import (
        bearing_adjustment,
        calibrated,
        covis_calibrated,
        covis_sparse,
        dropout_blend,
        ensemble,
        masked,
        methods,
        range_bearing,
        scalable,
        unfolding,
        view_adjustment,
        visibility_adjustment,
        visibility_bearing,
    )

    for spec in (*methods.SPECS, calibrated.SPEC, unfolding.SPEC, scalable.SPEC, *masked.SPECS,
                 ensemble.SPEC, *covis_calibrated.SPECS, covis_sparse.SPEC, dropout_blend.SPEC,
                 range_bearing.SPEC, visibility_bearing.SPEC, bearing_adjustment.SPEC,
                 *visibility_adjustment.SPECS, view_adjustment.SPEC):
        _METHODS.setdefault(spec.label, spec)


class _Registry(Mapping[str, MethodSpec]):
    """Read-only view of the registered methods, in registration order (use register_method)."""

    def __getitem__(self, label: str) -> MethodSpec:
        _load_builtins()
        return _METHODS[label]

    def __iter__(self) -> Iterator[str]:
        _load_builtins()
        return iter(list(_METHODS))

    def __len__(self) -> int:
        _load_builtins()
        return len(_METHODS)

    def __repr__(self) -> str:
        return f"METHODS({list(self)})"


METHODS: Mapping[str, MethodSpec] = _Registry()
"""Label -> :class:`MethodSpec`, in registration order (read-only view; use register_method)."""

DEFAULT_METHODS: dict[tuple[str | frozenset[str], bool], str] = {
    ("visibility", False): "CAL-SMA",
    ("bearing", False): "BEARING-BA",
    ("range", False): "UNFOLD",
    ("visibility", True): "VIEW-BA",
    ("bearing", True): "BEARING-BA",
    ("range", True): "range-quantile",
    (frozenset({"range", "bearing"}), False): "LOC-SMA",
    (frozenset({"range", "bearing"}), True): "LOC-SMA",
    (frozenset({"visibility", "bearing"}), False): "VB-SMA",
}
"""(sensor, masked) -> the label ``build_map`` uses when no method is given; a fused set of
sensors is keyed by its frozenset. The measured figures behind each choice are in the README
and ``benchmarks/``. Bearing histories, complete or masked, go to BEARING-BA, which refines the
map of the bearing default before it (CAL-SMA complete, ``covis-auto`` masked) by estimating the
viewpoints; :class:`mappers.online.OnlineMapper` updates it incrementally on complete bearing
histories (:mod:`mappers.online_bearing`). Masked visibility histories go to VIEW-BA
(:mod:`mappers.view_adjustment`), which refines ``dropout-blend``'s map by estimating each step's
viewpoint and heading from the observed sets of a limited view, and keeps that map when the mask
is not a view cone or the view is wider than 150 degrees. The fused defaults end with a bundle adjustment too,
as a parameter of the same labels: LOC-SMA ``refine="range-bearing"`` (range and angle
residuals, :mod:`mappers.range_bearing_adjustment`), VB-SMA ``refine=True`` (BEARING-BA on the
bearing part); ``refine=None`` / ``refine=False`` give the maps before."""

DROPOUT_DEFAULTS: dict[str, str] = {
    "visibility": "VIS-BA-WALK",
}
"""sensor -> the label ``build_map`` uses instead of the complete default when no method is given
and the complete history's flicker rate (:func:`mappers.flicker.flicker_rate`) is above
:data:`mappers.flicker.FLICKER_THRESHOLD`: the history has dropouts (a camera's misses), which
perfect sensing does not produce. Perfect histories stay on :data:`DEFAULT_METHODS`. Visibility:
VIS-BA-WALK (:mod:`mappers.visibility_adjustment` with the walk's continuity prior, started from
CAL-SMA; it replaced ``dropout-blend``: at ``miss_rate = 0.5`` on the 25 fresh layouts 0.049 m
against 0.069, 0.70 s per map against 0.43). It assumes the steps are ordered like a walk's,
which the routing checks (:func:`mappers.flicker.persistence`)."""

SCALABLE_DEFAULTS: dict[tuple[str, bool], str] = {
    ("visibility", False): "CAL-SMA-SPARSE",
    ("bearing", False): "CAL-SMA-SPARSE",
    ("bearing", True): "covis-sparse",
    ("visibility", True): "dropout-blend",
}
"""(sensor, masked) -> the default above :data:`SCALABLE_ABOVE_OBJECTS` objects. Masked visibility
keeps VIEW-BA's start there (``dropout-blend``, dense, up to its 5,000 objects): VIEW-BA's joint
step solves a (2F, 2F) system of the F free objects and sums N x M pairs per round."""


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
    _load_builtins()
    if not isinstance(spec, MethodSpec):
        raise ValueError(f"spec must be a MethodSpec, got {type(spec).__name__}")
    if not isinstance(spec.label, str) or not spec.label:
        raise ValueError("spec.label must be a non-empty string")
    if not callable(spec.factory):
        raise ValueError(f"spec.factory of {spec.label!r} is not callable")
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
    _load_builtins()
    key = None if sensor is None else check_sensor_set(sensor)
    return tuple(
        label for label, spec in _METHODS.items()
        if (key is None or _maps(spec, key))
        and (masked is None or ("masked" if masked else "complete") in spec.histories)
    )


def resolve_method(method: str | None, sensor, masked: bool = False,
                   n_objects: int | None = None) -> MethodSpec:
    """The spec of ``method`` (a label, matched case-insensitively; None = the default for
    ``sensor`` — a sensor, or a fused set of them — and the kind of history, the scalable one
    above :data:`SCALABLE_ABOVE_OBJECTS` objects when ``n_objects`` is given) if it maps such
    histories, else a ValueError that lists the labels which do."""
    key = check_sensor_set(sensor)
    sensor = sensor_name(key)
    kind = "masked" if masked else "complete"
    fits = methods_for(key, masked)  # loads the built-ins
    if method is None:
        large = n_objects is not None and n_objects > SCALABLE_ABOVE_OBJECTS
        method = ((large and SCALABLE_DEFAULTS.get((key, bool(masked))))
                  or DEFAULT_METHODS.get((key, bool(masked))))
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
