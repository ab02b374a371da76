"""``build_map``: histories and anchors in, a metric map out (SPEC §3).

normalise rows (paper eq. 7) -> embed in 2-D with one of :data:`mappers.METHODS` -> fit the
affine map taking the anchors' embedded points onto their known positions -> apply it to every
object. Objects never sensed are reported in ``Map.unmapped`` and never placed.
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from threadpoolctl import ThreadpoolController

from mappers.align import apply_affine, check_anchors, check_not_collinear, fit_affine
from mappers.methods import DEFAULT_METHODS, METHODS, SENSORS, MappingError

__all__ = ["SENSORS", "Map", "build_map", "infer_sensor"]

# Up to this many objects one BLAS thread is fastest: the matrices are small and the machine's
# other threads (or processes) only add contention. Above it, the BLAS library decides.
_SINGLE_THREAD_MAX_OBJECTS = 500
_controller: ThreadpoolController | None = None


def _thread_limit(n_objects: int):
    """Context limiting BLAS/OpenMP to one thread for small problems (no-op for large ones).

    The controller is built once: scanning the loaded libraries costs ~5-10 ms per call.
    """
    global _controller
    if _controller is None:
        _controller = ThreadpoolController()
    return _controller.limit(limits=1 if n_objects <= _SINGLE_THREAD_MAX_OBJECTS else None)


@dataclass(frozen=True, eq=False)
class Map:
    """A map built by :func:`build_map`.

    Attributes:
        positions: (M, 2) estimated object positions in world coordinates [m]; NaN rows for
            unmapped objects.
        unmapped: ids of objects that could not be placed (empty history).
        embedding: (M, 2) the method's 2-D embedding before the anchor fit (NaN rows likewise).
        method: label of the method used.
        params: the method's parameters (defaults merged with the ones given).
        sensor: sensor kind of the histories (given or inferred).
        warnings: repairs and degradations worth knowing (graph joined, anchors dropped, ...).
        affine: (3, 2) affine map with ``positions = [embedding, 1] @ affine``.
        anchor_ids: the anchors actually used for the fit.
    """

    positions: np.ndarray
    unmapped: tuple[int, ...]
    embedding: np.ndarray
    method: str
    params: dict[str, Any]
    sensor: str
    warnings: tuple[str, ...] = ()
    affine: np.ndarray | None = None
    anchor_ids: tuple[int, ...] = field(default=())


def infer_sensor(X: np.ndarray, mask: np.ndarray | None = None) -> str:
    """Guess the sensor of a history matrix from its observed entries.

    All entries 0/1 -> "visibility"; an even number of columns whose (cos, sin) pairs are unit
    vectors (all-zero pairs ignored) -> "bearing"; anything else -> "range".
    """
    X = np.asarray(X, dtype=float)
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


def _check_histories(histories: Any) -> np.ndarray:
    try:
        X = np.array(histories, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"histories must be a numeric (M, D) array: {exc}") from exc
    if X.ndim != 2:
        raise ValueError(f"histories must be a 2-D (objects x columns) array, got shape {X.shape}")
    if X.shape[0] < 3 or X.shape[1] < 1:
        raise ValueError(f"histories need at least 3 objects and 1 column, got shape {X.shape}")
    return X


def _check_mask(mask: Any, shape: tuple[int, int]) -> np.ndarray | None:
    if mask is None:
        return None
    mask = np.asarray(mask)
    if mask.dtype != bool:
        raise ValueError(f"mask must be a boolean array (True = observed), got dtype {mask.dtype}")
    if mask.shape != shape:
        raise ValueError(f"mask must have the shape of histories {shape}, got {mask.shape}")
    return None if mask.all() else mask


def _embed(
    method: str,
    est: Any,
    X: np.ndarray,
    fit_params: dict[str, Any] | None = None,
    allow_nan_rows: bool = False,
) -> tuple[np.ndarray, list[str]]:
    n = X.shape[0]
    with warnings.catch_warnings(record=True) as caught, _thread_limit(n):
        warnings.simplefilter("always")
        try:
            Y = est.fit_transform(X, **(fit_params or {}))
        except (KeyboardInterrupt, MemoryError):
            raise
        except Exception as exc:  # any failure inside a method becomes one clear error
            raise MappingError(f"method {method!r} failed: {type(exc).__name__}: {exc}") from exc
    Y = np.asarray(Y, dtype=float)
    finite_rows = np.all(np.isfinite(Y), axis=1) if Y.shape == (n, 2) else None
    if finite_rows is None or not (finite_rows.all() or (allow_nan_rows and finite_rows.any())):
        raise MappingError(
            f"method {method!r} failed: returned an embedding of shape {Y.shape} "
            f"{'with NaN/inf' if Y.size and not np.all(np.isfinite(Y)) else ''}".rstrip()
        )
    notes = list(dict.fromkeys(f"{method}: {w.category.__name__}: {w.message}" for w in caught))
    return Y, notes


def _usable_anchors(
    ids: np.ndarray, pos: np.ndarray, ok: np.ndarray, why: str, notes: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    """Drop anchors that are not ``ok`` (with a note); ValueError if fewer than 3 remain."""
    if ok.all():
        return ids, pos
    lost = ids[~ok].tolist()
    if ok.sum() < 3:
        raise ValueError(
            f"anchors {lost} {why} (unmapped): only {int(ok.sum())} anchors remain, "
            "at least 3 are needed"
        )
    check_not_collinear(pos[ok], "remaining anchor positions (world)")
    notes.append(f"anchors {lost} {why} and were not used for the fit")
    return ids[ok], pos[ok]


def build_map(
    histories: Any,
    anchor_ids: Sequence[int] | np.ndarray,
    anchor_positions: Any,
    method: str | None = None,
    *,
    sensor: str | None = None,
    mask: np.ndarray | None = None,
    normalize: bool | None = None,
    random_state: int | None = 0,
    **params: Any,
) -> Map:
    """Build a metric map of M objects from their observation histories.

    Args:
        histories: (M, D) history matrix (one row per object; visibility 0/1, bearing
            interleaved cos/sin, or range), or any object with a ``.matrix`` attribute such as
            ``lfmdr_gym.History`` (its ``sensor`` and ``mask`` are then used unless given).
        anchor_ids: (A,) ids of the anchor objects, A >= 3, distinct, in [0, M).
        anchor_positions: (A, 2) their known positions [m]; not collinear.
        method: a label of :data:`mappers.METHODS`; None = ``DEFAULT_METHODS[sensor]``.
        sensor: "visibility", "bearing" or "range"; None = inferred (:func:`infer_sensor`).
        mask: optional (M, D) bool, True where observed; a mask with False entries is handed to
            ``mappers.missing.build_masked_embedding``; an all-True mask is no mask.
        normalize: divide each row by its norm (paper eq. 7); None = the method's choice (on for
            the paper's methods, off for those that need the raw values, such as UNFOLD).
        random_state: seed handed to methods that take one.
        **params: method parameters (``n_neighbors`` = K, ``sigma2``, ``degree``, ...).

    Returns:
        A :class:`Map`. Objects whose history is empty (no non-zero observed entry) are listed
        in ``unmapped`` with NaN rows; the others are still mapped.

    Raises:
        ValueError: bad input, naming the problem. MappingError (a ValueError) when the method
        itself fails (e.g. Hessian LLE's eigenproblem), naming the method and the cause.
    """
    if hasattr(histories, "matrix") and not isinstance(histories, np.ndarray):
        sensor = sensor if sensor is not None else getattr(histories, "sensor", None)
        mask = mask if mask is not None else getattr(histories, "mask", None)
        histories = histories.matrix
    X = _check_histories(histories)
    m = X.shape[0]
    mask = _check_mask(mask, X.shape)
    observed = X if mask is None else X[mask]
    if not np.all(np.isfinite(observed)):
        raise ValueError("histories contain NaN or inf (in observed entries)")
    if mask is not None:
        X = np.where(mask, X, 0.0)

    if sensor is None:
        sensor = infer_sensor(X, mask)
    elif sensor not in SENSORS:
        raise ValueError(f"sensor must be one of {list(SENSORS)} or None, got {sensor!r}")
    if sensor == "bearing" and X.shape[1] % 2:
        raise ValueError(f"bearing histories need an even number of columns, got {X.shape[1]}")

    # With a partial mask, method and parameters are mappers.missing's to interpret (it has its
    # own masked methods); otherwise they must name a registered method and its parameters.
    spec = None
    merged = dict(params)
    if mask is None:
        if method is None:
            method = DEFAULT_METHODS[sensor]
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; known: {list(METHODS)}")
        spec = METHODS[method]
        if spec.sensors is not None and sensor not in spec.sensors:
            raise ValueError(
                f"method {method!r} maps {' or '.join(spec.sensors)} histories only, got {sensor} "
                f"(the default for {sensor} is {DEFAULT_METHODS[sensor]!r})"
            )
        if normalize and not spec.normalize:
            raise ValueError(f"method {method!r} needs the raw histories: normalize must be False or None")
        spec.check_params(params)
        merged = {**spec.defaults, **params}
        if "random_state" in spec.parameters and "random_state" not in params:
            merged["random_state"] = random_state

    ids, pos = check_anchors(anchor_ids, anchor_positions, m)

    has_data = np.any((X != 0) if mask is None else (mask & (X != 0)), axis=1)
    unmapped = tuple(int(i) for i in np.flatnonzero(~has_data))
    notes: list[str] = []
    ids, pos = _usable_anchors(ids, pos, has_data[ids], "have empty histories", notes)
    mapped = np.flatnonzero(has_data)
    n = mapped.size
    k = merged.get("n_neighbors")
    if k is not None and (
        isinstance(k, bool) or not isinstance(k, int | np.integer) or not 1 <= k < n
    ):
        raise ValueError(
            f"n_neighbors must be an integer in [1, {n - 1}] for {n} mapped objects, got {k!r}"
        )

    Xm = X[mapped]
    # The anchors as rows of Xm, for methods that hold them fixed (the masked methods, and
    # registered ones with ``uses_anchors``); the affine fit below is then the identity.
    anchors = {"anchor_ids": np.searchsorted(mapped, ids), "anchor_positions": pos}
    fit_params = None
    if mask is not None:
        from mappers.missing import build_masked_embedding  # looked up per call: tests swap it

        est = _MaskedEmbedding(
            build_masked_embedding, mask[mapped], method, sensor, {**merged, **anchors}
        )
        module = sys.modules.get("mappers.missing")
        masked_methods = getattr(module, "MASKED_METHODS", None)
        if method is None:
            method = f"masked default ({sensor})"
        elif masked_methods is not None and method not in masked_methods:
            # mappers.missing maps it with the sensor's masked default: say so, do not misreport
            default = getattr(module, "DEFAULT_METHOD", {}).get(sensor, "its default")
            notes.append(f"method {method!r} needs complete histories; this masked history was "
                         f"mapped with {default!r} (mappers.missing)")
            method = default
    else:
        if spec.normalize if normalize is None else normalize:
            Xm = Xm / np.linalg.norm(Xm, axis=1, keepdims=True)  # paper eq. 7
        try:
            est = spec.factory(**merged)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"bad parameters for method {method!r}: {exc}") from exc
        if spec.uses_anchors:
            fit_params = anchors
    Y, caught = _embed(method, est, Xm, fit_params, allow_nan_rows=mask is not None)
    notes.extend(caught)
    placed = np.all(np.isfinite(Y), axis=1)
    if not placed.all():  # the masked path may leave objects it could not place
        lost = mapped[~placed]
        notes.append(f"objects {lost.tolist()} could not be placed from their masked histories")
        unmapped = tuple(sorted({*unmapped, *(int(i) for i in lost)}))
        ok = np.isin(ids, mapped[placed])
        ids, pos = _usable_anchors(ids, pos, ok, "could not be placed", notes)
        Y, mapped = Y[placed], mapped[placed]

    local = np.searchsorted(mapped, ids)
    try:
        T = fit_affine(Y[local], pos)
    except ValueError as exc:
        raise MappingError(f"method {method!r}: cannot fit the anchors: {exc}") from exc
    positions = np.full((m, 2), np.nan)
    embedding = np.full((m, 2), np.nan)
    embedding[mapped] = Y
    positions[mapped] = apply_affine(Y, T)
    return Map(
        positions=positions,
        unmapped=unmapped,
        embedding=embedding,
        method=method,
        params=merged,
        sensor=sensor,
        warnings=tuple(notes),
        affine=T,
        anchor_ids=tuple(int(i) for i in ids),
    )


class _MaskedEmbedding:
    """Adapter so the masked path goes through the same error handling as the estimators."""

    def __init__(self, fn, mask, method, sensor, params) -> None:
        self.fn, self.mask, self.method, self.sensor, self.params = fn, mask, method, sensor, params

    def fit_transform(self, X: np.ndarray) -> np.ndarray:
        return self.fn(X, self.mask, self.method, self.sensor, **self.params)
