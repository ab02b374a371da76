"""Imperfect sensing in the world: field of view, range, noise, dropouts, occlusion, ``observed``."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from paths import EXAMPLES

import lfmdr_gym  # noqa: F401  (registers the ids)
from lfmdr_gym.env import LFMDREnv
from lfmdr_gym.histories import recording
from lfmdr_gym.sim import sensors

EVERY_LIMIT = {
    "visibility": dict(fov_deg=90.0, max_range=0.45, miss_rate=0.2, false_rate=0.05),
    "bearing": dict(fov_deg=90.0, max_range=1.5, bearing_noise_deg=2.0, line_of_sight=True),
    "range": dict(fov_deg=90.0, max_range=1.5, range_noise=0.01, line_of_sight=True),
}


def _actions(n, seed=0):
    return np.random.default_rng(seed).uniform(-0.7, 0.7, (n, 1)).astype(np.float32)


def _rollout(env, n, seed=3):
    """Observations and infos of the reset and ``n`` moves."""
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    for a in _actions(n):
        obs, _, _, _, info = env.step(a)
        out.append((obs, info))
    return out


def _brute_in_view(pose, objects, fov_deg, max_range):
    """Object by object, in plain math: centre within fov/2 of the heading and within range."""
    x, y, h = pose
    out = []
    for ox, oy in objects:
        theta = math.atan2(oy - y, ox - x) - h
        theta = math.atan2(math.sin(theta), math.cos(theta))  # wrapped into (-pi, pi]
        d = math.hypot(ox - x, oy - y)
        out.append(abs(theta) <= math.radians(fov_deg) / 2 and (max_range is None or d <= max_range))
    return np.array(out)


def _brute_clear(pose, objects, r):
    """Whether the segment robot -> object j keeps at least r from every other object's centre
    (pair by pair, in plain float arithmetic)."""
    px, py = float(pose[0]), float(pose[1])
    points = [(float(x), float(y)) for x, y in objects]
    out = []
    for j, (jx, jy) in enumerate(points):
        sx, sy = jx - px, jy - py
        clear = True
        for k, (kx, ky) in enumerate(points):
            if k == j:
                continue
            t = min(max(((kx - px) * sx + (ky - py) * sy) / (sx * sx + sy * sy), 0.0), 1.0)
            dx, dy = px + t * sx - kx, py + t * sy - ky
            if math.sqrt(dx * dx + dy * dy) < r:
                clear = False
                break
        out.append(clear)
    return np.array(out)


def test_off_by_default_and_explicit_defaults_change_nothing():
    plain = _rollout(LFMDREnv("bearing"), 50)
    explicit = _rollout(LFMDREnv("bearing", fov_deg=360, bearing_noise_deg=0.0, line_of_sight=False), 50)
    for (a, _), (b, _) in zip(plain, explicit, strict=True):
        assert "observed" not in a and set(a) == set(b)
        np.testing.assert_array_equal(a["bearing"], b["bearing"])


@pytest.mark.parametrize("sensor", ["visibility", "bearing", "range"])
@pytest.mark.parametrize(("fov", "max_range"), [(90.0, None), (60.0, 1.0), (360.0, 0.8)])
def test_field_of_view_and_range_against_brute_force(sensor, fov, max_range):
    env = LFMDREnv(sensor, fov_deg=fov, max_range=max_range)
    assert env.observation_space["observed"] == gym.spaces.MultiBinary(50)
    counts = []
    for obs, info in _rollout(env, 150):
        pose, objects = info["robot_pose"], info["object_positions"]
        expect = _brute_in_view(pose, objects, fov, max_range)
        np.testing.assert_array_equal(obs["observed"], expect.astype(np.int8))
        if sensor == "visibility":
            perfect = sensors.visibility(pose, objects, 0.024, math.radians(5.0), True)
        elif sensor == "bearing":
            perfect = sensors.bearing(pose, objects).astype(np.float32)
        else:
            perfect = sensors.ranges(pose, objects, max_range).astype(np.float32)
        np.testing.assert_array_equal(obs[sensor][expect], perfect[expect])  # no noise: exact
        assert not obs[sensor][~expect].any()  # not observed: 0
        counts.append(expect.sum())
    assert 0 < np.mean(counts) < 50  # the limits bite, and something is seen


@pytest.mark.parametrize(("sensor", "max_range"), [("bearing", None), ("range", None),
                                                   ("bearing", 1.0)])
def test_line_of_sight_against_brute_force(sensor, max_range):
    # a dense layout, so that objects hide each other often
    env = LFMDREnv(sensor, n_objects=120, object_clearance=0.02, line_of_sight=True,
                   max_range=max_range)
    hidden = 0
    for obs, info in _rollout(env, 40):
        pose, objects = info["robot_pose"], info["object_positions"]
        expect = _brute_clear(pose, objects, 0.024) & _brute_in_view(pose, objects, 360.0, max_range)
        np.testing.assert_array_equal(obs["observed"], expect.astype(np.int8))
        hidden += (~expect).sum()
    assert hidden > 0


def _wrapped(a):
    return np.arctan2(np.sin(a), np.cos(a))


def test_bearing_noise_mean_and_spread():
    sigma = 5.0
    noisy, clean = LFMDREnv("bearing", bearing_noise_deg=sigma), LFMDREnv("bearing")
    err = []
    for (a, _), (b, _) in zip(_rollout(noisy, 400), _rollout(clean, 400), strict=True):
        err.append(_wrapped(np.arctan2(a["bearing"][:, 1], a["bearing"][:, 0])
                            - np.arctan2(b["bearing"][:, 1], b["bearing"][:, 0])))
        assert a["observed"].all()  # noise alone hides nothing
    err = np.degrees(np.concatenate(err))
    n = err.size
    assert abs(err.mean()) < 4 * sigma / math.sqrt(n)
    assert err.std() == pytest.approx(sigma, rel=0.03)


def test_range_noise_mean_and_spread():
    sigma = 0.02
    noisy, clean = LFMDREnv("range", range_noise=sigma), LFMDREnv("range")
    err = np.concatenate([a["range"].astype(float) - b["range"].astype(float) for (a, _), (b, _)
                          in zip(_rollout(noisy, 400), _rollout(clean, 400), strict=True)])
    assert abs(err.mean()) < 4 * sigma / math.sqrt(err.size)
    assert err.std() == pytest.approx(sigma, rel=0.03)


def test_miss_and_false_rates():
    noisy = LFMDREnv("visibility", miss_rate=0.3, false_rate=0.02)
    clean = LFMDREnv("visibility")
    truth, seen = [], []
    for (a, _), (b, _) in zip(_rollout(noisy, 1500), _rollout(clean, 1500), strict=True):
        truth.append(b["visibility"])
        seen.append(a["visibility"])
        assert a["observed"].all()
    truth, seen = np.concatenate(truth) == 1, np.concatenate(seen) == 1
    miss = (~seen[truth]).mean()
    false = seen[~truth].mean()
    assert miss == pytest.approx(0.3, abs=4 * math.sqrt(0.3 * 0.7 / truth.sum()))
    assert false == pytest.approx(0.02, abs=4 * math.sqrt(0.02 * 0.98 / (~truth).sum()))


@pytest.mark.parametrize("sensor", ["visibility", "bearing", "range"])
def test_noise_and_dropouts_keep_the_path(sensor):
    plain, limited = LFMDREnv(sensor), LFMDREnv(sensor, **EVERY_LIMIT[sensor])
    for env in (plain, limited):
        env.reset(seed=11)
    for _ in range(2):  # the second episode: reset without a seed continues np_random alike
        a, b = _rollout(plain, 200, seed=None), _rollout(limited, 200, seed=None)
        for (oa, ia), (ob, ib) in zip(a, b, strict=True):
            np.testing.assert_array_equal(ia["robot_pose"], ib["robot_pose"])
            np.testing.assert_array_equal(ia["object_positions"], ib["object_positions"])
            np.testing.assert_array_equal(oa["proximity"], ob["proximity"])


@pytest.mark.parametrize("sensor", ["visibility", "bearing", "range"])
def test_noise_is_seeded(sensor):
    env = LFMDREnv(sensor, **EVERY_LIMIT[sensor])

    def readings(seed):
        return b"".join(o[sensor].tobytes() + o["observed"].tobytes() for o, _ in _rollout(env, 100, seed))

    assert readings(5) == readings(5)
    assert readings(5) != readings(6)


@pytest.mark.parametrize("sensor", ["visibility", "bearing", "range"])
def test_check_env_with_every_limit_on(sensor):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(lfmdr_gym.env_id_for(sensor), **EVERY_LIMIT[sensor])
        check_env(env.unwrapped, skip_render_check=True)
        env.close()


def test_make_with_keywords():
    env = gym.make("LFMDR-Bearing-v0", fov_deg=90, max_range=1.5, bearing_noise_deg=2)
    obs, _ = env.reset(seed=0)
    assert obs["observed"].dtype == np.int8 and 0 < obs["observed"].sum() < 50
    env.close()


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"fov_deg": 0.0}, "fov_deg"),
        ({"fov_deg": 361.0}, "fov_deg"),
        ({"fov_deg": -90.0}, "fov_deg"),
        ({"fov_deg": "wide"}, "fov_deg"),
        ({"max_range": -1.0}, "max_range"),
        ({"sensor": "bearing", "bearing_noise_deg": -1.0}, "bearing_noise_deg"),
        ({"sensor": "bearing", "bearing_noise_deg": math.nan}, "bearing_noise_deg"),
        ({"sensor": "range", "range_noise": -0.1}, "range_noise"),
        ({"miss_rate": 1.0}, "miss_rate"),
        ({"miss_rate": -0.1}, "miss_rate"),
        ({"false_rate": 1.0}, "false_rate"),
        ({"sensor": "bearing", "line_of_sight": "yes"}, "line_of_sight"),
        # a limit of another sensor is refused, not ignored
        ({"sensor": "visibility", "bearing_noise_deg": 2.0}, "bearing_noise_deg"),
        ({"sensor": "bearing", "range_noise": 0.1}, "range_noise"),
        ({"sensor": "range", "miss_rate": 0.1}, "miss_rate"),
        ({"sensor": "bearing", "false_rate": 0.1}, "false_rate"),
        ({"sensor": "visibility", "line_of_sight": True}, "line_of_sight"),
    ],
)
def test_bad_keywords_refused_with_the_name(kwargs, name):
    with pytest.raises(ValueError, match=name):
        LFMDREnv(**kwargs)


# ----------------------------------------------------------------------------- the observed set end to end
def _expected_mask(env_kwargs, sensor, n_steps, seed):
    """The mask a history should carry: the env's "observed" flags after each move, per column."""
    env = LFMDREnv(sensor, **env_kwargs)
    policy = lfmdr_gym.RandomWalkPolicy()
    obs, _ = env.reset(seed=seed)
    policy.reset(seed=recording._policy_seed(seed))
    flags = []
    for _ in range(n_steps):
        obs, *_ = env.step(policy(obs))
        flags.append(obs["observed"].astype(bool))
    return np.repeat(np.array(flags).T, 2 if sensor == "bearing" else 1, axis=1)


@pytest.mark.parametrize("sensor", ["visibility", "bearing", "range"])
def test_collect_puts_observed_into_the_mask(sensor, tmp_path):
    kwargs = EVERY_LIMIT[sensor]
    history = lfmdr_gym.collect(lfmdr_gym.env_id_for(sensor), lfmdr_gym.RandomWalkPolicy(), 120,
                                seed=4, make_kwargs=kwargs)
    assert history.mask is not None and history.mask.shape == history.matrix.shape
    np.testing.assert_array_equal(history.mask, _expected_mask(kwargs, sensor, 120, 4))
    assert not history.matrix[~history.mask].any()  # unobserved entries read 0
    assert 0 < history.mask.mean() < 1
    assert history.meta["env_kwargs"]["fov_deg"] == 90.0  # the settings travel with the history
    loaded = lfmdr_gym.History.load(history.save(tmp_path / "h.npz"))
    np.testing.assert_array_equal(loaded.mask, history.mask)
    np.testing.assert_array_equal(loaded.matrix, history.matrix)
    assert loaded.meta == history.meta


def test_collect_without_limits_has_no_mask():
    history = lfmdr_gym.collect("LFMDR-Bearing-v0", lfmdr_gym.RandomWalkPolicy(), 30, seed=1)
    assert history.mask is None


def _steer(obs):
    """A deterministic, batch-aware policy (turn toward the freer side), as in test_history."""
    prox = np.asarray(obs["proximity"], dtype=np.float32)
    n = prox.shape[-1]
    return (0.7 * np.tanh(4.0 * (prox[..., n // 4] - prox[..., 3 * n // 4]))).astype(np.float32)


@pytest.mark.parametrize("mode", ["NextStep", "SameStep", "Disabled"])
def test_masks_survive_make_vec(mode):
    kwargs, n = EVERY_LIMIT["bearing"], 40
    envs = gym.make_vec("LFMDR-Bearing-v0", num_envs=2, max_episode_steps=n,
                        vector_kwargs={"autoreset_mode": mode}, **kwargs)
    histories = lfmdr_gym.collect_vector(envs, _steer, n, seed=7, n_episodes=2)
    envs.close()
    assert len(histories) == 4
    for i in range(2):  # sub-env i: a seeded episode, then one continuing its random streams
        env = gym.make("LFMDR-Bearing-v0", max_episode_steps=n, **kwargs)
        singles = [lfmdr_gym.collect(env, _steer, n, seed=7 + i), lfmdr_gym.collect(env, _steer, n)]
        for h, single in zip(histories[2 * i: 2 * i + 2], singles, strict=True):
            assert h.mask is not None and 0 < h.mask.mean() < 1
            np.testing.assert_array_equal(h.mask, single.mask)
            np.testing.assert_array_equal(h.matrix, single.matrix)


def test_build_map_maps_a_masked_history_with_the_masked_default():
    from mappers import DEFAULT_METHODS, build_map, mean_position_error

    history = lfmdr_gym.collect("LFMDR-Bearing-v0", lfmdr_gym.RandomWalkPolicy(), 1500, seed=2,
                                make_kwargs=dict(fov_deg=90.0, max_range=1.5, bearing_noise_deg=2.0))
    m = build_map(history, history.anchor_ids, history.anchor_positions)
    assert m.method == DEFAULT_METHODS[("bearing", True)]
    exclude = sorted({*history.anchor_ids.tolist(), *m.unmapped})
    error = mean_position_error(m.positions, history.object_positions, exclude)
    assert len(m.unmapped) < 5 and error < 0.3  # a map, not noise: the arena is 2.5 m wide


def test_limited_camera_example(tmp_path, capsys):
    import runpy

    script = EXAMPLES / "limited_camera.py"
    history = runpy.run_path(str(script))["main"](["--steps", "800", "--out", str(tmp_path / "m.png")])
    out = capsys.readouterr().out
    assert history.mask is not None and (tmp_path / "m.png").is_file()
    mpe = float(out.split("MPE ")[1].split(" m")[0])
    assert 0 < mpe < 0.3 and "objects per step" in out


def test_render_draws_only_the_observed_bearings():
    from lfmdr_gym.render import SENSED, draw_frame

    env = LFMDREnv("bearing", fov_deg=90, max_range=1.5, render_mode="rgb_array")
    obs, info = env.reset(seed=5)
    assert 0 < obs["observed"].sum() < 50
    args = dict(arena_half=1.25, object_positions=info["object_positions"], object_radius=0.024,
                robot_pose=info["robot_pose"], robot_radius=0.05)
    none = np.zeros(50, dtype=np.int8)
    # nothing observed: the frame of no sensor at all
    np.testing.assert_array_equal(draw_frame(**args, sensor="bearing", reading=obs["bearing"],
                                             observed=none), draw_frame(**args))
    frame = env.render()
    assert (frame == np.array(SENSED, dtype=np.uint8)).all(axis=2).any()  # observed: drawn as sensed
