"""The small contract an exploration policy meets, and the adapters and checks around it.

A policy decides the robot's next heading change from the current observation alone. Anything
that meets one of two shapes can drive an :class:`~lfmdr_gym.env.LFMDREnv`:

* a callable ``policy(observation) -> action`` (optionally with ``reset(seed=None)``), or
* a Stable-Baselines3-style object with ``predict(observation, state=None, episode_start=None,
  deterministic=False) -> (action, state)`` — a trained SB3 model plugs in unchanged.

:func:`as_policy` turns either into a callable. Observations may be single (as from
``gymnasium.make``) or batched with a leading sub-environment axis (as from
``gymnasium.make_vec``); the registered policies answer in kind.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["Policy", "PredictPolicy", "as_policy", "base_env", "check_policy"]


@runtime_checkable
class Policy(Protocol):
    """What :func:`~lfmdr_gym.histories.recording.collect` drives the robot with.

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
      :func:`lfmdr_gym.sim.sensors.ray_directions`). Its value is the distance [m] from the robot's
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
