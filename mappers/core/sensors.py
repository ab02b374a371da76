"""The sensor vocabulary: which kinds of history exist and how their columns are laid out.

Defined once here; the world (``lfmdr_gym``), the registry of methods, the protocol and the
command line all take their sensor names from :data:`SENSORS`.

A history has one row per object and, per step, ``COLUMNS_PER_STEP[sensor]`` columns in step
order: visibility one 0/1 column (paper §4.3.1), bearing the ``(cos, sin)`` pair of the bearing
relative to the heading (paper §4.4.1), range one distance (paper §6, "range-only mapping").
An optional boolean mask of the same shape marks the entries the sensor actually measured, and
an optional *timeline* ((N, 2) integers) says which robot took each step and at which tick of its
clock, for logged data of several robots binned in time.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Any

import numpy as np
import scipy.sparse as sp

__all__ = [
    "COLUMNS_PER_STEP",
    "FUSED_SENSORS",
    "SENSORS",
    "check_matrix",
    "check_sensor",
    "check_sensor_set",
    "check_values",
    "sensor_name",
    "check_timeline",
    "infer_sensor",
    "sensors_of",
    "step_observations",
]

SENSORS: tuple[str, ...] = ("visibility", "bearing", "range")
"""The kinds of history, in the order tables and listings use."""

COLUMNS_PER_STEP = MappingProxyType({"visibility": 1, "bearing": 2, "range": 1})
"""Matrix columns one step contributes, per sensor."""

FUSED_SENSORS = MappingProxyType({
    "range-bearing": frozenset({"range", "bearing"}),
    "visibility-bearing": frozenset({"visibility", "bearing"}),
})
"""Names of the sensor sets fused histories come in (a mapping sensor -> matrix of the same
objects and steps): range and bearing together, as a camera that also measures distance gives
them; visibility and bearing from one walk (the paper's open question, §6). Any set of two or
more sensors of :data:`SENSORS` can be fused; these are the ones with names and defaults."""


def check_sensor(sensor: object, *, allow_none: bool = False) -> str | None:
    """``sensor`` if it names a sensor of :data:`SENSORS` (or is None when allowed), else a
    ValueError listing the sensors."""
    if sensor is None and allow_none:
        return None
    if not isinstance(sensor, str) or sensor not in SENSORS:
        extra = " or None" if allow_none else ""
        raise ValueError(f"sensor must be one of {list(SENSORS)}{extra}, got {sensor!r}")
    return sensor


def check_sensor_set(sensors: object) -> str | frozenset[str]:
    """The key a registry uses for one sensor or a fused set: a sensor name stays as it is; a
    name of :data:`FUSED_SENSORS` or a collection of two or more distinct sensors becomes a
    frozenset (a collection of one, its sensor); anything else is a ValueError naming the
    sensors."""
    if isinstance(sensors, str):
        if sensors in FUSED_SENSORS:
            return FUSED_SENSORS[sensors]
        return check_sensor(sensors)
    try:
        names = list(sensors)  # type: ignore[call-overload]
    except TypeError:
        names = None
    if not names or not all(isinstance(n, str) for n in names):
        raise ValueError(f"sensor must be one of {list(SENSORS)}, a fused set of them or one of "
                         f"{list(FUSED_SENSORS)}, got {sensors!r}")
    unknown = [n for n in names if n not in SENSORS]
    if unknown:
        raise ValueError(f"unknown sensor name(s) {unknown}; sensors are {list(SENSORS)}")
    if len(set(names)) != len(names):
        raise ValueError(f"sensors of a fused set must be distinct, got {names}")
    return names[0] if len(names) == 1 else frozenset(names)


def sensors_of(sensor: object) -> tuple[str, ...]:
    """The sensors a name stands for, in :data:`SENSORS` order: ``(sensor,)`` for one sensor, the
    set's for a name of :data:`FUSED_SENSORS`; anything else is a ValueError naming both."""
    if isinstance(sensor, str) and sensor in FUSED_SENSORS:
        return tuple(s for s in SENSORS if s in FUSED_SENSORS[sensor])
    if isinstance(sensor, str) and sensor in SENSORS:
        return (sensor,)
    raise ValueError(f"sensor must be one of {list(SENSORS)} or a fused set of "
                     f"{list(FUSED_SENSORS)}, got {sensor!r}")


def sensor_name(key: str | frozenset[str]) -> str:
    """How listings and messages name a sensor or a fused set (``"range-bearing"``)."""
    if isinstance(key, str):
        return key
    named = {v: k for k, v in FUSED_SENSORS.items()}
    return named.get(frozenset(key), "+".join(s for s in SENSORS if s in key))


def check_matrix(value: Any, name: str, *, copy: bool = True) -> np.ndarray:
    """``value`` as a float (M, D) history matrix, M >= 3 objects by D >= 1 columns (a new array
    when ``copy``, else ``value`` itself if it already is one); a ValueError naming ``name``
    (``"histories"``, say) when it is not numeric or not of that shape."""
    try:
        X = np.array(value, dtype=float) if copy else np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric (M, D) array: {exc}") from exc
    if X.ndim != 2 or X.shape[0] < 3 or X.shape[1] < 1:
        raise ValueError(f"{name} must be a 2-D (objects x columns) array with at least 3 objects "
                         f"and 1 column, got shape {X.shape}")
    return X


def check_timeline(timeline: Any, n_steps: int) -> np.ndarray | None:
    """A validated (N, 2) int64 timeline (robot, tick per step), or None; else ValueError."""
    if timeline is None:
        return None
    tl = np.asarray(timeline)
    if tl.shape != (n_steps, 2) or not np.issubdtype(tl.dtype, np.integer):
        raise ValueError(f"timeline must be an ({n_steps}, 2) integer array (robot, tick per step), "
                         f"got {tl.dtype} {tl.shape}")
    if n_steps and tl.min() < 0:
        raise ValueError("timeline holds negative robots or ticks")
    return tl.astype(np.int64)


def check_values(X: Any, mask: Any = None, sensor: str | None = None) -> str:
    """The sensor of a history matrix: ``sensor`` checked (a name of :data:`SENSORS`), or
    inferred from ``X`` (:func:`infer_sensor`) when None; a ValueError when the observed values
    cannot be of it (a negative range, say bearings in radians). ``X`` dense or scipy sparse
    (its stored values are the observed ones; ``mask``, if any, already applied)."""
    if sensor is None:
        return infer_sensor(X, None if sp.issparse(X) else mask)
    check_sensor(sensor)
    if sensor == "range":
        _check_ranges(X, mask)
    return sensor


def _check_ranges(X: Any, mask: Any = None) -> None:
    """A ValueError unless every observed value of ``X`` is >= 0 (a range can be no less)."""
    if sp.issparse(X):
        observed = sp.csr_array(X).data
    else:
        X = np.asarray(X, dtype=float)
        observed = X if mask is None else X[np.asarray(mask, dtype=bool)]
    negative = observed[observed < 0]
    if negative.size:
        raise ValueError(
            f"range histories must be >= 0, got {negative.size} negative observed value(s) "
            f"(the smallest {negative.min():g}). Bearings (angles) are passed as interleaved "
            "(cos, sin) column pairs, not as angles: for an (M, N) matrix of angles `a`, "
            "X = np.stack([np.cos(a), np.sin(a)], axis=-1).reshape(M, 2 * N) with the mask "
            "repeated per column pair (np.repeat(mask, 2, axis=1)); or give sensor='bearing' "
            "with those pairs.")


def infer_sensor(X: np.ndarray, mask: np.ndarray | None = None) -> str:
    """Guess the sensor of a history matrix from its observed entries.

    All entries 0/1 -> "visibility"; an even number of columns whose (cos, sin) pairs are unit
    vectors (all-zero pairs ignored) -> "bearing"; else, all entries >= 0 -> "range"; anything
    else (e.g. bearings given as angles in radians) is a ValueError. A scipy sparse ``X`` (no
    mask) is judged from its stored values alone, never densified.
    """
    if sp.issparse(X):
        if mask is not None:
            raise ValueError("a mask cannot be given with a sparse history matrix")
        X = sp.csr_array(X, dtype=np.float64)
        sensor = _infer_sparse_sensor(X)
    else:
        X = np.asarray(X, dtype=float)
        sensor = _infer_dense_sensor(X, mask)
    if sensor == "range":
        _check_ranges(X, mask)
    return sensor


def _infer_dense_sensor(X: np.ndarray, mask: np.ndarray | None) -> str:
    observed = X if mask is None else X[mask]
    if np.all((observed == 0) | (observed == 1)):
        return "visibility"
    if X.shape[1] % 2 == 0:
        c, s = X[:, 0::2], X[:, 1::2]
        pair_seen = (
            np.ones(c.shape, dtype=bool) if mask is None else (mask[:, 0::2] & mask[:, 1::2])
        )
        r2 = c**2 + s**2
        nonzero = pair_seen & (r2 > 0)
        if nonzero.any() and np.allclose(r2[nonzero], 1.0, atol=1e-4):
            return "bearing"
    return "range"


def _infer_sparse_sensor(X: sp.csr_array) -> str:
    """:func:`infer_sensor` of a sparse matrix from its stored values (the unstored are 0)."""
    data = X.data
    if np.all((data == 0) | (data == 1)):
        return "visibility"
    if X.shape[1] % 2 == 0:
        # Each step's cos^2 + sin^2: the squares summed over the column pair (col // 2).
        coo = X.tocoo()
        r2 = sp.coo_array((coo.data * coo.data, (coo.row, coo.col // 2)),
                          shape=(X.shape[0], X.shape[1] // 2)).tocsr()  # sums duplicates
        r2.eliminate_zeros()
        if r2.nnz and np.allclose(r2.data, 1.0, atol=1e-4):
            return "bearing"
    return "range"


def step_observations(
    X: np.ndarray, mask: np.ndarray | None, sensor: str
) -> tuple[np.ndarray, np.ndarray]:
    """Per-step view of a (possibly masked) history matrix.

    Returns ``(seen, values)``: ``seen`` (M, N) bool, True where the object was sensed in the
    step; ``values`` (M, N) float: the 0/1 visibility, the bearing angle [rad] or the range [m]
    (NaN where not sensed). A visibility 0, an unmasked range of 0 and a bearing pair (0, 0)
    count as not sensed.
    """
    check_sensor(sensor)
    columns = COLUMNS_PER_STEP[sensor]
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[1] % columns:
        raise ValueError(f"X must be (M, N*{columns}) for {sensor!r}, got {X.shape}")
    if mask is not None:
        mask = np.asarray(mask)
        if mask.dtype != np.bool_ or mask.shape != X.shape:
            raise ValueError(
                f"mask must be a bool array of shape {X.shape}, got {mask.dtype} {mask.shape}"
            )
    Xf = np.where(np.isfinite(X), X, 0.0)
    if sensor == "bearing":
        c, s = Xf[:, 0::2], Xf[:, 1::2]
        seen = (c != 0) | (s != 0)
        if mask is not None:
            seen &= mask[:, 0::2] & mask[:, 1::2]
        values = np.where(seen, np.arctan2(s, c), np.nan)
    else:
        seen = Xf > 0 if mask is None else (mask & np.isfinite(X))
        if sensor == "visibility":
            seen &= Xf > 0
        values = np.where(seen, Xf, np.nan)
    return seen, values
