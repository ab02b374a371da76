"""How a method's embedding becomes a map: the inputs checked, the method fitted, the anchors fit.

:func:`check_inputs` validates a history (sensor, mask, timeline); :func:`fit_checked` is
``build_map`` once the method is chosen: rows without data left unmapped, rows normalised (paper eq. 7) when the method
asks for it, the estimator fitted, the objects it could not place set aside, and the affine map
onto the anchors applied (paper §3). The viewpoint adjustments draw their start maps with it.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from mappers.catalog import MethodSpec, check_size
from mappers.core.align import apply_affine, check_anchors, check_not_collinear, fit_affine
from mappers.core.errors import MappingError
from mappers.core.sensors import COLUMNS_PER_STEP, check_matrix, check_values, sensor_name
from mappers.core.threads import thread_limit

__all__ = ["Map", "check_inputs", "fit_checked", "fit_fused_method"]

# Up to this many objects one BLAS thread is fastest: the matrices are small and the machine's
# other threads (or processes) only add contention. Above it, the BLAS library decides.
_SINGLE_THREAD_MAX_OBJECTS = 500


def _thread_limit(n_objects: int):
    """Context limiting BLAS/OpenMP to one thread for small problems (no-op for large ones)."""
    return thread_limit(1 if n_objects <= _SINGLE_THREAD_MAX_OBJECTS else None)


@dataclass(frozen=True, eq=False)
class Map:
    """A map built by :func:`build_map`.

    Attributes:
        positions: (M, 2) estimated object positions in world coordinates [m]; NaN rows for
            unmapped objects.
        unmapped: ids of objects that could not be placed (empty history, or a masked method
            could not place them).
        embedding: (M, 2) the method's 2-D embedding before the anchor fit (NaN rows likewise).
        method: label of the method used.
        params: the method's parameters (defaults merged with the ones given).
        sensor: sensor kind of the histories (given or inferred); for fused histories the name
            of the set (``"range-bearing"``, :data:`mappers.core.sensors.FUSED_SENSORS`).
        warnings: repairs and degradations worth knowing (graph joined, anchors dropped, ...).
        affine: (3, 2) affine map with ``positions = [embedding, 1] @ affine``.
        anchor_ids: the anchors actually used for the fit.
        covariances: (M, d, d) each object's position covariance [m²] in the map's frame (zero
            for the anchors, NaN for unmapped objects), or None when ``build_map`` was not asked
            for it (``uncertainty=``; :mod:`mappers.covariances`).
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
    covariances: np.ndarray | None = None


def _check_mask(mask: Any, shape: tuple[int, int]) -> np.ndarray | None:
    if mask is None:
        return None
    mask = np.asarray(mask)
    if mask.dtype != bool:
        raise ValueError(f"mask must be a boolean array (True = observed), got dtype {mask.dtype}")
    if mask.shape != shape:
        raise ValueError(f"mask must have the shape of histories {shape}, got {mask.shape}")
    return None if mask.all() else mask


def _sparse_inputs(X: Any, sensor: str | None, mask: Any) -> tuple[Any, Any, str]:
    """A scipy sparse history as a float64 csr_array (checked as :func:`_check_histories`), its
    mask as a bool csr_array (None when absent or all True), unobserved entries dropped."""
    X = sp.csr_array(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[0] < 3 or X.shape[1] < 1:
        raise ValueError(f"histories need at least 3 objects and 1 column, got shape {X.shape}")
    if mask is not None:
        dtype = mask.dtype if sp.issparse(mask) else np.asarray(mask).dtype
        if dtype != np.bool_:
            raise ValueError(f"mask must be a boolean array (True = observed), got dtype {dtype}")
        mask = sp.csr_array(mask, dtype=bool)
        if mask.shape != X.shape:
            raise ValueError(f"mask must have the shape of histories {X.shape}, got {mask.shape}")
        mask.eliminate_zeros()
        if mask.nnz == X.shape[0] * X.shape[1]:
            mask = None
        else:
            X = sp.csr_array(X.multiply(mask))
    X.eliminate_zeros()
    if not np.all(np.isfinite(X.data)):
        raise ValueError("histories contain NaN or inf (in observed entries)")
    return X, mask, check_values(X, None, sensor)  # the stored values: never densified


def check_inputs(histories, sensor=None, mask=None, timeline=None):
    """The validated history matrix (unobserved entries zeroed), mask, sensor and timeline, as
    ``build_map`` takes them; a
    ``History``-like object (with ``.matrix``) brings its own sensor, mask and timeline. A
    ``scipy.sparse`` matrix, or a History stored sparse (``is_sparse``), stays sparse."""
    # (is_sparse first: hasattr(.., "matrix") would build a History's dense matrix, or refuse to)
    if getattr(histories, "is_sparse", False) or (
            hasattr(histories, "matrix") and not isinstance(histories, np.ndarray)):
        sensor = sensor if sensor is not None else getattr(histories, "sensor", None)
        timeline = timeline if timeline is not None else getattr(histories, "timeline", None)
        stored_sparse = getattr(histories, "is_sparse", False)
        if mask is None:  # a compact History's own mask stays sparse (History.sparse_mask)
            mask = (histories.sparse_mask if stored_sparse and getattr(histories, "masked", False)
                    else getattr(histories, "mask", None))
        sparse_rows = stored_sparse and (mask is None or sp.issparse(mask))
        histories = histories.sparse if sparse_rows else histories.matrix
    if sp.issparse(histories):
        X, mask, sensor = _sparse_inputs(histories, sensor, mask)
        return X, mask, sensor, timeline
    X = check_matrix(histories, "histories")
    mask = _check_mask(mask, X.shape)
    observed = X if mask is None else X[mask]
    if not np.all(np.isfinite(observed)):
        raise ValueError("histories contain NaN or inf (in observed entries)")
    if mask is not None:
        X = np.where(mask, X, 0.0)
    sensor = check_values(X, mask, sensor)
    if X.shape[1] % COLUMNS_PER_STEP[sensor]:
        raise ValueError(f"{sensor} histories need an even number of columns (x, y per step), "
                         f"got {X.shape[1]}" if COLUMNS_PER_STEP[sensor] == 2 else
                         f"{sensor} histories need a multiple of {COLUMNS_PER_STEP[sensor]} "
                         f"columns, got {X.shape[1]}")
    return X, mask, sensor, timeline


DENSE_BUDGET_BYTES = 2 * 2**30
"""Largest dense float64 matrix ``build_map`` builds from sparse histories for a dense method."""


def _for_method(spec: MethodSpec, X: Any, mask: Any, params: dict[str, Any]) -> tuple[Any, Any]:
    """Sparse histories (and mask) densified for a method that needs a dense matrix with these
    resolved parameters (within the budget)."""
    if not sp.issparse(X) or spec.takes_sparse(params):
        return X, mask
    need = 8 * X.shape[0] * X.shape[1]
    if need > DENSE_BUDGET_BYTES:
        raise ValueError(
            f"method {spec.label!r} needs the dense history matrix, {need / 2**30:.1f} GiB for "
            f"shape {X.shape} (budget {DENSE_BUDGET_BYTES / 2**30:.0f} GiB); use a method that "
            "maps sparse histories, e.g. 'CAL-SMA' with sparse=True (or 'COVIS-SPARSE' when "
            "masked)"
        )
    return X.toarray(), (mask.toarray() if sp.issparse(mask) else mask)


def _method_params(spec: MethodSpec, params: dict[str, Any], normalize, random_state):
    if normalize and not spec.normalize:
        raise ValueError(f"method {spec.label!r} needs the raw histories: normalize must be False or None")
    merged = spec.resolved_params(params)
    if "random_state" in spec.parameters and "random_state" not in params:
        merged["random_state"] = random_state
    return merged


def _check_neighbors(merged: dict[str, Any], n: int) -> None:
    k = merged.get("n_neighbors")
    if k is not None and (isinstance(k, bool) or not isinstance(k, int | np.integer) or not 1 <= k < n):
        raise ValueError(
            f"n_neighbors must be an integer in [1, {n - 1}] for {n} mapped objects, got {k!r}"
        )


def _embed(method: str, est: Any, X: Any, fit_params: dict[str, Any],
           allow_nan_rows: bool, n: int) -> tuple[np.ndarray, list[str]]:
    with warnings.catch_warnings(record=True) as caught, _thread_limit(n):
        warnings.simplefilter("always")
        try:
            Y = est.fit_transform(X, **fit_params)
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


def _fit_inputs(spec: MethodSpec, mapped, ids, pos, mask, sensor, timeline) -> dict[str, Any]:
    """What ``fit_transform`` receives besides X, as the spec declares (see MethodSpec)."""
    inputs: dict[str, Any] = {}
    if spec.uses_anchors:  # the anchors as rows of the mapped objects
        inputs.update(anchor_ids=np.searchsorted(mapped, ids), anchor_positions=pos)
    if spec.takes_masks and not spec.fused:  # fused methods get ``masks`` (_build_fused_map)
        inputs.update(mask=None if mask is None else mask[mapped], sensor=sensor)
    if spec.uses_timeline:
        inputs["timeline"] = timeline
    return inputs


def _placed(Y, mapped, ids, pos, unmapped, notes):
    """Keep the rows a masked method placed; the others join ``unmapped``."""
    placed = np.all(np.isfinite(Y), axis=1)
    if placed.all():
        return Y, mapped, ids, pos, unmapped
    lost = mapped[~placed]
    notes.append(f"objects {lost.tolist()} could not be placed from their masked histories")
    unmapped = tuple(sorted({*unmapped, *(int(i) for i in lost)}))
    ids, pos = _usable_anchors(ids, pos, np.isin(ids, mapped[placed]), "could not be placed", notes)
    return Y[placed], mapped[placed], ids, pos, unmapped


def _anchor_fit(spec: MethodSpec, Y: np.ndarray, local: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """The affine map onto the anchors (the identity, to rounding, when the method held them
    fixed: ``uses_anchors``)."""
    try:
        return fit_affine(Y[local], pos)
    except ValueError as exc:
        raise MappingError(f"method {spec.label!r}: cannot fit the anchors: {exc}") from exc


def fit_checked(spec, X, anchor_ids, anchor_positions, sensor, mask, timeline, normalize,
                random_state, params, notes) -> tuple[Map, Any, np.ndarray]:
    """The map of ``spec``'s method on a single sensor's histories checked by
    :func:`check_inputs`, the fitted estimator, and the rows it was fitted on (the objects with
    data; an online update keeps the estimator's state). ``notes`` are warnings gathered before
    (they lead ``Map.warnings``)."""
    m = X.shape[0]
    merged = _method_params(spec, params, normalize, random_state)
    ids, pos = check_anchors(anchor_ids, anchor_positions, m)
    X, mask = _for_method(spec, X, mask, merged)
    if sp.issparse(X):
        has_data = np.diff(X.indptr) > 0
    else:
        has_data = np.any((X != 0) if mask is None else (mask & (X != 0)), axis=1)
    unmapped = tuple(int(i) for i in np.flatnonzero(~has_data))
    ids, pos = _usable_anchors(ids, pos, has_data[ids], "have empty histories", notes)
    mapped = np.flatnonzero(has_data)
    _check_neighbors(merged, mapped.size)
    check_size(spec, mapped.size, merged)
    Xm = X[mapped]
    if (spec.normalize if normalize is None else normalize) and sp.issparse(Xm):
        norms = np.sqrt(np.asarray(Xm.multiply(Xm).sum(axis=1)).ravel())
        Xm = sp.csr_array(sp.diags_array(1.0 / norms) @ Xm)  # paper eq. 7
    elif spec.normalize if normalize is None else normalize:
        Xm = Xm / np.linalg.norm(Xm, axis=1, keepdims=True)  # paper eq. 7
    try:
        est = spec.load()(**merged)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"bad parameters for method {spec.label!r}: {exc}") from exc
    inputs = _fit_inputs(spec, mapped, ids, pos, mask, sensor, timeline)
    Y, caught = _embed(spec.label, est, Xm, inputs, allow_nan_rows=spec.takes_masks, n=mapped.size)
    notes.extend(caught)
    return _finish(spec, merged, sensor, Y, m, mapped, ids, pos, unmapped, notes), est, mapped


def _finish(spec, merged, sensor, Y, m, mapped, ids, pos, unmapped, notes) -> Map:
    """The Map of an embedding ``Y`` of the ``mapped`` rows: objects a method left unplaced join
    ``unmapped``, and the affine fit onto the anchors takes the rest to world coordinates."""
    Y, mapped, ids, pos, unmapped = _placed(Y, mapped, ids, pos, unmapped, notes)
    T = _anchor_fit(spec, Y, np.searchsorted(mapped, ids), pos)
    positions = np.full((m, 2), np.nan)
    embedding = np.full((m, 2), np.nan)
    embedding[mapped] = Y
    positions[mapped] = apply_affine(Y, T)
    return Map(positions=positions, unmapped=unmapped, embedding=embedding, method=spec.label,
               params=merged, sensor=sensor, warnings=tuple(notes), affine=T,
               anchor_ids=tuple(int(i) for i in ids))


def fit_fused_method(spec: MethodSpec, Xs: dict[str, Any], masks: dict[str, Any], key,
                     timeline, anchor_ids, anchor_positions, *, normalize: bool | None = None,
                     random_state: int | None = 0, params: dict[str, Any] | None = None,
                     with_estimator: bool = False) -> Map | tuple[Map, Any, np.ndarray]:
    """The map of ``spec``'s method on fused histories checked by
    :func:`mappers.core.fused_histories.check_fused` (``Xs``, ``masks``, ``key``, ``timeline``);
    ``with_estimator``: ``(map, fitted estimator, rows it was fitted on)``, as
    :func:`fit_checked`."""
    params = dict(params or {})
    merged = _method_params(spec, params, normalize, random_state)
    m = next(iter(Xs.values())).shape[0]
    ids, pos = check_anchors(anchor_ids, anchor_positions, m)
    has_data = np.zeros(m, dtype=bool)
    for s, X in Xs.items():
        has_data |= np.any((X != 0) if masks[s] is None else (masks[s] & (X != 0)), axis=1)
    unmapped = tuple(int(i) for i in np.flatnonzero(~has_data))
    notes: list[str] = []
    ids, pos = _usable_anchors(ids, pos, has_data[ids], "have empty histories", notes)
    mapped = np.flatnonzero(has_data)
    _check_neighbors(merged, mapped.size)
    try:
        est = spec.load()(**merged)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"bad parameters for method {spec.label!r}: {exc}") from exc
    inputs = _fit_inputs(spec, mapped, ids, pos, None, key, timeline)
    inputs["masks"] = {s: None if v is None else v[mapped] for s, v in masks.items()}
    Y, caught = _embed(spec.label, est, {s: X[mapped] for s, X in Xs.items()}, inputs,
                       allow_nan_rows=True, n=mapped.size)
    notes.extend(caught)
    result = _finish(spec, merged, sensor_name(key), Y, m, mapped, ids, pos, unmapped, notes)
    return (result, est, mapped) if with_estimator else result
