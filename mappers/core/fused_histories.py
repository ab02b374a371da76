"""Fused histories: several sensors' histories of the same objects over the same steps.

``build_map`` takes them as a mapping sensor -> matrix (``{"range": R, "bearing": B}``), with
masks keyed the same way; a method declares the sensor sets it maps in its
:class:`~mappers.catalog.MethodSpec` (``sensors`` entries that are frozensets). This module
checks such input and reports what is wrong with it by name: a sensor the vocabulary does not
know, matrices that do not describe the same objects and steps, a mask missing for one sensor.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from mappers.core.sensors import (
    COLUMNS_PER_STEP,
    check_matrix,
    check_sensor_set,
    check_timeline,
    check_values,
)

__all__ = ["check_fused"]


def _matrix(sensor: str, value: Any) -> tuple[np.ndarray, Any]:
    """A sensor's matrix, and the mask a ``History``-like value brings (else None)."""
    own_mask = None
    if hasattr(value, "matrix") and not isinstance(value, np.ndarray):
        given = getattr(value, "sensor", sensor)
        if given != sensor:
            raise ValueError(f"histories[{sensor!r}] holds {given} histories")
        own_mask, value = getattr(value, "mask", None), value.matrix
    X = check_matrix(value, f"histories[{sensor!r}]")
    if X.shape[1] % COLUMNS_PER_STEP[sensor]:
        raise ValueError(f"histories[{sensor!r}] has {X.shape[1]} columns, not a multiple of "
                         f"{COLUMNS_PER_STEP[sensor]} (columns per step of {sensor})")
    return X, own_mask


def _masks(mask: Any, own: dict[str, Any], shapes: dict[str, tuple[int, int]]):
    """Masks keyed by sensor (None: complete), each checked against its matrix."""
    if mask is None:
        mask = own
    elif not isinstance(mask, Mapping):
        raise ValueError(f"mask of fused histories must be a mapping sensor -> mask with the keys "
                         f"{sorted(shapes)} (None values: complete), got {type(mask).__name__}")
    missing = sorted(set(shapes) - set(mask)) if mask is not own else []
    extra = sorted(set(mask) - set(shapes))
    if missing or extra:
        raise ValueError(f"mask must have one entry per sensor of the histories {sorted(shapes)}: "
                         + (f"missing {missing}" if missing else "")
                         + ("; " if missing and extra else "") + (f"unknown {extra}" if extra else ""))
    out: dict[str, np.ndarray | None] = {}
    for sensor, shape in shapes.items():
        m = mask.get(sensor)
        if m is not None:
            m = np.asarray(m)
            if m.dtype != bool or m.shape != shape:
                raise ValueError(f"mask[{sensor!r}] must be a boolean array of shape {shape}, "
                                 f"got {m.dtype} {m.shape}")
            m = None if m.all() else m
        out[sensor] = m
    return out


def check_fused(
    histories: Mapping[str, Any], mask: Any = None, timeline: Any = None
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray | None], frozenset[str], np.ndarray | None]:
    """Validated fused histories: ``(matrices, masks, sensor set, timeline)``.

    Args:
        histories: sensor name -> (M, N * columns per step) matrix (or a ``History``-like
            object with ``.matrix`` and ``.mask``), two or more sensors, the same M objects in
            the same row order and the same N steps.
        mask: None (each sensor complete, or the masks its History brought) or a mapping with
            exactly the keys of ``histories``: a boolean mask of that sensor's shape, or None.
        timeline: optional (N, 2) ints, as for a single history.

    Unobserved entries are zeroed, as ``build_map`` does for one sensor.
    """
    key = check_sensor_set(list(histories))
    if isinstance(key, str):
        raise ValueError(f"fused histories need two or more sensors, got only {key!r}; "
                         "pass its matrix directly")
    matrices, own = {}, {}
    for sensor, value in histories.items():
        matrices[sensor], own[sensor] = _matrix(sensor, value)
    steps = {s: (X.shape[0], X.shape[1] // COLUMNS_PER_STEP[s]) for s, X in matrices.items()}
    if len(set(steps.values())) > 1:
        raise ValueError("fused histories must hold the same objects and steps; (objects, steps) "
                         f"per sensor: {steps}")
    masks = _masks(mask, own, {s: X.shape for s, X in matrices.items()})
    for s, X in matrices.items():
        observed = X if masks[s] is None else X[masks[s]]
        if not np.all(np.isfinite(observed)):
            raise ValueError(f"histories[{s!r}] contain NaN or inf (in observed entries)")
        check_values(X, masks[s], s)  # e.g. no negative range
        if masks[s] is not None:
            matrices[s] = np.where(masks[s], X, 0.0)
    n_steps = next(iter(steps.values()))[1]
    return matrices, masks, key, check_timeline(timeline, n_steps)

