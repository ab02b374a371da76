"""3-D bearing histories: one unit ray per step, and the observations they hold.

A 3-D bearing history has one row per object and three columns per step, ``(x, y, z)`` of the
unit ray from the sensor to the object in the sensor's frame (a camera's optical frame: z
forward, x right, y down); an object not seen in a step has the ray ``(0, 0, 0)``, or is masked
out by a boolean mask of the history's shape. A range history of the same objects and steps
(one column per step) may come with it (:mod:`mappers.core.fused_histories`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["RAY_COLUMNS", "RayObservations", "ray_observations"]

RAY_COLUMNS = 3
"""Columns one step of a 3-D bearing history takes: the ray's x, y, z."""

_UNIT_TOL = 1e-3
"""How far an observed ray's length may be from 1 (float32 storage, rounding)."""


class RayObservations(NamedTuple):
    """The sightings of a 3-D history, one entry per (step, object) seen.

    Attributes:
        step: (K,) step index of each sighting.
        obj: (K,) object index (row of the history).
        ray: (K, 3) unit ray in the sensor's frame.
        range: (K,) measured range [m], NaN where none was measured.
        n_steps, n_objects: the history's shape in steps and objects.
    """

    step: np.ndarray
    obj: np.ndarray
    ray: np.ndarray
    range: np.ndarray
    n_steps: int
    n_objects: int


_RANGES_HINT = "; a history of ranges alone is mapped with sensor='range'"


def ray_observations(X, mask=None, ranges=None, range_mask=None) -> RayObservations:
    """The sightings of a 3-D bearing history ``X`` (M, 3N) with its optional ``mask`` (M, 3N),
    and of an optional range history ``ranges`` (M, N) with ``range_mask``.

    A ray that is observed (masked in) but of length 0 is a ValueError (a direction cannot be
    zero); without a mask a zero ray means "not seen". A history whose columns are not a
    multiple of 3, or whose rays are not of unit length, is a ValueError that says what it looks
    like instead (a 2-D history of (cos, sin) pairs needs 2-D anchors). A range is used where it
    is observed, positive and its object was seen; a range of an object without a ray is refused.
    """
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[1] == 0 or X.shape[1] % RAY_COLUMNS:
        pairs = X.ndim == 2 and X.shape[1] % 2 == 0
        raise ValueError(
            f"a 3-D bearing history has 3 columns (a ray's x, y, z) per step, got shape {X.shape}"
            + ("; it looks like a 2-D bearing history of (cos, sin) pairs, which needs (A, 2) "
               "anchor positions" if pairs else "") + _RANGES_HINT)
    m, n = X.shape[0], X.shape[1] // RAY_COLUMNS
    rays = X.reshape(m, n, RAY_COLUMNS)
    if mask is not None:
        mask = np.asarray(mask)
        if mask.dtype != np.bool_ or mask.shape != X.shape:
            raise ValueError(f"mask must be a bool array of the history's shape {X.shape}, got "
                             f"{mask.dtype} {mask.shape}")
        step_mask = mask.reshape(m, n, RAY_COLUMNS).all(axis=2)
        if np.any(mask.reshape(m, n, RAY_COLUMNS).any(axis=2) & ~step_mask):
            raise ValueError("mask must mark a ray's three columns alike (all observed or none)")
        rays = np.where(step_mask[..., None], rays, 0.0)
        if not np.all(np.isfinite(rays)):
            raise ValueError("the history holds NaN or inf in observed rays")
        length = np.linalg.norm(rays, axis=2)
        zero = step_mask & (length == 0)
        if zero.any():
            o, s = np.argwhere(zero)[0]
            raise ValueError(f"{int(zero.sum())} observed ray(s) have length 0 (the first: object "
                             f"{o}, step {s}): a direction cannot be zero")
        seen = step_mask
    else:
        if not np.all(np.isfinite(rays)):
            raise ValueError("the history holds NaN or inf")
        length = np.linalg.norm(rays, axis=2)
        seen = length > 0
    bad = seen & (np.abs(length - 1.0) > _UNIT_TOL)
    if bad.any():
        raise ValueError(
            "a 3-D bearing history holds unit rays (x, y, z) per step; found rays of length "
            f"{np.round(length[bad][:3], 3).tolist()}"
            + (" (columns in a multiple of 2 and 3: is it a 2-D history of (cos, sin) pairs? "
               "those need (A, 2) anchor positions)" if X.shape[1] % 2 == 0 else "")
            + _RANGES_HINT)
    obj, step = np.nonzero(seen)
    order = np.lexsort((obj, step))
    obj, step = obj[order], step[order]
    ray = rays[obj, step] / length[obj, step][:, None]
    rng_k = np.full(len(obj), np.nan)
    if ranges is not None:
        rng_k = _ranges_at(ranges, range_mask, (m, n), seen, obj, step)
    return RayObservations(step, obj, ray, rng_k, n, m)


def _ranges_at(R, range_mask, shape, seen, obj, step) -> np.ndarray:
    R = np.asarray(R, dtype=float)
    if R.shape != shape:
        raise ValueError(f"the range history must have shape {shape} (objects, steps of the "
                         f"rays), got {R.shape}")
    has = R > 0 if range_mask is None else np.asarray(range_mask, dtype=bool) & np.isfinite(R)
    if range_mask is not None and np.any(has & (R <= 0)):
        raise ValueError("observed ranges must be > 0")
    if np.any(has & ~np.isfinite(R)):
        raise ValueError("the range history holds NaN or inf in observed entries")
    if np.any(has & ~seen):
        o, s = np.argwhere(has & ~seen)[0]
        raise ValueError(f"object {o} has a range but no ray at step {s}")
    return np.where(has[obj, step], R[obj, step], np.nan)
