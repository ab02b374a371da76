"""The mapping reward wrapper, the agent's view, the shipped RL policy and its training example."""

from __future__ import annotations

import importlib.util
import math
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from paths import ROOT

import lfmdr_gym
from lfmdr_gym import POLICIES, collect
from lfmdr_gym.exploration.agent_view import AgentView, ViewConfig
from lfmdr_gym.exploration.rl import MLPExplorationPolicy, load_mlp, mlp_forward
from lfmdr_gym.wrappers import MappingRewardWrapper


def _load_example():
    spec = importlib.util.spec_from_file_location("train_rl_policy",
                                                  ROOT / "examples" / "train_rl_policy.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("reward", ["odometry", "pose"])
@pytest.mark.parametrize("env_id", list(lfmdr_gym.ENV_IDS))
def test_reward_wrapper_passes_check_env(env_id, reward):
    env = MappingRewardWrapper(gym.make(env_id, max_episode_steps=50), reward=reward)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # check_env's note that a wrapper is not the raw env: the wrapper is what is checked
        warnings.filterwarnings("ignore", message=".*different from the unwrapped")
        check_env(env, skip_render_check=True)
    env.close()


def test_reward_wrapper_refuses_an_unknown_reward():
    with pytest.raises(ValueError, match="reward"):
        MappingRewardWrapper(gym.make("LFMDR-Visibility-v0"), reward="map-error")


@pytest.mark.parametrize("reward", ["odometry", "pose"])
def test_coverage_reward_falls_as_the_robot_circles(reward):
    """Turning at max_turn in an empty arena the robot circles the same few cells: each lap
    earns less than the one before (1/sqrt(1 + n) with n the earlier visits)."""
    env = MappingRewardWrapper(gym.make("LFMDR-Bearing-v0", n_objects=4, max_episode_steps=100),
                               reward=reward)
    corners = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    env.reset(seed=1, options={"object_positions": corners, "anchor_ids": np.arange(4),
                               "robot_pose": np.zeros(3)})
    rewards = np.array([env.step(np.array([1.0], np.float32))[1] for _ in range(32)])
    laps = rewards.reshape(4, 8).sum(axis=1)
    assert np.all(np.diff(laps) < 0) and laps[0] > 6.0 and laps[-1] < 4.0


def test_observation_holds_no_ground_truth():
    """Two layouts seen from the same start pose with the same free surroundings look alike:
    the features read only the proximity ring, the visit memory and presence counts."""
    env = MappingRewardWrapper(gym.make("LFMDR-Visibility-v0", max_episode_steps=20))
    obs, info = env.reset(seed=3)
    config = env.view.config
    assert obs.shape == (config.n_features,) and obs.dtype == np.float32
    prox = obs[:config.n_rays]
    raw = env.unwrapped._last_obs["proximity"]
    np.testing.assert_allclose(prox, np.minimum(raw / config.proximity_range, 1.0), rtol=1e-6)
    odo = obs[config.n_rays + 24:config.n_rays + 28]
    np.testing.assert_allclose(odo, [0.0, 0.0, 1.0, 0.0])  # the start is its own origin
    pose = info["robot_pose"]
    obs2, *_ = env.step(np.array([0.0], np.float32))
    moved = np.hypot(*(env.unwrapped.world.pose[:2] - pose[:2]))
    assert obs2[config.n_rays + 24] * config.extent == pytest.approx(moved, abs=0.02)


def test_agent_view_dead_reckons_and_refuses_bad_input():
    env = gym.make("LFMDR-Visibility-v0", max_episode_steps=200)
    view = AgentView(ViewConfig.for_env(env))
    obs, info = env.reset(seed=5)
    view.reset(obs)
    start = info["robot_pose"]
    rng = np.random.default_rng(0)
    for _ in range(25):
        turn = view.turn_for(rng.uniform(-1, 1))
        obs, _, _, _, info = env.step(np.array([turn], np.float32))
        view.step(turn, obs)
    c, s = math.cos(start[2]), math.sin(start[2])
    x, y, _ = view.odometry
    est = start[:2] + [c * x - s * y, s * x + c * y]
    assert np.hypot(*(est - info["robot_pose"][:2])) < 0.1
    assert view.visits.sum() == 26
    with pytest.raises(ValueError, match="proximity"):
        view.step(0.0, {"visibility": np.zeros(50)})
    with pytest.raises(ValueError, match="shape"):
        view.step(0.0, {"proximity": np.ones((2, 32))})
    with pytest.raises(ValueError, match="finite"):
        view.turn_for(np.nan)
    with pytest.raises(ValueError, match="n_rays"):
        ViewConfig(n_rays=0)
    with pytest.raises(RuntimeError, match="reset"):
        AgentView(ViewConfig()).turn_for(0.0)
    env.close()


def test_the_shield_keeps_the_robot_off_obstacles():
    """Whatever the network wishes, the shielded turns are blocked no more often than the
    random walk's (about 9 % of its moves)."""
    env = MappingRewardWrapper(gym.make("LFMDR-Visibility-v0", max_episode_steps=400))
    env.reset(seed=7)
    blocked = sum(env.step(np.array([1.0], np.float32))[4]["blocked"] for _ in range(400))
    assert blocked / 400 < 0.1


@pytest.mark.parametrize("env_id", list(lfmdr_gym.ENV_IDS))
def test_rl_policy_is_registered_and_deterministic(env_id):
    env = gym.make(env_id, max_episode_steps=120)
    policy = POLICIES["rl"](env, seed=0)
    assert isinstance(policy, MLPExplorationPolicy)
    a = collect(env, policy, 100, seed=11)
    b = collect(env, policy, 100, seed=11)
    np.testing.assert_array_equal(a.robot_poses, b.robot_poses)
    assert a.meta["blocked_moves"] < 15
    env.close()


def test_rl_policy_gets_out_of_a_pocket():
    """Layout seed 3 (bearing) wedges the robot between the wall and a cylinder: the network
    alone repeated blocked moves (453 of 500 blocked); with the random walk taking over after
    STUCK_STEPS observations in contact, about as few are blocked as for the random walk."""
    env = gym.make("LFMDR-Bearing-v0")
    history = collect(env, POLICIES["rl"](env), 500, seed=3)
    walk = collect(env, POLICIES["random-walk"](env), 500, seed=3)
    assert history.meta["blocked_moves"] < max(2 * walk.meta["blocked_moves"], 60)
    env.close()


def test_rl_policy_refuses_a_mismatched_env_and_bad_files(tmp_path):
    env = gym.make("LFMDR-Visibility-v0", n_proximity_rays=16)
    with pytest.raises(ValueError, match="n_rays"):
        POLICIES["rl"](env)
    with pytest.raises(FileNotFoundError, match="train"):
        MLPExplorationPolicy.for_env(gym.make("LFMDR-Visibility-v0"), tmp_path / "none.npz")
    bad = tmp_path / "bad.npz"
    np.savez(bad, weight_0=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="config"):
        load_mlp(bad)


def test_mlp_forward_is_tanh_layers_and_a_clipped_linear_output():
    w0, b0 = np.array([[1.0, 0.0], [0.0, 2.0]]), np.array([0.0, 1.0])
    w1, b1 = np.array([[1.0, -1.0]]), np.array([0.5])
    x = np.array([0.3, -0.2])
    expected = np.clip(np.tanh(w0 @ x + b0) @ w1.T + b1, -1, 1)
    np.testing.assert_allclose(mlp_forward([(w0, b0), (w1, b1)], x), expected)
    assert mlp_forward([(w0, b0), (10 * w1, b1)], np.array([3.0, -3.0]))[0] == 1.0


def test_training_example_trains_and_exports_what_sb3_predicts(tmp_path):
    pytest.importorskip("stable_baselines3")
    example = _load_example()
    cfg = example.TrainConfig(timesteps=256, n_envs=2, episode_steps=64, n_steps=64,
                              batch_size=64)
    model, path, diff = example.train(cfg, tmp_path / "m.npz")
    assert diff < 1e-5
    # the exported file drives the registered policy's numpy forward pass on fresh observations
    env = MappingRewardWrapper(gym.make("LFMDR-Bearing-v0", max_episode_steps=64))
    layers, config = load_mlp(path)
    assert config["n_rays"] == 32
    obs, _ = env.reset(seed=2)
    batch = [obs]
    for _ in range(20):
        obs, *_ = env.step(env.action_space.sample())
        batch.append(obs)
    batch = np.array(batch)
    sb3, _ = model.predict(batch, deterministic=True)
    np.testing.assert_allclose(mlp_forward(layers, batch), sb3, atol=1e-5)
    policy = MLPExplorationPolicy.for_env(gym.make("LFMDR-Bearing-v0"), path)
    assert collect("LFMDR-Bearing-v0", policy, 30, seed=1).n_steps == 30


def test_shipped_model_matches_sb3_when_loaded_into_a_fresh_agent():
    """The shipped weights put back into an SB3 PPO actor predict what numpy computes."""
    pytest.importorskip("stable_baselines3")
    import torch
    from stable_baselines3 import PPO

    env = MappingRewardWrapper(gym.make("LFMDR-Visibility-v0", max_episode_steps=64))
    layers, _ = load_mlp()
    hidden = [w.shape[0] for w, _ in layers[:-1]]
    model = PPO("MlpPolicy", env, device="cpu", seed=0, n_steps=64, batch_size=64,
                policy_kwargs={"net_arch": {"pi": hidden, "vf": hidden},
                               "activation_fn": torch.nn.Tanh})
    linears = [m for m in model.policy.mlp_extractor.policy_net if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        for lin, (w, b) in zip([*linears, model.policy.action_net], layers, strict=True):
            lin.weight.copy_(torch.as_tensor(w))
            lin.bias.copy_(torch.as_tensor(b))
    obs, _ = env.reset(seed=4)
    batch = [obs]
    for _ in range(30):
        obs, *_ = env.step(env.action_space.sample())
        batch.append(obs)
    sb3, _ = model.predict(np.array(batch), deterministic=True)
    np.testing.assert_allclose(mlp_forward(layers, np.array(batch)), sb3, atol=1e-5)


@pytest.mark.slow
def test_full_training_run(tmp_path):
    pytest.importorskip("stable_baselines3")
    example = _load_example()
    assert example.main(["--out", str(tmp_path / "full.npz")]) == 0
    assert (tmp_path / "full.npz").stat().st_size < 100_000


def _ring(pose, objects, n_rays=32, max_range=0.5):
    from lfmdr_gym.sim.sensors import proximity

    return proximity(pose, objects, 0.024, 1.25, n_rays, max_range)


def test_scan_match_recovers_the_advance_of_a_move():
    """Random scenes (12 objects in view, random heading, turn and advance): the matched advance
    is within a few millimetres on average (dead reckoning's error on a stopped move is up to
    the whole 0.2 m step)."""
    from lfmdr_gym.exploration.scan_match import matched_advance

    errors = []
    for seed in range(30):
        rng = np.random.default_rng(seed)
        objects = rng.uniform(-0.6, 0.6, (12, 2)) + [0.7, 0.7]
        start = np.array([0.6, 0.55, rng.uniform(-3, 3)])
        turn, advance = rng.uniform(-0.7, 0.7), rng.uniform(0.0, 0.2)
        heading = start[2] + turn
        end = np.array([start[0] + advance * math.cos(heading),
                        start[1] + advance * math.sin(heading), heading])
        keep = (np.hypot(*(objects - start[:2]).T) > 0.1) & (np.hypot(*(objects - end[:2]).T) > 0.1)
        found = matched_advance(_ring(start, objects[keep]), _ring(end, objects[keep]), turn,
                                0.2, 0.5)
        if found is not None:
            errors.append(abs(found - advance))
    assert len(errors) >= 15
    assert np.mean(errors) < 0.008 and np.max(errors) < 0.03


def test_scan_match_needs_something_in_view_and_contact_reads_the_ring():
    from lfmdr_gym.exploration.scan_match import contact, matched_advance

    empty = np.full(32, 0.5)
    assert matched_advance(empty, empty, 0.0, 0.2, 0.5) is None
    ring = empty.copy()
    ring[3] = 0.0505
    assert contact(ring, 0.05) and not contact(empty, 0.05)


def test_coverage_scan_drifts_less_than_plain_dead_reckoning():
    """Over 300 steps the corrected odometry ends nearer the true pose (4 layouts)."""
    from lfmdr_gym.exploration.coverage import CoveragePolicy

    errors = {False: [], True: []}
    for correct in (False, True):
        for seed in range(4):
            env = gym.make("LFMDR-Visibility-v0", max_episode_steps=300)
            policy = CoveragePolicy.for_env(env, seed=seed, correct_drift=correct)
            obs, info = env.reset(seed=30 + seed)
            start = info["robot_pose"]
            policy.reset(seed)
            for _ in range(300):
                obs, _, _, _, info = env.step(policy(obs))
            # (odometry includes the last move as foreseen: corrected only at the next call)
            c, s = math.cos(start[2]), math.sin(start[2])
            x, y, _ = policy.odometry
            est = start[:2] + [c * x - s * y, s * x + c * y]
            errors[correct].append(np.hypot(*(est - info["robot_pose"][:2])))
            env.close()
    assert np.mean(errors[True]) < 0.5 * np.mean(errors[False])
    with pytest.raises(ValueError, match="correct_drift"):
        CoveragePolicy(correct_drift="yes")
