"""History files (round trip, damage, atomic writes) and the collectors collect / collect_vector."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import lfmdr_gym  # noqa: F401  (registers the ids)
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.histories import history as history_module
from lfmdr_gym.histories.history import History, HistoryFileError
from lfmdr_gym.histories.recording import collect, collect_vector


def steer(obs):
    """A deterministic, observation-driven policy (turn toward the freer side); batch-aware."""
    prox = np.asarray(obs["proximity"], dtype=np.float32)
    n = prox.shape[-1]
    return (0.7 * np.tanh(4.0 * (prox[..., n // 4] - prox[..., 3 * n // 4]))).astype(np.float32)


def _small_history(mask: bool = False) -> History:
    rng = np.random.default_rng(0)
    matrix = rng.normal(size=(6, 8))
    return History(
        sensor="bearing",
        matrix=matrix,
        object_positions=rng.uniform(-1, 1, (6, 2)),
        anchor_ids=np.array([0, 2, 5]),
        anchor_positions=rng.uniform(-1, 1, (3, 2)),
        robot_poses=rng.uniform(-1, 1, (4, 3)),
        mask=(rng.uniform(size=matrix.shape) > 0.3) if mask else None,
        meta={"seed": 3, "note": "tiny", "nested": {"a": [1, 2]}},
    )


# ----------------------------------------------------------------------------- files
@pytest.mark.parametrize("mask", [False, True])
def test_save_load_round_trip_is_bit_identical(tmp_path, mask):
    h = _small_history(mask)
    path = h.save(tmp_path / "sub" / "h.npz")
    back = History.load(path)
    for name in ("matrix", "object_positions", "anchor_ids", "anchor_positions", "robot_poses"):
        a, b = getattr(h, name), getattr(back, name)
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert (back.mask is None) == (not mask)
    if mask:
        assert np.array_equal(h.mask, back.mask)
    assert back.meta == h.meta and back.sensor == h.sensor


def test_collected_history_round_trip(tmp_path):
    h = collect("LFMDR-Visibility-v0", RandomWalkPolicy(), 50, seed=1)
    back = History.load(h.save(tmp_path / "v.npz"))
    assert np.array_equal(back.matrix, h.matrix) and np.array_equal(back.robot_poses, h.robot_poses)
    assert back.meta == h.meta


def test_damaged_and_foreign_files_raise_history_file_error(tmp_path):
    path = _small_history().save(tmp_path / "h.npz")
    data = path.read_bytes()
    for n in (len(data) // 2, len(data) - 30, 10):
        cut = tmp_path / f"cut{n}.npz"
        cut.write_bytes(data[:n])
        with pytest.raises(HistoryFileError):
            History.load(cut)
    # flipped bytes anywhere: either the content survives intact or HistoryFileError (never a
    # zlib.error or NotImplementedError from inside the zip reader)
    for pos in range(0, len(data), 7):
        flipped = bytearray(data)
        flipped[pos] ^= 0xFF
        bad = tmp_path / "flipped.npz"
        bad.write_bytes(bytes(flipped))
        try:
            back = History.load(bad)
        except HistoryFileError:
            continue
        assert np.array_equal(back.matrix, _small_history().matrix)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, a=np.arange(3))
    with pytest.raises(HistoryFileError, match="not an lfmdr history"):
        History.load(foreign)
    text = tmp_path / "text.npz"
    text.write_text("hello")
    with pytest.raises(HistoryFileError, match="not an .npz archive") as info:
        History.load(text)
    assert "allow_pickle" not in str(info.value)  # ours, not numpy's
    with pytest.raises(FileNotFoundError):
        History.load(tmp_path / "missing.npz")


def test_save_is_atomic_and_leaves_no_temporary_files(tmp_path, monkeypatch):
    h = _small_history()
    path = h.save(tmp_path / "h.npz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.npz"]
    before = path.read_bytes()

    def failing_savez(fh, **arrays):
        fh.write(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(history_module.np, "savez_compressed", failing_savez)
    with pytest.raises(OSError, match="disk full"):
        _small_history(mask=True).save(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.npz"]  # no temp file left
    assert path.read_bytes() == before  # the old file is untouched


# ----------------------------------------------------------------------------- collect
@pytest.mark.parametrize("env_id, sensor, per_step", [
    ("LFMDR-Visibility-v0", "visibility", 1),
    ("LFMDR-Bearing-v0", "bearing", 2),
    ("LFMDR-Range-v0", "range", 1),
])
def test_collect_stacks_the_observations(env_id, sensor, per_step):
    n = 40
    env = gym.make(env_id)
    h = collect(env, steer, n, seed=5)
    # the same episode by hand
    obs, info0 = env.reset(seed=5)
    readings, poses = [], []
    for _ in range(n):
        obs, _, _, _, info = env.step(np.asarray(steer(obs)).reshape(1))
        readings.append(obs[sensor])
        poses.append(info["robot_pose"])
    m = info0["object_positions"].shape[0]
    assert h.sensor == sensor and h.n_steps == n and h.matrix.dtype == np.float64
    assert h.matrix.shape == (m, per_step * n)
    for t in (0, 17, n - 1):
        expected = np.asarray(readings[t], dtype=np.float64).reshape(m, per_step)
        assert np.array_equal(h.matrix[:, per_step * t: per_step * (t + 1)], expected)
    assert np.array_equal(h.robot_poses, np.array(poses))
    assert np.array_equal(h.object_positions, info0["object_positions"])
    assert np.array_equal(h.anchor_ids, info0["anchor_ids"])
    assert np.array_equal(h.anchor_positions, info0["anchor_positions"])
    assert h.meta["env_id"] == env_id and h.meta["seed"] == 5 and h.meta["n_steps"] == n
    assert h.meta["sensor"] == sensor and 0 <= h.meta["blocked_moves"] <= n
    if sensor == "visibility":
        assert set(np.unique(h.matrix)) <= {0.0, 1.0}
    if sensor == "bearing":  # interleaved cos, sin: unit vectors per step
        assert np.allclose(h.matrix[:, 0::2] ** 2 + h.matrix[:, 1::2] ** 2, 1.0, atol=1e-6)


def test_collect_is_deterministic_for_a_seed():
    a = collect("LFMDR-Visibility-v0", RandomWalkPolicy(), 150, seed=11)
    b = collect("LFMDR-Visibility-v0", RandomWalkPolicy(), 150, seed=11)
    c = collect("LFMDR-Visibility-v0", RandomWalkPolicy(), 150, seed=12)
    assert np.array_equal(a.matrix, b.matrix) and np.array_equal(a.robot_poses, b.robot_poses)
    assert a.meta == b.meta
    assert not np.array_equal(a.robot_poses, c.robot_poses)


def test_step_counts_are_checked_alike_everywhere():
    """collect, collect_history and checkpoints_for take numpy integers and refuse bools, floats
    and counts below 1 with one message naming the argument."""
    from lfmdr_gym.experiments.engine import check_jobs
    from lfmdr_gym.experiments.episodes import collect_history
    from lfmdr_gym.experiments.mapping import checkpoints_for

    assert collect("LFMDR-Visibility-v0", RandomWalkPolicy(), np.int64(3), seed=1).n_steps == 3
    assert checkpoints_for(np.int64(400), np.int32(200), "visibility") == (200, 400)
    for bad, message in ((True, "must be an integer, got True"), (2.0, "must be an integer"),
                         (0, "must be >= 1, got 0")):
        with pytest.raises(ValueError, match="n_steps " + message):
            collect("LFMDR-Visibility-v0", RandomWalkPolicy(), bad, seed=1)
        with pytest.raises(ValueError, match="steps " + message):
            collect_history("LFMDR-Visibility-v0", bad, seed=1)
        with pytest.raises(ValueError, match="every " + message):
            checkpoints_for(400, bad, "visibility")
    with pytest.raises(ValueError, match="jobs must be"):
        check_jobs(True)


def test_collect_refuses_episodes_shorter_than_n_steps():
    env = gym.make("LFMDR-Visibility-v0", max_episode_steps=10)
    with pytest.raises(ValueError, match="max_episode_steps"):
        collect(env, steer, 11, seed=0)

    class EndsEarly(gym.Wrapper):  # truncates after 5 moves without telling the spec
        def reset(self, **kwargs):
            self.t = 0
            return self.env.reset(**kwargs)

        def step(self, action):
            obs, r, term, trunc, info = self.env.step(action)
            self.t += 1
            return obs, r, term, self.t >= 5, info

    with pytest.raises(ValueError, match="ended after 5 of n_steps=8"):
        collect(EndsEarly(gym.make("LFMDR-Visibility-v0")), steer, 8, seed=0)


@pytest.mark.parametrize("bad", [0, -3, 2.5, True])
def test_collect_rejects_bad_n_steps(bad):
    with pytest.raises(ValueError, match="n_steps"):
        collect("LFMDR-Visibility-v0", steer, bad)


def test_collect_rejects_wrong_action_shapes_and_non_dict_observations():
    with pytest.raises(ValueError, match="action"):
        collect("LFMDR-Visibility-v0", lambda obs: np.zeros(3, np.float32), 5, seed=0)
    flat = gym.wrappers.FlattenObservation(gym.make("LFMDR-Visibility-v0"))
    with pytest.raises(ValueError, match="dict observation"):
        collect(flat, lambda obs: np.zeros(1, np.float32), 5, seed=0)


# ----------------------------------------------------------------------------- collect_vector
def _single_env_episodes(env_id, seed, n_steps, n_episodes, max_episode_steps):
    """What one sub-env of a vector env should record: a seeded episode, then continued ones."""
    env = gym.make(env_id, max_episode_steps=max_episode_steps)
    out = [collect(env, steer, n_steps, seed=seed)]
    for _ in range(n_episodes - 1):  # the autoreset continues the sub-env's random stream
        out.append(collect(env, steer, n_steps, seed=None))
    return out


def _same(a: History, b: History) -> bool:
    return (np.array_equal(a.matrix, b.matrix) and np.array_equal(a.robot_poses, b.robot_poses)
            and np.array_equal(a.object_positions, b.object_positions)
            and np.array_equal(a.anchor_ids, b.anchor_ids))


@pytest.mark.parametrize("mode", ["NextStep", "SameStep", "Disabled"])
def test_collect_vector_skips_the_autoreset_step(mode):
    n, episodes = 12, 2
    envs = gym.make_vec("LFMDR-Bearing-v0", num_envs=2, max_episode_steps=n,
                        vector_kwargs={"autoreset_mode": mode})
    hs = collect_vector(envs, steer, n, seed=21, n_episodes=episodes)
    envs.close()
    assert len(hs) == 2 * episodes
    for i in range(2):
        expected = _single_env_episodes("LFMDR-Bearing-v0", 21 + i, n, episodes, n)
        for e in range(episodes):
            got = hs[i * episodes + e]
            assert got.meta["sub_env"] == i and got.meta["episode"] == e
            assert _same(got, expected[e]), (i, e)
    # the episodes really differ: the autoreset drew a new layout
    assert not np.array_equal(hs[0].object_positions, hs[1].object_positions)


def test_collect_vector_with_episodes_longer_than_n_steps():
    envs = gym.make_vec("LFMDR-Visibility-v0", num_envs=2, max_episode_steps=10)
    hs = collect_vector(envs, steer, 7, seed=3, n_episodes=2)
    envs.close()
    expected = _single_env_episodes("LFMDR-Visibility-v0", 4, 7, 2, 10)
    assert _same(hs[2], expected[0]) and _same(hs[3], expected[1])


def test_collect_vector_with_the_random_walk_and_errors():
    envs = gym.make_vec("LFMDR-Visibility-v0", num_envs=3)
    hs = collect_vector(envs, RandomWalkPolicy.for_env(envs), 30, seed=0)
    assert [h.matrix.shape for h in hs] == [(50, 30)] * 3
    assert [h.meta["seed"] for h in hs] == [0, 1, 2]
    with pytest.raises(ValueError, match="vector env"):
        collect_vector(envs, lambda obs: np.zeros(1, np.float32), 5, seed=0)
    with pytest.raises(ValueError, match="max_episode_steps"):
        collect_vector(envs, steer, 2001, seed=0)
    envs.close()
    short = gym.make_vec("LFMDR-Visibility-v0", num_envs=2, max_episode_steps=6)
    with pytest.raises(ValueError, match="max_episode_steps"):
        collect_vector(short, steer, 7, seed=0)
    short.close()
    with pytest.raises(ValueError, match="VectorEnv"):
        collect_vector(gym.make("LFMDR-Visibility-v0"), steer, 5)


@pytest.mark.parametrize("bad", [-1, 1.5, "3", [1, 2]])
def test_collectors_reject_bad_seeds(bad):
    with pytest.raises(ValueError, match="seed"):
        collect("LFMDR-Visibility-v0", steer, 5, seed=bad)
    envs = gym.make_vec("LFMDR-Visibility-v0", num_envs=2)
    with pytest.raises(ValueError, match="seed"):
        collect_vector(envs, steer, 5, seed=bad)
    envs.close()


def test_collect_accepts_numpy_integer_seeds_and_sb3_models():
    class Model:  # SB3-style, deterministic: steer by the proximity ring
        def predict(self, observation, state=None, episode_start=None, deterministic=False):
            return np.asarray(steer(observation)).reshape(-1, 1)[0], state

    a = collect("LFMDR-Visibility-v0", Model(), 20, seed=np.int64(4))
    b = collect("LFMDR-Visibility-v0", steer, 20, seed=4)
    assert a.meta["seed"] == 4 and np.array_equal(a.matrix, b.matrix)


@pytest.mark.parametrize("compact", [False, True])
def test_partly_observed_says_whether_a_mask_hides_anything(compact):
    """A limited view leaves entries unobserved; noise alone reports a mask that is all True,
    which the mappers treat as complete; a perfect history has no mask. The same answer from a
    compact (sparse) history."""
    def episode(**sensing):
        env = gym.make("LFMDR-Visibility-v0", max_episode_steps=60, **sensing)
        return collect(env, RandomWalkPolicy.for_env(env), 60, seed=3, compact=compact)

    perfect, noisy, limited = episode(), episode(miss_rate=0.3), episode(fov_deg=90)
    assert not perfect.masked and not perfect.partly_observed
    assert noisy.masked and noisy.mask.all() and not noisy.partly_observed
    assert limited.masked and not limited.mask.all() and limited.partly_observed
