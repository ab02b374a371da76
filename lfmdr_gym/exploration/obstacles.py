"""The cylinders a robot has bumped its proximity ring into, in its own odometry frame, and where
a straight move among them stops.

One ring sees a 48 mm cylinder with one to three of its 32 rays, too few to place it: a policy
that plans from one ring must keep a margin around each hit (the random walk's collision check
models a hit as a cylinder just behind it and asks for 20 mm more). A robot that knows its own
position to millimetres (:class:`~lfmdr_gym.exploration.even.EvenPolicy` relocalises on the walls)
can instead keep every hit it has seen: the hits of one cylinder, seen from many viewpoints, fit a
circle of the known radius to a millimetre or two, and a move can then be planned to pass a cylinder
closely or to stop beside it, as the physics would stop it.

:class:`ObstacleMap` keeps the hits (not those on the walls' straight runs) and fits the circles
near the robot when asked; :func:`advance` gives how far each of many moves goes before its
first predicted contact. Both see only what the ring reported and the radius of the objects
(configuration, like the room's size; never the layout).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from lfmdr_gym.checks import check_real

__all__ = ["ObstacleMap", "advance", "ring_hits"]

FIT_STEPS = 8  # Gauss-Newton steps of a circle fit (it converges in 3-4 from the first guess)


class ObstacleMap:
    """The ring's hits on cylinders so far, fitted to circles of radius ``obstacle_radius``.

    Args:
        obstacle_radius: the objects' radius [m].
        proximity_range: the ring's range [m] (a ray that reads it has hit nothing).
        link: hits closer than the cylinder's diameter plus ``link`` [m] belong to one cylinder.
        tolerance: RMS distance [m] of a cluster's hits from its fitted circle above which the
            cluster is not one cylinder (two touching ones, or a corner's hits): each of its hits
            then stands for a cylinder just behind it, as in the random walk's collision check.
    """

    def __init__(self, obstacle_radius: float, proximity_range: float, *, link: float = 0.01,
                 tolerance: float = 0.003) -> None:
        self.obstacle_radius = check_real("obstacle_radius", obstacle_radius, low=0.0)
        self.proximity_range = check_real("proximity_range", proximity_range, low=0.0,
                                          low_open=True)
        self.link = check_real("link", link, low=0.0)
        self.tolerance = check_real("tolerance", tolerance, low=0.0)
        self.reset()

    def reset(self) -> None:
        """Forget every hit (a new episode)."""
        self._points: list[np.ndarray] = []
        self._rays: list[np.ndarray] = []

    def add(self, proximity: np.ndarray, pose: np.ndarray, skip: np.ndarray | None = None) -> None:
        """Keep the hits of one ring read at ``pose`` (x, y, heading), but those of rays
        ``skip`` (a bool mask, e.g. the rays on a wall)."""
        points, rays, keep = ring_hits(proximity, pose, self.proximity_range)
        if skip is not None:
            keep &= ~skip
        self.add_hits(points[keep], rays[keep])

    def add_hits(self, points: np.ndarray, rays: np.ndarray) -> None:
        """Keep hit ``points`` (m, 2) and the unit ``rays`` (m, 2) that found them, as
        :func:`ring_hits` gives them."""
        if len(points):
            self._points.append(points)
            self._rays.append(rays)

    @property
    def n_hits(self) -> int:
        """Hits kept so far."""
        return sum(len(p) for p in self._points)

    def centres(self, near: np.ndarray, reach: float,
                drop: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
        """The cylinders' centres (k, 2) from the hits within ``reach`` of ``near`` (2,):
        per cluster of hits the centre of the circle of the objects' radius through them
        (least squares), or, for a cluster of fewer than 3 hits or one that fits no circle, a
        centre one radius behind each hit along its ray. ``drop``: a function of points (m, 2)
        giving a bool mask of hits to leave out (e.g. those on the fixed walls)."""
        if not self._points:
            return np.zeros((0, 2))
        points, rays = np.vstack(self._points), np.vstack(self._rays)
        self._points, self._rays = [points], [rays]  # stacked once: later calls add the new
        close = np.hypot(points[:, 0] - near[0], points[:, 1] - near[1]) < reach
        points, rays = points[close], rays[close]
        if drop is not None and len(points):
            keep = ~drop(points)
            points, rays = points[keep], rays[keep]
        m = len(points)
        if m == 0:
            return np.zeros((0, 2))
        r = self.obstacle_radius
        behind = points + r * rays  # one hit's guess: the ray passes through the centre
        pairs = cKDTree(points).query_pairs(2.0 * r + self.link, output_type="ndarray")
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
        n_clusters, label = connected_components(graph, directed=False)
        out = []
        for j in range(n_clusters):
            idx = np.flatnonzero(label == j)
            centre = _fit_circle(points[idx], r, behind[idx].mean(axis=0)) if idx.size >= 3 else None
            if centre is not None:
                d = np.hypot(*(points[idx] - centre).T) - r
                if np.sqrt(np.mean(d ** 2)) < self.tolerance:
                    out.append(centre[None])
                    continue
            out.append(behind[idx])
        return np.vstack(out)


def ring_hits(proximity: np.ndarray, pose: np.ndarray,
              proximity_range: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One ring read at ``pose`` (x, y, heading): every ray's end point (n, 2), its unit
    direction (n, 2), and whether it hit something (n,) (a ray that reads the range has not)."""
    n = proximity.size
    x, y, heading = pose
    angles = heading + 2.0 * np.pi * np.arange(n) / n
    rays = np.column_stack([np.cos(angles), np.sin(angles)])
    points = np.array([x, y]) + proximity[:, None] * rays
    return points, rays, proximity < proximity_range * (1.0 - 1e-6)


def _fit_circle(points: np.ndarray, radius: float, guess: np.ndarray) -> np.ndarray:
    """The centre of the circle of ``radius`` nearest, in least squares, to ``points`` (m, 2),
    by Gauss-Newton from ``guess``. (A circle of known radius: scipy's general least-squares
    solvers would do it too, at fifty times the cost per call, and this runs per cylinder per
    step.)"""
    centre = guess.astype(np.float64)
    for _ in range(FIT_STEPS):
        d = centre - points
        dist = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        step = np.linalg.lstsq(d / dist[:, None], radius - dist, rcond=None)[0]
        centre = centre + step
        if np.abs(step).max() < 1e-6:
            break
    return centre


def advance(start: np.ndarray, directions: np.ndarray, length: float, centres: np.ndarray,
            reach: float, halfplanes: Sequence = ()) -> np.ndarray:
    """How far (at most ``length``) a point moves from each of ``start`` (P, 2) along the unit
    ``directions`` (P, 2) before it comes within ``reach`` of one of ``centres`` (k, 2) (the
    robot's and a cylinder's radii, plus a margin) or leaves a half-plane of ``halfplanes``
    ((normal (2,), offset): where ``normal . p >= offset``). A point already inside a forbidden
    region stops at once only if it moves further in."""
    out = np.full(len(start), float(length))
    if len(centres):
        d = start[:, None, :] - centres[None]
        b = (d * directions[:, None]).sum(axis=-1)  # < 0: moving toward the centre
        disc = b * b - ((d ** 2).sum(axis=-1) - reach * reach)
        hit = -b - np.sqrt(np.maximum(disc, 0.0))
        stop = np.where((disc > 0.0) & (b < 0.0), np.maximum(hit, 0.0), np.inf)
        out = np.minimum(out, stop.min(axis=1))
    for normal, offset in halfplanes:
        room = start @ normal - offset
        toward = directions @ normal
        stop = np.where(toward < 0.0, np.maximum(room, 0.0) / np.maximum(-toward, 1e-12), np.inf)
        out = np.minimum(out, stop)
    return out
