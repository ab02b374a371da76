"""An exploration policy that spreads its viewpoints evenly at the scale of the step.

A visibility map is built from how often two objects are seen together, i.e. from where the
robot's viewpoints fall in the discs that see each object. The visit counts of
:class:`~lfmdr_gym.exploration.coverage.CoveragePolicy` (0.25 m cells) even out the coarse density
of the viewpoints, but within a cell they still fall where the walk happens to put them. Placed
directly, without a walk (``docs/online-and-exploration.md``), 500 viewpoints spread like blue noise
(greedy farthest-point sampling) give a far better CAL-SMA map than 500 uniform random ones, and a
better one than 2,000 steps of the random walk. :class:`SpreadPolicy` steers toward such a spread (a
walk of 0.2 m steps lays it less well; measured in ``docs/online-and-exploration.md``):

- it remembers its viewpoints in its own dead-reckoned frame (the drift-corrected odometry of
  :class:`~lfmdr_gym.exploration.coverage.CoveragePolicy` with ``correct_drift=True``);
- each candidate turn is scored by the best three-move plan that starts with it (the later turns
  from a fixed fan): the sum, discounted by ``discount`` per move, of a Gaussian kernel density
  (width ``sigma``) of the viewpoints at each planned point, the plan's own earlier points
  included; a point the proximity ring does not report free is scored as blocked;
- when the viewpoints nearby are already dense, a pull toward the nearest *hole* (ground the
  ring has seen free, farther than ``hole_radius`` from every viewpoint) keeps it from dithering
  in covered ground: ``pull`` times the distance from the plan's last point to that hole;
- a move the physics stopped short (the ring shows contact) is followed by ``escape_moves``
  random-walk moves, so that a blocked plan is not tried again and again.

It knows only what it senses and what it did, never the pose or the layout in ``info``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from lfmdr_gym.checks import check_int, check_real
from lfmdr_gym.exploration.coverage import CoveragePolicy

__all__ = ["SpreadPolicy"]


class SpreadPolicy(CoveragePolicy):
    """Steer so that the viewpoints spread evenly at a fine scale (module docstring).

    Args:
        sigma: width of the Gaussian kernel of the viewpoint density [m].
        fan: number of turns (evenly over ``[-max_turn, max_turn]``) tried for the second and
            third move of a plan, at least 2.
        discount: weight of each further move of a plan, in (0, 1].
        pull: weight of the distance to the nearest hole [1/m]; 0 turns the pull off.
        hole_radius: a seen-free grid point farther than this from every viewpoint is a hole [m].
        free_cell: side of the grid of seen-free ground (the holes' candidates) [m].
        escape_moves: random-walk moves after a stopped move (0: none).
        max_turn, step_length, robot_radius, extent, proximity_range, seed, and the collision
            check's keywords: as for :class:`~lfmdr_gym.exploration.coverage.CoveragePolicy` (its
            drift correction is always on, its ``cell`` grid unused).

    One observation at a time (it keeps per-episode memory); :meth:`reset` forgets it.
    Attributes: ``viewpoints`` (k, 2) in the frame of the start, ``odometry`` (x, y, heading).
    """

    def __init__(self, max_turn: float = math.pi / 4, step_length: float = 0.2,
                 robot_radius: float = 0.05, *, sigma: float = 0.13, fan: int = 7,
                 discount: float = 0.7, pull: float = 0.5, hole_radius: float = 0.15,
                 free_cell: float = 0.1, escape_moves: int = 3, **kwargs: Any) -> None:
        if "correct_drift" in kwargs and kwargs["correct_drift"] is not True:
            raise ValueError("SpreadPolicy always corrects its drift; correct_drift must be True")
        kwargs["correct_drift"] = True
        self.sigma = check_real("sigma", sigma, low=0.0, low_open=True)
        self.fan = check_int("fan", fan, low=2)
        self.discount = check_real("discount", discount, low=0.0, low_open=True, high=1.0)
        self.pull = check_real("pull", pull, low=0.0)
        self.hole_radius = check_real("hole_radius", hole_radius, low=0.0, low_open=True)
        self.free_cell = check_real("free_cell", free_cell, low=0.0, low_open=True)
        self.escape_moves = check_int("escape_moves", escape_moves, low=0)
        super().__init__(max_turn, step_length, robot_radius, **kwargs)
        later = np.linspace(-self.max_turn, self.max_turn, fan)
        self._later = np.array(list(itertools.product(later, repeat=2)))  # (fan^2, 2)

    def _forget(self) -> None:
        super()._forget()
        if not hasattr(self, "free_cell"):  # (the base class's __init__ calls this first)
            return
        n = 2 * int(math.ceil(self.extent / self.free_cell))
        self._m = n
        centres = (np.arange(n) + 0.5) * self.free_cell - self.extent
        gx, gy = np.meshgrid(centres, centres, indexing="ij")
        self._grid = np.stack([gx, gy], axis=-1)  # (n, n, 2) cell centres
        self._seen_free = np.zeros((n, n), dtype=bool)
        self._hit = np.zeros((n, n), dtype=bool)
        self._nearest = np.full((n, n), np.inf)  # distance of each cell to the nearest viewpoint
        self._points: list[tuple[float, float]] = []

    @property
    def viewpoints(self) -> np.ndarray:
        """The dead-reckoned viewpoints so far, (k, 2), in the frame of the start."""
        return np.array(self._points, dtype=np.float64).reshape(-1, 2)

    def _free_cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        idx = np.floor((xy + self.extent) / self.free_cell).astype(int)
        return tuple(np.clip(idx, 0, self._m - 1).T)

    def _remember(self, prox: np.ndarray) -> None:
        """Add the viewpoint and what the ring shows free (and hit) around it."""
        x, y, heading = self.odometry
        self._points.append((float(x), float(y)))
        d = np.hypot(self._grid[..., 0] - x, self._grid[..., 1] - y)
        np.minimum(self._nearest, d, out=self._nearest)
        n = prox.size
        angles = heading + 2.0 * np.pi * np.arange(n) / n
        c, s = np.cos(angles), np.sin(angles)
        reach = np.maximum(prox - self.robot_radius, 0.0)  # free up to a robot radius short of a hit
        frac = np.linspace(0.0, 1.0, 6)
        fx = x + (reach[:, None] * frac) * c[:, None]
        fy = y + (reach[:, None] * frac) * s[:, None]
        self._seen_free[self._free_cells(np.column_stack([fx.ravel(), fy.ravel()]))] = True
        hit = prox < self.proximity_range * (1.0 - 1e-6)
        if hit.any():
            hxy = np.column_stack([x + prox[hit] * c[hit], y + prox[hit] * s[hit]])
            self._hit[self._free_cells(hxy)] = True

    def _hole(self) -> np.ndarray | None:
        """The nearest seen-free, never-hit grid point farther than ``hole_radius`` from every
        viewpoint, or None."""
        holes = self._seen_free & ~self._hit & (self._nearest > self.hole_radius)
        if not holes.any():
            return None
        pts = self._grid[holes]
        x, y = self.odometry[:2]
        return pts[np.argmin((pts[:, 0] - x) ** 2 + (pts[:, 1] - y) ** 2)]

    def _scores(self, proximity: np.ndarray, turns: np.ndarray) -> np.ndarray:
        """The cost of the best three-move plan starting with each turn; lower is better."""
        x, y = self.odometry[:2]
        t = turns.size
        plans, wx, wy, blocked = self._plans(proximity, turns, self._later)
        step = self.step_length
        pts = self.viewpoints
        near = pts[(pts[:, 0] - x) ** 2 + (pts[:, 1] - y) ** 2 < (4 * self.sigma + 3 * step) ** 2]
        s2 = 2.0 * self.sigma ** 2
        cost = np.zeros(plans.shape[0])
        for k in range(3):
            dens = np.zeros(plans.shape[0])
            if len(near):
                d2 = (wx[:, k, None] - near[:, 0]) ** 2 + (wy[:, k, None] - near[:, 1]) ** 2
                dens = np.exp(-d2 / s2).sum(axis=1)
            for e in range(k):
                dens += np.exp(-((wx[:, k] - wx[:, e]) ** 2 + (wy[:, k] - wy[:, e]) ** 2) / s2)
            # a blocked point costs more than any density it could have (it is not reachable)
            cost += self.discount ** k * np.where(blocked[:, k], 50.0, dens)
        if self.pull > 0:
            hole = self._hole()
            if hole is not None:
                cost += self.pull * np.hypot(wx[:, -1] - hole[0], wy[:, -1] - hole[1])
        return cost.reshape(t, -1).min(axis=1)

    def __call__(self, observation: Mapping[str, Any]) -> np.ndarray:
        """The heading change for one observation, shape (1,)."""
        prox = self._proximity(observation)
        escaping = self._sense(prox)
        turns = self.rng.uniform(-self.max_turn, self.max_turn, self.n_tries)
        if not escaping:  # (an escape is a random-walk move: the draws in the order drawn)
            turns = turns[np.argsort(self._scores(prox, turns), kind="stable")]
        return self._move(prox, turns)

    def __repr__(self) -> str:
        return (f"SpreadPolicy(sigma={self.sigma:g}, fan={self.fan}, discount={self.discount:g}, "
                f"pull={self.pull:g}, hole_radius={self.hole_radius:g}, seed={self.seed!r})")
