"""Which method maps which data: the one table of defaults, and the function that chooses.

``build_map``, :func:`mappers.default_method`, the command line and the MRCLAM command all ask
:func:`choose_method`. A row of :data:`DEFAULTS` is keyed by the sensor (or the frozenset of a
fused history's sensors) and whether the history is masked, and says

- ``method``: the default;
- ``localisation_free``: the map that estimates no viewpoint (and its parameters) — the start an
  adjustment refines, one ``method=`` away for a user who wants the paper's kind of map;
- ``large``: the default above :data:`SCALABLE_ABOVE_OBJECTS` objects (None: ``method``);
- ``dropouts``: the default for a complete history that flickers like a sensor with dropouts
  (:func:`mappers.core.flicker.flicker_rate`), whose steps are ordered like a walk's.

The figures behind each choice are on the documentation's benchmarks page.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import scipy.sparse as sp

from mappers.core.flicker import FLICKER_THRESHOLD, MIN_PERSISTENCE, flicker_rate, persistence
from mappers.core.sensors import check_sensor_set

__all__ = [
    "DEFAULTS",
    "DEFAULT_METHODS",
    "DENSE_MAX_OBJECTS",
    "SCALABLE_ABOVE_OBJECTS",
    "Choice",
    "choose_for_history",
    "choose_method",
    "localisation_free",
]

DENSE_MAX_OBJECTS = 5000
"""Largest M a method holding (M, M) matrices is given by default (``MethodSpec.max_objects``):
one such float64 matrix is 200 MB there and the paper's methods hold several."""

SCALABLE_ABOVE_OBJECTS = 500
"""Above this many objects the ``large`` default is chosen: dense CAL-SMA takes tens of seconds
at M = 1,000, its sparse form a few."""


@dataclass(frozen=True)
class Choice:
    """One row of :data:`DEFAULTS` (see the module's docstring)."""

    method: str
    localisation_free: str
    localisation_free_params: Mapping[str, Any] = field(default_factory=dict)
    large: str | None = None
    dropouts: str | None = None


_RB = frozenset({"range", "bearing"})
_VB = frozenset({"visibility", "bearing"})

DEFAULTS: Mapping[tuple[str | frozenset[str], bool], Choice] = MappingProxyType({
    ("visibility", False): Choice("CAL-SMA", "CAL-SMA", large="CAL-SMA-SPARSE",
                                  dropouts="VIS-BA-WALK"),
    ("bearing", False): Choice("BEARING-BA", "CAL-SMA", large="CAL-SMA-SPARSE"),
    ("range", False): Choice("UNFOLD", "UNFOLD"),
    # VIEW-BA's joint step solves a (2F, 2F) system of the F free objects: above the size
    # threshold masked visibility keeps VIEW-BA's start.
    ("visibility", True): Choice("VIEW-BA", "dropout-blend", large="dropout-blend"),
    ("bearing", True): Choice("BEARING-BA", "covis-auto", large="covis-sparse"),
    ("range", True): Choice("range-quantile", "range-quantile"),
    (_RB, False): Choice("LOC-SMA", "LOC-SMA", {"refine": None}),
    (_RB, True): Choice("LOC-SMA", "LOC-SMA", {"refine": None}),
    (_VB, False): Choice("VB-SMA", "VB-SMA", {"refine": False}),
})
"""(sensor or frozenset of sensors, masked) -> :class:`Choice`: the one table of defaults."""

DEFAULT_METHODS: Mapping[tuple[str | frozenset[str], bool], str] = MappingProxyType(
    {key: choice.method for key, choice in DEFAULTS.items()})
"""(sensor, masked) -> the default label, read from :data:`DEFAULTS` (a read-only view)."""


def _row(sensor, masked: bool) -> Choice | None:
    return DEFAULTS.get((check_sensor_set(sensor), bool(masked)))


def choose_method(sensor, *, masked: bool = False, n_objects: int | None = None,
                  dropouts: bool = False) -> str | None:
    """The default label for histories of ``sensor`` (a sensor or a set of fused sensors),
    complete or ``masked``, of ``n_objects`` objects (None: not known), that flicker like a
    sensor with ``dropouts`` (complete histories only); None when the table has no row."""
    row = _row(sensor, masked)
    if row is None:
        return None
    if n_objects is not None and n_objects > SCALABLE_ABOVE_OBJECTS and row.large:
        return row.large
    if dropouts and not masked and row.dropouts:
        return row.dropouts
    return row.method


def localisation_free(sensor, masked: bool = False) -> tuple[str, dict[str, Any]]:
    """``(label, params)`` of the map that estimates no viewpoint for such histories: the start
    of the viewpoint adjustments, and the paper's kind of map. KeyError if the table has no
    row."""
    row = _row(sensor, masked)
    if row is None:
        raise KeyError(f"no default for {'masked' if masked else 'complete'} {sensor!r} histories")
    return row.localisation_free, dict(row.localisation_free_params)


def choose_for_history(X, mask, sensor: str, timeline=None,
                       notes: list[str] | None = None) -> str | None:
    """:func:`choose_method` for a single sensor's histories as ``build_map`` checked them
    (``mappers.fitting.check_inputs``); when it is the dropout default (a complete, dense
    history of at most :data:`SCALABLE_ABOVE_OBJECTS` objects, whose steps are ordered like a
    walk's — :func:`mappers.core.flicker.persistence` at least :data:`MIN_PERSISTENCE` — and
    that flickers like a sensor with dropouts, :func:`mappers.core.flicker.flicker_rate` above
    :data:`FLICKER_THRESHOLD`), a note says so. Perfect histories never flicker so much: their
    rate is a few percent."""
    n = X.shape[0]
    plain = choose_method(sensor, masked=mask is not None, n_objects=n)
    if (mask is not None or sp.issparse(X) or n > SCALABLE_ABOVE_OBJECTS
            or choose_method(sensor, dropouts=True, n_objects=n) == plain):
        return plain
    if not persistence(X, timeline) >= MIN_PERSISTENCE:
        return plain  # unordered viewpoints: a flicker says nothing about misses
    rate = flicker_rate(X, timeline)
    if not rate > FLICKER_THRESHOLD:
        return plain
    label = choose_method(sensor, dropouts=True, n_objects=n)
    if notes is not None:
        notes.append(f"the history flickers (visible at the steps before and after, not at the step: "
                     f"{rate:.0%} of such steps, above {FLICKER_THRESHOLD:.0%}): a sensor with "
                     f"dropouts, mapped with {label!r} (which assumes the steps are ordered like "
                     "a walk's, consecutive viewpoints close together)")
    return label
