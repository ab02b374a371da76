"""A mapping reward for reinforcement learning, offered as a Gymnasium wrapper.

The LFMDR envs return no reward (mapping has none of its own). A map built from observation
histories is best where the robot's viewpoints sample the ground evenly (measured in
``docs/online-and-exploration.md``: even coverage with the true pose gives after 500 steps the
visibility map a random walk gives after 2,000), so the reward here is coverage: each move earns
``1 / sqrt(1 + n)``, n the earlier visits to the cell (0.25 m) it enters.

``reward="odometry"`` (default) counts visits in the robot's dead-reckoned frame, from what it
senses and does only, the same grid the agent's features show; ``reward="pose"`` counts them at
the true pose from ``info["robot_pose"]``. The latter is a *training signal* that uses ground
truth (drift-free, so an agent is not rewarded for covering a drifted grid); it is never part of
the agent's observation. Rebuilding the map after each move to reward its improvement was not
done: CAL-SMA costs tens of milliseconds per map, thousands of times an env step.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from lfmdr_gym.exploration.agent_view import AgentView, ViewConfig

__all__ = ["REWARDS", "MappingRewardWrapper"]

REWARDS = ("odometry", "pose")


class MappingRewardWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """
    ## Description

    Wraps an LFMDR env (``gymnasium.make("LFMDR-Visibility-v0")`` and the like) for a
    reinforcement-learning agent: a compact observation of what the robot senses, a shielded
    steering action and a coverage reward (module docstring). ``info`` passes through unchanged
    (ground truth for scoring; never in the observation).

    ## Observation Space

    ``Box(-1, 1, (n,), float32)`` with n = n_rays + 30 (n_rays + 28 without presence): the features of
    :class:`~lfmdr_gym.exploration.agent_view.AgentView` (proximity ring, novelty of the
    dead-reckoned cells around, dead-reckoned pose, presence summary).

    ## Action Space

    ``Box(-1, 1, (1,), float32)``: the wished heading change as a fraction of the env's
    ``max_turn``. The turn made is the nearest that passes the random walk's collision check
    (:meth:`~lfmdr_gym.exploration.agent_view.AgentView.turn_for`); ``info["turn"]`` reports it.

    ## Rewards

    ``1 / sqrt(1 + n)`` per move, n the visits to the entered cell before this one, counted in
    the dead-reckoned grid (``reward="odometry"``) or at the true pose (``reward="pose"``,
    ground truth as a training signal). Episodes end as the wrapped env's do (truncation).

    ## Arguments

    ``MappingRewardWrapper(env, reward="odometry", cell=0.25, presence=True)``: ``cell`` is the
    side of the grid cells [m] for the reward and the features; ``presence=False`` leaves the
    two presence figures out of the observation.
    """

    def __init__(self, env: gym.Env, *, reward: str = "odometry", cell: float = 0.25,
                 presence: bool = True) -> None:
        # RecordConstructorArgs: env.spec can then rebuild the wrapped env (check_env does).
        gym.utils.RecordConstructorArgs.__init__(self, reward=reward, cell=cell, presence=presence)
        gym.Wrapper.__init__(self, env)
        if reward not in REWARDS:
            raise ValueError(f"reward must be one of {REWARDS}, got {reward!r}")
        self.reward_kind = reward
        self.view = AgentView(ViewConfig.for_env(env, cell=cell, presence=presence))
        n = self.view.config.n_features
        self.observation_space = spaces.Box(-1.0, 1.0, (n,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
        self._pose_visits: dict[tuple[int, int], int] = {}

    def _pose_novelty(self, info: dict[str, Any]) -> float:
        x, y = np.asarray(info["robot_pose"], dtype=float)[:2]
        cell = self.view.config.cell
        key = (math.floor(x / cell), math.floor(y / cell))
        n = self._pose_visits.get(key, 0)
        self._pose_visits[key] = n + 1
        return 1.0 / math.sqrt(1.0 + n)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._pose_visits = {}
        if self.reward_kind == "pose":
            self._pose_novelty(info)
        return self.view.reset(obs), info

    def step(self, action: Any):
        turn = self.view.turn_for(action)
        obs, _, terminated, truncated, info = self.env.step(np.array([turn], np.float32))
        features, novelty = self.view.step(turn, obs)
        reward = self._pose_novelty(info) if self.reward_kind == "pose" else novelty
        info = dict(info, turn=turn)
        return features, float(reward), terminated, truncated, info
