"""The spread policy: contract, determinism, dead reckoning, an even spread, bad arguments."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import lfmdr_gym  # noqa: F401 - registers the env ids
from lfmdr_gym import POLICIES, collect
from lfmdr_gym.exploration.contract import check_policy
from lfmdr_gym.exploration.spread import SpreadPolicy


def test_spread_meets_the_policy_contract_and_is_deterministic():
    env = gym.make("LFMDR-Visibility-v0", max_episode_steps=200)
    policy = POLICIES["spread"](env, seed=0)
    assert isinstance(policy, SpreadPolicy)
    check_policy(policy, env, n_steps=40, seed=5)
    a = collect(env, POLICIES["spread"](env, seed=1), 120, seed=7)
    b = collect(env, POLICIES["spread"](env, seed=2), 120, seed=7)  # collect reseeds the policy
    np.testing.assert_array_equal(a.robot_poses, b.robot_poses)
    env.close()


def test_spread_dead_reckons_its_viewpoints():
    env = gym.make("LFMDR-Visibility-v0", max_episode_steps=60)
    _, info = env.reset(seed=4)
    x0, y0, h0 = info["robot_pose"]  # the origin of the policy's frame (collect resets alike)
    policy = SpreadPolicy.for_env(env, seed=0)
    history = collect(env, policy, 50, seed=4)
    odo = policy.viewpoints  # one per observation: the start, then after each move but the last
    assert odo.shape == (50, 2)
    np.testing.assert_array_equal(odo[0], [0.0, 0.0])
    c, s = np.cos(h0), np.sin(h0)
    world = odo @ np.array([[c, s], [-s, c]]) + [x0, y0]
    err = np.hypot(*(world[1:] - history.robot_poses[:-1, :2]).T)
    assert np.median(err) < 0.05
    env.close()


def _crowding(poses: np.ndarray, sigma: float = 0.13) -> float:
    """Mean kernel density of the other viewpoints at each viewpoint (lower: more evenly spread)."""
    d2 = ((poses[:, None, :2] - poses[None, :, :2]) ** 2).sum(axis=-1)
    return float((np.exp(-d2 / (2.0 * sigma * sigma)).sum(axis=1) - 1.0).mean())


def test_spread_crowds_its_viewpoints_less_than_the_random_walk():
    # measured at the true poses: 0.77-0.85 of the random walk's crowding on these layouts
    env = gym.make("LFMDR-Visibility-v0", max_episode_steps=300)
    for seed in (11, 12, 13):
        spread = collect(env, POLICIES["spread"](env), 300, seed=seed).robot_poses
        walk = collect(env, POLICIES["random-walk"](env), 300, seed=seed).robot_poses
        assert _crowding(spread) < 0.9 * _crowding(walk)
    env.close()


@pytest.mark.parametrize("kwargs, name", [
    ({"sigma": 0.0}, "sigma"), ({"sigma": float("nan")}, "sigma"), ({"fan": 1}, "fan"),
    ({"fan": 2.5}, "fan"), ({"discount": 0.0}, "discount"), ({"discount": 1.5}, "discount"),
    ({"pull": -1.0}, "pull"), ({"hole_radius": -0.1}, "hole_radius"),
    ({"free_cell": 0}, "free_cell"), ({"escape_moves": -1}, "escape_moves"),
    ({"correct_drift": False}, "correct_drift"), ({"cell": -1.0}, "cell"),
    ({"sigma": True}, "sigma"), ({"pull": True}, "pull"), ({"fan": True}, "fan"),
])
def test_spread_refuses_bad_arguments(kwargs, name):
    with pytest.raises(ValueError, match=name):
        SpreadPolicy(**kwargs)


def test_spread_refuses_bad_observations():
    policy = SpreadPolicy(seed=0)
    with pytest.raises(ValueError, match="one observation at a time"):
        policy({"proximity": np.ones((3, 32))})
    with pytest.raises(ValueError, match="proximity"):
        policy(np.ones(32))
