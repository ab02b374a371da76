"""Anchors in 3-D: their checks, and the fits that take an embedding onto them (paper §3, step
4, in three dimensions).

A 3-D embedding is defined up to an affine map of space (12 parameters): four anchors not on one
plane fix it, more give a least-squares fit. A map that is already metric (a bundle adjustment's,
or one built from ranges) needs only a similarity (rotation, translation, one scale: 7
parameters), which three anchors not on one line fix (Umeyama, *Least-squares estimation of
transformation parameters between two point patterns*, IEEE TPAMI 13(4), 1991).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mappers.core.align import check_anchor_ids, check_anchor_positions

__all__ = [
    "apply_affine_3d",
    "check_anchors_3d",
    "check_not_collinear_3d",
    "check_not_coplanar",
    "fit_affine_3d",
    "fit_similarity_3d",
    "umeyama",
]

_RTOL = 1e-6
"""A singular value of the centred points below this share of the largest is taken as zero."""


def _centred_singular_values(points: Any, what: str, min_points: int, fit: str) -> np.ndarray:
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{what} must have shape (n, 3), got {points.shape}")
    if points.shape[0] < min_points:
        raise ValueError(f"{what}: {fit} needs at least {min_points} points, got {points.shape[0]}")
    if not np.all(np.isfinite(points)):
        raise ValueError(f"{what} contain NaN or inf")
    return np.linalg.svd(points - points.mean(axis=0), compute_uv=False)


def check_not_collinear_3d(points: Any, what: str, *, rtol: float = _RTOL) -> None:
    """ValueError unless the (n, 3) ``points`` are at least 3 and not (nearly) on one line: the
    second singular value of the centred points is above ``rtol`` times the first. A similarity
    fit needs this."""
    s = _centred_singular_values(points, what, 3, "a similarity fit")
    if s[0] == 0 or s[1] <= rtol * s[0]:
        raise ValueError(f"{what} lie on one line (singular values {s[0]:.3g}, {s[1]:.3g}, "
                         f"{s[2]:.3g}): a similarity cannot be fitted (it needs 3 anchors not on "
                         "one line)")


def check_not_coplanar(points: Any, what: str, *, rtol: float = _RTOL) -> None:
    """ValueError unless the (n, 3) ``points`` are at least 4 and not (nearly) on one plane: the
    third singular value of the centred points is above ``rtol`` times the first. An affine fit
    in 3-D needs this; the message says that a similarity needs only 3 not on one line."""
    s = _centred_singular_values(points, what, 4, "an affine fit in 3-D")
    if s[0] == 0 or s[2] <= rtol * s[0]:
        raise ValueError(f"{what} lie on one plane (singular values {s[0]:.3g}, {s[1]:.3g}, "
                         f"{s[2]:.3g}): a 3-D affine map cannot be fitted (it needs 4 anchors not "
                         "on one plane; a similarity fit needs 3 not on one line)")


def check_anchors_3d(anchor_ids: Any, anchor_positions: Any, n_objects: int, *,
                     fit: str = "similarity") -> tuple[np.ndarray, np.ndarray]:
    """Validated 3-D anchors: (A,) int64 ids (distinct, in [0, n_objects)) and (A, 3) finite
    positions, not on one line (``fit="similarity"``) or not on one plane (``fit="affine"``)."""
    ids = check_anchor_ids(anchor_ids, n_objects, min_count=4 if fit == "affine" else 3)
    pos = check_anchor_positions(anchor_positions, ids.size, dim=3)
    if fit == "affine":
        check_not_coplanar(pos, "anchor positions (world)")
    elif fit == "similarity":
        check_not_collinear_3d(pos, "anchor positions (world)")
    else:
        raise ValueError(f"fit must be 'affine' or 'similarity', got {fit!r}")
    return ids, pos


def fit_affine_3d(src: Any, dst: Any) -> np.ndarray:
    """Least-squares affine map of space taking ``src`` (n, 3) onto ``dst`` (n, 3), n >= 4, both
    not on one plane. Returns a (4, 3) matrix ``T`` with ``dst ~= [src, 1] @ T``."""
    src, dst = np.asarray(src, dtype=float), np.asarray(dst, dtype=float)
    if src.shape != dst.shape:
        raise ValueError(f"src and dst must have the same shape, got {src.shape} and {dst.shape}")
    check_not_coplanar(dst, "anchor positions (world)")
    check_not_coplanar(src, "anchors' embedded points")
    T, *_ = np.linalg.lstsq(np.column_stack([src, np.ones(len(src))]), dst, rcond=None)
    return T


def fit_similarity_3d(src: Any, dst: Any, *, scale: bool = True) -> np.ndarray:
    """Least-squares similarity (rotation, translation and, if ``scale``, one scale factor; no
    reflection) taking ``src`` (n, 3) onto ``dst`` (n, 3), n >= 3, both not on one line
    (Umeyama 1991). Returns it as a (4, 3) matrix ``T`` with ``dst ~= [src, 1] @ T``."""
    src, dst = np.asarray(src, dtype=float), np.asarray(dst, dtype=float)
    if src.shape != dst.shape:
        raise ValueError(f"src and dst must have the same shape, got {src.shape} and {dst.shape}")
    check_not_collinear_3d(dst, "anchor positions (world)")
    check_not_collinear_3d(src, "anchors' embedded points")
    R, s, t = umeyama(src, dst, scale)
    return np.vstack([s * R.T, t])


def umeyama(src: np.ndarray, dst: np.ndarray, scale: bool = True) -> tuple[np.ndarray, float, np.ndarray]:
    """``(R, s, t)`` with ``dst ~= s * R @ src + t`` in least squares (Umeyama 1991, eqs. 38-42)."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    U, S, Vt = np.linalg.svd(b.T @ a / len(src))
    D = np.ones(3)
    D[2] = np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0
    R = U @ np.diag(D) @ Vt
    var = np.mean(np.sum(a * a, axis=1))
    s = float(np.sum(S * D) / var) if scale else 1.0
    return R, s, mu_d - s * R @ mu_s


def apply_affine_3d(points: Any, transform: Any) -> np.ndarray:
    """Apply a (4, 3) transform of :func:`fit_affine_3d` or :func:`fit_similarity_3d` to (n, 3)
    ``points``."""
    points, transform = np.asarray(points, dtype=float), np.asarray(transform, dtype=float)
    if transform.shape != (4, 3):
        raise ValueError(f"transform must have shape (4, 3), got {transform.shape}")
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {points.shape}")
    return points @ transform[:3] + transform[3]
