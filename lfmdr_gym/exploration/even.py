"""An exploration policy that covers the room evenly: the fastest mapper of the registered
policies (measured in ``docs/online-and-exploration.md``).

A visibility map is built from how often two objects are seen together, i.e. from where the
robot's viewpoints fall in the discs that see each object; it is best when the viewpoints cover
the room evenly (``docs/online-and-exploration.md``). :class:`EvenPolicy` measures evenness
directly and plans for it:

- its coverage is a sum of Gaussian kernels (width ``sigma``) at its viewpoints on a fine grid
  (``grid``) in its own dead-reckoned frame (the drift-corrected odometry of
  :class:`~lfmdr_gym.exploration.coverage.CoveragePolicy` with ``correct_drift=True``);
- the ground to cover is the room: the walls the proximity ring shows, with the room's size,
  place its rectangle (:class:`~lfmdr_gym.exploration.walls.WallFrame`); before a wall is seen, the
  convex hull of the ground the ring has shown free;
- each of ``fan`` turns is scored by the best plan of ``1 + lookahead`` moves that starts with
  it (the later turns from the same fan): the variance of the coverage over the room once the
  plan's kernels are added (lower is more even);
- a plan's moves are simulated among the obstacles it has sensed: the cylinders fitted to every
  ring hit so far (:class:`~lfmdr_gym.exploration.obstacles.ObstacleMap`) and the room's walls
  (until both axes are fixed, also the walls in the current ring), each move stopping at its first
  predicted contact (``stop_margin`` short of it); plans whose moves are all full are preferred, and
  a move stopped short is taken only where no turn has a full plan (as the physics would stop it:
  beside the object). The random walk's collision check, which keeps 20 mm and a free next move
  around each hit of the current ring, is left to the escapes; planning with the fitted cylinders
  instead lets the robot pass the objects closely, where viewpoints inform a visibility map most
  (``docs/online-and-exploration.md``);
- once the walls of an axis are fixed, seeing them again corrects the dead reckoning (its drift
  stays at millimetres over 500 steps), which keeps the fitted cylinders in place;
- a move the physics stopped short (the ring shows contact) is followed by ``escape_moves``
  random-walk moves (with the random walk's collision check), so that a blocked plan is not
  tried again and again.

It knows only what it senses, what it did, the room's size (``arena_size``) and the objects'
radius (``obstacle_radius``), configuration like the step length (:meth:`EvenPolicy.for_env`
reads them from the env's world), never the pose or the layout in ``info``. With
``arena_size=None`` it covers the seen-free hull only.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from lfmdr_gym.checks import check_int, check_real
from lfmdr_gym.exploration.contract import base_env
from lfmdr_gym.exploration.coverage import CoveragePolicy
from lfmdr_gym.exploration.obstacles import ObstacleMap, advance, ring_hits
from lfmdr_gym.exploration.walls import WallFrame, wall_runs

__all__ = ["EvenPolicy"]

RUN_TOLERANCE = 0.005  # a hit this close to a wall run's line [m] is on the wall
WALL_TOLERANCE = 0.012  # a kept hit this close to a fixed wall [m] is the wall's, not a cylinder's
REACH_SLACK = 0.1  # cylinders fitted this far [m] beyond the plans' reach (and the two radii)


class EvenPolicy(CoveragePolicy):
    """Plan moves that keep the coverage of the room even (module docstring).

    Args:
        sigma: width of the Gaussian kernel of a viewpoint's coverage [m].
        grid: side of the cells the coverage is kept on [m].
        fan: number of turns, evenly over ``[-max_turn, max_turn]``, tried for each move of a
            plan, at least 2 (a plan count of ``fan ** (1 + lookahead)``).
        lookahead: moves planned after the first (0: greedy).
        arena_size: the room's side [m], or None to cover the seen-free hull only.
        wall_sightings: sightings of an axis's walls that fix them
            (:class:`~lfmdr_gym.exploration.walls.WallFrame`).
        escape_moves: random-walk moves after a stopped move (0: none).
        stop_margin: how far short of a predicted contact a planned move stops [m].
        max_turn, step_length, robot_radius, extent, proximity_range, seed, and the collision
            check's keywords: as for :class:`~lfmdr_gym.exploration.coverage.CoveragePolicy` (its
            drift correction is always on, its ``cell`` grid unused; ``extent`` bounds the coverage
            grid around the start; ``obstacle_radius`` is also the fitted cylinders' radius; the
            collision check guards the escapes only).

    One observation at a time (it keeps per-episode memory); :meth:`reset` forgets it.
    Attributes: ``coverage`` (the grid of summed kernels), ``odometry`` (x, y, heading) in the
    frame of the start, ``walls`` (the :class:`~lfmdr_gym.exploration.walls.WallFrame`, or None),
    ``obstacles`` (the :class:`~lfmdr_gym.exploration.obstacles.ObstacleMap`).
    """

    def __init__(self, max_turn: float = math.pi / 4, step_length: float = 0.2,
                 robot_radius: float = 0.05, *, sigma: float = 0.1, grid: float = 0.05,
                 fan: int = 9, lookahead: int = 2, arena_size: float | None = 2.5,
                 wall_sightings: int = 3, escape_moves: int = 3, stop_margin: float = 0.005,
                 **kwargs: Any) -> None:
        if "correct_drift" in kwargs and kwargs["correct_drift"] is not True:
            raise ValueError("EvenPolicy always corrects its drift; correct_drift must be True")
        kwargs["correct_drift"] = True
        self.sigma = check_real("sigma", sigma, low=0.0, low_open=True)
        self.grid = check_real("grid", grid, low=0.0, low_open=True)
        self.fan = check_int("fan", fan, low=2)
        self.lookahead = check_int("lookahead", lookahead, low=0)
        self.escape_moves = check_int("escape_moves", escape_moves, low=0)
        self.arena_size = None if arena_size is None else check_real(
            "arena_size", arena_size, low=0.0, low_open=True)
        self.wall_sightings = check_int("wall_sightings", wall_sightings, low=1)
        self.stop_margin = check_real("stop_margin", stop_margin, low=0.0)
        self._ready = False
        super().__init__(max_turn, step_length, robot_radius, **kwargs)
        self.obstacles = ObstacleMap(self.obstacle_radius, self.proximity_range)
        if self.grid > self.extent:
            raise ValueError(f"grid must be at most extent ({self.extent:g}), got {grid!r}")
        if self.arena_size is not None and self.extent < self.arena_size:
            raise ValueError(f"extent ({self.extent:g}) must be at least arena_size "
                             f"({self.arena_size:g}): the room may lie that far from the start")
        self.walls = None if self.arena_size is None else WallFrame(
            self.arena_size, self.robot_radius, self.proximity_range, self.wall_sightings)
        n = 2 * int(math.ceil(self.extent / self.grid))
        centres = (np.arange(n) + 0.5) * self.grid - self.extent
        gx, gy = np.meshgrid(centres, centres, indexing="ij")
        self._points = np.column_stack([gx.ravel(), gy.ravel()])  # the cells' centres
        self._side = n
        fan_turns = np.linspace(-self.max_turn, self.max_turn, self.fan)
        self._fan = fan_turns
        self._later = np.array(list(itertools.product(fan_turns, repeat=self.lookahead)),
                               dtype=np.float64).reshape(self.fan ** self.lookahead, self.lookahead)
        self._ready = True
        self._forget()

    @classmethod
    def for_env(cls, env: Any, **kwargs: Any) -> EvenPolicy:
        """As :meth:`CoveragePolicy.for_env`, plus the room's size from the env's world
        (``world.arena_size``: configuration, as the step length is; not the layout) and a
        coverage grid (``extent``) that holds the room from any start."""
        size = getattr(getattr(base_env(env), "world", None), "arena_size", None)
        if size is not None:
            kwargs.setdefault("arena_size", float(size))
        if kwargs.get("arena_size") is not None:  # the grid holds the room from any start
            kwargs.setdefault("extent", max(3.0, kwargs["arena_size"] + 0.5))
        return super().for_env(env, **kwargs)

    def _forget(self) -> None:
        super()._forget()
        if not self._ready:  # (the base class's __init__ calls this first)
            return
        self.coverage = np.zeros(self._side * self._side)
        self._mask = np.zeros(self._side * self._side, dtype=bool)
        self._hull = np.zeros((0, 2))
        self._room_fixed = False  # the mask is the fixed walls' rectangle: nothing to update
        self._ring_walls: list = []  # the current ring's walls as half-planes of the centre
        if self.walls is not None:
            self.walls.reset()
        self.obstacles.reset()

    def _patch(self, x: float, y: float, reach: float) -> np.ndarray:
        """Flat indices of the grid's cells within ``reach`` (per axis) of (x, y)."""
        lo = np.floor((np.array([x, y]) - reach + self.extent) / self.grid).astype(int)
        hi = np.ceil((np.array([x, y]) + reach + self.extent) / self.grid).astype(int) + 1
        lo, hi = np.maximum(lo, 0), np.minimum(hi, self._side)
        ii, jj = np.meshgrid(np.arange(lo[0], hi[0]), np.arange(lo[1], hi[1]), indexing="ij")
        return (ii * self._side + jj).ravel()

    def _kernel(self, cells: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The coverage kernels at points (x, y) (any shape ``s``) over ``cells``: ``s + (c,)``."""
        p = self._points[cells]
        # exp(-((px - x)^2 + (py - y)^2) / (2 sigma^2)), the same operations in the same order,
        # in place in one buffer: a third less time than with a temporary per operation
        d2 = np.subtract(p[:, 0], x[..., None])
        np.square(d2, out=d2)
        dy = np.subtract(p[:, 1], y[..., None])
        d2 += np.square(dy, out=dy)
        np.negative(d2, out=d2)
        d2 /= 2.0 * self.sigma ** 2
        return np.exp(d2, out=d2)

    def _remember(self, prox: np.ndarray) -> None:
        """Relocalise on the walls, keep the ring's hits on obstacles, add the viewpoint's
        kernel, and update the room's mask."""
        runs = wall_runs(prox, self.odometry, self.proximity_range)
        if self.walls is not None:
            shift = self.walls.observe(prox, self.odometry, runs)
            self.odometry = self.odometry + np.array([shift[0], shift[1], 0.0])
            runs = [(centre + shift, direction) for centre, direction in runs]  # moved along
        self._keep_hits(prox, runs)
        x, y, heading = self.odometry
        cells = self._patch(x, y, 4.0 * self.sigma)
        self.coverage[cells] += self._kernel(cells, np.array(x), np.array(y))
        if self._room_fixed:
            return
        # the ground the ring shows free: each ray up to a robot radius short of its reading
        n = prox.size
        angles = heading + 2.0 * np.pi * np.arange(n) / n
        reach = np.maximum(prox - self.robot_radius, 0.0)
        ends = np.column_stack([x + reach * np.cos(angles), y + reach * np.sin(angles)])
        pts = np.vstack([self._hull, ends, [[x, y]]])
        inside = None if self.walls is None else self.walls.inside(self._points, pts)
        try:
            hull = ConvexHull(pts)
        except QhullError:  # all the free ground on a line (a ring reading zero): keep the points
            self._hull = pts
        else:
            self._hull = pts[hull.vertices]
            if inside is None:
                eq = hull.equations
                inside = ((self._points @ eq[:, :2].T + eq[:, 2]) <= 1e-9).all(axis=1)
        if inside is not None:
            self._mask = inside
        self._room_fixed = self.walls is not None and self.walls.fixed

    def _keep_hits(self, prox: np.ndarray, runs: list) -> None:
        """Add the ring's hits off its straight ``runs`` (walls, :func:`wall_runs` at the
        current odometry) to the obstacle map; keep the runs as bounds on the robot's centre for
        this step's plans."""
        x, y, _ = self.odometry
        hits, rays, hit = ring_hits(prox, self.odometry, self.proximity_range)
        on_wall = np.zeros(prox.size, dtype=bool)
        self._ring_walls = []
        for centre, direction in runs:
            normal = np.array([-direction[1], direction[0]])
            if normal @ (np.array([x, y]) - centre) < 0.0:
                normal = -normal  # toward the robot
            on_wall |= hit & (np.abs((hits - centre) @ normal) < RUN_TOLERANCE)
            self._ring_walls.append((normal, float(centre @ normal) + self.robot_radius))
        keep = hit & ~on_wall
        self.obstacles.add_hits(hits[keep], rays[keep])

    def _plans(self, proximity: np.ndarray, turns: np.ndarray,
               later: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every plan that starts with one of ``turns`` (t,) and goes on with a row of ``later``
        (p, k - 1), turn-major: the plans (t * p, k), their points in the odometry frame (two
        arrays (t * p, k)), each move simulated among the sensed obstacles to its first
        predicted contact, and whether each move was stopped short. (``proximity`` is already
        in the obstacle map and the ring's walls.)"""
        x, y, heading = self.odometry
        step, margin = self.step_length, self.stop_margin
        reach = ((1 + later.shape[1]) * step + self.obstacle_radius + self.robot_radius
                 + REACH_SLACK)
        drop = None if self.walls is None else functools.partial(self.walls.on_walls,
                                                                 tolerance=WALL_TOLERANCE)
        centres = self.obstacles.centres(np.array([x, y]), reach, drop)
        bounds = [] if self.walls is None else self.walls.halfplanes()
        if self.walls is None or not self.walls.fixed:
            bounds = bounds + self._ring_walls
        bounds = [(normal, offset + margin) for normal, offset in bounds]
        contact = self.robot_radius + self.obstacle_radius + margin
        plans = self._plan_turns(turns, later)
        headings = heading + np.cumsum(plans, axis=1)
        count, moves = plans.shape
        wx, wy = np.empty((count, moves)), np.empty((count, moves))
        blocked = np.zeros((count, moves), dtype=bool)
        # move j is shared by every fan ** (moves - 1 - j) consecutive plans: simulated once
        starts = np.array([[x, y]])
        for j in range(moves):
            shared = self.fan ** (moves - 1 - j)
            rows = np.arange(0, count, shared)
            units = np.column_stack([np.cos(headings[rows, j]), np.sin(headings[rows, j])])
            starts = np.repeat(starts, len(rows) // len(starts), axis=0)
            went = advance(starts, units, step, centres, contact, bounds)
            starts = starts + went[:, None] * units
            wx[:, j] = np.repeat(starts[:, 0], shared)
            wy[:, j] = np.repeat(starts[:, 1], shared)
            blocked[:, j] = np.repeat(went < step - 1e-9, shared)
        return plans, wx, wy, blocked

    def _plan_kernels(self, cells: np.ndarray, wx: np.ndarray, wy: np.ndarray) -> np.ndarray:
        """Each plan's kernels summed over ``cells``, (plans, cells), from its points ``wx, wy``
        (plans, moves). The plans come turn-major, so a plan's first j + 1 turns fix its first
        j + 1 points and every ``fan ** (moves - 1 - j)`` consecutive plans share point j: its
        kernel is computed once per distinct point (819 instead of 2,187 for the default fan and
        look-ahead; the same values, summed in the same order)."""
        total = None
        plans, moves = wx.shape
        first = plans // self.fan ** (moves - 1)  # the first turns tried
        for j in range(moves):
            shared = self.fan ** (moves - 1 - j)
            rows = np.arange(0, plans, shared)
            kernel = self._kernel(cells, wx[rows, j], wy[rows, j])  # (plans // shared, cells)
            # broadcast over the plans that share the point: (first, fan x j, 1 x rest, cells)
            kernel = kernel.reshape((first,) + (self.fan,) * j + (1,) * (moves - 1 - j)
                                    + (cells.size,))
            total = kernel if total is None else total + kernel
        return total.reshape(plans, cells.size)

    def _scores(self, proximity: np.ndarray, turns: np.ndarray) -> np.ndarray:
        """The coverage's variance over the room after the best plan starting with each turn
        (turns whose every plan is blocked after the rest, by their own variance); lower is
        better."""
        x, y = self.odometry[:2]
        plans, wx, wy, blocked = self._plans(proximity, turns, self._later)
        cells = self._patch(x, y, plans.shape[1] * self.step_length + 4.0 * self.sigma)
        cells = cells[self._mask[cells]]
        room = self.coverage[self._mask]
        n = max(room.size, 1)
        s1, s2 = float(room.sum()), float((room ** 2).sum())
        here = self.coverage[cells]

        def variance(added: np.ndarray) -> np.ndarray:
            """The room's coverage variance once each row of ``added`` (over ``cells``) is in."""
            cross = np.multiply(2.0 * here, added)  # 2 here added + added^2, one buffer fewer
            cross += np.square(added)
            return (s2 + cross.sum(axis=1)) / n - ((s1 + added.sum(axis=1)) / n) ** 2

        var = variance(self._plan_kernels(cells, wx, wy))
        best = np.where(blocked.any(axis=1), np.inf, var).reshape(turns.size, -1).min(axis=1)
        if np.isfinite(best).all():
            return best
        first = variance(self._kernel(cells, wx[::len(self._later), 0], wy[::len(self._later), 0]))
        return np.where(np.isfinite(best), best, 1e6 + first)

    def __call__(self, observation: Mapping[str, Any]) -> np.ndarray:
        """The heading change for one observation, shape (1,)."""
        prox = self._proximity(observation)
        if self._sense(prox):  # an escape: the random walk's move, under its collision check
            return self._move(prox, self.rng.uniform(-self.max_turn, self.max_turn, self.n_tries))
        # ties between turns (e.g. all plans blocked alike) are broken by a tiny random jitter
        turns = np.clip(self._fan + self.rng.uniform(-1e-6, 1e-6, self.fan),
                        -self.max_turn, self.max_turn)
        # the best turn: its plans already stopped at the obstacles it has sensed
        return self._move(prox, turns[np.argsort(self._scores(prox, turns), kind="stable")],
                          check=False)

    def __repr__(self) -> str:
        return (f"EvenPolicy(sigma={self.sigma:g}, fan={self.fan}, lookahead={self.lookahead}, "
                f"arena_size={self.arena_size!r}, seed={self.seed!r})")
