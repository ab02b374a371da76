"""lfmdr_gym: the paper's simulated world as Gymnasium environments, and its recorded histories.

``import lfmdr_gym`` registers the environment ids (importing twice is harmless)::

    import gymnasium as gym
    import lfmdr_gym  # noqa: F401

    env = gym.make("LFMDR-Visibility-v0")   # or "LFMDR-Bearing-v0", "LFMDR-Range-v0",
    # "LFMDR-RangeBearing-v0", "LFMDR-VisibilityBearing-v0", "LFMDR-Camera-v0"
    env = gym.make("LFMDR-Camera3D-v0")     # tags at heights, a pitched camera: 3-D maps
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from gymnasium.envs.registration import register, registry

from lfmdr_gym.env import LFMDREnv
from lfmdr_gym.exploration import POLICIES, RandomWalkPolicy, as_policy
from lfmdr_gym.histories import History, collect, collect_vector
from lfmdr_gym.sim import CAMERA_PRESET
from mappers.core.sensors import FUSED_SENSORS, SENSORS, check_sensor

__all__ = [
    "LFMDREnv",
    "POLICIES", "RandomWalkPolicy", "as_policy",
    "History", "collect", "collect_vector",
    "ENV_IDS", "ENV_IDS_3D", "PRESETS", "env_id_for",
]

MAX_EPISODE_STEPS = 2000
"""The paper's episode length N (paper §4.1)."""

ENV_IDS: dict[str, str] = {
    **{f"LFMDR-{sensor.capitalize()}-v0": sensor for sensor in SENSORS},
    **{"LFMDR-" + "".join(w.capitalize() for w in name.split("-")) + "-v0": name
       for name in FUSED_SENSORS},
    "LFMDR-Camera-v0": "range-bearing",
}
"""Registered id -> sensor (or fused set): LFMDR-Visibility-v0, LFMDR-Bearing-v0,
LFMDR-Range-v0; LFMDR-RangeBearing-v0 and LFMDR-VisibilityBearing-v0 (both observations every
step); LFMDR-Camera-v0, the range-bearing env preset to the MRCLAM robots' camera
(:data:`lfmdr_gym.sim.camera.CAMERA_PRESET`)."""

PRESETS: dict[str, Mapping[str, Any]] = {"LFMDR-Camera-v0": CAMERA_PRESET}
"""Registered id -> the env keywords it sets beyond its sensor (overridable in ``gym.make``)."""


def env_id_for(sensor: str) -> str:
    """The registered env id whose observations are ``sensor``'s (a sensor or a fused set's
    name), without a preset."""
    if sensor not in FUSED_SENSORS:
        check_sensor(sensor)
    return next(env_id for env_id, s in ENV_IDS.items() if s == sensor and env_id not in PRESETS)


ENV_IDS_3D: dict[str, str] = {"LFMDR-Camera3D-v0": "range-bearing"}
"""Registered 3-D id -> its default sensor: LFMDR-Camera3D-v0, tags at heights on posts and walls
read by a pitched camera (:class:`lfmdr_gym.camera3d_env.Camera3DEnv`; ``sensor=`` in
``gym.make`` picks visibility, bearing or range instead). Kept apart from :data:`ENV_IDS`, whose
envs are planar."""

for _env_id, _sensor in ENV_IDS_3D.items():
    if _env_id not in registry:
        register(
            id=_env_id,
            entry_point="lfmdr_gym.camera3d_env:Camera3DEnv",
            kwargs={"sensor": _sensor},
            max_episode_steps=MAX_EPISODE_STEPS,
        )

for _env_id, _sensor in ENV_IDS.items():  # one loop, as panda-gym registers its variants
    if _env_id not in registry:  # a second import (or importlib.reload) must not re-register
        register(
            id=_env_id,
            entry_point="lfmdr_gym.env:LFMDREnv",
            kwargs={"sensor": _sensor, **dict(PRESETS.get(_env_id, {}))},
            max_episode_steps=MAX_EPISODE_STEPS,
        )
