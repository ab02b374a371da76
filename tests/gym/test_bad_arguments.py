"""Every env checks its constructor's arguments: a bad one is refused with a ValueError that
names it (the contract both envs' docstrings state: "Every argument is checked on construction")."""

from __future__ import annotations

import pytest

from lfmdr_gym.camera3d_env import Camera3DEnv
from lfmdr_gym.env import LFMDREnv

BAD_ARGUMENTS = [
    (LFMDREnv, {"sensor": "sonar"}, "sensor"),
    (LFMDREnv, {"step_length": 0.0}, "step_length"),
    (LFMDREnv, {"step_length": -0.2}, "step_length"),
    (LFMDREnv, {"max_turn": 0.0}, "max_turn"),
    (LFMDREnv, {"max_turn": 4.0}, "max_turn"),
    (LFMDREnv, {"visual_angle_deg": 0.0}, "visual_angle_deg"),
    (LFMDREnv, {"visual_angle_deg": 180.0}, "visual_angle_deg"),
    (LFMDREnv, {"occlusion": "yes"}, "occlusion"),
    (LFMDREnv, {"n_proximity_rays": 0}, "n_proximity_rays"),
    (LFMDREnv, {"proximity_range": -0.5}, "proximity_range"),
    (LFMDREnv, {"max_range": 0.0}, "max_range"),
    (LFMDREnv, {"render_mode": "ansi"}, "render_mode"),
    (LFMDREnv, {"n_objects": 500}, "n_objects"),
    (LFMDREnv, {"arena_size": -1.0}, "arena_size"),
    (LFMDREnv, {"object_diameter": -0.048}, "object_diameter"),
    (LFMDREnv, {"robot_radius": 0.0}, "robot_radius"),
    (LFMDREnv, {"n_anchors": 2}, "n_anchors"),
    (LFMDREnv, {"object_clearance": -1.0}, "object_clearance"),
    (Camera3DEnv, {"sensor": "visibility-bearing"}, "sensor must be one of"),
    (Camera3DEnv, {"sensor": "bearing", "range_noise": 0.1}, "range_noise applies"),
    (Camera3DEnv, {"sensor": "range", "bearing_noise_deg": 1.0}, "bearing_noise_deg applies"),
    (Camera3DEnv, {"n_anchors": 3}, "n_anchors"),
    (Camera3DEnv, {"tag_heights": (2.0, 1.0)}, "tag_heights"),
    (Camera3DEnv, {"miss_rate": 1.0}, "miss_rate"),
    (Camera3DEnv, {"hfov_deg": 200.0}, "hfov_deg"),
    (Camera3DEnv, {"tags_per_post": -1}, "tags_per_post"),
]
"""``(env class, keyword arguments, what the message must name)``."""


@pytest.mark.parametrize(("env_class", "kwargs", "name"), BAD_ARGUMENTS,
                         ids=[f"{cls.__name__}-{next(iter(kw))}" for cls, kw, _ in BAD_ARGUMENTS])
def test_a_bad_constructor_argument_is_refused_naming_it(env_class, kwargs, name):
    with pytest.raises(ValueError, match=name):
        env_class(**kwargs)
