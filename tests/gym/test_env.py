"""The Gymnasium environments: API conformance, determinism, physics, sensors, rendering, vectors."""

from __future__ import annotations

import importlib
import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.utils.passive_env_checker import env_render_passive_checker

import lfmdr_gym
from lfmdr_gym.env import LFMDREnv
from lfmdr_gym.sim import sensors

ENV_IDS = sorted(i for i in gym.registry if i.startswith("LFMDR-") and i not in lfmdr_gym.ENV_IDS_3D)
SENSOR_OF = {"LFMDR-Visibility-v0": "visibility", "LFMDR-Bearing-v0": "bearing", "LFMDR-Range-v0": "range",
             "LFMDR-RangeBearing-v0": "range-bearing", "LFMDR-VisibilityBearing-v0": "visibility-bearing",
             "LFMDR-Camera-v0": "range-bearing"}
KEYS_OF = {"visibility": {"visibility"}, "bearing": {"bearing"}, "range": {"range"},
           "range-bearing": {"range", "bearing"}, "visibility-bearing": {"visibility", "bearing"}}


def test_ids_registered_once():
    assert ENV_IDS == sorted(SENSOR_OF)
    before = len(gym.registry)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # re-registering would warn
        importlib.reload(lfmdr_gym)
    assert len(gym.registry) == before
    for env_id in ENV_IDS:
        assert gym.spec(env_id).max_episode_steps == 2000


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env_without_warnings(env_id):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id)
        check_env(env.unwrapped, skip_render_check=True)  # "human" needs a display: tested below
        env.close()
        env = gym.make(env_id, render_mode="rgb_array")
        env.reset(seed=0)
        env_render_passive_checker(env.unwrapped)
        env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env_with_default_arguments(env_id):
    """A newcomer's first check: gymnasium's checker with its defaults, render check included
    ("human" is listed only where pygame and a display make it work)."""
    from lfmdr_gym.render import human_rendering_error

    env = gym.make(env_id)
    listed = list(env.unwrapped.metadata["render_modes"])  # what check_env renders
    assert ("human" in listed) == (human_rendering_error() is None)
    check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_spaces_dtypes_and_info(env_id):
    env = gym.make(env_id)
    obs, info = env.reset(seed=3)
    observed = {"observed"} if env_id == "LFMDR-Camera-v0" else set()  # a preset with limits
    assert set(obs) == KEYS_OF[SENSOR_OF[env_id]] | {"proximity"} | observed
    for _ in range(50):
        assert obs in env.observation_space
        for k, v in obs.items():
            assert v.dtype == env.observation_space[k].dtype
        assert info["robot_pose"].shape == (3,) and info["robot_pose"].dtype == np.float64
        assert -math.pi < info["robot_pose"][2] <= math.pi
        assert info["object_positions"].shape == (50, 2)
        assert info["anchor_ids"].shape == (4,) and info["anchor_ids"].dtype == np.int64
        np.testing.assert_array_equal(info["anchor_positions"], info["object_positions"][info["anchor_ids"]])
        assert isinstance(info["blocked"], bool)
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert reward == 0.0 and terminated is False and truncated is False
    assert env.action_space == gym.spaces.Box(-math.pi / 4, math.pi / 4, (1,), np.float32)


def test_info_arrays_are_fresh_every_step():
    env = LFMDREnv()
    _, a = env.reset(seed=0)
    _, _, _, _, b = env.step(np.zeros(1, np.float32))
    for key in ("robot_pose", "object_positions", "anchor_ids", "anchor_positions"):
        assert a[key] is not b[key]
    b["object_positions"][:] = 99.0
    _, _, _, _, c = env.step(np.zeros(1, np.float32))
    assert np.abs(c["object_positions"]).max() < 1.25


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_same_seed_same_actions_bit_identical(env_id):
    def rollout(seed):
        env = gym.make(env_id)
        rng = np.random.default_rng(123)
        obs, info = env.reset(seed=seed)
        out = [obs[k].tobytes() for k in sorted(obs)] + [info["robot_pose"].tobytes()]
        for _ in range(300):
            obs, _, _, _, info = env.step(rng.uniform(-1, 1, 1).astype(np.float32))
            out += [obs[k].tobytes() for k in sorted(obs)] + [info["robot_pose"].tobytes()]
        return out

    assert rollout(7) == rollout(7)
    assert rollout(7) != rollout(8)


def test_reset_without_seed_continues_the_stream_and_rebuilds_the_world():
    env = LFMDREnv()
    _, a = env.reset(seed=1)
    _, b = env.reset()
    assert not np.array_equal(a["object_positions"], b["object_positions"])
    _, c = env.reset(seed=1)
    np.testing.assert_array_equal(a["object_positions"], c["object_positions"])
    np.testing.assert_array_equal(a["robot_pose"], c["robot_pose"])


@pytest.mark.parametrize("sensor", ["visibility", "bearing", "range"])
def test_observation_is_the_sensor_function_of_the_true_pose(sensor):
    env = LFMDREnv(sensor, max_range=0.8 if sensor == "range" else None)
    obs, info = env.reset(seed=4)
    rng = np.random.default_rng(0)
    for _ in range(200):
        pose, objects = info["robot_pose"], info["object_positions"]
        if sensor == "visibility":
            expect = sensors.visibility(pose, objects, 0.024, math.radians(5.0), True)
        elif sensor == "bearing":
            expect = sensors.bearing(pose, objects).astype(np.float32)
        else:
            expect = sensors.ranges(pose, objects, 0.8).astype(np.float32)
        np.testing.assert_array_equal(obs[sensor], expect)
        np.testing.assert_allclose(
            obs["proximity"], sensors.proximity(pose, objects, 0.024, 1.25, env.n_proximity_rays, 0.5), rtol=1e-6
        )
        obs, _, _, _, info = env.step(rng.uniform(-0.8, 0.8, 1).astype(np.float32))
    if sensor == "range":
        assert (obs["range"] == 0).any() and (obs["range"] > 0).any()


def reach_clearances(poses, objects):
    d = np.hypot(*(poses[:, None, :2] - objects[None]).transpose(2, 0, 1))
    return d.min(), (1.25 - np.abs(poses[:, :2])).min()


@pytest.mark.parametrize(
    "policy",
    ["hard_left", "hard_right", "straight", "random"],
)
def test_never_passes_through_objects_or_walls(policy):
    env = LFMDREnv()
    rng = np.random.default_rng(0)
    n_blocked = 0
    for seed in range(3):
        obs, info = env.reset(seed=seed)
        objects = info["object_positions"]
        poses = []
        for _ in range(1500):
            if policy == "hard_left":
                action = np.array([math.pi / 4], np.float32)
            elif policy == "hard_right":
                action = np.array([-math.pi / 4], np.float32)
            elif policy == "straight":
                action = np.zeros(1, np.float32)
            else:
                action = rng.uniform(-math.pi / 4, math.pi / 4, 1).astype(np.float32)
            obs, _, _, _, info = env.step(action)
            poses.append(info["robot_pose"])
            n_blocked += info["blocked"]
        poses = np.array(poses)
        obj_gap, wall_gap = reach_clearances(poses, objects)
        assert obj_gap >= 0.024 + 0.05 - 1e-9
        assert wall_gap >= 0.05 - 1e-9
        steps = np.hypot(*np.diff(poses[:, :2], axis=0).T)
        assert steps.max() <= 0.2 + 1e-12
    assert n_blocked > 0  # the policies did run into things


def test_user_layout_through_reset_options():
    grid = np.array([[x, y] for x in (-0.9, -0.3, 0.3, 0.9) for y in (-0.9, 0.0, 0.9)])
    env = LFMDREnv(n_objects=12)
    obs, info = env.reset(
        seed=0, options={"object_positions": grid, "anchor_ids": [0, 2, 9], "robot_pose": [0.0, -0.45, 0.0]}
    )
    np.testing.assert_array_equal(info["object_positions"], grid)
    np.testing.assert_array_equal(info["anchor_ids"], [0, 2, 9])
    np.testing.assert_array_equal(info["anchor_positions"], grid[[0, 2, 9]])
    np.testing.assert_array_equal(info["robot_pose"], [0.0, -0.45, 0.0])
    obs, _, _, _, info = env.step(np.zeros(1, np.float32))
    np.testing.assert_allclose(info["robot_pose"], [0.2, -0.45, 0.0])
    with pytest.raises(ValueError, match="object_positions"):
        env.reset(options={"object_positions": grid[:5]})


def test_actions_are_clipped_and_nan_refused():
    env = LFMDREnv()
    _, info = env.reset(seed=0)
    h0 = info["robot_pose"][2]
    _, _, _, _, info = env.step(np.array([10.0], np.float32))
    assert math.isclose(math.remainder(info["robot_pose"][2] - h0, 2 * math.pi), math.pi / 4, abs_tol=1e-6)
    with pytest.raises(ValueError, match="action"):
        env.step(np.array([np.nan], np.float32))


def test_truncation_after_2000_steps():
    env = gym.make("LFMDR-Bearing-v0")
    env.reset(seed=0)
    action = np.zeros(1, np.float32)
    for i in range(2000):
        _, _, terminated, truncated, _ = env.step(action)
        assert not terminated
        assert truncated == (i == 1999)


def test_large_arena_same_density():
    env = LFMDREnv(n_objects=500, arena_size=2.5 * math.sqrt(10.0))
    obs, info = env.reset(seed=0)
    assert obs["visibility"].shape == (500,)
    visible = [obs["visibility"].sum()]
    for _ in range(100):
        obs, *_ = env.step(env.action_space.sample())
        visible.append(obs["visibility"].sum())
    assert 0 < np.mean(visible) < 50


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_render_rgb_array(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (480, 480, 3) and frame.dtype == np.uint8
    colours = {tuple(c) for c in frame.reshape(-1, 3)}
    from lfmdr_gym import render

    assert {render.ANCHOR, render.ROBOT, render.WALL, render.PROXIMITY_RAY} <= colours
    env.step(env.action_space.sample())
    assert not np.array_equal(env.render(), frame)


def test_render_human_needs_pygame_and_a_display():
    from lfmdr_gym.render import human_rendering_error

    err = human_rendering_error()
    if err is None:
        pytest.skip("pygame and a display are available here")
    with pytest.raises(type(err), match=r"lfmdr\[human\]"):
        LFMDREnv(render_mode="human")


def test_render_without_mode_warns_and_returns_none():
    env = LFMDREnv()
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_vector_envs(mode):
    envs = gym.make_vec("LFMDR-Visibility-v0", num_envs=2, vectorization_mode=mode)
    try:
        obs, info = envs.reset(seed=[0, 1])
        assert obs["visibility"].shape == (2, 50) and obs["proximity"].shape == (2, 32)
        assert info["robot_pose"].shape == (2, 3)
        for _ in range(5):
            obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
        assert obs["visibility"].dtype == np.int8
        assert reward.shape == (2,)
        assert not np.array_equal(info["object_positions"][0], info["object_positions"][1])
    finally:
        envs.close()


def test_step_and_render_before_reset_ask_for_a_reset():
    env = LFMDREnv(render_mode="rgb_array")
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(1, np.float32))
    with pytest.raises(gym.error.ResetNeeded):
        env.render()
