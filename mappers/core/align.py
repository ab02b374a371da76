"""Anchors: their validation, and the least-squares affine fit of their embedded points onto
their known positions (paper §3, step 4).

A DR embedding is only defined up to an affine map (scale, rotation, shear, reflection,
translation); the anchors fix it. Three non-collinear anchors determine the six affine
parameters exactly; more anchors give a least-squares fit.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["apply_affine", "check_anchor_ids", "check_anchor_positions", "check_anchors", "check_not_collinear",
           "fit_affine"]


def check_not_collinear(points: np.ndarray, what: str, *, rtol: float = 1e-6) -> None:
    """Raise ValueError if the (n, 2) ``points`` are fewer than 3 or lie (nearly) on one line.

    Collinear means the smaller singular value of the centred points is below ``rtol`` times
    the larger one (or the points coincide).
    """
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 2:
        raise ValueError(f"{what} must have shape (n, 2), got {points.shape}")
    if points.shape[0] < 3:
        raise ValueError(f"{what}: need at least 3 points for an affine fit, got {points.shape[0]}")
    if not np.all(np.isfinite(points)):
        raise ValueError(f"{what} contain NaN or inf")
    s = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    if s[0] == 0 or s[1] <= rtol * s[0]:
        raise ValueError(
            f"{what} are collinear (singular values {s[0]:.3g}, {s[1]:.3g}): "
            "an affine map cannot be fitted"
        )


def check_anchor_ids(anchor_ids: Any, n_objects: int, *, min_count: int = 3) -> np.ndarray:
    """Validated anchor ids: (A,) int64, A >= ``min_count``, distinct, in [0, n_objects)."""
    ids = np.asarray(anchor_ids)
    if ids.ndim != 1 or ids.dtype == bool or (ids.size and not np.issubdtype(ids.dtype, np.integer)):
        raise ValueError(f"anchor_ids must be a 1-D array of integer object ids, got {ids!r}")
    if ids.size < min_count:
        raise ValueError(f"need at least {min_count} anchors, got {ids.size}")
    out = ids[(ids < 0) | (ids >= n_objects)]
    if out.size:
        raise ValueError(f"anchor_ids out of range [0, {n_objects - 1}]: {out.tolist()}")
    uniq, counts = np.unique(ids, return_counts=True)
    if np.any(counts > 1):
        raise ValueError(f"anchor_ids must be distinct; duplicates: {uniq[counts > 1].tolist()}")
    return ids.astype(np.int64)


def check_anchors(
    anchor_ids: Any, anchor_positions: Any, n_objects: int
) -> tuple[np.ndarray, np.ndarray]:
    """Validated anchors: (A,) int64 ids and (A, 2) float positions, else ValueError.

    ``anchor_ids``: A >= 3 distinct integer object ids in [0, n_objects); ``anchor_positions``:
    their known (A, 2) positions, finite and not collinear (an affine map needs three).
    """
    ids = check_anchor_ids(anchor_ids, n_objects)
    pos = check_anchor_positions(anchor_positions, ids.size)
    check_not_collinear(pos, "anchor positions (world)")
    return ids, pos


def check_anchor_positions(anchor_positions: Any, n_anchors: int, dim: int = 2) -> np.ndarray:
    """The known positions of ``n_anchors`` anchors as an (A, ``dim``) float array, else
    ValueError: not numeric, another shape, or NaN/inf. The 2-D and 3-D anchor checks
    (:func:`check_anchors`, :func:`mappers.core.align_3d.check_anchors_3d`) share it; the
    geometry (not on one line or plane) is theirs."""
    try:
        pos = np.array(anchor_positions, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"anchor_positions must be a numeric (A, {dim}) array: {exc}") from exc
    if pos.shape != (n_anchors, dim):
        raise ValueError(f"anchor_positions must have shape ({n_anchors}, {dim}), got {pos.shape}")
    if not np.all(np.isfinite(pos)):
        raise ValueError("anchor_positions contain NaN or inf")
    return pos


def fit_affine(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares affine map taking ``src`` (n, 2) onto ``dst`` (n, 2), n >= 3.

    Returns a (3, 2) matrix ``T`` with ``dst ~= [src, 1] @ T`` (use :func:`apply_affine`).
    Raises ValueError when either point set is collinear (the fit would be degenerate).
    """
    src = np.asarray(src, dtype=float)
    dst = np.asarray(dst, dtype=float)
    if src.shape != dst.shape:
        raise ValueError(f"src and dst must have the same shape, got {src.shape} and {dst.shape}")
    check_not_collinear(dst, "anchor positions (world)")
    check_not_collinear(src, "anchors' embedded points")
    design = np.column_stack([src, np.ones(len(src))])
    T, *_ = np.linalg.lstsq(design, dst, rcond=None)
    return T


def apply_affine(points: np.ndarray, transform: np.ndarray) -> np.ndarray:
    """Apply a (3, 2) affine ``transform`` from :func:`fit_affine` to (n, 2) ``points``."""
    points = np.asarray(points, dtype=float)
    transform = np.asarray(transform, dtype=float)
    if transform.shape != (3, 2):
        raise ValueError(f"transform must have shape (3, 2), got {transform.shape}")
    return points @ transform[:2] + transform[2]
