"""lfmdr_gym: the paper's simulated world as Gymnasium environments, and its recorded histories.

``import lfmdr_gym`` registers the environment ids (importing twice is harmless)::

    import gymnasium as gym
    import lfmdr_gym  # noqa: F401

    env = gym.make("LFMDR-Visibility-v0")   # or "LFMDR-Bearing-v0", "LFMDR-Range-v0"
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from lfmdr_gym.env import LFMDREnv
from lfmdr_gym.history import History
from lfmdr_gym.policies import POLICIES, RandomWalkPolicy, as_policy
from lfmdr_gym.recording import collect, collect_vector
from mappers.sensors import SENSORS, check_sensor

__all__ = ["ENV_IDS", "POLICIES", "History", "LFMDREnv", "RandomWalkPolicy", "as_policy", "collect",
           "collect_vector", "env_id_for"]

MAX_EPISODE_STEPS = 2000
"""The paper's episode length N (paper §4.1)."""

ENV_IDS: dict[str, str] = {f"LFMDR-{sensor.capitalize()}-v0": sensor for sensor in SENSORS}
"""Registered id -> sensor: LFMDR-Visibility-v0, LFMDR-Bearing-v0, LFMDR-Range-v0."""


def env_id_for(sensor: str) -> str:
    """The registered env id whose observations are ``sensor``'s."""
    check_sensor(sensor)
    return next(env_id for env_id, s in ENV_IDS.items() if s == sensor)

for _env_id, _sensor in ENV_IDS.items():  # one loop, as panda-gym registers its variants
    if _env_id not in registry:  # a second import (or importlib.reload) must not re-register
        register(
            id=_env_id,
            entry_point="lfmdr_gym.env:LFMDREnv",
            kwargs={"sensor": _sensor},
            max_episode_steps=MAX_EPISODE_STEPS,
        )
