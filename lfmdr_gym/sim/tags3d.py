"""Tags in 3-D for ``LFMDR-Camera3D-v0``: where they hang (posts and walls) and which are anchors.

The robot drives the planar arena of :class:`lfmdr_gym.sim.world.World`, whose cylinders become
*posts* taller than the tags (see :mod:`lfmdr_gym.sim.view3d`). The objects to map are *tags*:
``tags_per_post`` on every post, at heights drawn uniformly in the tag band (a tag on a post is a
band around it; its position is the point on the post's axis), and ``n_wall_tags`` on the four
walls, at uniform positions along the perimeter (at least ``corner_margin`` from a corner) and
uniform heights in the band. Post tags come first (post by post), then wall tags.

Anchors follow the rule the project uses on the STAR-loc data (issue 34), so that worlds and
real data agree: the lowest tag, then repeatedly the tag farthest from those picked
(farthest-point order by the true positions). A 3-D affine fit needs at least four anchors not on
one plane; :func:`choose_anchors` refuses a set that is.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from lfmdr_gym.checks import check_int, check_real
from lfmdr_gym.sim.world import check_anchor_indices

__all__ = ["TagLayout", "check_anchor_ids", "check_heights", "check_tags", "choose_anchors", "coplanar",
           "place_tags"]

ON_AXIS_TOLERANCE = 1e-9
"""Horizontal distance [m] within which a user's tag counts as mounted on a post's axis."""


@dataclass(frozen=True, eq=False)
class TagLayout:
    """The tags of one episode: positions (M, 3), the post each is on (M,) (-1: none, e.g. on
    a wall) and the anchor indices (A,)."""

    positions: np.ndarray
    hosts: np.ndarray
    anchor_ids: np.ndarray


def coplanar(points: np.ndarray, rtol: float = 1e-6) -> bool:
    """Whether 3-D ``points`` lie (nearly) on one plane: they cannot fix a 3-D affine map."""
    centred = points - points.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    return bool(sv.size < 3 or sv[0] == 0.0 or sv[2] <= rtol * sv[0])


def place_tags(rng: np.random.Generator, posts: np.ndarray, arena_half: float, *,
               tags_per_post: int, n_wall_tags: int, heights: tuple[float, float],
               corner_margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Random tag positions (M, 3) and hosts (M,) for posts (K, 2) in the arena of half-side
    ``arena_half`` (see the module docstring). Draws: the post tags' heights, then the wall
    tags' places along the perimeter, then their heights."""
    lo, hi = heights
    k = posts.shape[0]
    post_z = rng.uniform(lo, hi, size=(k, tags_per_post))
    post_tags = np.column_stack((np.repeat(posts, tags_per_post, axis=0), post_z.ravel()))
    hosts = np.repeat(np.arange(k, dtype=np.int64), tags_per_post)
    a = arena_half
    side_len = 2.0 * (a - corner_margin)
    s = rng.uniform(0.0, 4.0 * side_len, size=n_wall_tags)  # position along the usable perimeter
    side, t = np.divmod(s, side_len)
    t = t - (a - corner_margin)  # along the side, centred
    side = side.astype(np.int64)
    # sides: south (y = -a), east (x = a), north (y = a), west (x = -a)
    x = np.select([side == 0, side == 1, side == 2], [t, np.full_like(t, a), -t], np.full_like(t, -a))
    y = np.select([side == 0, side == 1, side == 2], [np.full_like(t, -a), t, np.full_like(t, a)], -t)
    wall_z = rng.uniform(lo, hi, size=n_wall_tags)
    wall_tags = np.column_stack((x, y, wall_z))
    return (np.concatenate((post_tags, wall_tags)),
            np.concatenate((hosts, np.full(n_wall_tags, -1, dtype=np.int64))))


def check_tags(positions: Any, posts: np.ndarray, post_radius: float,
               arena_half: float) -> tuple[np.ndarray, np.ndarray]:
    """A user's tag positions (M, 3), checked, and their hosts: a tag on a post's axis (within
    :data:`ON_AXIS_TOLERANCE`) is mounted on it; any other tag must lie inside the walls (or on
    them) and outside every post. Heights may be any finite number."""
    pos = np.array(positions, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] < 4:
        raise ValueError(f"tag_positions must have shape (M, 3) with M >= 4, got {pos.shape}")
    if not np.isfinite(pos).all():
        raise ValueError("tag_positions must be finite")
    outside = np.flatnonzero((np.abs(pos[:, :2]) > arena_half).any(axis=1))
    if outside.size:
        j = int(outside[0])
        raise ValueError(f"tag_positions[{j}] = {pos[j].tolist()} is outside the walls "
                         f"(|x|, |y| <= {arena_half:g})")
    d = np.sqrt(((pos[:, None, :2] - posts[None, :, :]) ** 2).sum(axis=-1))  # (M, K)
    hosts = np.full(pos.shape[0], -1, dtype=np.int64)
    if posts.shape[0]:
        nearest = d.argmin(axis=1)
        on_axis = d[np.arange(pos.shape[0]), nearest] <= ON_AXIS_TOLERANCE
        hosts[on_axis] = nearest[on_axis]
        inside = np.flatnonzero(~on_axis & (d.min(axis=1) < post_radius))
        if inside.size:
            j = int(inside[0])
            raise ValueError(f"tag_positions[{j}] = {pos[j].tolist()} is inside post "
                             f"{int(nearest[j])} but not on its axis")
    return pos, hosts


def choose_anchors(positions: np.ndarray, n_anchors: int) -> np.ndarray:
    """The lowest tag, then ``n_anchors - 1`` times the tag farthest from those picked (ties: the
    lower index); ValueError if they lie on one plane."""
    n_anchors = check_int("n_anchors", n_anchors, low=4)
    m = positions.shape[0]
    if n_anchors > m:
        raise ValueError(f"n_anchors={n_anchors} exceeds the {m} tags")
    ids = [int(np.argmin(positions[:, 2]))]
    gap = np.linalg.norm(positions - positions[ids[0]], axis=1)
    for _ in range(n_anchors - 1):
        j = int(np.argmax(gap))
        ids.append(j)
        gap = np.minimum(gap, np.linalg.norm(positions - positions[j], axis=1))
    out = np.array(ids, dtype=np.int64)
    if coplanar(positions[out]):
        raise ValueError(f"the anchors {out.tolist()} lie on one plane: a 3-D map needs four "
                         "not on one plane; give anchor_ids in the reset options")
    return out


def check_anchor_ids(anchor_ids: Any, positions: np.ndarray) -> np.ndarray:
    """User anchor indices: >= 4 distinct integers in range, not on one plane."""
    ids = check_anchor_indices(anchor_ids, positions.shape[0], 4, " in 3-D")
    if coplanar(positions[ids]):
        raise ValueError(f"anchor_ids {ids.tolist()} name tags on one plane: a 3-D map needs "
                         "four not on one plane")
    return ids


def check_heights(heights: Any) -> tuple[float, float]:
    """The tag band ``(low, high)`` [m], ``0 <= low < high``."""
    try:
        lo, hi = heights
    except (TypeError, ValueError):
        raise ValueError(f"tag_heights must be a pair (low, high), got {heights!r}") from None
    lo = check_real("tag_heights[0]", lo, low=0.0)
    hi = check_real("tag_heights[1]", hi, low=lo, low_open=True)
    return lo, hi
