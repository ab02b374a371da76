"""Exploration policies: the registry, the contract every policy meets, the coverage policy."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import lfmdr_gym
from lfmdr_gym import POLICIES, collect
from lfmdr_gym.cli import main
from lfmdr_gym.exploration.contract import check_policy
from lfmdr_gym.exploration.coverage import CoveragePolicy

GEOMETRY = {"max_turn", "step_length", "world", "robot_radius", "object_radius", "unwrapped",
            "observation_space", "action_space", "single_action_space",
            "arena_size"}  # the room's size: configuration, as the step length is


class GroundTruthRead(Exception):
    """Raised when a policy factory reads anything of the env but its geometry and spaces."""


class GeometryOnly:
    """Stands for an env (and its world) to a policy factory: the geometry and the spaces are
    readable; anything else (poses, layout, info, the env's methods) raises GroundTruthRead."""

    def __init__(self, env, part=None):
        object.__setattr__(self, "_env", env)
        object.__setattr__(self, "_part", part if part is not None else env.unwrapped)

    def __getattr__(self, name):
        if name not in GEOMETRY:
            if name in ("get_attr", "spec") or name.startswith("__"):
                raise AttributeError(name)  # a probe that for_env makes with hasattr/getattr
            raise GroundTruthRead(name)
        if name == "unwrapped":
            return self
        if name in ("observation_space", "action_space", "single_action_space"):
            return getattr(self._env, name)
        value = getattr(self._part, name)
        return GeometryOnly(self._env, value) if name == "world" else value


def _holds(obj, kinds, depth=2) -> bool:
    if isinstance(obj, kinds):
        return True
    if depth == 0:
        return False
    values = list(vars(obj).values()) if hasattr(obj, "__dict__") else []
    if isinstance(obj, dict):
        values = list(obj.values())
    elif isinstance(obj, list | tuple):
        values = list(obj)
    return any(_holds(v, kinds, depth - 1) for v in values)


@pytest.mark.parametrize("name", list(POLICIES))
@pytest.mark.parametrize("env_id", list(lfmdr_gym.ENV_IDS))
def test_every_policy_sees_observations_only(name, env_id):
    env = gym.make(env_id, max_episode_steps=60)
    policy = POLICIES[name](GeometryOnly(env), seed=1)
    assert not _holds(policy, (gym.Env, GeometryOnly, lfmdr_gym.env.World))
    # 20 steps each (the even policy costs ~35 ms of CPU a step; 30 and 40 took 1.6x as long)
    check_policy(policy, env, n_steps=20, seed=2)
    history = collect(env, policy, 20, seed=3)
    assert history.n_objects == env.unwrapped.world.n_objects
    env.close()


def test_check_policy_catches_a_policy_that_breaks_the_contract():
    env = gym.make("LFMDR-Visibility-v0", max_episode_steps=30)
    rng = np.random.default_rng()
    with pytest.raises(AssertionError, match="same seed"):
        check_policy(lambda obs: rng.uniform(-0.5, 0.5, 1), env, n_steps=5)
    with pytest.raises(AssertionError, match="outside"):
        check_policy(lambda obs: np.array([3.0]), env, n_steps=5)
    env.close()


@pytest.mark.parametrize("name", list(POLICIES))
def test_every_registered_entry_point_names_a_policy_class(name):
    spec = POLICIES[name]
    assert spec.name == name
    module, _, attr = spec.entry_point.partition(":")
    assert module.startswith("lfmdr_gym.exploration.") and attr
    assert callable(spec.load().for_env)


def test_registered_keywords_are_defaults_a_caller_overrides():
    env = gym.make("LFMDR-Visibility-v0")
    assert POLICIES["coverage-scan"](env).correct_drift is True
    assert POLICIES["coverage-scan"](env, correct_drift=False).correct_drift is False
    assert POLICIES["coverage"](env).correct_drift is False
    env.close()


def test_the_registry_imports_a_policy_only_when_it_is_asked_for():
    # A fresh interpreter: ``import lfmdr_gym`` loads the random walk but none of the other
    # policies; asking the registry for one imports its module then.
    code = (
        "import sys\n"
        "import lfmdr_gym\n"
        "others = ['coverage', 'spread', 'even', 'rl', 'agent_view']\n"
        "loaded = [m for m in others if 'lfmdr_gym.exploration.' + m in sys.modules]\n"
        "assert not loaded, loaded\n"
        "assert lfmdr_gym.POLICIES['even'].load().__name__ == 'EvenPolicy'\n"
        "assert 'lfmdr_gym.exploration.even' in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_coverage_dead_reckons_its_moves_and_counts_visits():
    env = gym.make("LFMDR-Bearing-v0", max_episode_steps=40)
    policy = CoveragePolicy.for_env(env, seed=0)
    log = []

    class Logged(CoveragePolicy):
        def __call__(self, obs):
            action = super().__call__(obs)
            log.append(self.odometry.copy())
            return action

    policy.__class__ = Logged
    history = collect(env, policy, 30, seed=4)
    odo, true = np.array(log), history.robot_poses
    c, s = np.cos(true[0, 2] - odo[0, 2]), np.sin(true[0, 2] - odo[0, 2])
    world = (odo[:, :2] - odo[0, :2]) @ np.array([[c, s], [-s, c]]) + true[0, :2]
    assert np.median(np.hypot(*(world - true[:, :2]).T)) < 0.05
    assert policy.visits.sum() == 30 and (policy.visits > 0).sum() >= 8
    env.close()


@pytest.mark.parametrize("kwargs, name", [({"cell": 0.0}, "cell"), ({"extent": -1.0}, "extent"),
                                          ({"cell": 1.0, "extent": 0.5}, "extent"),
                                          ({"cell": True}, "cell")])
def test_coverage_refuses_bad_arguments(kwargs, name):
    with pytest.raises(ValueError, match=name):
        CoveragePolicy(**kwargs)


def test_coverage_refuses_batched_observations():
    with pytest.raises(ValueError, match="one observation at a time"):
        CoveragePolicy(seed=0)({"proximity": np.ones((3, 32))})


def test_collect_with_a_policy(tmp_path, capsys):
    path = tmp_path / "h.npz"
    assert main(["collect", "--steps", "60", "--seed", "3", "--policy", "coverage",
                 "--out", str(path)]) == 0
    assert path.exists()
    assert main(["collect", "--steps", "60", "--policy", "no-such", "--out", str(path)]) != 0
    assert "no-such" in capsys.readouterr().err
