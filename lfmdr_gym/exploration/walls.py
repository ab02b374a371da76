"""The arena's walls in a robot's own odometry frame, found from its proximity rings.

A policy that knows only what it senses cannot read the layout, but a room's walls are in its
proximity ring: a run of four or more consecutive rays that hit points on one straight line is
a wall (an object's cylinder bends the run; its residual from a line is larger). Given the room's
size (configuration a user knows, like the step length; never the pose or the layout),
:class:`WallFrame` turns the walls it sees into the room's rectangle in the odometry frame:

- the walls' orientation comes from the first wall seen (the odometry's heading does not drift:
  the robot turns exactly as commanded), modulo 90 degrees;
- per axis, the low wall's offset is the median of the first ``sightings`` sightings of either
  wall of that axis (a wall is the low one when the robot is above it); until an axis has a
  sighting, its extent is the room's width centred on the free ground seen so far;
- after that, a wall seen again where it should not be means the dead reckoning has drifted:
  :meth:`WallFrame.observe` returns the shift that puts the robot back (its relocalisation).

It is the sensed substitute for the true arena in :class:`lfmdr_gym.exploration.even.EvenPolicy`.
"""

from __future__ import annotations

import math

import numpy as np

from lfmdr_gym.checks import check_int, check_real

__all__ = ["WallFrame", "wall_runs"]

MIN_RUN = 4  # rays in a run before it can be a wall
MAX_RESIDUAL = 0.004  # RMS distance of a wall's hits from their line [m]
MIN_SPREAD = 0.04  # RMS extent of a wall's hits along their line [m]


def wall_runs(proximity: np.ndarray, pose: np.ndarray, proximity_range: float) -> list:
    """The straight runs of one proximity ring: a list of (centre (2,), direction (2,)) in the
    frame of ``pose`` (x, y, heading), one per run of at least ``MIN_RUN`` consecutive hits whose
    points lie on a line (RMS residual below ``MAX_RESIDUAL``, RMS extent above ``MIN_SPREAD``)."""
    n = proximity.size
    hit = proximity < proximity_range * (1.0 - 1e-6)
    if hit.all():
        runs = [np.arange(n)]
    elif not hit.any():
        runs = []
    else:  # start at a miss, so that no run wraps past it
        order = (int(np.argmin(hit)) + np.arange(n)) % n
        runs, current = [], []
        for k in order:
            if hit[k]:
                current.append(k)
            elif current:
                runs.append(np.array(current))
                current = []
        if current:
            runs.append(np.array(current))
    x, y, heading = pose
    angles = heading + 2.0 * np.pi * np.arange(n) / n
    out = []
    for run in runs:
        if run.size < MIN_RUN:
            continue
        pts = np.column_stack([x + proximity[run] * np.cos(angles[run]),
                               y + proximity[run] * np.sin(angles[run])])
        centre = pts.mean(axis=0)
        _, sv, vt = np.linalg.svd(pts - centre, full_matrices=False)
        rms = sv / math.sqrt(run.size)
        if rms[1] < MAX_RESIDUAL and rms[0] > MIN_SPREAD:
            out.append((centre, vt[0]))
    return out


class WallFrame:
    """The room's rectangle in the odometry frame, from the walls the proximity rings show
    (module docstring).

    Args:
        arena_size: the room's side [m] (a square room, as :class:`~lfmdr_gym.sim.world.World`).
        robot_radius: the robot's radius [m]; the rectangle is where its centre can be.
        proximity_range: the ring's range [m] (a ray that reads it has hit nothing).
        sightings: sightings per axis that fix its walls; later ones relocalise the robot.

    Attributes: ``theta`` (the walls' orientation in the odometry frame, or None before any
    wall), ``lows`` (per axis, the low wall's offsets seen so far).
    """

    def __init__(self, arena_size: float, robot_radius: float, proximity_range: float,
                 sightings: int = 3) -> None:
        self.arena_size = check_real("arena_size", arena_size, low=0.0, low_open=True)
        self.robot_radius = check_real("robot_radius", robot_radius, low=0.0)
        if 2.0 * self.robot_radius >= self.arena_size:
            raise ValueError(f"robot_radius={robot_radius} leaves no room in arena_size={arena_size}")
        self.proximity_range = check_real("proximity_range", proximity_range, low=0.0, low_open=True)
        self.sightings = check_int("sightings", sightings, low=1)
        self.reset()

    def reset(self) -> None:
        """Forget the walls (a new episode)."""
        self.theta: float | None = None
        self.lows: tuple[list[float], list[float]] = ([], [])

    @property
    def fixed(self) -> bool:
        """Whether both axes' walls are fixed (the rectangle no longer changes)."""
        return all(len(lows) >= self.sightings for lows in self.lows)

    def _rotation(self) -> np.ndarray:
        """Odometry frame -> the walls' frame (axis 0 and 1 along the walls)."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return np.array([[c, s], [-s, c]])

    def observe(self, proximity: np.ndarray, pose: np.ndarray, runs: list | None = None
                ) -> np.ndarray:
        """Take one ring seen from ``pose`` (x, y, heading in the odometry frame); return the
        shift (2,) to add to the pose's position: zero until an axis's walls are fixed, then
        what puts the walls seen back where they were fixed. ``runs``: the ring's
        :func:`wall_runs` at ``pose``, if the caller has them already."""
        shift = np.zeros(2)
        position = np.asarray(pose[:2], dtype=np.float64)
        if runs is None:
            runs = wall_runs(proximity, pose, self.proximity_range)
        for centre, direction in runs:
            if self.theta is None:
                self.theta = math.atan2(direction[1], direction[0]) % (0.5 * math.pi)
            rot = self._rotation()
            along = rot @ direction
            axis = 0 if abs(along[0]) < abs(along[1]) else 1  # a wall along axis 1 sits at fixed u
            wall = float((rot @ (centre + shift))[axis])  # the hits move with the robot
            robot = float((rot @ (position + shift))[axis])
            low = wall if robot > wall else wall - self.arena_size
            if len(self.lows[axis]) >= self.sightings:
                offset = np.zeros(2)
                offset[axis] = self._low(axis) - low
                shift += rot.T @ offset
            else:
                self.lows[axis].append(low)
        return shift

    def _low(self, axis: int) -> float | None:
        """The low wall's fixed offset along ``axis`` (the median of its sightings), or None
        before any sighting."""
        return float(np.median(self.lows[axis])) if self.lows[axis] else None

    def halfplanes(self) -> list:
        """The room's bounds on the robot's centre from the axes whose walls have been seen:
        (normal (2,), offset) pairs, the centre fitting where ``normal . p >= offset`` (none
        before a wall is seen)."""
        if self.theta is None:
            return []
        rot = self._rotation()
        width = self.arena_size - 2.0 * self.robot_radius
        out = []
        for axis in (0, 1):
            low = self._low(axis)
            if low is not None:
                lo = low + self.robot_radius
                out += [(rot[axis], lo), (-rot[axis], -(lo + width))]
        return out

    def on_walls(self, points: np.ndarray, tolerance: float) -> np.ndarray:
        """Whether each of ``points`` (k, 2) lies within ``tolerance`` of a wall seen so far."""
        near = np.zeros(len(points), dtype=bool)
        if self.theta is None:
            return near
        p = points @ self._rotation().T
        for axis in (0, 1):
            lo = self._low(axis)
            if lo is not None:
                near |= ((np.abs(p[:, axis] - lo) <= tolerance)
                         | (np.abs(p[:, axis] - lo - self.arena_size) <= tolerance))
        return near

    def inside(self, points: np.ndarray, free: np.ndarray) -> np.ndarray:
        """Whether each of ``points`` (k, 2) is inside the room's rectangle (where the robot's
        centre fits), or None before any wall is seen. An axis with no sighting yet spans the
        room's width centred on ``free`` (m, 2), the free ground seen so far."""
        if self.theta is None:
            return None
        rot = self._rotation()
        p, f = points @ rot.T, free @ rot.T
        width = self.arena_size - 2.0 * self.robot_radius
        ok = np.ones(len(points), dtype=bool)
        for axis in (0, 1):
            low = self._low(axis)
            if low is not None:
                lo = low + self.robot_radius
            else:
                lo = 0.5 * (f[:, axis].max() + f[:, axis].min() - width)
            ok &= (p[:, axis] >= lo) & (p[:, axis] <= lo + width)
        return ok
