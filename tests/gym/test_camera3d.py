"""LFMDR-Camera3D-v0: API conformance, what the camera reads, sensing keywords, recording in 3-D."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import lfmdr_gym
from lfmdr_gym import RandomWalkPolicy, collect, collect_vector
from lfmdr_gym.camera3d_env import Camera3DEnv
from lfmdr_gym.histories.history import History

POSTS = np.array([(-0.8, -0.8), (0.8, -0.8), (0.8, 0.8), (-0.8, 0.8), (0.6, 0.0)])
# a small world: 5 posts with one tag each, 3 wall tags
SMALL = dict(n_posts=5, tags_per_post=1, n_wall_tags=3, n_anchors=4)
TAGS = np.array([
    (-0.8, -0.8, 0.3), (0.8, -0.8, 1.9), (0.8, 0.8, 0.5), (-0.8, 0.8, 1.0),
    (0.6, 0.0, 0.4),        # on post 4, straight ahead of the robot below
    (1.25, 0.0, 0.6),       # on the east wall, behind post 4: hidden
    (1.25, 0.3, 0.3),       # on the east wall, in view, clear of post 4
    (-1.25, 0.0, 1.0),      # on the west wall, behind the robot
])
POSE = (0.0, 0.0, 0.0)


def _reset(env, **extra):
    return env.reset(seed=0, options={"post_positions": POSTS, "tag_positions": TAGS,
                                      "robot_pose": POSE, **extra})


def test_registered_and_passes_the_checker():
    assert "LFMDR-Camera3D-v0" in gym.registry and "LFMDR-Camera3D-v0" not in lfmdr_gym.ENV_IDS
    assert gym.spec("LFMDR-Camera3D-v0").max_episode_steps == 2000
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for sensor in ("range-bearing", "visibility"):
            env = gym.make("LFMDR-Camera3D-v0", sensor=sensor, render_mode="rgb_array")
            check_env(env.unwrapped, skip_render_check=True)
            env.reset(seed=0)
            frame = env.render()
            assert frame.shape == (480, 480, 3) and frame.dtype == np.uint8
            env.close()


def test_a_tag_in_view_is_read_with_its_ray_and_range():
    env = Camera3DEnv(pitch_deg=0.0, camera_height=0.3, **SMALL)
    obs, info = _reset(env)
    np.testing.assert_array_equal(info["object_positions"], TAGS)
    np.testing.assert_array_equal(info["anchor_positions"], TAGS[info["anchor_ids"]])
    d4 = math.hypot(0.6, 0.1)
    np.testing.assert_allclose(obs["bearing"][4], (0.0, -0.1 / d4, 0.6 / d4), atol=1e-6)
    assert obs["range"][4] == pytest.approx(d4, abs=1e-6)
    d6 = math.sqrt(1.25**2 + 0.3**2)
    np.testing.assert_allclose(obs["bearing"][6], (-0.3 / d6, 0.0, 1.25 / d6), atol=1e-6)
    assert obs["observed"].tolist() == [0, 0, 0, 0, 1, 0, 1, 0]
    # not read: zero rays and ranges (behind, hidden behind post 4, out of the vertical view)
    assert not obs["bearing"][[0, 3, 5, 7]].any() and not obs["range"][[0, 3, 5, 7]].any()
    for name in ("bearing", "range", "observed"):
        assert obs[name] in env.observation_space[name]


def test_occlusion_off_and_range_limit():
    env = Camera3DEnv(pitch_deg=0.0, occlusion=False, **SMALL)
    assert _reset(env)[0]["observed"][5] == 1  # seen through post 4
    env = Camera3DEnv(pitch_deg=0.0, max_range=1.0, **SMALL)
    assert _reset(env)[0]["observed"].tolist() == [0, 0, 0, 0, 1, 0, 0, 0]


def test_same_seed_same_episode_and_noise_leaves_the_path_alone():
    def run(**kw):
        env = Camera3DEnv(**kw)
        obs, _ = env.reset(seed=5)
        rng = np.random.default_rng(9)
        poses, reads = [], []
        for _ in range(200):
            obs, _, _, _, info = env.step(rng.uniform(-1, 1, 1).astype(np.float32))
            poses.append(info["robot_pose"])
            reads.append((obs["bearing"].copy(), obs["range"].copy(), obs["observed"].copy()))
        return np.array(poses), reads

    p1, r1 = run()
    p2, r2 = run()
    np.testing.assert_array_equal(p1, p2)
    assert all(np.array_equal(a, b) for x, y in zip(r1, r2, strict=True) for a, b in zip(x, y, strict=True))
    sigma = math.radians(1.0)
    p3, r3 = run(bearing_noise_deg=1.0, range_noise=0.02)
    np.testing.assert_array_equal(p1, p3)  # noise has its own stream
    seen = np.concatenate([o for _, _, o in r1]).astype(bool)
    assert np.array_equal(seen, np.concatenate([o for _, _, o in r3]).astype(bool))
    clean = np.concatenate([b for b, _, _ in r1])[seen].astype(float)
    noisy = np.concatenate([b for b, _, _ in r3])[seen].astype(float)
    angle = np.arccos(np.clip(np.einsum("ij,ij->i", clean, noisy), -1, 1))
    # two Gaussian angular components of sd sigma: E[angle^2] = 2 sigma^2
    assert angle.size > 500
    assert math.sqrt(np.mean(angle**2)) == pytest.approx(math.sqrt(2) * sigma, rel=0.1)
    dr = (np.concatenate([r for _, r, _ in r3]) - np.concatenate([r for _, r, _ in r1]))[seen]
    assert np.std(dr) == pytest.approx(0.02, rel=0.1)


def test_miss_rate_drops_detections():
    env = Camera3DEnv(miss_rate=0.5)
    full = Camera3DEnv()
    seen = []
    for e in (full, env):
        e.reset(seed=2)
        count = 0
        for _ in range(300):
            obs, *_ = e.step(np.full(1, 0.3, np.float32))
            count += int(obs["observed"].sum())
        seen.append(count)
    assert seen[0] > 100
    assert seen[1] / seen[0] == pytest.approx(0.5, abs=0.1)


def test_visibility_sensor_reads_what_the_camera_detects():
    vis = Camera3DEnv(sensor="visibility", **SMALL)
    rb = Camera3DEnv(**SMALL)
    o1, _ = vis.reset(seed=4)
    o2, _ = rb.reset(seed=4)
    assert set(o1) == {"visibility", "proximity"}
    for _ in range(50):
        np.testing.assert_array_equal(o1["visibility"], o2["observed"])
        o1, *_ = vis.step(np.full(1, 0.3, np.float32))
        o2, *_ = rb.step(np.full(1, 0.3, np.float32))


def test_bad_reset_options_are_named():
    env = Camera3DEnv(**SMALL)
    with pytest.raises(ValueError, match="8 rows"):
        _reset(env, tag_positions=TAGS[:6])
    flat = TAGS.copy()
    flat[:4, 2] = 0.5  # the four corner posts' tags at one height: on one plane
    with pytest.raises(ValueError, match="one plane"):
        _reset(env, tag_positions=flat, anchor_ids=[0, 1, 2, 3])
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(seed=0, options={"layout": 1})


def test_collect_records_a_3d_history(tmp_path):
    h = collect("LFMDR-Camera3D-v0", RandomWalkPolicy(), 150, seed=3,
                make_kwargs={"bearing_noise_deg": 1.0, "range_noise": 0.02})
    assert isinstance(h, History) and h.sensor == "range-bearing" and h.dimension == 3
    b, r = h.parts["bearing"], h.parts["range"]
    assert b.columns_per_step == 3 and b.shape == (50, 450) and r.shape == (50, 150)
    assert h.object_positions.shape == (50, 3) and h.anchor_positions.shape == (6, 3)
    rays = b.matrix.reshape(50, 150, 3)
    seen = b.mask.reshape(50, 150, 3)
    assert seen.any() and (seen == seen[..., :1]).all()
    np.testing.assert_allclose(np.linalg.norm(rays[seen[..., 0]], axis=1), 1.0, atol=1e-6)
    assert not rays[~seen[..., 0]].any()
    np.testing.assert_array_equal(r.mask, seen[..., 0])
    back = History.load(h.save(tmp_path / "cam3d.npz"))
    assert back.dimension == 3 and back.sensor == "range-bearing"
    np.testing.assert_array_equal(back.parts["bearing"].matrix, b.matrix)
    np.testing.assert_array_equal(back.parts["range"].mask, r.mask)


def test_recorded_rays_and_ranges_point_back_at_the_tags():
    """Each recorded reading, put back through the camera's true pose (ground truth, for the
    test only), lands on its tag: the history is the camera's view of the world."""
    from lfmdr_gym.sim.view3d import camera_frame

    env = gym.make("LFMDR-Camera3D-v0", pitch_deg=15.0, camera_height=0.25)
    h = collect(env, RandomWalkPolicy.for_env(env), 100, seed=11)
    env.close()
    rays = h.parts["bearing"].matrix.reshape(h.n_objects, h.n_steps, 3)
    ranges = h.parts["range"].matrix
    seen = h.parts["range"].mask
    assert seen.sum() > 100
    for t, pose in enumerate(h.robot_poses):
        centre, rot = camera_frame(pose, 0.25, np.radians(15.0))
        j = seen[:, t]
        back = centre + ranges[j, t, None] * (rays[j, t] @ rot)
        np.testing.assert_allclose(back, h.object_positions[j], atol=1e-5)


def test_compact_and_vector_recording_give_the_same_3d_history():
    plain = collect("LFMDR-Camera3D-v0", RandomWalkPolicy(), 60, seed=8)
    small = collect("LFMDR-Camera3D-v0", RandomWalkPolicy(), 60, seed=8, compact=True)
    assert small.compact and small.dimension == 3
    for part in ("bearing", "range"):
        np.testing.assert_allclose(small.parts[part].matrix, plain.parts[part].matrix, atol=1e-6)
        np.testing.assert_array_equal(small.parts[part].mask, plain.parts[part].mask)
    envs = gym.make_vec("LFMDR-Camera3D-v0", num_envs=2, max_episode_steps=60)
    vec = collect_vector(envs, RandomWalkPolicy(), 60, seed=8)
    envs.close()
    assert [h.dimension for h in vec] == [3, 3]
    np.testing.assert_array_equal(vec[0].object_positions, plain.object_positions)
    assert vec[0].parts["bearing"].shape == (50, 180)


def test_build_map_maps_a_camera3d_history_in_3d():
    """A noise-free walk's rays and ranges map every tag to within rounding (build_map picks
    the 3-D default from the (A, 3) anchors); a visibility walk gives a 3-D map too."""
    from mappers import build_map

    h = collect("LFMDR-Camera3D-v0", RandomWalkPolicy(), 400, seed=5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = build_map(h, h.anchor_ids, h.anchor_positions)
    rest = np.setdiff1d(np.arange(h.n_objects), h.anchor_ids)
    assert m.positions.shape == (50, 3) and not m.unmapped
    err = np.linalg.norm(m.positions[rest] - h.object_positions[rest], axis=1)
    assert err.max() < 1e-4
    vis = collect("LFMDR-Camera3D-v0", RandomWalkPolicy(), 400, seed=5,
                  make_kwargs={"sensor": "visibility"})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mv = build_map(vis, vis.anchor_ids, vis.anchor_positions)
    assert mv.positions.shape == (50, 3)
