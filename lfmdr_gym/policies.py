"""Exploration policies: the small contract a policy meets, and the paper's random-walk agent.

A policy decides the robot's next heading change from the current observation alone. Anything
that meets one of two shapes can drive an :class:`~lfmdr_gym.env.LFMDREnv`:

* a callable ``policy(observation) -> action`` (optionally with ``reset(seed=None)``), or
* a Stable-Baselines3-style object with ``predict(observation, state=None, episode_start=None,
  deterministic=False) -> (action, state)`` — a trained SB3 model plugs in unchanged.

:func:`as_policy` turns either into a callable. Observations may be single (as from
``gymnasium.make``) or batched with a leading sub-environment axis (as from
``gymnasium.make_vec``); the policies here answer in kind.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any, Protocol, runtime_checkable

import numpy as np

from lfmdr_gym import kernels
from lfmdr_gym.world import check_int, check_real

__all__ = ["POLICIES", "Policy", "PredictPolicy", "RandomWalkPolicy", "as_policy", "check_policy"]


@runtime_checkable
class Policy(Protocol):
    """What :func:`~lfmdr_gym.history.collect` drives the robot with.

    ``policy(observation)`` returns the action: shape (1,) for one observation, or (B, 1) for a
    batch of B observations from a vector env. A policy that keeps state or randomness should also
    offer ``reset(seed=None)``, called at the start of each collected episode (optional, so it is
    not part of the runtime check).

    The observation (a dict; each entry gains a leading axis of B from a vector env), as
    :class:`~lfmdr_gym.env.LFMDREnv` documents it:

    - ``"proximity"``: float32 (n_rays,), ``n_rays = env.n_proximity_rays`` (32 by default).
      Ray ``k`` leaves the robot's centre at ``heading + 2 pi k / n_rays``, counter-clockwise:
      ray 0 straight ahead, ray ``n_rays / 4`` to the left (+90 degrees), ``n_rays / 2``
      behind, ``3 n_rays / 4`` to the right (the unit vectors in the robot frame:
      :func:`lfmdr_gym.sensors.ray_directions`). Its value is the distance [m] from the robot's
      centre (its radius not subtracted) to the first obstacle on the ray, an object's surface
      or a wall, capped at ``env.proximity_range`` (0.5 m by default): the cap means nothing
      within that distance. A move along a ray's direction hits something on that ray when
      its reading is below ``step_length + robot_radius`` (0.25 m by default); rays are thin,
      so an object between two rays can still block a move (the physics then stops the robot
      short).
    - the mapping sensor's entry (``"visibility"``, ``"bearing"`` and/or ``"range"``, one row
      per object) and, with a sensing limit on, ``"observed"``: a policy may use them too.

    The action is the heading change [rad] before the move, in ``[-max_turn, max_turn]``
    (``pi / 4`` by default; clipped). A policy never sees ``info`` (the ground truth); the
    env's geometry (``max_turn``, ``step_length``, ``robot_radius``, ...) can be read once from
    the env, as :meth:`RandomWalkPolicy.for_env` does.
    """

    def __call__(self, observation: Any) -> np.ndarray: ...


class PredictPolicy:
    """Adapter from an SB3-style ``predict`` method to the :class:`Policy` callable.

    It carries the recurrent ``state`` from call to call (needed by SB3's recurrent policies) and
    passes ``episode_start``: True on the first call after :meth:`reset`, False afterwards, unless
    the caller gives it explicitly (a vector collector does, per sub-environment).
    """

    def __init__(self, model: Any, *, deterministic: bool = False) -> None:
        if not callable(getattr(model, "predict", None)):
            raise TypeError(f"{type(model).__name__} has no callable predict() method")
        self.model = model
        self.deterministic = deterministic
        self._state: Any = None
        self._starting = True

    def reset(self, seed: int | None = None) -> None:
        """Forget the recurrent state; the next call starts an episode. Seeds the model if it can."""
        self._state = None
        self._starting = True
        if seed is not None and callable(getattr(self.model, "set_random_seed", None)):
            self.model.set_random_seed(seed)

    def __call__(self, observation: Any, episode_start: np.ndarray | bool | None = None) -> np.ndarray:
        batch = _batch_size(observation)
        if episode_start is None:
            episode_start = self._starting
        starts = np.asarray(episode_start, dtype=bool)
        if batch is not None:
            starts = np.broadcast_to(starts, (batch,)).copy()
        else:
            starts = starts.reshape(1)
        action, self._state = self.model.predict(
            observation,
            state=self._state,
            episode_start=starts,
            deterministic=self.deterministic,
        )
        self._starting = False
        return np.asarray(action)

    def __repr__(self) -> str:
        return f"PredictPolicy({self.model!r}, deterministic={self.deterministic})"


def as_policy(obj: Any, *, deterministic: bool = False) -> Policy:
    """Return ``obj`` as a :class:`Policy` callable.

    An object with a ``predict`` method (SB3 style) is wrapped in :class:`PredictPolicy`
    (``deterministic`` is handed to ``predict``); any other callable is returned unchanged.
    Anything else raises TypeError.
    """
    if isinstance(obj, PredictPolicy):
        return obj
    if callable(getattr(obj, "predict", None)):
        return PredictPolicy(obj, deterministic=deterministic)
    if callable(obj):
        return obj
    raise TypeError(
        "a policy must be a callable policy(observation) -> action or an object with an "
        "SB3-style predict(observation, state=None, episode_start=None, deterministic=False) "
        f"-> (action, state) method; got {type(obj).__name__}"
    )


def _batch_size(observation: Any) -> int | None:
    """B for a batched observation (leading axis over sub-envs), None for a single one."""
    if isinstance(observation, Mapping) and "proximity" in observation:
        prox = np.asarray(observation["proximity"])
        return prox.shape[0] if prox.ndim == 2 else None
    return None


def base_env(env: Any) -> Any:
    """The unwrapped LFMDR env behind ``env`` (wrapped, or a vector env: its sub-env 0), or
    ``env`` itself when it is neither; a policy factory reads its geometry from it."""
    base = getattr(env, "unwrapped", env)
    if hasattr(env, "get_attr") and not hasattr(base, "world"):  # vector env: ask sub-env 0
        try:
            base = env.get_attr("unwrapped")[0]
        except (AttributeError, IndexError):
            pass
    return base


class RandomWalkPolicy:
    """The paper's agent (Yairi 2007, §4.1): a random walk with reactive obstacle avoidance.

    Each step it draws a heading change uniformly in ``[-max_turn, max_turn]``. It reads the
    observation's ``"proximity"`` ring (ray k at heading + 2*pi*k/n_rays, value = distance from the
    robot's centre to the first obstacle) and rejects a candidate direction when the robot's disc
    could not advance ``step_length + margin`` along it without touching an obstacle a ray
    reported (:meth:`clearance`); it then draws again (up to ``n_tries`` candidates, so the
    accepted direction is uniform over the free ones). With ``plan_ahead`` it prefers, among
    the draws, the first after which some heading within ``max_turn`` is still free, so that it
    does not walk into a corner it cannot turn out of in one step. If no draw is free it turns,
    by at most ``max_turn``, toward the direction with the most room; the physics stops the
    robot short of contact anyway.

    Measured in ``LFMDR-Visibility-v0`` (4 seeds x 2000 steps): blocked on about 9 % of moves
    with the env's default 32 proximity rays, 22 % with 16 rays (a 48 mm cylinder can hide
    between rays 22.5 degrees apart) and 6 % with 64; a blind uniform walk is blocked on 86 %.

    The proximity range must exceed ``step_length + robot_radius`` for the check to see far
    enough. Randomness comes from the policy's own generator, fixed by ``seed`` or
    :meth:`reset`. Works on one observation (returns shape (1,)) or a batch (returns (B, 1)).
    """

    def __init__(
        self,
        max_turn: float = math.pi / 4,
        step_length: float = 0.2,
        robot_radius: float = 0.05,
        *,
        margin: float = 0.02,
        obstacle_radius: float = 0.024,
        plan_ahead: bool = True,
        n_tries: int = 16,
        seed: int | None = None,
    ) -> None:
        self.max_turn = check_real("max_turn", max_turn, low=0.0, low_open=True, high=math.pi)
        self.step_length = check_real("step_length", step_length, low=0.0, low_open=True)
        self.robot_radius = check_real("robot_radius", robot_radius, low=0.0, low_open=True)
        self.margin = check_real("margin", margin, low=0.0)
        self.obstacle_radius = check_real("obstacle_radius", obstacle_radius, low=0.0)
        if not isinstance(plan_ahead, bool | np.bool_):
            raise ValueError(f"plan_ahead must be True or False, got {plan_ahead!r}")
        self.plan_ahead = bool(plan_ahead)
        self.n_tries = check_int("n_tries", n_tries, low=1)
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self._stuck_sign: np.ndarray | None = None  # per row: turn direction while stuck
        # Headings tried after a move (plan_ahead), as cosines and sines for _first_choice:
        # computed once, np.linspace costs microseconds.
        probes = np.linspace(-self.max_turn, self.max_turn, 5)
        self._probe_c, self._probe_s = np.cos(probes), np.sin(probes)
        self._ray_cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._ray_part_cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._unstick_cache: dict[int, np.ndarray] = {}

    @classmethod
    def for_env(cls, env: Any, **kwargs: Any) -> RandomWalkPolicy:
        """A policy matched to ``env``'s geometry (max turn, step length, robot and object radii).

        ``env`` may be an :class:`~lfmdr_gym.env.LFMDREnv` (wrapped or not) or a vector env of
        them; what cannot be read keeps its default, and keywords override.
        """
        base = base_env(env)
        world = getattr(base, "world", None)
        found = {
            "max_turn": getattr(base, "max_turn", None),
            "step_length": getattr(base, "step_length", None),
            "robot_radius": getattr(world, "robot_radius", None),
            "obstacle_radius": getattr(world, "object_radius", None),
        }
        params: dict[str, Any] = {k: float(v) for k, v in found.items() if v is not None}
        space = getattr(env, "single_action_space", None) or getattr(env, "action_space", None)
        if "max_turn" not in params and space is not None and hasattr(space, "high"):
            params["max_turn"] = float(np.max(space.high))
        params.update(kwargs)
        return cls(**params)

    def reset(self, seed: int | None = None) -> None:
        """Start an episode; reseed the generator (with ``seed=None`` the random stream carries on)."""
        self._stuck_sign = None
        if seed is not None:
            self.seed = seed
            self.rng = np.random.default_rng(seed)

    def _rays(self, n_rays: int) -> tuple[np.ndarray, np.ndarray]:
        if n_rays not in self._ray_cache:
            angles = 2.0 * np.pi * np.arange(n_rays) / n_rays
            ray = np.exp(1j * angles)  # unit direction of each ray, x + iy
            wrapped = np.angle(ray)  # heading-relative angle in (-pi, pi]
            self._ray_cache[n_rays] = (wrapped, ray)
        return self._ray_cache[n_rays]

    def _ray_parts(self, n_rays: int) -> tuple[np.ndarray, np.ndarray]:
        """The rays' unit directions as two contiguous arrays (x ahead, y left)."""
        if n_rays not in self._ray_part_cache:
            _, ray = self._rays(n_rays)
            self._ray_part_cache[n_rays] = (ray.real.copy(), ray.imag.copy())
        return self._ray_part_cache[n_rays]

    def _obstacles(self, proximity: np.ndarray) -> np.ndarray:
        """Modelled obstacle centres in the robot frame as complex x + iy (x ahead, y left).

        Complex numbers make a change of frame one multiplication (fewer numpy calls per step:
        the policy runs once per env step and must stay cheap).
        """
        _, ray = self._rays(proximity.shape[1])
        return (proximity + self.obstacle_radius) * ray

    def _travel(self, z: np.ndarray) -> np.ndarray:
        """Distance the disc can advance along +x before touching an obstacle centred at z.

        Minimum over the last axis; inf when nothing is in the way. Centres behind (x <= 0) never
        block, and touching means centres within ``robot_radius + obstacle_radius``.
        """
        x, y = z.real, z.imag
        reach2 = (self.robot_radius + self.obstacle_radius) ** 2 - y * y
        travel = x - np.sqrt(np.abs(reach2))
        # Speed: copyto(where=) and ufunc.reduce skip np.where's and ndarray.min's overheads.
        # (The mask is ~(a & b), not (x <= 0) | (reach2 <= 0): a NaN reading must block nothing.)
        np.copyto(travel, np.inf, where=~((x > 0.0) & (reach2 > 0.0)))
        return np.maximum(np.minimum.reduce(travel, axis=-1), 0.0)

    @staticmethod
    def _rotate(z: np.ndarray, turns: np.ndarray) -> np.ndarray:
        """Points z (..., n) seen from frames turned by ``turns`` (..., T): array (..., T, n)."""
        return z[..., None, :] * np.exp(-1j * turns)[..., None]

    def clearance(self, proximity: np.ndarray, turns: np.ndarray) -> np.ndarray:
        """How far the robot could advance after each candidate turn before touching an obstacle.

        ``proximity`` is (B, n_rays), ``turns`` (B, T); returns (B, T) distances (inf when no
        reported obstacle is in the way). A ray only reports one point of an obstacle's surface,
        so each reading is modelled as a cylinder of ``obstacle_radius`` just behind that point;
        the disc collides with it once their centres come within ``robot_radius +
        obstacle_radius``. Obstacles behind the robot (x <= 0 in the candidate's frame) never
        block a forward move.
        """
        return self._travel(self._rotate(self._obstacles(proximity), turns))

    def _plan(self, proximity: np.ndarray, turns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(free, safe) for each candidate turn, both (B, T) bool.

        free: the move itself is clear. safe: free, and from where it ends some heading within
        +-max_turn (five probes) is clear for the next move too, so the walk does not run into
        a corner or a wall it cannot turn away from in one step. (The reference for
        :meth:`_first_choice`, which the policy runs instead: the same decisions, compiled.)
        """
        need = self.step_length + self.margin
        z = self._rotate(self._obstacles(proximity), turns)  # (B, T, n)
        room = self._travel(z)
        free = room >= need
        if not self.plan_ahead:
            return free, free
        # Room for two moves straight on makes a draw safe without probing; probe only when
        # the first free draw of some row lacks it (this keeps the common case cheap).
        safe = room >= need + self.step_length
        first = free.argmax(axis=1)
        rows = np.flatnonzero(free.any(axis=1) & ~safe[np.arange(len(first)), first])
        if rows.size:
            probes = np.linspace(-self.max_turn, self.max_turn, 5)
            moved = z[rows] - self.step_length  # the obstacles seen from where the move ends
            z2 = self._rotate(moved, np.broadcast_to(probes, (*moved.shape[:2], 5)))
            safe[rows] = free[rows] & (self._travel(z2) >= need).any(axis=-1)
        return free, safe

    def _first_choice(self, proximity: np.ndarray, turns: np.ndarray) -> int:
        """Index of the first safe draw in ``turns``, else of the first free one, else -1.

        The decision of :meth:`_plan` for one ring (n,) and its draws (T,), made lazily, draw by
        draw, by the compiled :func:`lfmdr_gym.kernels.first_choice` (the policy runs once per
        env step; usually the first draw settles it). Only readings nearer than ``need +
        step_length + robot_radius`` can block a move or spoil the one after it.
        """
        ray_x, ray_y = self._ray_parts(proximity.size)
        return kernels.first_choice(
            proximity, turns, ray_x, ray_y, self._probe_c, self._probe_s, self.obstacle_radius,
            self.robot_radius, self.step_length, self.margin, self.plan_ahead,
        )

    def _act(self, proximity: np.ndarray) -> np.ndarray:
        batch = proximity.shape[0]
        turns = self.rng.uniform(-self.max_turn, self.max_turn, size=(batch, self.n_tries))
        if self._stuck_sign is None or self._stuck_sign.shape != (batch,):
            self._stuck_sign = np.zeros(batch)
        chosen = np.empty(batch, dtype=np.float32)
        for b in range(batch):
            first = self._first_choice(proximity[b], turns[b])
            if first >= 0:
                chosen[b] = turns[b, first]
                self._stuck_sign[b] = 0.0
            else:
                chosen[b] = self._unstick(b, proximity[b])
        return chosen.reshape(batch, 1)

    def _act_one(self, proximity: np.ndarray) -> np.ndarray:
        """:meth:`_act` for one observation (the same draws and decisions, fewer numpy calls:
        the policy runs once per env step)."""
        turns = self.rng.uniform(-self.max_turn, self.max_turn, size=self.n_tries)
        if self._stuck_sign is None or self._stuck_sign.shape != (1,):
            self._stuck_sign = np.zeros(1)
        first = self._first_choice(proximity, turns)
        if first >= 0:
            self._stuck_sign[0] = 0.0
            return np.array((turns[first],), dtype=np.float32)
        return np.array((self._unstick(0, proximity),), dtype=np.float32)

    def _unstick(self, row: int, proximity: np.ndarray) -> float:
        """The turn when no draw is free: at most max_turn toward the ray direction with the
        most room (ties go to the smallest turn). A robot still stuck keeps turning the same way,
        so that it cannot swing back and forth between two blocked headings."""
        previous = self._stuck_sign[row]
        if previous != 0:
            return previous * self.max_turn
        n = proximity.size
        if n not in self._unstick_cache:  # ray directions, smallest turn first (cached)
            wrapped, _ = self._rays(n)
            self._unstick_cache[n] = wrapped[np.argsort(np.abs(wrapped), kind="stable")][None, :]
        by_turn = self._unstick_cache[n]
        room = self.clearance(proximity[None, :], by_turn)[0]
        mt = self.max_turn
        turn = min(max(float(by_turn[0, room.argmax()]), -mt), mt)  # as np.clip, without its cost
        self._stuck_sign[row] = 1.0 if turn >= 0 else -1.0
        return turn

    def __call__(self, observation: Mapping[str, Any]) -> np.ndarray:
        """The heading change for ``observation``: shape (1,), or (B, 1) for a batch."""
        if not isinstance(observation, Mapping) or "proximity" not in observation:
            raise ValueError(
                "RandomWalkPolicy needs a dict observation with a 'proximity' entry, got "
                f"{type(observation).__name__}"
            )
        prox = np.asarray(observation["proximity"], dtype=np.float64)
        if prox.ndim == 1:
            if type(self)._act is RandomWalkPolicy._act:  # (a subclass's own _act is kept)
                return self._act_one(prox)
            return self._act(prox[None, :])[0]
        if prox.ndim == 2:
            return self._act(prox)
        raise ValueError(f"observation['proximity'] must be 1-D or 2-D (batched), got {prox.shape}")

    def __repr__(self) -> str:
        return (
            f"RandomWalkPolicy(max_turn={self.max_turn:.4g}, step_length={self.step_length:g}, "
            f"robot_radius={self.robot_radius:g}, margin={self.margin:g}, "
            f"obstacle_radius={self.obstacle_radius:g}, plan_ahead={self.plan_ahead}, "
            f"n_tries={self.n_tries}, seed={self.seed!r})"
        )



def _coverage(env: Any, **kwargs: Any) -> Any:
    from lfmdr_gym.exploration import CoveragePolicy

    return CoveragePolicy.for_env(env, **kwargs)


def _coverage_scan(env: Any, **kwargs: Any) -> Any:
    from lfmdr_gym.exploration import CoveragePolicy

    return CoveragePolicy.for_env(env, **{"correct_drift": True, **kwargs})


def _spread(env: Any, **kwargs: Any) -> Any:
    from lfmdr_gym.spread import SpreadPolicy

    return SpreadPolicy.for_env(env, **kwargs)


def _even(env: Any, **kwargs: Any) -> Any:
    from lfmdr_gym.even import EvenPolicy

    return EvenPolicy.for_env(env, **kwargs)


def _rl(env: Any, **kwargs: Any) -> Any:
    from lfmdr_gym.rl_policy import MLPExplorationPolicy

    return MLPExplorationPolicy.for_env(env, **kwargs)


POLICIES: Mapping[str, Callable[..., Any]] = MappingProxyType({
    "random-walk": RandomWalkPolicy.for_env,
    "coverage": _coverage,
    "coverage-scan": _coverage_scan,
    "rl": _rl,
    "spread": _spread,
    "even": _even,
})
"""Name -> factory ``factory(env, **kwargs) -> policy``: the exploration policies ``lfmdr collect
--policy NAME`` offers. A factory reads only the env's geometry (turn limit, step length, robot
and object radii, the room's size) and spaces; the policy then sees observations only (:func:`check_policy`).

- ``"random-walk"``: the paper's agent (:class:`RandomWalkPolicy`).
- ``"coverage"``: even coverage from a dead-reckoned visit memory
  (:class:`lfmdr_gym.exploration.CoveragePolicy`).
- ``"coverage-scan"``: the same with its dead reckoning corrected from the proximity rings
  (``correct_drift=True``, :mod:`lfmdr_gym.scan_match`).
- ``"rl"``: a PPO agent trained on the coverage reward, run in numpy from the shipped weights
  (:class:`lfmdr_gym.rl_policy.MLPExplorationPolicy`; ``examples/train_rl_policy.py``).
- ``"spread"``: viewpoints spread evenly at the scale of the step (a kernel density of the
  drift-corrected dead-reckoned viewpoints, three-move look-ahead, a pull toward unvisited
  seen-free ground; :class:`lfmdr_gym.spread.SpreadPolicy`).
- ``"even"``: plans of three moves that keep the coverage of the room even (the room placed
  from the walls the ring sees, which also correct the dead reckoning; the moves simulated
  among cylinders fitted to every ring hit so far; :class:`lfmdr_gym.even.EvenPolicy`); the
  fastest mapper of these.
"""


def check_policy(policy: Any, env: Any, n_steps: int = 20, seed: int = 0) -> None:
    """Drive ``env`` with ``policy`` for ``n_steps`` moves, handing it observations only, and
    check the contract: every action lies in the env's action space, and with ``reset(seed)`` the
    same seed gives the same actions. AssertionError naming the breach otherwise.
    """
    pol = as_policy(policy)
    runs = []
    for _ in range(2):
        obs, _ = env.reset(seed=seed)
        if callable(getattr(pol, "reset", None)):
            pol.reset(seed=seed)
        actions = []
        for _ in range(n_steps):
            action = np.asarray(pol(obs), dtype=np.float32).reshape(env.action_space.shape)
            assert env.action_space.contains(action), f"action {action} outside {env.action_space}"
            actions.append(action)
            obs, _, terminated, truncated, _ = env.step(action)  # info is never handed on
            if terminated or truncated:
                break
        runs.append(np.array(actions))
    assert np.array_equal(runs[0], runs[1]), "the same seed gave different actions"
