"""An exploration policy that maps fast: even coverage from a dead-reckoned visit memory.

A map built from observation histories is best where the robot's viewpoints sample the ground
evenly: a visibility history measures how much two objects' visibility discs overlap, and a
random walk (the paper's agent, §4.1) samples that overlap unevenly, dwelling where it happens to
be. :class:`CoveragePolicy` keeps a count of its visits per cell of a grid and steers toward the
least-visited ground it can see is free, so its viewpoints spread evenly over the arena.

It knows only what it senses and what it did, never the pose or the layout in ``info``:

- the grid is in its own odometry frame (its start is the origin): it dead-reckons from its own
  turns and from the proximity ring, which says before each move how far the robot can advance
  (the full step when the way is clear; the room before the obstacle otherwise);
- each candidate turn is scored by the visit counts of the cells one and two steps ahead along
  it, counting only points the proximity ring reports free, nearer cells weighing more; the
  best-scored candidate that passes :class:`~lfmdr_gym.exploration.random_walk.RandomWalkPolicy`'s
  collision check is taken.

Dead reckoning drifts on moves the physics cuts short (an object hidden between two rays).
With ``correct_drift=True`` (registered as ``"coverage-scan"``) each move is re-reckoned once the
ring after it is known: made in full unless it ended in contact, else the advance a scan match
of the two rings gives (:mod:`lfmdr_gym.exploration.scan_match`). It maps visibility better and
bearing no better (``docs/online-and-exploration.md``), so the default stays off.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from lfmdr_gym.checks import check_real
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.exploration.scan_match import contact, matched_advance

__all__ = ["CoveragePolicy"]


class CoveragePolicy(RandomWalkPolicy):
    """Steer toward the least-visited free ground of a dead-reckoned grid (module docstring).

    Args:
        cell: side of a grid cell [m].
        extent: half-width of the grid around the start [m]; must exceed the arena's width so
            that any start keeps the arena inside (the default fits the paper's 2.5 m arena).
        correct_drift: re-reckon each move from the ring after it (module docstring).
        proximity_range: the ring's range [m] (``for_env`` reads it from the env's space).
        max_turn, step_length, robot_radius, margin, obstacle_radius, plan_ahead, n_tries, seed:
            as for :class:`~lfmdr_gym.exploration.random_walk.RandomWalkPolicy`.

    One observation at a time (it keeps per-episode memory); :meth:`reset` forgets it.
    Attributes: ``visits`` (the grid of visit counts), ``odometry`` (x, y, heading) in the frame
    of the start.
    """

    escape_moves = 0  # random-walk moves after a stopped move (the planners set their own)

    def __init__(self, max_turn: float = math.pi / 4, step_length: float = 0.2,
                 robot_radius: float = 0.05, *, cell: float = 0.25, extent: float = 3.0,
                 correct_drift: bool = False, proximity_range: float = 0.5,
                 **kwargs: Any) -> None:
        super().__init__(max_turn, step_length, robot_radius, **kwargs)
        if not isinstance(correct_drift, bool | np.bool_):
            raise ValueError(f"correct_drift must be True or False, got {correct_drift!r}")
        self.correct_drift = bool(correct_drift)
        self.proximity_range = float(proximity_range)
        self.cell = check_real("cell", cell, low=0.0, low_open=True)
        self.extent = check_real("extent", extent, low=0.0, low_open=True)
        if extent < cell:
            raise ValueError(f"extent must be at least one cell ({cell}), got {extent!r}")
        self._n = 2 * int(math.ceil(extent / cell))
        self._forget()

    @classmethod
    def for_env(cls, env: Any, **kwargs: Any) -> CoveragePolicy:
        """As :meth:`RandomWalkPolicy.for_env`, plus the proximity ring's range from the env's
        observation space (the scan match of ``correct_drift`` needs it)."""
        space = getattr(env, "observation_space", None)
        try:
            kwargs.setdefault("proximity_range", float(np.max(space["proximity"].high)))
        except (TypeError, KeyError):
            pass
        return super().for_env(env, **kwargs)

    def _forget(self) -> None:
        self.visits = np.zeros((self._n, self._n))
        self.odometry = np.zeros(3)
        self._escape = 0
        self._last: tuple | None = None  # (x, y, heading, turn, ring) of the last move's start

    def _correct(self, prox: np.ndarray) -> None:
        """Redo the last move's dead reckoning now that the ring after it is known: a move ends
        free after the full step, or in contact after the advance a scan match gives."""
        x, y, heading, turn, before = self._last
        advance = self.step_length
        if contact(prox, self.robot_radius):
            matched = matched_advance(before, prox, turn, self.step_length, self.proximity_range)
            advance = self._last_advance if matched is None else matched
        self.odometry = np.array([x + advance * math.cos(heading), y + advance * math.sin(heading),
                                  self.odometry[2]])

    def reset(self, seed: int | None = None) -> None:
        """Start an episode: forget the visits and the odometry; reseed as the random walk does."""
        super().reset(seed)
        self._forget()

    def _cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        idx = np.floor((xy + self.extent) / self.cell).astype(int)
        return tuple(np.clip(idx, 0, self._n - 1).T)

    def _scores(self, proximity: np.ndarray, turns: np.ndarray) -> np.ndarray:
        """Visit counts ahead along each turn (cells one and two steps on, the nearer weighing
        double), over the points the proximity ring reports free; lower is better."""
        x, y, heading = self.odometry
        room = self.clearance(proximity[None, :], turns[None, :])[0]
        score = np.zeros(turns.size)
        for k, weight in ((1, 1.0), (2, 0.5)):
            d = k * self.step_length
            ahead = np.column_stack([x + d * np.cos(heading + turns), y + d * np.sin(heading + turns)])
            counts = self.visits[self._cells(ahead)]
            # a point beyond an obstacle is unknown ground: scored as the most visited cell seen
            score += weight * np.where(room >= d, counts, self.visits.max())
        return score

    def _sense(self, prox: np.ndarray) -> bool:
        """Take in one ring: re-reckon the last move from it (with ``correct_drift``), remember
        the viewpoint (:meth:`_remember`), and say whether this move is an escape, a random-walk
        move (one of ``escape_moves``, 0 here) after a move the physics stopped short."""
        stopped = False
        if self._last is not None:
            stopped = contact(prox, self.robot_radius)
            self._correct(prox)
        self._remember(prox)
        if stopped:
            self._escape = self.escape_moves
        if self._escape > 0:
            self._escape -= 1
            return True
        return False

    def _remember(self, prox: np.ndarray) -> None:
        """Count a visit to the viewpoint's cell."""
        self.visits[self._cells(self.odometry[None, :2])] += 1

    @staticmethod
    def _plan_turns(turns: np.ndarray, later: np.ndarray) -> np.ndarray:
        """Every plan (t * p, k) that starts with one of ``turns`` (t,) and goes on with a row
        of ``later`` (p, k - 1), turn-major."""
        return np.concatenate([np.repeat(turns, len(later))[:, None],
                               np.tile(later, (turns.size, 1))], axis=1)

    def _plans(self, proximity: np.ndarray, turns: np.ndarray,
               later: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every plan that starts with one of ``turns`` (t,) and goes on with the turns of a row
        of ``later`` (p, k - 1), turn-major: the plans (t * p, k), their points' coordinates in
        the odometry frame (two arrays (t * p, k)), and whether each point is blocked (the ring's
        ray toward it reports an obstacle before it, a robot radius included)."""
        x, y, heading = self.odometry
        plans = self._plan_turns(turns, later)
        rel = np.cumsum(plans, axis=1)  # headings relative to the current one
        step = self.step_length
        px = step * np.cumsum(np.cos(rel), axis=1)  # plan points in the robot's frame
        py = step * np.cumsum(np.sin(rel), axis=1)
        n = proximity.size
        dist = np.hypot(px, py)
        ray = np.round(np.arctan2(py, px) / (2.0 * np.pi / n)).astype(int) % n
        limit = np.minimum(dist + self.robot_radius, self.proximity_range * (1.0 - 1e-6))
        blocked = proximity[ray] < limit
        ch, sh = math.cos(heading), math.sin(heading)
        return plans, x + ch * px - sh * py, y + sh * px + ch * py, blocked

    def __call__(self, observation: Mapping[str, Any]) -> np.ndarray:
        """The heading change for one observation, shape (1,)."""
        prox = self._proximity(observation)
        self._sense(prox)
        mt = self.max_turn
        turns = self.rng.uniform(-mt, mt, self.n_tries)
        return self._move(prox, turns[np.argsort(self._scores(prox, turns), kind="stable")])

    def _proximity(self, observation: Mapping[str, Any]) -> np.ndarray:
        """The proximity ring of one observation (a ValueError for anything else)."""
        name = type(self).__name__
        if not isinstance(observation, Mapping) or "proximity" not in observation:
            raise ValueError(f"{name} needs a dict observation with a 'proximity' entry, "
                             f"got {type(observation).__name__}")
        prox = np.asarray(observation["proximity"], dtype=np.float64)
        if prox.ndim != 1:
            raise ValueError(f"{name} takes one observation at a time (it keeps "
                             f"per-episode memory), got proximity of shape {prox.shape}")
        if self._stuck_sign is None or self._stuck_sign.shape != (1,):
            self._stuck_sign = np.zeros(1)
        return prox

    def _move(self, prox: np.ndarray, turns: np.ndarray, check: bool = True) -> np.ndarray:
        """Take the first of ``turns`` (best first) the collision check passes (with ``check``;
        else the first, for a planner that has simulated the obstacles itself), dead-reckon the
        move, and return the action, shape (1,)."""
        first = self._first_choice(prox, turns) if check else 0
        if first < 0:
            turn = self._unstick(0, prox)
        else:
            turn = float(turns[first])
            self._stuck_sign[0] = 0.0
        # dead reckoning: the move advances the step, or the room the ring reports if less
        room = float(self.clearance(prox[None, :], np.array([[turn]]))[0, 0])
        heading = self.odometry[2] + turn
        advance = min(self.step_length, max(room, 0.0))
        if self.correct_drift:
            self._last = (self.odometry[0], self.odometry[1], heading, turn, prox)
            self._last_advance = advance
        self.odometry = np.array([self.odometry[0] + advance * math.cos(heading),
                                  self.odometry[1] + advance * math.sin(heading),
                                  math.remainder(heading, 2.0 * math.pi)])
        return np.array([turn], np.float32)

    def __repr__(self) -> str:
        return f"CoveragePolicy(cell={self.cell:g}, extent={self.extent:g}, seed={self.seed!r})"
