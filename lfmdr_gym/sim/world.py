"""The simulated arena: a pymunk space with walls, static cylinders and a disc robot.

Everything about the physical world sits behind :class:`World` (as panda-gym hides pybullet
behind one small class): random layouts with clearances, the choice of anchors, users' own
layouts, and moves that can never take the robot through an object or a wall. The environment
hands its ``np_random`` to :meth:`World.layout`, so one seed fixes the whole episode.

Why moves are checked rather than simulated: a pymunk kinematic body driven by velocity passes
straight through static shapes, and a dynamic body would need many sub-steps per move. A move is
a straight segment, so one query finds its first contact exactly and the robot stops just short
of it. The query is a thin segment (radius 0) against the obstacles grown by the robot's radius
(their Minkowski sums with the robot's disc: cylinders of radius r + R, walls thickened by R),
which is the swept-disc test in the robot's configuration space. A swept query *with* a radius
(``segment_query_first(a, b, R)``) is not used because Chipmunk's spatial index tests the bare
segment against bounding boxes, so it misses a thin wall or a cylinder that the robot's edge
would hit but its centre line passes by (Chipmunk2D issue #138). The grown shapes live in the
same space in their own collision category, next to the true walls and cylinders.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pymunk

from lfmdr_gym.checks import check_int, check_real
from lfmdr_gym.sim.grid import sample_separated

__all__ = ["ANCHOR_CHOICES", "Layout", "World", "action_turn", "check_anchor_indices", "wrap_angle"]

ANCHOR_CHOICES = ("corners", "random", "grid")
LAYOUT_OPTIONS = ("object_positions", "anchor_ids", "robot_pose")

ROBOT_GROUP = 1
"""pymunk group of the robot's shape: queries with the same group never report the robot itself."""

PHYSICAL = 0b01
"""Collision category of the true walls, cylinders and robot."""

GROWN = 0b10
"""Collision category of the obstacles grown by the robot's radius (configuration space)."""

CONTACT_MARGIN = 1e-9
"""Smallest gap [m] the robot keeps from any obstacle after a blocked move.

pymunk's swept queries report nothing for a disc that starts overlapping a shape, so the robot
must never end a move touching one within rounding error; a blocked move stops ``BACKOFF``
before the contact and is cancelled if that still leaves less than this gap."""

BACKOFF = 1e-5
"""Distance [m] a blocked move stops before the contact point along its path."""

START_MARGIN = 1e-2
"""Gap [m] between the robot and every obstacle at a random start pose."""

RANDOM_COVERAGE = 0.40
"""Largest share of the (clearance-inflated) placement area random layouts are asked to cover.

Random sequential placement jams near 0.547 for discs and slows down sharply before it; a
layout denser than this is refused on construction rather than after a long search."""

_BATCH = 64  # candidates drawn per rejection-sampling round (fixed, so layouts are reproducible)

GRID_SAMPLER_MIN_OBJECTS = 400
"""From this many objects random layouts are sampled with a background grid (O(M) rather than
O(M^2) distance checks); the draws and decisions are the same either way (tests/gym/sim/test_world.py)."""


def wrap_angle(angle: float) -> float:
    """``angle`` wrapped into (-pi, pi]."""
    a = math.pi - ((math.pi - angle) % (2.0 * math.pi))
    return a + 2.0 * math.pi if a <= -math.pi else a


def action_turn(action: Any, max_turn: float) -> float:
    """The turn [rad] an env's action asks for (a number, or a 1-element array), limited to
    [-max_turn, max_turn]; ValueError for NaN."""
    try:
        turn = float(action[0])
    except (TypeError, IndexError):
        turn = float(action)
    if turn != turn:
        raise ValueError(f"action must be a number, got {action!r}")
    return max_turn if turn > max_turn else (-max_turn if turn < -max_turn else turn)


def collinear(points: np.ndarray, rtol: float = 1e-6) -> bool:
    """Whether 2-D ``points`` lie (nearly) on one line: they cannot fix an affine map."""
    centred = points - points.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    return bool(sv[0] == 0.0 or sv[-1] <= rtol * sv[0])


def check_anchor_indices(anchor_ids: Any, n_positions: int, min_count: int,
                         where: str = "") -> np.ndarray:
    """User anchor indices (a reset option) as an (A,) int64 array, else a ValueError naming
    ``anchor_ids``: a 1-D integer array of at least ``min_count`` distinct indices in
    ``[0, n_positions)``. ``where`` ends the too-few message (``" in 3-D"``). The geometry (not
    collinear, not on one plane) is the caller's check."""
    ids = np.asarray(anchor_ids)
    if ids.ndim != 1 or not np.issubdtype(ids.dtype, np.integer):
        raise ValueError(f"anchor_ids must be a 1-D integer array, got {ids.dtype} {ids.shape}")
    ids = ids.astype(np.int64)
    if ids.size < min_count:
        raise ValueError(f"anchor_ids needs at least {min_count} anchors{where}, got {ids.size}")
    if ids.min() < 0 or ids.max() >= n_positions:
        raise ValueError(f"anchor_ids must lie in [0, {n_positions}), got {ids.tolist()}")
    if np.unique(ids).size != ids.size:
        raise ValueError(f"anchor_ids must be distinct, got {ids.tolist()}")
    return ids


def nearest_distinct(positions: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """For each target in turn, the index of the nearest position not taken by an earlier one."""
    from scipy.spatial import cKDTree

    tree = cKDTree(positions)
    taken: set[int] = set()
    out = []
    for t in targets:
        k = min(len(taken) + 1, positions.shape[0])  # enough neighbours to find a free one
        _, idx = tree.query(t, k=k)
        j = next(int(i) for i in np.atleast_1d(idx) if int(i) not in taken)
        taken.add(j)
        out.append(j)
    return np.array(out, dtype=np.int64)


@dataclass(frozen=True, eq=False)
class Layout:
    """One episode's world: object centres (M, 2), anchor indices (A,), robot pose (x, y, heading)."""

    object_positions: np.ndarray
    anchor_ids: np.ndarray
    robot_pose: np.ndarray


class World:
    """A square arena centred on the origin with M static cylinders and a disc robot (pymunk).

    All sizes are metres. Random layouts keep every pair of cylinders at least
    ``object_clearance`` apart (surface to surface) and every cylinder at least
    ``wall_clearance`` from the walls; with the defaults the robot (diameter 0.1 m) fits between
    any two. Anchors are the objects nearest ``n_anchors`` points spread evenly along the wall
    starting at the corner (-a, -a) — the four corners for the default 4 — (``"corners"``), the
    objects nearest a lattice of points spread over the arena (``"grid"``, for many anchors in a
    large arena), or a random set (``"random"``); they are never collinear.

    Call :meth:`layout` (with the env's ``np_random``) then :meth:`build` to start an episode,
    then :meth:`move` once per step.
    """

    def __init__(
        self,
        *,
        n_objects: int = 50,
        arena_size: float = 2.5,
        object_diameter: float = 0.048,
        robot_radius: float = 0.05,
        object_clearance: float = 0.15,
        wall_clearance: float = 0.15,
        anchors: str = "corners",
        n_anchors: int = 4,
    ) -> None:
        self.arena_size = check_real("arena_size", arena_size, low=0.0, low_open=True)
        self.object_diameter = check_real("object_diameter", object_diameter, low=0.0, low_open=True)
        self.robot_radius = check_real("robot_radius", robot_radius, low=0.0, low_open=True)
        self.object_clearance = check_real("object_clearance", object_clearance, low=0.0)
        self.wall_clearance = check_real("wall_clearance", wall_clearance, low=0.0)
        self.n_anchors = check_int("n_anchors", n_anchors, low=3)
        self.n_objects = check_int("n_objects", n_objects, low=3)
        if self.n_anchors > self.n_objects:
            raise ValueError(f"n_anchors={n_anchors} exceeds n_objects={n_objects}")
        if anchors not in ANCHOR_CHOICES:
            raise ValueError(f"anchors must be one of {ANCHOR_CHOICES}, got {anchors!r}")
        self.anchors = anchors
        self.arena_half = 0.5 * self.arena_size
        self.object_radius = 0.5 * self.object_diameter
        if 2.0 * self.robot_radius + 2.0 * CONTACT_MARGIN >= self.arena_size:
            raise ValueError(f"robot_radius={robot_radius} leaves no room in arena_size={arena_size}")
        # Centres of randomly placed objects lie in [-place_half, place_half]^2.
        self.place_half = self.arena_half - self.object_radius - self.wall_clearance
        if self.place_half < 0.0:
            raise ValueError(
                f"wall_clearance={wall_clearance} with object_diameter={object_diameter} leaves no "
                f"room for objects in arena_size={arena_size}"
            )
        self.min_separation = self.object_diameter + self.object_clearance
        if self.n_objects > self.capacity:
            raise ValueError(
                f"n_objects={n_objects} cannot be laid out at random with object_clearance="
                f"{object_clearance} and wall_clearance={wall_clearance} in arena_size={arena_size}: "
                f"about {self.capacity} fit; enlarge the arena or reduce the clearances"
            )
        self._grown_filter = pymunk.ShapeFilter(group=ROBOT_GROUP, mask=GROWN)
        self._space: pymunk.Space | None = None
        self._body: pymunk.Body | None = None
        self._body_stale = False  # the robot's pymunk body lags (x, y, heading); see `space`
        self.object_positions = np.zeros((0, 2))
        self.anchor_ids = np.zeros(0, dtype=np.int64)
        self.x = self.y = self.heading = 0.0

    # ------------------------------------------------------------------ layouts
    @property
    def capacity(self) -> int:
        """Rough number of objects a random layout can hold (see :data:`RANDOM_COVERAGE`).

        Discs of diameter ``min_separation`` around the centres are disjoint and lie in the
        placement square grown by half that diameter on each side.
        """
        s = self.min_separation
        area = (2.0 * self.place_half + s) ** 2
        return int(RANDOM_COVERAGE * area / (0.25 * math.pi * s * s))

    def layout(self, rng: np.random.Generator, options: Mapping[str, Any] | None = None) -> Layout:
        """A layout for a new episode: the user's parts from ``options``, the rest drawn from ``rng``.

        ``options`` may hold ``"object_positions"`` (M, 2), ``"anchor_ids"`` (A >= 3 distinct
        indices) and ``"robot_pose"`` (x, y, heading); each is validated (ValueError). Draws are
        made in a fixed order (objects, anchors, pose), so the same ``rng`` state gives the same
        layout.
        """
        options = {} if options is None else options
        if not isinstance(options, Mapping):
            raise ValueError(f"options must be a dict, got {type(options).__name__}")
        unknown = sorted(set(options) - set(LAYOUT_OPTIONS))
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; allowed: {list(LAYOUT_OPTIONS)}")
        pos = options.get("object_positions")
        pos = self.sample_objects(rng) if pos is None else self.check_objects(pos)
        ids = options.get("anchor_ids")
        ids = self.choose_anchors(pos, rng) if ids is None else self.check_anchor_ids(ids, pos)
        pose = options.get("robot_pose")
        pose = self.sample_pose(pos, rng) if pose is None else self.check_pose(pose, pos)
        pos.setflags(write=False)
        ids.setflags(write=False)
        return Layout(pos, ids, pose)

    def sample_objects(self, rng: np.random.Generator) -> np.ndarray:
        """Uniform random centres (n_objects, 2) with the clearances, by rejection sampling."""
        n, a = self.n_objects, self.place_half
        budget = 2000 * n + 20000
        if n >= GRID_SAMPLER_MIN_OBJECTS:
            pts, drawn = sample_separated(rng, n, a, self.min_separation, _BATCH, budget)
        else:
            pts, drawn = self._sample_dense(rng, n, a, budget)
        if pts.shape[0] < n:
            raise ValueError(
                f"could not place n_objects={n} with the clearances after {drawn} random "
                "draws; reduce n_objects or the clearances, or enlarge the arena"
            )
        return pts

    def _sample_dense(self, rng: np.random.Generator, n: int, a: float,
                      budget: int) -> tuple[np.ndarray, int]:
        """:func:`~lfmdr_gym.sim.grid.sample_separated` checking each batch against every accepted
        point at once (fastest for small M)."""
        s2 = self.min_separation**2
        pts = np.empty((n, 2))
        k, drawn = 0, 0
        while k < n:
            if drawn >= budget:
                return pts[:k], drawn
            batch = rng.uniform(-a, a, size=(_BATCH, 2))
            drawn += _BATCH
            if k:
                diff = batch[:, None, :] - pts[None, :k, :]
                free = np.einsum("ijk,ijk->ij", diff, diff).min(axis=1) >= s2
            else:
                free = np.ones(_BATCH, dtype=bool)
            k0 = k
            for i in np.flatnonzero(free):
                p = batch[i]
                if k > k0:
                    d = pts[k0:k] - p
                    if (np.einsum("ij,ij->i", d, d) < s2).any():
                        continue
                pts[k] = p
                k += 1
                if k == n:
                    break
        return pts, drawn

    def anchor_targets(self) -> np.ndarray:
        """Points (n_anchors, 2) evenly spaced along the walls from corner (-a, -a), anticlockwise."""
        a = self.arena_half
        corners = np.array([(-a, -a), (a, -a), (a, a), (-a, a), (-a, -a)])
        t = 4.0 * np.arange(self.n_anchors) / self.n_anchors  # position along the perimeter, in sides
        side = np.floor(t).astype(int)
        frac = (t - side)[:, None]
        return corners[side] * (1.0 - frac) + corners[side + 1] * frac

    def grid_targets(self) -> np.ndarray:
        """Points (n_anchors, 2) spread over the placement square: the centres of a ceil(sqrt(A))
        column lattice, row by row from (-a, -a), the last row's points spread over its width."""
        n, a = self.n_anchors, self.place_half
        cols = math.ceil(math.sqrt(n))
        rows = math.ceil(n / cols)
        out = []
        for row in range(rows):
            k = min(cols, n - row * cols)  # points in this row
            y = -a + (row + 0.5) * 2.0 * a / rows
            out += [(-a + (i + 0.5) * 2.0 * a / k, y) for i in range(k)]
        return np.array(out)

    def choose_anchors(self, positions: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Anchor indices for ``positions`` by the ``anchors`` rule; never collinear."""
        m = positions.shape[0]
        if self.anchors == "corners":
            targets = self.anchor_targets()
            d2 = ((positions[None, :, :] - targets[:, None, :]) ** 2).sum(axis=-1)
            ids: list[int] = []
            for row in d2:  # nearest object to each target, each object used once
                ids.append(int(next(j for j in np.argsort(row, kind="stable") if j not in ids)))
            out = np.array(ids, dtype=np.int64)
            if collinear(positions[out]):
                raise ValueError(
                    "the objects nearest the corners are collinear; use anchors='random' or give "
                    "anchor_ids in the reset options"
                )
            return out
        if self.anchors == "grid":
            out = nearest_distinct(positions, self.grid_targets())
            if collinear(positions[out]):
                raise ValueError(
                    "the objects nearest the grid points are collinear; use anchors='random' or "
                    "give anchor_ids in the reset options"
                )
            return out
        for _ in range(1000):
            out = np.sort(rng.choice(m, size=self.n_anchors, replace=False)).astype(np.int64)
            if not collinear(positions[out]):
                return out
        raise ValueError(f"no non-collinear set of n_anchors={self.n_anchors} objects in this layout")

    def sample_pose(self, positions: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """A uniform random start pose clear of every obstacle by ``START_MARGIN``."""
        lim = self.arena_half - self.robot_radius - START_MARGIN
        if lim <= 0:
            lim = self.arena_half - self.robot_radius - CONTACT_MARGIN
        need = (self.object_radius + self.robot_radius + START_MARGIN) ** 2
        for _ in range(1000):
            xy = rng.uniform(-lim, lim, size=(_BATCH, 2))
            diff = xy[:, None, :] - positions[None, :, :]
            ok = np.flatnonzero(np.einsum("ijk,ijk->ij", diff, diff).min(axis=1) >= need)
            if ok.size:
                heading = wrap_angle(math.pi - rng.uniform(0.0, 2.0 * math.pi))
                return np.array((xy[ok[0], 0], xy[ok[0], 1], heading))
        raise ValueError("no free start pose for the robot in this layout")

    def check_objects(self, positions: Any) -> np.ndarray:
        """Validate user object positions: (n_objects, 2), inside the walls, not overlapping."""
        pos = np.array(positions, dtype=np.float64)  # a copy: the caller's array stays theirs
        if pos.shape != (self.n_objects, 2):
            raise ValueError(f"object_positions must have shape ({self.n_objects}, 2), got {pos.shape}")
        if not np.isfinite(pos).all():
            raise ValueError("object_positions must be finite")
        lim = self.arena_half - self.object_radius
        if (np.abs(pos) > lim).any():
            bad = int(np.flatnonzero((np.abs(pos) > lim).any(axis=1))[0])
            raise ValueError(f"object_positions[{bad}] = {pos[bad].tolist()} is not inside the walls (|x|, |y| <= {lim:g})")
        diff = pos[:, None, :] - pos[None, :, :]
        d2 = np.einsum("ijk,ijk->ij", diff, diff)
        np.fill_diagonal(d2, np.inf)
        if d2.min() < self.object_diameter**2:
            i, j = np.unravel_index(np.argmin(d2), d2.shape)
            raise ValueError(f"object_positions: objects {min(i, j)} and {max(i, j)} overlap")
        return pos

    def check_anchor_ids(self, anchor_ids: Any, positions: np.ndarray) -> np.ndarray:
        """Validate user anchor indices: >= 3 distinct integers in range, not collinear."""
        ids = check_anchor_indices(anchor_ids, positions.shape[0], 3)
        if collinear(positions[ids]):
            raise ValueError(f"anchor_ids {ids.tolist()} name collinear objects")
        return ids

    def check_pose(self, pose: Any, positions: np.ndarray) -> np.ndarray:
        """Validate a user robot pose: inside the walls and not touching any object."""
        p = np.array(pose, dtype=np.float64)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"robot_pose must be 3 finite numbers (x, y, heading), got {pose!r}")
        lim = self.arena_half - self.robot_radius - CONTACT_MARGIN
        if abs(p[0]) > lim or abs(p[1]) > lim:
            raise ValueError(f"robot_pose {p[:2].tolist()} puts the robot in a wall (|x|, |y| <= {lim:g})")
        d = np.hypot(*(positions - p[:2]).T)
        if (d < self.object_radius + self.robot_radius + CONTACT_MARGIN).any():
            raise ValueError(f"robot_pose {p[:2].tolist()} overlaps object {int(np.argmin(d))}")
        p[2] = wrap_angle(float(p[2]))
        return p

    # ------------------------------------------------------------------ physics
    def build(self, layout: Layout) -> None:
        """Make a fresh pymunk space for ``layout``: walls and cylinders static, the robot kinematic."""
        space = pymunk.Space()
        static = space.static_body
        a, r, rr = self.arena_half, self.object_radius, self.robot_radius
        corners = [(-a, -a), (a, -a), (a, a), (-a, a)]
        centres = [(float(x), float(y)) for x, y in layout.object_positions]
        physical: list[pymunk.Shape] = [
            pymunk.Segment(static, corners[i], corners[(i + 1) % 4], 0.0) for i in range(4)
        ]
        physical += [pymunk.Circle(static, r, offset=c) for c in centres]
        grown: list[pymunk.Shape] = [
            pymunk.Segment(static, corners[i], corners[(i + 1) % 4], rr) for i in range(4)
        ]
        grown += [pymunk.Circle(static, r + rr, offset=c) for c in centres]
        for shape in physical:
            shape.filter = pymunk.ShapeFilter(categories=PHYSICAL)
        for shape in grown:
            shape.filter = pymunk.ShapeFilter(categories=GROWN)
        space.add(*physical, *grown)
        body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        disc = pymunk.Circle(body, rr)
        disc.filter = pymunk.ShapeFilter(group=ROBOT_GROUP, categories=PHYSICAL)
        space.add(body, disc)
        self._space, self._body = space, body
        self.object_positions = layout.object_positions
        self.anchor_ids = layout.anchor_ids
        x, y, h = (float(v) for v in layout.robot_pose)
        self._place(x, y, h)

    def _place(self, x: float, y: float, heading: float) -> None:
        # Speed: moving the pymunk body (two property setters and a reindex) costs as much as the
        # move's query, and no query of ours can see the robot's own shape (ROBOT_GROUP). So the
        # body is only brought up to date when someone asks for `space` or `body`.
        self.x, self.y, self.heading = x, y, heading
        self._body_stale = True

    def _sync_body(self) -> None:
        if self._body_stale and self._body is not None:
            self._body.position = (self.x, self.y)
            self._body.angle = self.heading
            self._space.reindex_shapes_for_body(self._body)
        self._body_stale = False

    @property
    def built(self) -> bool:
        """Whether :meth:`build` has made a space (without syncing the robot's body)."""
        return self._space is not None

    @property
    def space(self) -> pymunk.Space | None:
        """The pymunk space (None before :meth:`build`), with the robot's body at its pose."""
        self._sync_body()
        return self._space

    @property
    def body(self) -> pymunk.Body | None:
        """The robot's kinematic pymunk body (None before :meth:`build`), at the robot's pose."""
        self._sync_body()
        return self._body

    @property
    def pose(self) -> np.ndarray:
        """The robot's pose (x, y, heading in (-pi, pi]) as a new float64 array."""
        return np.array((self.x, self.y, self.heading))

    def move(self, turn: float, distance: float) -> bool:
        """Turn by ``turn`` [rad], then advance ``distance`` along the new heading.

        The swept disc is checked against every wall and cylinder first; on contact the robot
        stops just short of it (see :data:`BACKOFF`, :data:`CONTACT_MARGIN`). Returns whether the
        move was blocked.
        """
        h = wrap_angle(self.heading + turn)
        c, s = math.cos(h), math.sin(h)
        x0, y0 = self.x, self.y
        x1, y1 = x0 + distance * c, y0 + distance * s
        # Thin segment against the grown obstacles == the robot's disc swept along the move.
        space = self._space  # the robot's body may be stale here: the query never sees it
        hit = space.segment_query_first((x0, y0), (x1, y1), 0.0, self._grown_filter)
        if hit is not None:
            travel = hit.alpha * distance - BACKOFF
            if travel > 0.0:
                x1, y1 = x0 + travel * c, y0 + travel * s
                # A grazing contact gains almost no gap from backing off along the path: stay
                # put rather than end within rounding error of an obstacle.
                near = space.point_query_nearest((x1, y1), CONTACT_MARGIN, self._grown_filter)
                if near is not None:
                    x1, y1 = x0, y0
            else:
                x1, y1 = x0, y0
        self._place(x1, y1, h)
        return hit is not None
