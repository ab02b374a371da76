"""``build_map`` in 3-D: what :func:`mappers.build_map` does when the anchors are (A, 3).

The dimension comes from the anchors: (A, 3) anchor positions give a 3-D map. Histories:
visibility (M, N) of 0/1 -> ``COVIS-3D``; a 3-D bearing history (M, 3N) of unit rays, or fused
``{"bearing": rays, "range": (M, N)}`` -> ``SPATIAL-BA`` (:mod:`mappers.spatial.rays` says the
layout); ranges alone (M, N), complete or masked -> ``RANGE-3D``. A 2-D bearing history of
(cos, sin) pairs with 3-D anchors is refused, naming it.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import Any

import numpy as np

from mappers.defaults import choose_method
from mappers.fitting import Map
from mappers.spatial.covisibility_3d import CoVisibility3D
from mappers.spatial.frustum import FrustumAdjustment
from mappers.spatial.frustum_walk import FrustumWalkAdjustment
from mappers.spatial.range_3d import Range3D
from mappers.spatial.rays import RAY_COLUMNS
from mappers.spatial.sightings_median_3d import SightingsMedian3D
from mappers.spatial.spatial_ba import SpatialAdjustment

__all__ = ["METHODS_3D", "anchor_dimension", "build_map_3d", "default_for_histories_3d",
           "default_method_3d", "fit_map_3d", "step_columns_3d"]

METHODS_3D = {"SPATIAL-BA": SpatialAdjustment, "COVIS-3D": CoVisibility3D, "RANGE-3D": Range3D,
              "FRUSTUM-BA": FrustumAdjustment, "FRUSTUM-BA-WALK": FrustumWalkAdjustment,
              "COVIS-3D-MEDIAN": SightingsMedian3D}
"""The 3-D methods by label: rays (and ranges) -> SPATIAL-BA, sightings -> COVIS-3D (or
FRUSTUM-BA given a planar robot's camera calibration, ``method="FRUSTUM-BA"``, or FRUSTUM-BA-WALK,
the same with the walk prior on the ordered steps' viewpoints, or COVIS-3D-MEDIAN, the median of
three co-observation embeddings of ordered steps), ranges alone -> RANGE-3D."""

SENSORS_3D = {"SPATIAL-BA": ("bearing", "range-bearing"), "COVIS-3D": ("visibility",),
              "FRUSTUM-BA": ("visibility",), "FRUSTUM-BA-WALK": ("visibility",),
              "COVIS-3D-MEDIAN": ("visibility",),
              "RANGE-3D": ("range",)}
"""The histories each 3-D method maps (``"range-bearing"``: fused rays and ranges)."""


def anchor_dimension(anchor_positions: Any) -> int | None:
    """2 or 3: the columns of the anchor positions when they are an (A, 2) or (A, 3) array;
    None when they are neither (the 2-D checks then name the problem)."""
    try:
        shape = np.shape(anchor_positions)
    except (TypeError, ValueError):
        return None
    return shape[1] if len(shape) == 2 and shape[1] in (2, 3) else None


def _unpack(histories, sensor, mask):
    parts = getattr(histories, "parts", None)
    if isinstance(parts, Mapping) and not isinstance(histories, Mapping):
        histories = {k: getattr(v, "matrix", v) for k, v in parts.items()}
    if isinstance(histories, Mapping):
        masks = mask if isinstance(mask, Mapping) else {}
        return dict(histories), "range-bearing" if "range" in histories else "bearing", masks
    if hasattr(histories, "matrix") and not isinstance(histories, np.ndarray):
        sensor = sensor if sensor is not None else getattr(histories, "sensor", None)
        mask = mask if mask is not None else getattr(histories, "mask", None)
        histories = histories.matrix
    X = np.asarray(histories, dtype=float)
    if sensor is None:
        observed = X if mask is None else X[np.asarray(mask, dtype=bool)]
        sensor = "visibility" if np.all((observed == 0) | (observed == 1)) else "bearing"
    if sensor not in ("visibility", "bearing", "range"):
        raise ValueError(f"with 3-D anchors a single history is 'visibility', 'bearing' (3-D "
                         f"rays) or 'range', got sensor {sensor!r}")
    return X, sensor, mask


def default_method_3d(sensor, masked: bool = False) -> str:
    """The 3-D default for a sensor (or set of fused sensors), the ``spatial`` column of
    :data:`mappers.defaults.DEFAULTS`: ``"COVIS-3D"`` for sightings, ``"SPATIAL-BA"`` for rays
    (with or without ranges), ``"RANGE-3D"`` for ranges alone. A sensor with no 3-D method is a
    ValueError saying so."""
    chosen = choose_method(sensor, masked=masked, dimension=3)
    if chosen is None:
        raise ValueError(f"no 3-D method maps {sensor!r} histories: with 3-D anchors give "
                         "sightings (visibility), 3-D rays (bearing), ranges or rays and ranges")
    return chosen[0]


def default_for_histories_3d(histories, sensor: str | None = None, mask=None) -> str:
    """The label :func:`build_map_3d` maps ``histories`` with when no method is given."""
    X, sensor, mask = _unpack(histories, sensor, mask)
    masked = any(v is not None for v in mask.values()) if isinstance(mask, Mapping) \
        else mask is not None
    return default_method_3d(sensor, masked)


def build_map_3d(histories, anchor_ids, anchor_positions, method: str | None = None, *,
                 sensor: str | None = None, mask=None, **params) -> Map:
    """The 3-D map of the objects (see the module's docstring): a :class:`mappers.Map` whose
    ``positions`` and ``embedding`` are (M, 3), NaN rows for the objects listed in
    ``unmapped``. ``method``: ``"SPATIAL-BA"``, ``"COVIS-3D"``, ``"FRUSTUM-BA"``,
    ``"FRUSTUM-BA-WALK"``, ``"COVIS-3D-MEDIAN"`` or ``"RANGE-3D"`` (None: by the sensor);
    ``params`` go to the method."""
    return fit_map_3d(histories, anchor_ids, anchor_positions, method, sensor=sensor, mask=mask,
                      **params)[0]


def fit_map_3d(histories, anchor_ids, anchor_positions, method: str | None = None, *,
               sensor: str | None = None, mask=None, **params):
    """:func:`build_map_3d`'s map, with the fitted estimator and the unpacked histories, their
    mask(s) and sensor: ``(Map, est, X, mask, sensor)`` (what the covariances need)."""
    X, sensor, mask = _unpack(histories, sensor, mask)
    label = method.upper() if isinstance(method, str) else default_method_3d(sensor)
    if label not in METHODS_3D:
        raise ValueError(f"method {method!r} does not map in 3-D; 3-D methods: {list(METHODS_3D)}")
    if sensor not in SENSORS_3D[label]:
        raise ValueError(f"method {label!r} does not map {sensor} histories (it maps "
                         f"{' and '.join(SENSORS_3D[label])})")
    est = METHODS_3D[label](**params)
    inputs = {"masks": mask} if isinstance(X, Mapping) else {"mask": mask}
    Y = est.fit_transform(X, anchor_ids=anchor_ids, anchor_positions=anchor_positions, **inputs)
    placed = np.all(np.isfinite(Y), axis=1)
    unmapped = tuple(int(i) for i in np.flatnonzero(~placed))
    # worded as the 2-D notes (mappers.fitting): the object ids (rows of the history), all of them
    notes = (f"objects {list(unmapped)} could not be placed from their histories",) \
        if unmapped else ()
    notes += tuple(getattr(est, "notes_", ()))
    result = Map(positions=Y, unmapped=unmapped, embedding=Y.copy(), method=label,
                 params={k: getattr(est, k) for k in inspect.signature(type(est)).parameters},
                 sensor=sensor, warnings=notes, affine=None,
                 anchor_ids=tuple(int(i) for i in np.asarray(anchor_ids)))
    return result, est, X, mask, sensor


def step_columns_3d(X, sensor: str) -> dict | int:
    """Columns one step takes in 3-D histories ``X`` of ``sensor`` as :func:`fit_map_3d` unpacks
    them: 1 for sightings and ranges, :data:`~mappers.spatial.rays.RAY_COLUMNS` for rays, a
    mapping of those for fused histories."""
    if isinstance(X, Mapping):
        return {k: RAY_COLUMNS if k == "bearing" else 1 for k in X}
    return RAY_COLUMNS if sensor == "bearing" else 1
