"""Which method maps which data: the one table of defaults, and the function that chooses.

``build_map``, :func:`mappers.default_method`, the command line and the MRCLAM command all ask
:func:`choose_method`. A row of :data:`DEFAULTS` is keyed by the sensor (or the frozenset of a
fused history's sensors) and whether the history is masked, and says

- ``method``: the default;
- ``localisation_free``: the map that estimates no viewpoint (and its parameters) — the start an
  adjustment refines, one ``method=`` away for a user who wants the paper's kind of map;
- ``large``: the default above :data:`SCALABLE_ABOVE_OBJECTS` objects (None: ``method``), with
  its parameters (``CAL-SMA`` with ``sparse=True``: its scalable form);
- ``dropouts``: the default for a complete history that flickers like a sensor with dropouts
  (:func:`mappers.core.flicker.flicker_rate`), whose steps are ordered like a walk's;
- ``logged``: the default for a real robot's logged run (the UTIAS MRCLAM dataset,
  ``lfmdr mrclam``), where a landmark is in view in a few percent of the steps and the sensor's
  model is not known (None: ``method``), chosen leave-one-run-out on the logs
  (``benchmarks/bench_mrclam.py``);
- ``sightings``: the default for a masked history that is a log of sightings
  (:func:`is_sightings_log`: the mask says what was seen, not what was in view) whose steps are
  ordered like a walk's (:func:`mappers.core.flicker.persistence` at least
  :data:`mappers.core.flicker.MIN_PERSISTENCE`), in place of ``method`` when that is
  ``VIEW-BA`` (None: ``localisation_free``, as for such a log of unordered viewpoints);
- ``spatial``: the default when the anchors are 3-D, (A, 3) positions (a label of
  :data:`mappers.spatial.METHODS_3D`; None: no 3-D path for such histories): ``COVIS-3D`` for
  sightings, ``SPATIAL-BA`` for 3-D rays with or without ranges, ``RANGE-3D`` for ranges alone
  (issue 34). A 3-D history's
  unseen entries are zeros or masked alike, so both rows of a sensor name the same method.

Each choice is a label with its parameters, ``(label, params)``. The figures behind each choice are
on the documentation's benchmarks page.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
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
    "is_sightings_log",
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
    large_params: Mapping[str, Any] = field(default_factory=dict)
    dropouts: str | None = None
    dropouts_params: Mapping[str, Any] = field(default_factory=dict)
    logged: str | None = None
    logged_params: Mapping[str, Any] = field(default_factory=dict)
    spatial: str | None = None
    sightings: str | None = None
    sightings_params: Mapping[str, Any] = field(default_factory=dict)


_RB = frozenset({"range", "bearing"})
_VB = frozenset({"visibility", "bearing"})
_SPARSE: Mapping[str, Any] = MappingProxyType({"sparse": True})
_LARGE_BEARING_BA: Mapping[str, Any] = MappingProxyType(
    {"start": "COVIS-SPARSE", "start_params": MappingProxyType({"n_rounds": 5}),
     "schur_solver": "cg", "schur_rtol": 1e-3, "gain_tol": 1e-2, "max_rounds": 6})
_COVIS_3D, _SPATIAL_BA, _RANGE_3D = "COVIS-3D", "SPATIAL-BA", "RANGE-3D"
# A walk-ordered log of sightings: COVIS-ENSEMBLE over windows of 1-6 steps, the members' maps
# combined by each object's geometric median (one failed member cannot move it). Chosen on the
# simulators' tuning layouts (the project's world and the second simulator, seeds 100-111) and
# confirmed on their fresh layouts and on MRCLAM, which had no say. Where its members scatter by
# more than 0.15 of the anchors' spread (short logs: too few co-observations) the map is
# DROPOUT-BLEND's: chosen on the tests' synthetic walks (tests/synthetic_walk.py), never fires
# on the simulators' logs or MRCLAM (docs/dead-ends.md, "Defaults that carry").
_SIGHTINGS: Mapping[str, Any] = MappingProxyType(
    {"windows": (1, 2, 3, 4, 6), "min_co": (3, 5), "combine": "median", "max_spread": 0.15})

DEFAULTS: Mapping[tuple[str | frozenset[str], bool], Choice] = MappingProxyType({
    ("visibility", False): Choice("CAL-SMA", "CAL-SMA", large="CAL-SMA", large_params=_SPARSE,
                                  dropouts="VIS-BA-WALK", spatial=_COVIS_3D),
    ("bearing", False): Choice("BEARING-BA", "CAL-SMA", large="CAL-SMA", large_params=_SPARSE,
                               spatial=_SPATIAL_BA),
    ("range", False): Choice("UNFOLD", "UNFOLD", spatial=_RANGE_3D),
    # VIEW-BA's joint step solves a (2F, 2F) system of the F free objects: above the size
    # threshold masked visibility keeps VIEW-BA's start. On logged runs (MRCLAM) the pattern of
    # what was seen is mapped, for bearing too: no bearing-only statistic measured better on
    # them (docs/bearing-on-real-data.md).
    ("visibility", True): Choice("VIEW-BA", "DROPOUT-BLEND", large="DROPOUT-BLEND",
                                 logged="COVIS-ENSEMBLE", spatial=_COVIS_3D,
                                 sightings="COVIS-ENSEMBLE", sightings_params=_SIGHTINGS),
    # Above the size threshold masked bearing is BEARING-BA started from COVIS-SPARSE (five
    # calibration rounds instead of ten: the adjustment refines its map to the same error), its
    # joint step on the sparse Schur engine (conjugate gradients to a relative residual of
    # 1e-3), until a round lowers the cost by at most 1 % of the start's (two rounds at
    # M = 1,000), at most six (issue 34's goal: M = 1,000, N = 20,000 in <= 10 s,
    # docs/guide/scale.md).
    ("bearing", True): Choice("BEARING-BA", "COVIS-AUTO", large="BEARING-BA",
                              large_params=_LARGE_BEARING_BA, logged="COVIS-ENSEMBLE", spatial=_SPATIAL_BA),
    ("range", True): Choice("RANGE-QUANTILE", "RANGE-QUANTILE", spatial=_RANGE_3D),
    (_RB, False): Choice("LOC-SMA", "LOC-SMA", {"refine": None}, spatial=_SPATIAL_BA),
    (_RB, True): Choice("LOC-SMA", "LOC-SMA", {"refine": None}, spatial=_SPATIAL_BA),
    (_VB, False): Choice("VB-SMA", "VB-SMA", {"refine": False}),
})
"""(sensor or frozenset of sensors, masked) -> :class:`Choice`: the one table of defaults."""

DEFAULT_METHODS: Mapping[tuple[str | frozenset[str], bool], str] = MappingProxyType(
    {key: choice.method for key, choice in DEFAULTS.items()})
"""(sensor, masked) -> the default label, read from :data:`DEFAULTS` (a read-only view)."""


def _row(sensor, masked: bool) -> Choice | None:
    return DEFAULTS.get((check_sensor_set(sensor), bool(masked)))


def choose_method(sensor, *, masked: bool = False, n_objects: int | None = None,
                  dropouts: bool = False, logged: bool = False,
                  dimension: int = 2) -> tuple[str, dict[str, Any]] | None:
    """``(label, params)`` of the default for histories of ``sensor`` (a sensor or a set of fused
    sensors), complete or ``masked``, of ``n_objects`` objects (None: not known), that flicker
    like a sensor with ``dropouts`` (complete histories only), or ``logged`` by real robots (a
    run of the MRCLAM dataset; it outranks the others); with 3-D anchors (``dimension=3``) the
    row's ``spatial`` column. None when the table has no row (or no 3-D method)."""
    if dimension not in (2, 3):
        raise ValueError(f"dimension must be 2 or 3 (the anchors' columns), got {dimension!r}")
    row = _row(sensor, masked)
    if row is None:
        return None
    if dimension == 3:
        return (row.spatial, {}) if row.spatial else None
    if logged and row.logged:
        return row.logged, dict(row.logged_params)
    if n_objects is not None and n_objects > SCALABLE_ABOVE_OBJECTS and row.large:
        return row.large, dict(row.large_params)
    if dropouts and not masked and row.dropouts:
        return row.dropouts, dict(row.dropouts_params)
    return row.method, {}


def localisation_free(sensor, masked: bool = False) -> tuple[str, dict[str, Any]]:
    """``(label, params)`` of the map that estimates no viewpoint for such histories: the start
    of the viewpoint adjustments, and the paper's kind of map. KeyError if the table has no
    row."""
    row = _row(sensor, masked)
    if row is None:
        raise KeyError(f"no default for {'masked' if masked else 'complete'} {sensor!r} histories")
    return row.localisation_free, dict(row.localisation_free_params)


def is_sightings_log(X, mask) -> bool:
    """Whether a masked visibility history (``X`` and ``mask`` (M, N), dense or scipy sparse)
    is a log of sightings: every observed entry reads 1, so the mask says what was seen, not what
    was in view (a table of detections: ``lfmdr_gym.histories.observations``). VIEW-BA reads the
    mask as the view cone, which such a log is not: through a 90-degree view of both simulators
    its map of the sightings alone is worse than its start map, and on MRCLAM it keeps it
    (``benchmarks/bench_defaults_carry.py``). False for a complete history (``mask`` None)."""
    if mask is None:
        return False
    if sp.issparse(mask) or sp.issparse(X):
        observed = sp.csr_array(mask, dtype=bool)
        seen = observed.multiply(sp.csr_array(X) > 0.5)
        return observed.nnz > 0 and seen.nnz == observed.nnz
    observed = np.asarray(mask, dtype=bool)
    return bool(observed.any() and np.all(np.asarray(X)[observed] > 0.5))


def _seen(X, mask) -> np.ndarray:
    """(M, N) dense 0/1: the sightings of a log of sightings (every observed entry is one)."""
    return (sp.csr_array(mask, dtype=bool).toarray() if sp.issparse(mask)
            else np.asarray(mask, dtype=bool)).astype(float)


def choose_for_history(X, mask, sensor: str, timeline=None,
                       notes: list[str] | None = None) -> tuple[str, dict[str, Any]] | None:
    """:func:`choose_method` for a single sensor's histories as ``build_map`` checked them
    (``mappers.fitting.check_inputs``); when it is the dropout default (a complete, dense
    history of at most :data:`SCALABLE_ABOVE_OBJECTS` objects, whose steps are ordered like a
    walk's — :func:`mappers.core.flicker.persistence` at least :data:`MIN_PERSISTENCE` — and
    that flickers like a sensor with dropouts, :func:`mappers.core.flicker.flicker_rate` above
    :data:`FLICKER_THRESHOLD`), a note says so. Perfect histories never flicker so much: their
    rate is a few percent. A masked visibility history that is a log of sightings
    (:func:`is_sightings_log`) gets the row's ``sightings`` default instead of ``VIEW-BA`` when
    its steps are ordered like a walk's, else the localisation-free map, with a note."""
    n = X.shape[0]
    plain = choose_method(sensor, masked=mask is not None, n_objects=n)
    if plain is not None and plain[0] == "VIEW-BA" and is_sightings_log(X, mask):
        row = _row(sensor, True)
        walk = row.sightings is not None and persistence(_seen(X, mask), timeline) >= MIN_PERSISTENCE
        label, params = ((row.sightings, dict(row.sightings_params)) if walk
                         else localisation_free(sensor, masked=True))
        if notes is not None:
            order = ("its steps are ordered like a walk's" if walk
                     else "its steps are not ordered like a walk's")
            notes.append(f"every observed entry of the masked visibility history is a sighting: a "
                         f"log of what was seen, not of what was in view, so the mask is not a "
                         f"view cone and it is mapped with {label!r}, not 'VIEW-BA' ({order})")
        return label, params
    if (mask is not None or sp.issparse(X) or n > SCALABLE_ABOVE_OBJECTS
            or choose_method(sensor, dropouts=True, n_objects=n) == plain):
        return plain
    if not persistence(X, timeline) >= MIN_PERSISTENCE:
        return plain  # unordered viewpoints: a flicker says nothing about misses
    rate = flicker_rate(X, timeline)
    if not rate > FLICKER_THRESHOLD:
        return plain
    label, params = choose_method(sensor, dropouts=True, n_objects=n)
    if notes is not None:
        notes.append(f"the history flickers (visible at the steps before and after, not at the step: "
                     f"{rate:.0%} of such steps, above {FLICKER_THRESHOLD:.0%}): a sensor with "
                     f"dropouts, mapped with {label!r} (which assumes the steps are ordered like "
                     "a walk's, consecutive viewpoints close together)")
    return label, params
