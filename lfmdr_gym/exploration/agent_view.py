"""What a learned exploration policy sees: a compact feature vector built from the robot's senses.

A mapping sensor reports one value per object, and the objects' identities are arbitrary per
layout, so the raw readings mean nothing to a fixed-size network trained on other layouts. What
does carry over is how the robot's own viewpoints are spread: :class:`AgentView` keeps a visit
count per cell of a grid in the robot's dead-reckoned frame (as
:class:`~lfmdr_gym.exploration.coverage.CoveragePolicy` does) and hands a network

- the proximity ring, scaled to [0, 1];
- the novelty ``1 / (1 + visits)`` of the cells 1, 2 and 4 steps away in 8 directions around the
  heading (the ground the robot has covered, seen from where it stands);
- its dead-reckoned position (scaled by the grid's half-width) and heading (cos, sin);
- two presence figures (``presence=True``): the fraction of objects sensed now and the
  fraction sensed at least once. Presence is the visibility reading, or the ``"observed"`` mask
  under sensing limits; the bearing and range sensors without limits sense every object, so
  both read 1.

It reads observations and its own turns only, never ``info``. Dead reckoning: a move advances
the step, or less if the proximity ring reports less room along the turn
(:meth:`~lfmdr_gym.exploration.random_walk.RandomWalkPolicy.clearance`). That drifts on moves the
physics stops short (an object hidden between two rays), so by default (``correct_drift``) the view
uses what the physics guarantees: a move is made in full unless it ends in contact, which the ring
after it shows; a move ending in contact gets its advance from a scan match of the rings before and
after it (:mod:`lfmdr_gym.exploration.scan_match`); ``correct_drift=False`` keeps the plain model
(the drift of both is measured in ``docs/online-and-exploration.md``).

The network's action in [-1, 1] is a wish; :meth:`AgentView.turn_for` scales it to a turn and
shields it: among turns near the wish, the first that the random walk's collision check passes
(safe first, then merely free), so a learned policy never has to learn obstacle avoidance.

The same object serves training (:class:`lfmdr_gym.wrappers.MappingRewardWrapper`) and the
shipped policy (:class:`lfmdr_gym.exploration.rl.MLPExplorationPolicy`), so both see the same
numbers.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from lfmdr_gym.checks import check_int, check_real
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.exploration.scan_match import contact, matched_advance

__all__ = ["AgentView", "ViewConfig"]

_DIRECTIONS = 8
_DISTANCES = (1, 2, 4)  # in steps
_SHIELD_STEP = 0.1  # [rad] spacing of the turns the shield tries around the wish


@dataclass(frozen=True)
class ViewConfig:
    """The geometry an :class:`AgentView` needs, read from an env (``for_env``) or a model file.

    Lengths in metres, ``max_turn`` in radians.
    """

    n_rays: int = 32
    proximity_range: float = 0.5
    n_objects: int = 50
    max_turn: float = math.pi / 4
    step_length: float = 0.2
    robot_radius: float = 0.05
    object_radius: float = 0.024
    cell: float = 0.25
    extent: float = 3.0
    correct_drift: bool = True
    presence: bool = True

    def __post_init__(self) -> None:
        # checks only: the (frozen) fields keep the values given
        for name in ("n_rays", "n_objects"):
            check_int(name, getattr(self, name), low=1)
        for name in ("proximity_range", "max_turn", "step_length", "robot_radius",
                     "object_radius", "cell", "extent"):
            check_real(name, getattr(self, name), low=0.0, low_open=True)
        for name in ("correct_drift", "presence"):
            if not isinstance(getattr(self, name), bool | np.bool_):
                raise ValueError(f"{name} must be True or False, got {getattr(self, name)!r}")
        if self.extent < self.cell:
            raise ValueError(f"extent must be at least one cell ({self.cell}), got {self.extent!r}")

    @property
    def n_features(self) -> int:
        """Length of the feature vector."""
        return self.n_rays + _DIRECTIONS * len(_DISTANCES) + 4 + (2 if self.presence else 0)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def for_env(cls, env: Any, **kwargs: Any) -> ViewConfig:
        """The configuration matching ``env`` (wrapped or not): its geometry and its spaces only."""
        base = getattr(env, "unwrapped", env)
        world = getattr(base, "world", None)
        space = getattr(env, "observation_space", None)
        try:
            prox = space["proximity"]
        except (TypeError, KeyError) as exc:
            raise ValueError("the env's observation space must be a Dict with a 'proximity' "
                             f"Box (an LFMDR env), got {space!r}") from exc
        sensor = next((k for k in space.keys() if k not in ("proximity", "observed")), None)
        if sensor is None:
            raise ValueError(f"the env's observation space has no sensor entry: {space!r}")
        found = {
            "n_rays": int(prox.shape[0]),
            "proximity_range": float(np.max(prox.high)),
            "n_objects": int(space[sensor].shape[0]),
            "max_turn": getattr(base, "max_turn", None),
            "step_length": getattr(base, "step_length", None),
            "robot_radius": getattr(world, "robot_radius", None),
            "object_radius": getattr(world, "object_radius", None),
        }
        params = {k: (float(v) if isinstance(v, float | np.floating) else v)
                  for k, v in found.items() if v is not None}
        params.update(kwargs)
        return cls(**params)


class AgentView:
    """Dead-reckoned visit memory and the features a learned policy acts on (module docstring).

    Use: ``features = view.reset(obs)``; then per move ``turn = view.turn_for(action)``,
    ``env.step([turn])``, ``features, novelty = view.step(turn, new_obs)``. ``novelty`` is
    ``1 / sqrt(1 + visits)`` of the cell the move entered, counted before this visit: the
    sensed coverage reward of :class:`~lfmdr_gym.wrappers.MappingRewardWrapper`.

    Attributes: ``visits`` (grid of visit counts), ``odometry`` (x, y, heading) in the frame of
    the start, ``sensed`` (per object, the steps it was sensed on).
    """

    def __init__(self, config: ViewConfig) -> None:
        if not isinstance(config, ViewConfig):
            raise TypeError(f"config must be a ViewConfig, got {type(config).__name__}")
        self.config = c = config
        self._walker = RandomWalkPolicy(c.max_turn, c.step_length, c.robot_radius,
                                        obstacle_radius=c.object_radius, seed=0)
        self._n = 2 * int(math.ceil(c.extent / c.cell))
        a = 2.0 * np.pi * np.arange(_DIRECTIONS) / _DIRECTIONS
        d = np.array(_DISTANCES, float) * c.step_length
        self._probe_angles = np.repeat(a, len(d))
        self._probe_dist = np.tile(d, _DIRECTIONS)
        # Turns the shield tries, nearest the wish first: 0, +0.1, -0.1, +0.2, -0.2, ... far
        # enough to reach the whole +-max_turn range from any wish (then clipped to it).
        k = np.arange(1, int(math.ceil(2.0 * c.max_turn / _SHIELD_STEP)) + 1)
        self._offsets = np.concatenate([[0.0], np.stack([k, -k], axis=1).ravel() * _SHIELD_STEP])
        self._proximity: np.ndarray | None = None
        self.visits = np.zeros((self._n, self._n))
        self.odometry = np.zeros(3)
        self.sensed = np.zeros(c.n_objects)
        self._steps = 0
        self._now = 0.0  # fraction of objects sensed in the last observation

    def _cell(self, x: float, y: float) -> tuple[int, int]:
        n, c = self._n, self.config
        i = min(max(int(math.floor((x + c.extent) / c.cell)), 0), n - 1)
        j = min(max(int(math.floor((y + c.extent) / c.cell)), 0), n - 1)
        return i, j

    def _read(self, observation: Any) -> np.ndarray:
        c = self.config
        if not isinstance(observation, Mapping) or "proximity" not in observation:
            raise ValueError("AgentView needs a dict observation with a 'proximity' entry, got "
                             f"{type(observation).__name__}")
        prox = np.asarray(observation["proximity"], dtype=np.float64)
        if prox.shape != (c.n_rays,):
            raise ValueError(f"observation['proximity'] must have shape ({c.n_rays},) (one "
                             f"observation at a time), got {prox.shape}")
        if "observed" in observation:
            presence = np.asarray(observation["observed"]) > 0
        elif "visibility" in observation:
            presence = np.asarray(observation["visibility"]) > 0
        else:
            presence = np.ones(c.n_objects, dtype=bool)
        if presence.shape != (c.n_objects,):
            raise ValueError(f"the observation's presence must have shape ({c.n_objects},), got "
                             f"{presence.shape}")
        self.sensed += presence
        self._steps += 1
        self._now = presence.mean()
        return prox

    def reset(self, observation: Mapping[str, Any]) -> np.ndarray:
        """Forget the episode, take the first observation, return its features."""
        self.visits[:] = 0.0
        self.odometry = np.zeros(3)
        self.sensed[:] = 0.0
        self._steps = 0
        self._proximity = self._read(observation)
        self.visits[self._cell(0.0, 0.0)] += 1
        return self.features()

    def turn_for(self, action: Any) -> float:
        """The shielded turn for a network's action in [-1, 1] (clipped), as a float32 value."""
        if self._proximity is None:
            raise RuntimeError("call reset(observation) before turn_for()")
        a = float(np.asarray(action, dtype=np.float64).reshape(-1)[0])
        if not math.isfinite(a):
            raise ValueError(f"action must be a finite number, got {action!r}")
        mt = self.config.max_turn
        wish = min(max(a, -1.0), 1.0) * mt
        turns = np.clip(wish + self._offsets, -mt, mt)
        first = self._walker._first_choice(self._proximity, turns)
        if first >= 0:
            self._walker._stuck_sign = np.zeros(1)
            turn = float(turns[first])
        else:
            if self._walker._stuck_sign is None:
                self._walker._stuck_sign = np.zeros(1)
            turn = self._walker._unstick(0, self._proximity)
        return float(np.float32(turn))

    @property
    def in_contact(self) -> bool:
        """Whether the last observation's ring shows the robot touching an obstacle."""
        if self._proximity is None:
            raise RuntimeError("call reset(observation) before in_contact")
        return contact(self._proximity, self.config.robot_radius)

    def step(self, turn: float, observation: Mapping[str, Any]) -> tuple[np.ndarray, float]:
        """Dead-reckon the move just made with ``turn`` and take its observation.

        Returns the new features and the novelty of the cell entered (module docstring).
        """
        if self._proximity is None:
            raise RuntimeError("call reset(observation) before step()")
        c = self.config
        room = float(self._walker.clearance(self._proximity[None, :], np.array([[turn]]))[0, 0])
        x, y, h = self.odometry
        h = h + float(turn)
        advance = min(c.step_length, max(room, 0.0))
        before = self._proximity
        self._proximity = self._read(observation)
        if c.correct_drift:
            # A move is either made in full or stopped in contact (the physics), so a move that
            # ends free went the full step whatever room the ring's model foresaw.
            if not contact(self._proximity, c.robot_radius):
                advance = c.step_length
            else:
                matched = matched_advance(before, self._proximity, float(turn), c.step_length,
                                          c.proximity_range)
                if matched is not None:
                    advance = matched
        x, y = x + advance * math.cos(h), y + advance * math.sin(h)
        self.odometry = np.array([x, y, math.remainder(h, 2.0 * math.pi)])
        cell = self._cell(x, y)
        novelty = 1.0 / math.sqrt(1.0 + self.visits[cell])
        self.visits[cell] += 1
        return self.features(), novelty

    def features(self) -> np.ndarray:
        """The feature vector (float32, every entry in [-1, 1]) of the current state."""
        c = self.config
        x, y, h = self.odometry
        ang = h + self._probe_angles
        px = (x + self._probe_dist * np.cos(ang) + c.extent) / c.cell
        py = (y + self._probe_dist * np.sin(ang) + c.extent) / c.cell
        i = np.clip(np.floor(px).astype(int), 0, self._n - 1)
        j = np.clip(np.floor(py).astype(int), 0, self._n - 1)
        novelty = 1.0 / (1.0 + self.visits[i, j])
        odo = [np.clip(x / c.extent, -1, 1), np.clip(y / c.extent, -1, 1), math.cos(h), math.sin(h)]
        presence = [self._now, float((self.sensed > 0).mean())] if c.presence else []
        out = np.concatenate([np.minimum(self._proximity / c.proximity_range, 1.0), novelty, odo,
                              presence])
        return out.astype(np.float32)
