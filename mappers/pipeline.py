"""``build_map``: histories and anchors in, a metric map out (paper §3).

Choose the method (:mod:`mappers.defaults`, unless one is named) -> resolve its label
(:mod:`mappers.catalog`) -> normalise rows (paper eq. 7), embed in 2-D, fit the affine map taking
the anchors' embedded points onto their known positions and apply it to every object
(:mod:`mappers.fitting`). Objects never sensed are reported in ``Map.unmapped`` and never placed.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp

from mappers.catalog import implied_params, resolve_method
from mappers.core.errors import MappingError
from mappers.core.fused_histories import check_fused
from mappers.core.sensors import COLUMNS_PER_STEP, check_sensor_set
from mappers.core.uncertainty import check_uncertainty
from mappers.covariances import (
    covariance_threads,
    has_model_covariances,
    with_covariances,
    with_held_out_check,
    with_held_out_floor,
    with_model_covariances,
)
from mappers.defaults import choose_for_history
from mappers.fitting import Map, check_inputs, fit_checked, fit_fused_method
from mappers.spatial.marginals import spatial_held_out
from mappers.spatial.pipeline_3d import (
    anchor_dimension,
    build_map_3d,
    default_for_histories_3d,
    fit_map_3d,
    step_columns_3d,
)
from mappers.spatial.spatial_ba import SpatialAdjustment
from mappers.viewpoints import held_out_anchors, released_anchor

__all__ = ["Map", "MapWarning", "build_map", "default_method"]


class MapWarning(UserWarning):
    """A note of ``Map.warnings`` (a repair, a degradation, a start map kept), issued by
    :func:`build_map` so that it reaches Python's warnings too."""


def build_map(
    histories: Any,
    anchor_ids: Sequence[int] | np.ndarray,
    anchor_positions: Any,
    method: str | None = None,
    *,
    sensor: str | None = None,
    mask: np.ndarray | None = None,
    timeline: np.ndarray | None = None,
    normalize: bool | None = None,
    random_state: int | None = 0,
    uncertainty: bool | str = False,
    **params: Any,
) -> Map:
    """Build a metric map of M objects from their observation histories.

    Args:
        histories: (M, D) history matrix (one row per object; visibility 0/1, bearing
            interleaved cos/sin, or range), or any object with a ``.matrix`` attribute such as
            ``lfmdr_gym.History`` (its ``sensor``, ``mask`` and ``timeline`` are then used
            unless given); or fused histories, a mapping sensor -> matrix (or History) of the
            same objects and steps, e.g. ``{"range": R, "bearing": B}`` (:mod:`mappers.core.fused_histories`),
            mapped by a method that takes that set of sensors; or an object whose ``parts`` is
            such a mapping (a fused ``lfmdr_gym.History``, whose ``timeline`` is then used
            unless given).
        anchor_ids: (A,) ids of the anchor objects, A >= 3, distinct, in [0, M).
        anchor_positions: (A, 2) their known positions [m]; not collinear. (A, 3) positions
            make a 3-D map (:func:`mappers.spatial.pipeline_3d.build_map_3d`: 3-D rays, rays
            and ranges, ranges alone, or sightings; ``Map.positions`` is then (M, 3)).
        method: a label of :data:`mappers.METHODS` (case-insensitive) that maps this kind of
            history; None = the default for the sensor and for complete or masked histories
            (:func:`mappers.defaults.choose_method`, from :data:`mappers.defaults.DEFAULTS`,
            with its parameters: above 500 objects ``CAL-SMA`` with ``sparse=True``; a complete
            visibility history that flickers like a camera with dropouts gets the table's
            dropout default, with a note in ``Map.warnings``). A label that does not fit is a
            ValueError listing the labels that do; an old label resolves to its new one with a
            FutureWarning, or is refused saying what to use (:data:`mappers.catalog.ALIASES`,
            :data:`mappers.catalog.RETIRED`).
        sensor: "visibility", "bearing" or "range"; None = inferred (:func:`infer_sensor`); for
            fused histories the keys name the sensors (a given ``sensor`` must agree).
        mask: optional (M, D) bool, True where observed; an all-True mask is no mask. Fused
            histories take a mapping with one entry per sensor (None: complete).
        timeline: optional (N, 2) ints, robot and tick of each step, for methods that group
            consecutive steps (``COVIS-ENSEMBLE``, ``DROPOUT-BLEND``, the viewpoint adjustments).
        normalize: divide each row by its norm (paper eq. 7); None = the method's choice (on for
            the paper's methods, off for those that need the raw values, such as UNFOLD).
        random_state: seed handed to methods that take one (and to the bootstrap's draws).
        uncertainty: False (the default): no covariances, ``Map.covariances`` is None and nothing
            else changes; ``"model"``: from the normal equations of the method's bundle
            adjustment (``BEARING-BA``, ``LOC-SMA`` refined, ``SPATIAL-BA``); ``"jackknife"``:
            CAL-SMA's linearised block jackknife (complete visibility histories, dense CAL-SMA;
            a fraction of a map's time); ``"bootstrap"``: from replicate maps
            of a moving-block bootstrap over the steps (any method; about 20 maps' time);
            True: ``"model"`` where the method has one, plus the systematic floor its anchors,
            each released from the adjustment by one linearised step, estimate
            (:func:`mappers.covariances.with_held_out_floor`; ~0 where the model describes the
            readings, the size of a logged run's calibration errors where it does not), else
            ``"jackknife"`` where it applies, else ``"bootstrap"``
            (:mod:`mappers.covariances`); ``"anchors"``: True's covariances checked by the
            anchors, each held out in turn, and scaled when they miss them
            (:mod:`mappers.core.held_out_anchors`; for a method with an adjustment each anchor
            is released from it by one linearised step, else mapped again from the others);
            ``"floor"``: the model's with a floor for a logged sensor's systematic errors
            (:func:`mappers.core.uncertainty.systematic_floor`; methods with an adjustment). 3-D maps:
            the model for SPATIAL-BA, the bootstrap for COVIS-3D.
        **params: method parameters (``n_neighbors`` = K, ``sigma2``, ``degree``, ...).

    Returns:
        A :class:`Map`. Objects whose history is empty (no non-zero observed entry) are listed
        in ``unmapped`` with NaN rows; the others are still mapped. Each note of
        ``Map.warnings`` is also issued as a :class:`MapWarning`.

    Raises:
        ValueError: bad input, naming the problem. MappingError (a ValueError) when the method
        itself fails (e.g. Hessian LLE's eigenproblem), naming the method and the cause.
    """
    if check_uncertainty(uncertainty) in ("anchors", True):
        return _held_out_checked(histories, anchor_ids, anchor_positions, method, sensor=sensor,
                                 mask=mask, timeline=timeline, normalize=normalize,
                                 random_state=random_state,
                                 floor=check_uncertainty(uncertainty) is True, **params)
    if anchor_dimension(anchor_positions) == 3:
        uncertainty = check_uncertainty(uncertainty)
        result, est, X3, mask3, sensor3 = fit_map_3d(histories, anchor_ids, anchor_positions,
                                                     method, sensor=sensor, mask=mask, **params)
        if uncertainty is not False:
            result = _with_covariances_3d(result, uncertainty, est, X3, mask3, sensor3,
                                          anchor_ids, anchor_positions, random_state)
        for note in result.warnings:
            warnings.warn(note, MapWarning, stacklevel=2)
        return result
    result = _build_2d(histories, anchor_ids, anchor_positions, method, sensor, mask, timeline,
                       normalize, random_state, check_uncertainty(uncertainty), params)[0]
    for note in result.warnings:
        warnings.warn(note, MapWarning, stacklevel=2)
    return result


def _build_2d(histories, anchor_ids, anchor_positions, method, sensor, mask, timeline, normalize,
              random_state, uncertainty, params):
    """``build_map``'s 2-D map (with its covariances unless ``uncertainty`` is False), the fitted
    estimator and the rows it was fitted on: ``(Map, est, mapped)``."""
    histories, timeline = _unpacked(histories, timeline)
    if isinstance(histories, Mapping):
        result, est, mapped = _build_fused_map(histories, anchor_ids, anchor_positions, method,
                                               sensor, mask, timeline, normalize, random_state,
                                               params)
    else:
        result, est, mapped = _fit_map(histories, anchor_ids, anchor_positions, method, sensor,
                                       mask, timeline, normalize, random_state, params)
    if uncertainty is not False:
        result = _with_covariances(result, uncertainty, est, mapped, histories, anchor_ids,
                                   anchor_positions, sensor, mask, timeline, normalize,
                                   random_state, params)
    return result, est, mapped




def _unpacked(histories, timeline):
    """``(histories, timeline)``, a fused History (lfmdr_gym) as its single-sensor parts (a
    mapping, each with its own mask) and its timeline unless one is given."""
    parts = getattr(histories, "parts", None)
    if isinstance(parts, Mapping) and not isinstance(histories, Mapping):
        timeline = timeline if timeline is not None else getattr(histories, "timeline", None)
        histories = dict(parts)
    return histories, timeline


def _fit_map(histories, anchor_ids, anchor_positions, method, sensor, mask, timeline, normalize,
             random_state, params) -> tuple[Map, Any, np.ndarray]:
    """``build_map`` of a single sensor's histories: the map, the fitted estimator and the rows
    it was fitted on (the objects with data; an online update keeps the estimator's state)."""
    X, mask, sensor, timeline = check_inputs(histories, sensor, mask, timeline)
    notes: list[str] = []
    spec = _single_sensor_spec(method, X, mask, sensor, timeline, notes)
    return fit_checked(spec, X, anchor_ids, anchor_positions, sensor, mask, timeline, normalize,
                       random_state, params, notes)


def _single_sensor_spec(method, X, mask, sensor, timeline, notes):
    """The spec that maps checked single-sensor histories: ``method``'s, or (None) the default
    :func:`mappers.defaults.choose_for_history` picks, its parameters in the spec's defaults."""
    chosen = {}
    if method is None:
        picked = choose_for_history(X, mask, sensor, timeline, notes)
        method, chosen = picked if picked is not None else (None, {})
    spec = resolve_method(method, sensor, masked=mask is not None, n_objects=X.shape[0])
    return spec.with_defaults(chosen)


def _fused_spec(histories, mask, timeline, sensor):
    """The checked fused histories (:func:`mappers.core.fused_histories.check_fused`) and the
    spec that maps them by default."""
    Xs, masks, key, timeline = check_fused(histories, mask, timeline)
    _check_fused_sensor(sensor, key)
    n = next(iter(Xs.values())).shape[0]
    masked = any(v is not None for v in masks.values())
    return resolve_method(None, key, masked=masked, n_objects=n)


def default_method(histories: Any, *, sensor: str | None = None, mask: np.ndarray | None = None,
                   timeline: np.ndarray | None = None, return_params: bool = False,
                   anchor_positions: Any = None) -> str | tuple[str, dict[str, Any]]:
    """The label ``build_map(histories, ...)`` uses when no method is given, for every input
    ``build_map`` takes (single-sensor or fused histories, complete or masked): the default of
    :func:`mappers.defaults.choose_method` for the sensor, complete or masked, the number of
    objects and, for a complete history, whether it flickers like a sensor with dropouts.
    ``return_params=True``: ``(label, params)``, with the parameters the default is chosen with
    (``("CAL-SMA", {"sparse": True})`` above 500 objects). ``anchor_positions`` of shape
    (A, 3): the 3-D default ``build_map`` uses with such anchors (the table's ``spatial``
    column: ``COVIS-3D`` for sightings, ``SPATIAL-BA`` for 3-D rays, with or without ranges,
    ``RANGE-3D`` for ranges alone)."""
    if anchor_dimension(anchor_positions) == 3:
        label = default_for_histories_3d(histories, sensor, mask)
        return (label, {}) if return_params else label
    parts = getattr(histories, "parts", None)
    if isinstance(parts, Mapping) and not isinstance(histories, Mapping):
        timeline = timeline if timeline is not None else getattr(histories, "timeline", None)
        histories = dict(parts)
    if isinstance(histories, Mapping):
        spec = _fused_spec(histories, mask, timeline, sensor)
    else:
        X, mask, sensor, timeline = check_inputs(histories, sensor, mask, timeline)
        spec = _single_sensor_spec(None, X, mask, sensor, timeline, [])
    return (spec.label, implied_params(spec)) if return_params else spec.label


def _check_fused_sensor(sensor, key) -> None:
    if sensor is not None and check_sensor_set(sensor) != key:
        raise ValueError(f"sensor {sensor!r} does not name the sensors of the fused histories "
                         f"{sorted(key)}")


def _build_fused_map(histories, anchor_ids, anchor_positions, method, sensor, mask, timeline,
                     normalize, random_state, params) -> Map:
    """``build_map`` for fused histories (a mapping sensor -> matrix,
    :mod:`mappers.core.fused_histories`)."""
    Xs, masks, key, timeline = check_fused(histories, mask, timeline)
    _check_fused_sensor(sensor, key)
    n = next(iter(Xs.values())).shape[0]
    spec = resolve_method(method, key, masked=any(v is not None for v in masks.values()),
                          n_objects=n)
    return fit_fused_method(spec, Xs, masks, key, timeline, anchor_ids, anchor_positions,
                            normalize=normalize, random_state=random_state, params=params,
                            with_estimator=True)


def _step_columns(steps: np.ndarray, per_step: int) -> np.ndarray:
    return (steps[:, None] * per_step + np.arange(per_step)[None, :]).ravel()


def _with_covariances(result, uncertainty, est, mapped, histories, anchor_ids, anchor_positions,
                      sensor, mask, timeline, normalize, random_state, params) -> Map:
    """``result`` with ``Map.covariances`` (:func:`mappers.covariances.with_covariances`): the
    checked histories again, and the refit of a bootstrap replicate (the same method, its
    parameters as resolved, the chosen steps' columns, mask and timeline rows)."""
    method, params = result.method, dict(result.params)
    if isinstance(histories, Mapping):
        Xs, masks, _, timeline = check_fused(histories, mask, timeline)
        n_steps = next(iter(Xs.values())).shape[1] // COLUMNS_PER_STEP[next(iter(Xs))]

        def refit(steps):
            cols = {s: _step_columns(steps, COLUMNS_PER_STEP[s]) for s in Xs}
            return _build_fused_map(
                {s: v[:, cols[s]] for s, v in Xs.items()}, anchor_ids, anchor_positions, method,
                None, {s: None if v is None else v[:, cols[s]] for s, v in masks.items()},
                None if timeline is None else np.asarray(timeline)[steps], normalize,
                random_state, params)[0].positions

        X, M = Xs, masks
    else:
        X, M, sensor, timeline = check_inputs(histories, sensor, mask, timeline)
        per_step = COLUMNS_PER_STEP[sensor]
        n_steps = X.shape[1] // per_step

        def refit(steps):
            cols = _step_columns(steps, per_step)
            return _fit_map(X[:, cols], anchor_ids, anchor_positions, method, sensor,
                            None if M is None else M[:, cols],
                            None if timeline is None else np.asarray(timeline)[steps],
                            normalize, random_state, params)[0].positions

        if sp.issparse(X):  # the adjustments read dense histories
            X, M = X.toarray(), (M.toarray() if sp.issparse(M) else M)
    return with_covariances(result, uncertainty, est=est, mapped=mapped, X=X, mask=M,
                            n_steps=n_steps, refit=refit, random_state=random_state,
                            timeline=timeline)


def _with_covariances_3d(result, uncertainty, est, X, mask, sensor, anchor_ids, anchor_positions,
                         random_state) -> Map:
    """``result`` (a 3-D map) with ``Map.covariances``: the model's for SPATIAL-BA, a bootstrap's
    for COVIS-3D (each replicate the same method on the chosen steps' columns)."""
    per_step = step_columns_3d(X, sensor)
    if isinstance(X, Mapping):
        n_steps = X["bearing"].shape[1] // per_step["bearing"]

        def cut(steps):
            masks = dict(mask or {})
            return ({k: v[:, _step_columns(steps, per_step[k])] for k, v in X.items()},
                    {k: None if masks.get(k) is None else
                     np.asarray(masks[k])[:, _step_columns(steps, per_step[k])] for k in X})
    else:
        n_steps = X.shape[1] // per_step

        def cut(steps):
            cols = _step_columns(steps, per_step)
            return X[:, cols], None if mask is None else np.asarray(mask)[:, cols]

    def refit(steps):
        Xr, Mr = cut(steps)
        return build_map_3d(Xr, anchor_ids, anchor_positions, result.method, sensor=sensor,
                            mask=Mr, **result.params).positions

    return with_covariances(result, uncertainty, est=est, mapped=np.arange(len(result.positions)),
                            X=X, mask=mask, n_steps=n_steps, refit=refit,
                            random_state=random_state)


def _held_out_checked(histories, anchor_ids, anchor_positions, method, floor=False,
                      **kwargs) -> Map:
    """``build_map(..., uncertainty="anchors")``: the map with its own covariances (``True``),
    scaled by its held-out anchors (:func:`mappers.covariances.with_held_out_check`): each
    anchor in turn mapped by the same method from the other anchors; where that map cannot place
    it (a sparse logged run) and the method ends with a planar adjustment, the adjustment alone
    is fitted again from the full map with that anchor free
    (:func:`mappers.viewpoints.marginals.released_anchor`).

    ``floor`` (``uncertainty=True``): for a method with an adjustment, the model's covariances
    plus the floor its anchors, released from the adjustment by one linearised step, estimate
    (:func:`mappers.covariances.with_held_out_floor`); any other method's own covariances as
    they are (no map again)."""
    ids = np.asarray(anchor_ids, dtype=int)
    pos = np.asarray(anchor_positions, dtype=float)
    params = {k: kwargs.pop(k) for k in list(kwargs)
              if k not in ("sensor", "mask", "timeline", "normalize", "random_state")}
    if anchor_dimension(anchor_positions) == 3:
        result, est, X3, mask3, sensor3 = fit_map_3d(histories, ids, pos, method,
                                                     sensor=kwargs["sensor"],
                                                     mask=kwargs["mask"], **params)
        release = None
        with covariance_threads(len(result.positions)):
            linear = (spatial_held_out(est, pos, floor) if isinstance(est, SpatialAdjustment)
                      else None)
        if floor and linear is not None:  # (the model and the held-out anchors at once)
            result = with_model_covariances(result, linear[2])
        else:
            result = _with_covariances_3d(result, True, est, X3, mask3, sensor3, ids, pos,
                                          kwargs["random_state"])
    else:
        # (True: the model's covariances and the held-out anchors from one linearisation)
        result, est, mapped = _build_2d(histories, anchor_ids, anchor_positions, method,
                                        kwargs["sensor"], kwargs["mask"], kwargs["timeline"],
                                        kwargs["normalize"], kwargs["random_state"],
                                        not floor, params)
        with covariance_threads(len(result.positions)):
            release, linear = _releaser(result, est, mapped, histories, ids, pos,
                                        {**kwargs, **params}, floor)
        if floor and linear is not None:
            result = with_model_covariances(result, linear[2], mapped)
        elif floor:  # (no adjustment, or an anchor it did not place)
            hs, tl = _unpacked(histories, kwargs["timeline"])
            result = _with_covariances(result, True, est, mapped, hs, anchor_ids,
                                       anchor_positions, kwargs["sensor"], kwargs["mask"], tl,
                                       kwargs["normalize"], kwargs["random_state"], params)
    if floor:
        if has_model_covariances(est):
            held = linear if linear is not None else (np.full_like(pos, np.nan),
                                                      np.full((*pos.shape, pos.shape[1]), np.nan))
            result = with_held_out_floor(result, held[0], held[1], pos)
        for note in result.warnings:
            warnings.warn(note, MapWarning, stacklevel=3)
        return result
    for note in result.warnings:
        warnings.warn(note, MapWarning, stacklevel=3)
    kwargs = {**kwargs, **params}

    own = "model" if has_model_covariances(est) else True  # (True would add its floor)

    def held_out(j):
        if linear is not None:  # the method's adjustment, linearised: no map again
            return linear[0][j], linear[1][j]
        keep = np.arange(len(ids)) != j
        try:
            m = build_map(histories, ids[keep], pos[keep], method, uncertainty=own, **kwargs)
            p, c = m.positions[ids[j]], m.covariances[ids[j]]
            if np.all(np.isfinite(p)) and np.all(np.isfinite(c)):
                return p, c
        except (MappingError, ValueError):
            if release is None:
                raise
        if release is None:
            return p, c
        return release(j)

    checked = with_held_out_check(result, held_out, pos)
    for note in checked.warnings[len(result.warnings):]:
        warnings.warn(note, MapWarning, stacklevel=3)
    return checked


def _releaser(result, est, mapped, histories, ids, pos, kwargs, with_covariances=False):
    """``(release, linear)``: ``release(j)`` anchor ``j`` held out of ``est``'s adjustment, in
    the map's frame (:func:`mappers.viewpoints.marginals.released_anchor`), and ``linear`` every
    anchor held out of it linearised, ``(positions (A, 2), covariances (A, 2, 2))`` in the map's
    frame (:func:`mappers.viewpoints.held_out_anchors`); ``(None, None)`` when ``est`` has no
    adjustment. ``with_covariances``: ``linear`` has a third item, the model's covariances of
    the ``mapped`` rows in the adjustment's frame, from the same linearisation."""
    if not has_model_covariances(est) or np.any(~np.isin(ids, mapped)):
        return None, None
    parts = getattr(histories, "parts", None)
    timeline = kwargs["timeline"]
    if isinstance(parts, Mapping) and not isinstance(histories, Mapping):
        timeline = timeline if timeline is not None else getattr(histories, "timeline", None)
        histories = dict(parts)
    if isinstance(histories, Mapping):
        X, M, _, timeline = check_fused(histories, kwargs["mask"], timeline)
    else:
        X, M, _, timeline = check_inputs(histories, kwargs["sensor"], kwargs["mask"], timeline)
        if sp.issparse(X):
            X, M = X.toarray(), (M.toarray() if sp.issparse(M) else M)
    rows = (lambda a: None if a is None else (  # noqa: E731 - the mapped rows of each array
        {k: None if v is None else v[mapped] for k, v in a.items()} if isinstance(a, dict)
        else a[mapped]))
    local = np.searchsorted(mapped, ids)
    T = np.asarray(result.affine, dtype=float)

    def release(j):
        p, c = released_anchor(est, rows(X), rows(M), local, pos, j, timeline)
        return np.r_[p, 1.0] @ T, T[:2].T @ c @ T[:2]

    p, c, *model = held_out_anchors(est, rows(X), rows(M), local, timeline, with_covariances)
    return release, (p @ T[:2] + T[2], np.einsum("ji,ajk,kl->ail", T[:2], c, T[:2]), *model)
