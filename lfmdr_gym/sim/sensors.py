"""What the robot senses: pure, vectorised geometry of a robot pose and circular objects.

Every function here takes a robot pose ``(x, y, heading)`` and the ``(M, 2)`` object centres and
returns one reading per object (or per ray). Nothing depends on the simulator, so the same
functions turn logged poses and landmark positions into the histories the simulator would have
produced (paper §4.3.1, §4.4.1). Angles are in radians, counter-clockwise positive; the heading is the
direction the robot faces.

The ``*_from_rel`` kernels take the object offsets ``rel = objects - (x, y)`` and squared
distances ``d2`` already computed, so that the environment computes them once per step and
shares them between its sensors; the public functions are thin wrappers around them.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

import lfmdr_gym.sim.kernels as kernels

__all__ = [
    "bearing",
    "proximity",
    "ranges",
    "ray_directions",
    "visibility",
    "visibility_distance",
]


# ----------------------------------------------------------------------------- helpers
def _pose_and_rel(pose: ArrayLike, objects: ArrayLike) -> tuple[float, float, float, np.ndarray, np.ndarray]:
    p = np.asarray(pose, dtype=np.float64)
    if p.shape != (3,):
        raise ValueError(f"pose must be (x, y, heading), got shape {p.shape}")
    obj = np.asarray(objects, dtype=np.float64)
    if obj.ndim != 2 or obj.shape[1] != 2:
        raise ValueError(f"objects must have shape (M, 2), got {obj.shape}")
    x, y, h = float(p[0]), float(p[1]), float(p[2])
    rel = obj - (x, y)
    d2 = np.einsum("ij,ij->i", rel, rel)
    return x, y, h, rel, d2


def visibility_distance(radius: float, visual_angle: float) -> float:
    """Distance below which an object of ``radius`` subtends more than ``visual_angle``.

    ``2 * asin(radius / d) > visual_angle``  <=>  ``d < radius / sin(visual_angle / 2)``
    (for ``0 < visual_angle < pi``); e.g. 0.550 m for r = 24 mm and 5 degrees.
    """
    if not 0.0 < visual_angle < math.pi:
        raise ValueError(f"visual_angle must be in (0, pi) radians, got {visual_angle}")
    if not radius > 0.0:
        raise ValueError(f"radius must be > 0, got {radius}")
    return radius / math.sin(0.5 * visual_angle)


@lru_cache(maxsize=32)
def ray_directions(n_rays: int) -> np.ndarray:
    """Unit vectors (n_rays, 2) of the proximity rays in the robot frame: ray k at 2*pi*k/n_rays."""
    if n_rays < 1:
        raise ValueError(f"n_rays must be >= 1, got {n_rays}")
    a = 2.0 * np.pi * np.arange(n_rays) / n_rays
    dirs = np.stack([np.cos(a), np.sin(a)], axis=1)
    dirs.setflags(write=False)
    return dirs


# ----------------------------------------------------------------------------- visibility
def candidates(d2: np.ndarray, reach: float) -> np.ndarray:
    """Indices of the objects nearer than ``reach`` (squared distances ``d2``): a cheap prefilter.

    Each sensor below only needs objects within a known distance (visibility:
    ``hypot(d_vis, r)``; proximity: ``max_range + r``), so the per-step work scales with the few objects nearby
    rather than with M.
    """
    return (d2 < reach * reach).nonzero()[0]


def visibility_from_candidates(
    n_objects: int,
    cand: np.ndarray,
    rc: np.ndarray,
    dc2: np.ndarray,
    radius: float,
    visual_angle: float,
    occlusion: bool,
) -> np.ndarray:
    """Kernel of :func:`visibility` on a candidate subset.

    ``cand`` indexes every object nearer than ``hypot(d_vis, radius)`` with ``d_vis =
    visibility_distance(radius, visual_angle)`` (more is fine); ``rc`` (K, 2) and ``dc2`` (K,)
    are their offsets from the robot and squared distances. Targets are the candidates nearer
    than ``d_vis``; an occluder k of target j has ``d_k^2 = t^2 + h^2 < d_j^2 + r^2``, so it is
    among the candidates too.
    """
    d_vis = visibility_distance(radius, visual_angle)
    return visibility_kernel(n_objects, cand, rc, dc2, d_vis * d_vis, dc2 - radius * radius, occlusion)


def visibility_kernel(
    n_objects: int,
    cand: np.ndarray,
    rc: np.ndarray,
    dc2: np.ndarray,
    d_vis2: float,
    q: np.ndarray,
    occlusion: bool,
) -> np.ndarray:
    """:func:`visibility_from_candidates` with ``d_vis^2`` and ``q = dc2 - radius^2`` precomputed
    (the env shares ``q`` with the proximity ring): the compiled
    :func:`lfmdr_gym.sim.kernels.visible_targets`."""
    out = np.zeros(n_objects, dtype=np.int8)
    kernels.visible_targets(cand, rc, dc2, d_vis2, q, bool(occlusion), out)
    return out


def visibility(
    pose: ArrayLike,
    objects: ArrayLike,
    radius: float,
    visual_angle: float,
    occlusion: bool = True,
) -> np.ndarray:
    """Which objects the robot sees: (M,) int8, 1 = visible (paper §4.3.1).

    Object ``j`` at distance ``d_j`` from the robot's centre is visible iff

    1. its horizontal visual angle ``2 * asin(radius / d_j)`` exceeds ``visual_angle``
       (radians; ``r / d`` is capped at 1), and
    2. (when ``occlusion``) its line of sight is clear. Another object ``k`` blocks it when
       the foot of the perpendicular from ``k``'s centre onto the line through the robot's
       centre and ``j``'s centre lies on the segment between them and that perpendicular is
       shorter than ``radius``. For a robot centre outside every object and object centres at
       least ``radius`` apart (always so in the simulator, where objects never overlap) this is
       exactly: the segment from the robot's centre to ``j``'s centre passes within ``radius``
       of ``k``'s centre, i.e. meets ``k``'s disc.

    Visibility is omnidirectional (the paper's robot has a panoramic camera); all objects share one
    ``radius``. Works on any pose and object positions, e.g. logged data.
    """
    radius, visual_angle = float(radius), float(visual_angle)
    _, _, _, rel, d2 = _pose_and_rel(pose, objects)
    cand = candidates(d2, math.hypot(visibility_distance(radius, visual_angle), radius))
    return visibility_from_candidates(
        d2.shape[0], cand, rel[cand], d2[cand], radius, visual_angle, bool(occlusion)
    )


# ----------------------------------------------------------------------------- bearing / range
def bearing_from_rel(rel: np.ndarray, d2: np.ndarray, heading: float, dtype=np.float64) -> np.ndarray:
    """Kernel of :func:`bearing` on precomputed offsets and squared distances."""
    c, s = math.cos(heading), math.sin(heading)
    # Columns: rel . h (cos * d) and h x rel (sin * d), h = (cos heading, sin heading).
    b = rel @ np.array(((c, -s), (s, c)))
    d = np.sqrt(d2)
    d[d == 0.0] = np.inf  # an object at the robot's centre has no bearing: reading (0, 0)
    b /= d[:, None]
    return b.astype(dtype, copy=False)


def bearing(pose: ArrayLike, objects: ArrayLike) -> np.ndarray:
    """Bearing of every object relative to the heading, as (M, 2) ``[cos theta, sin theta]``.

    ``theta`` is measured from the robot's heading, counter-clockwise positive: an object to the
    robot's left has ``sin theta > 0``, one straight ahead ``(1, 0)``. Always available for every
    object (paper 4.4.1). An object exactly at the robot's centre reads ``(0, 0)``.
    """
    _, _, h, rel, d2 = _pose_and_rel(pose, objects)
    return bearing_from_rel(rel, d2, h)


def ranges_from_rel(d2: np.ndarray, max_range: float | None, dtype=np.float64) -> np.ndarray:
    """Kernel of :func:`ranges` on precomputed squared distances."""
    d = np.sqrt(d2)
    if max_range is not None:
        d[d > max_range] = 0.0
    return d.astype(dtype, copy=False)


def ranges(pose: ArrayLike, objects: ArrayLike, max_range: float | None = None) -> np.ndarray:
    """Distance (M,) from the robot's centre to each object's centre [m].

    With ``max_range``, objects farther than it are not sensed and read 0 (a range of exactly 0
    is otherwise impossible, since the robot never overlaps an object).
    """
    if max_range is not None and not max_range > 0:
        raise ValueError(f"max_range must be > 0 or None, got {max_range}")
    _, _, _, _, d2 = _pose_and_rel(pose, objects)
    return ranges_from_rel(d2, max_range)


# ----------------------------------------------------------------------------- proximity
def proximity_from_candidates(
    x: float,
    y: float,
    heading: float,
    rc: np.ndarray,
    dc2: np.ndarray,
    radius: float,
    arena_half: float,
    dirs: np.ndarray,
    max_range: float,
) -> np.ndarray:
    """Kernel of :func:`proximity` (float64). ``dirs`` = :func:`ray_directions` (robot frame);
    ``rc`` (K, 2), ``dc2`` (K,): offsets and squared distances of (at least) every object nearer
    than ``max_range + radius``."""
    return proximity_kernel(
        x, y, heading, rc, dc2 - radius * radius, arena_half, dirs, max_range
    )


def proximity_kernel(
    x: float,
    y: float,
    heading: float,
    rc: np.ndarray,
    q: np.ndarray,
    arena_half: float,
    dirs: np.ndarray,
    max_range: float,
) -> np.ndarray:
    """:func:`proximity_from_candidates` with ``q = dc2 - radius^2`` precomputed (the env shares
    it with the visibility test): the compiled :func:`lfmdr_gym.sim.kernels.proximity_ring`."""
    return kernels.proximity_ring(
        x, y, math.cos(heading), math.sin(heading), rc, q, arena_half, dirs, max_range
    )


def proximity(
    pose: ArrayLike,
    objects: ArrayLike,
    radius: float,
    arena_half: float,
    n_rays: int,
    max_range: float,
) -> np.ndarray:
    """A ring of ``n_rays`` range readings (n_rays,) for reactive obstacle avoidance.

    Ray ``k`` leaves the robot's centre at ``heading + 2*pi*k/n_rays`` (counter-clockwise); its
    reading is the distance to the first obstacle along it — an object's surface (a circle of
    ``radius``) or one of the walls ``x = +-arena_half``, ``y = +-arena_half`` — capped at
    ``max_range``. The robot's own radius is not subtracted; its centre is assumed to be inside
    the walls and outside every object.
    """
    if not max_range > 0:
        raise ValueError(f"max_range must be > 0, got {max_range}")
    if not arena_half > 0:
        raise ValueError(f"arena_half must be > 0, got {arena_half}")
    radius, max_range = float(radius), float(max_range)
    x, y, h, rel, d2 = _pose_and_rel(pose, objects)
    cand = candidates(d2, max_range + radius)
    return proximity_from_candidates(
        x, y, h, rel[cand], d2[cand], radius, float(arena_half), ray_directions(int(n_rays)), max_range
    )
