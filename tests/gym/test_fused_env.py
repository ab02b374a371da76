"""The fused-sensing envs (LFMDR-RangeBearing-v0, LFMDR-VisibilityBearing-v0, LFMDR-Camera-v0):
observations against brute-force geometry, the camera preset, collect -> file -> build_map."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from paths import EXAMPLES

import lfmdr_gym
from lfmdr_gym import History, RandomWalkPolicy, collect, collect_vector
from lfmdr_gym.env import LFMDREnv
from lfmdr_gym.sim import sensors
from lfmdr_gym.sim.camera import CAMERA_PRESET
from mappers import build_map


def _geometry(info):
    """Brute-force range and bearing of every object from the pose in ``info``."""
    x, y, h = info["robot_pose"]
    rel = info["object_positions"] - (x, y)
    r = np.array([math.hypot(dx, dy) for dx, dy in rel])
    theta = np.array([math.atan2(dy, dx) - h for dx, dy in rel])
    return r, theta


def _occluded(info, radius):
    """Brute force: object j is hidden when the segment robot -> j passes within ``radius`` of
    another object's centre (the sensors' line-of-sight test). Every pair (j, k) is tried, as
    arrays: the loop over pairs in Python took 6 s of the test's CPU."""
    p = info["robot_pose"][:2]
    objs = info["object_positions"]
    d = objs - p  # (j, 2): robot -> object j
    t = np.clip(np.einsum("kc,jc->jk", objs - p, d) / np.einsum("jc,jc->j", d, d)[:, None],
                0.0, 1.0)  # (j, k): where the segment robot -> j passes closest to k
    near = np.linalg.norm(p + t[:, :, None] * d[:, None, :] - objs[None, :, :], axis=2) < radius
    blocked = near & (t < 1.0)
    np.fill_diagonal(blocked, False)  # an object does not hide itself
    return blocked.any(axis=1)


def test_range_bearing_observations_match_the_geometry():
    env = gym.make("LFMDR-RangeBearing-v0")
    obs, info = env.reset(seed=5)
    rng = np.random.default_rng(0)
    for _ in range(40):
        r, theta = _geometry(info)
        np.testing.assert_allclose(obs["range"], r, atol=1e-5)
        np.testing.assert_allclose(obs["bearing"][:, 0], np.cos(theta), atol=1e-6)
        np.testing.assert_allclose(obs["bearing"][:, 1], np.sin(theta), atol=1e-6)
        assert "observed" not in obs
        obs, _, _, _, info = env.step(rng.uniform(-0.7, 0.7, 1).astype(np.float32))
    env.close()


def test_visibility_bearing_observations_match_the_single_sensors():
    env = gym.make("LFMDR-VisibilityBearing-v0")
    obs, info = env.reset(seed=2)
    radius = env.unwrapped.world.object_radius
    for _ in range(30):
        vis = sensors.visibility(info["robot_pose"], info["object_positions"], radius, math.radians(5.0))
        np.testing.assert_array_equal(obs["visibility"], vis.astype(np.int8))
        _, theta = _geometry(info)
        np.testing.assert_allclose(obs["bearing"][:, 1], np.sin(theta), atol=1e-6)
        obs, _, _, _, info = env.step(np.array([0.3], np.float32))
    env.close()


def test_one_camera_decides_for_both_sensors_and_the_noise_is_independent():
    kw = dict(fov_deg=90.0, max_range=1.2, bearing_noise_deg=3.0, range_noise=0.03,
              line_of_sight=True)
    env = LFMDREnv("range-bearing", **kw)
    obs, info = env.reset(seed=11)
    env.action_space.seed(11)  # the same path on every run
    r_err, b_err = [], []
    for _ in range(100):
        r, theta = _geometry(info)
        wrapped = np.angle(np.exp(1j * theta))
        expect = (np.abs(wrapped) <= math.radians(45.0)) & (r <= 1.2) \
            & ~_occluded(info, env.world.object_radius)
        np.testing.assert_array_equal(obs["observed"].astype(bool), expect)
        seen = expect
        assert np.all(obs["range"][~seen] == 0) and np.all(obs["bearing"][~seen] == 0)
        r_err.append(obs["range"][seen] - r[seen])
        b_err.append(np.angle(np.exp(1j * (np.arctan2(obs["bearing"][seen, 1], obs["bearing"][seen, 0])
                                           - theta[seen]))))
        obs, _, _, _, info = env.step(env.action_space.sample())
    r_err, b_err = np.concatenate(r_err), np.concatenate(b_err)
    assert r_err.size > 100
    assert 0.025 < r_err.std() < 0.035 and abs(r_err.mean()) < 0.005
    assert math.radians(2.5) < b_err.std() < math.radians(3.5)
    # drawn independently: the sample correlation of n independent pairs has spread 1/sqrt(n)
    assert abs(np.corrcoef(r_err, b_err)[0, 1]) < 4.0 / math.sqrt(r_err.size)


def test_limits_of_other_sensors_are_refused_and_bad_sensors_named():
    with pytest.raises(ValueError, match="miss_rate applies to the visibility sensor"):
        LFMDREnv("range-bearing", miss_rate=0.1)
    with pytest.raises(ValueError, match="range_noise applies to the range sensor"):
        LFMDREnv("visibility-bearing", range_noise=0.1)
    with pytest.raises(ValueError, match=r"sensor must be one of .* fused set"):
        LFMDREnv("range-visibility")
    LFMDREnv("visibility-bearing", miss_rate=0.1, bearing_noise_deg=1.0)  # each to its own sensor


def test_the_camera_preset_is_the_range_bearing_env_with_the_measured_keywords():
    spec = gym.spec("LFMDR-Camera-v0")
    assert spec.kwargs == {"sensor": "range-bearing", **CAMERA_PRESET}
    env = gym.make("LFMDR-Camera-v0")
    inner = env.unwrapped
    assert inner.sensors == ("bearing", "range")
    assert inner._limits.fov == CAMERA_PRESET["fov_deg"] and inner.max_range == CAMERA_PRESET["max_range"]
    assert inner._limits.line_of_sight
    env.close()
    wide = gym.make("LFMDR-Camera-v0", fov_deg=360.0).unwrapped  # a keyword overrides the preset
    assert wide._limits.fov == 360.0
    assert lfmdr_gym.env_id_for("range-bearing") == "LFMDR-RangeBearing-v0"


@pytest.mark.parametrize(("env_id", "sensor", "method", "tol"), [
    ("LFMDR-RangeBearing-v0", "range-bearing", "LOC-SMA", 1e-6),
    ("LFMDR-VisibilityBearing-v0", "visibility-bearing", "VB-SMA", 0.1),
    ("LFMDR-Camera-v0", "range-bearing", "LOC-SMA", 0.1),
])
def test_collect_save_load_build_map(tmp_path, env_id, sensor, method, tol):
    h = collect(env_id, RandomWalkPolicy(), 400, seed=3)
    assert h.sensor == sensor and h.fused and h.n_steps == 400
    assert (h.mask is not None) == (env_id == "LFMDR-Camera-v0")
    if h.mask is not None:
        np.testing.assert_array_equal(h.mask["bearing"][:, 0::2], h.mask["range"])
    back = History.load(h.save(tmp_path / "h.npz"))
    for s in h.sensors:
        np.testing.assert_array_equal(back.matrix[s], h.matrix[s])
    np.testing.assert_array_equal(back.robot_poses, h.robot_poses)
    m = build_map(back, back.anchor_ids, back.anchor_positions)
    assert m.method == method and m.sensor == sensor
    non_anchor = np.setdiff1d(np.arange(h.n_objects), [*h.anchor_ids, *m.unmapped])
    err = np.linalg.norm(m.positions - h.object_positions, axis=1)[non_anchor]
    assert err.mean() < tol


def test_fused_history_parts_are_the_single_sensor_envs_histories():
    fused = collect("LFMDR-RangeBearing-v0", RandomWalkPolicy(), 120, seed=8)
    for sensor, env_id in (("range", "LFMDR-Range-v0"), ("bearing", "LFMDR-Bearing-v0")):
        single = collect(env_id, RandomWalkPolicy(), 120, seed=8)
        np.testing.assert_array_equal(fused.parts[sensor].matrix, single.matrix)
        np.testing.assert_array_equal(fused.robot_poses, single.robot_poses)


def test_collect_vector_records_fused_envs():
    envs = gym.make_vec("LFMDR-Camera-v0", num_envs=2, max_episode_steps=30)
    hs = collect_vector(envs, lambda obs: np.zeros((2, 1), np.float32), 30, seed=4, n_episodes=2)
    envs.close()
    assert len(hs) == 4 and all(h.sensor == "range-bearing" and h.n_steps == 30 for h in hs)
    one = collect("LFMDR-Camera-v0", lambda obs: np.zeros(1, np.float32), 30, seed=4)
    np.testing.assert_array_equal(hs[0].matrix["range"], one.matrix["range"])
    np.testing.assert_array_equal(hs[0].mask["bearing"], one.mask["bearing"])


def test_lfmdr_collect_and_map_a_fused_env(tmp_path, capsys):
    from lfmdr_gym.cli import main

    path = tmp_path / "rb.npz"
    assert main(["collect", "--env", "LFMDR-RangeBearing-v0", "--steps", "200", "--env-kw",
                 "fov_deg=90", "--env-kw", "range_noise=0.01", "--out", str(path)]) == 0
    out = capsys.readouterr().out
    assert "sensor='range-bearing'" in out and "observed entries: bearing" in out
    assert main(["map", str(path), "--out", str(tmp_path / "map")]) == 0
    out = capsys.readouterr().out
    assert "LOC-SMA" in out and "MPE" in out
    mpe = float(out.split("MPE ")[1].split()[0])
    assert mpe < 0.1
    assert main(["run", "--online", "--env", "LFMDR-Camera-v0", "--steps", "20",
                 "--out", str(tmp_path / "live")]) == 2
    assert "takes one sensor's histories" in capsys.readouterr().err


@pytest.mark.parametrize("env_id", ["LFMDR-Camera-v0", "LFMDR-VisibilityBearing-v0"])
def test_compact_fused_histories_round_trip(tmp_path, env_id):
    small = collect(env_id, RandomWalkPolicy(), 150, seed=2, compact=True)
    dense = collect(env_id, RandomWalkPolicy(), 150, seed=2)
    assert small.compact and not dense.compact
    sparse_part = "range" if env_id == "LFMDR-Camera-v0" else "visibility"
    assert small.parts[sparse_part].is_sparse  # each part stored in its own compact form
    back = History.load(small.save(tmp_path / "c.npz"))
    for s in small.sensors:
        np.testing.assert_allclose(small.matrix[s], dense.matrix[s], atol=1e-6)  # float32
        np.testing.assert_array_equal(back.matrix[s], small.matrix[s])
    assert back.parts[sparse_part].is_sparse


def test_mrclam_camera_example(tmp_path, capsys):
    import runpy

    script = EXAMPLES / "mrclam_camera.py"
    out_file = tmp_path / "cam.npz"
    history = runpy.run_path(str(script))["main"](["--steps", "600", "--out", str(out_file)])
    out = capsys.readouterr().out
    assert history.sensor == "range-bearing" and History.load(out_file).fused
    mpe = {line.split(":")[0].strip(): float(line.split("MPE ")[1].split(" m")[0])
           for line in out.splitlines() if "MPE" in line}
    assert set(mpe) == {"range + bearing", "bearing", "range"}
    assert mpe["range + bearing"] < min(mpe["range"], mpe["bearing"])  # fusing pays
