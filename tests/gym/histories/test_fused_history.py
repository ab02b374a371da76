"""Fused histories (several sensors of one walk in one History): files, build_map, lfmdr map."""

from __future__ import annotations

import numpy as np
import pytest

from lfmdr_gym.cli import main
from lfmdr_gym.histories.history import History, HistoryFileError
from mappers import build_map

M, N = 12, 200


def _camera(mask: bool = True, seed: int = 0) -> History:
    """A range-bearing history of a camera (120-degree view, 2 m) on random poses, noise-free."""
    rng = np.random.default_rng(seed)
    objects = rng.uniform(-1.0, 1.0, (M, 2))
    objects[:4] = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
    poses = np.column_stack([rng.uniform(-0.8, 0.8, (N, 2)), rng.uniform(-np.pi, np.pi, N)])
    rel = objects[:, None, :] - poses[None, :, :2]
    r = np.hypot(rel[..., 0], rel[..., 1])
    theta = np.arctan2(rel[..., 1], rel[..., 0]) - poses[None, :, 2]
    seen = (np.abs(np.angle(np.exp(1j * theta))) <= np.radians(60)) & (r <= 2.0) if mask \
        else np.ones_like(r, dtype=bool)
    R = np.where(seen, r, 0.0)
    B = np.zeros((M, 2 * N))
    B[:, 0::2], B[:, 1::2] = np.where(seen, np.cos(theta), 0), np.where(seen, np.sin(theta), 0)
    return History(sensor="range-bearing", matrix={"range": R, "bearing": B},
                   mask={"range": seen, "bearing": np.repeat(seen, 2, axis=1)} if mask else None,
                   object_positions=objects, anchor_ids=[0, 1, 2, 3], anchor_positions=objects[:4],
                   robot_poses=poses, meta={"note": "synthetic"})


def test_a_fused_history_holds_one_matrix_per_sensor():
    h = _camera()
    assert h.fused and h.sensors == ("bearing", "range") and h.n_steps == N and h.n_objects == M
    assert h.columns_per_step == 3 and h.shape == (M, 3 * N)
    assert set(h.matrix) == {"range", "bearing"} and h.matrix["bearing"].shape == (M, 2 * N)
    assert set(h.parts) == {"range", "bearing"}
    rng_part = h.parts["range"]
    assert rng_part.sensor == "range" and not rng_part.fused and rng_part.parts is None
    np.testing.assert_array_equal(rng_part.mask, h.mask["range"])
    head = h.head(10)
    assert head.sensor == "range-bearing" and head.n_steps == 10
    np.testing.assert_array_equal(head.matrix["bearing"], h.matrix["bearing"][:, :20])
    np.testing.assert_array_equal(head.robot_poses, h.robot_poses[:10])
    with pytest.raises(ValueError, match=r"History.parts\[sensor\].sparse"):
        _ = h.sparse
    with pytest.raises(ValueError, match=r"History.parts\[sensor\].partly_observed"):
        _ = h.partly_observed
    assert rng_part.partly_observed  # a 120-degree camera out to 2 m


@pytest.mark.parametrize("mask", [True, False])
def test_fused_file_round_trip_is_bit_identical(tmp_path, mask):
    h = _camera(mask)
    path = h.save(tmp_path / "f.npz")
    with np.load(path, allow_pickle=False) as data:
        assert int(data["format_version"]) == 3 and "range.matrix" in data.files
    back = History.load(path)
    assert back.sensor == "range-bearing" and back.meta == h.meta
    for s in ("range", "bearing"):
        a, b = h.matrix[s], back.matrix[s]
        assert a.dtype == b.dtype and np.array_equal(a, b)
        if mask:
            np.testing.assert_array_equal(back.mask[s], h.mask[s])
    assert (back.mask is None) == (not mask)
    np.testing.assert_array_equal(back.robot_poses, h.robot_poses)


def test_single_sensor_files_keep_their_versions(tmp_path):
    single = _camera().parts["bearing"]
    path = single.save(tmp_path / "b.npz")
    with np.load(path, allow_pickle=False) as data:
        assert int(data["format_version"]) == 1 and "matrix" in data.files
    assert not History.load(path).fused


def test_a_fused_file_missing_a_sensor_is_a_history_file_error(tmp_path):
    path = _camera().save(tmp_path / "f.npz")
    with np.load(path, allow_pickle=False) as data:
        fields = {k: data[k] for k in data.files if not k.startswith("range.")}
    np.savez(tmp_path / "bad.npz", **fields)
    with pytest.raises(HistoryFileError, match="lacks the field 'range.matrix'"):
        History.load(tmp_path / "bad.npz")


def _kw(**over):
    base = dict(object_positions=np.zeros((M, 2)), anchor_ids=[0, 1, 2],
                anchor_positions=np.eye(3, 2))
    return {**base, **over}


@pytest.mark.parametrize(("kwargs", "message"), [
    (dict(sensor="range-bearing", matrix=np.zeros((M, N))), "mapping sensor -> matrix"),
    (dict(sensor="range-bearing", matrix={"range": np.zeros((M, N))}), r"missing \['bearing'\]"),
    (dict(sensor="range-bearing", matrix={"range": np.zeros((M, N)), "bearing": np.zeros((M, 2 * N)),
                                          "visibility": np.zeros((M, N))}), r"unknown \['visibility'\]"),
    (dict(sensor="range-bearing", matrix={"range": np.zeros((M, N)), "bearing": np.zeros((M, 2 * N - 4))}),
     "same objects and steps"),
    (dict(sensor="range-bearing", matrix={"range": np.zeros((M, N)), "bearing": np.zeros((M, 2 * N + 1))}),
     "bearing part .* not a multiple of 2"),
    (dict(sensor="range-bearing", matrix={"range": np.zeros((M, N)), "bearing": np.zeros((M, 2 * N))},
          mask={"range": np.ones((M, N), bool)}), r"mask .* missing \['bearing'\]"),
    (dict(sensor="range-bearing", matrix={"range": np.zeros((M, N)), "bearing": np.zeros((M, 2 * N))},
          mask=np.ones((M, N), bool)), "mask of a range-bearing history must be None or a mapping"),
    (dict(sensor="range", matrix={"range": np.zeros((M, N))}), "fused history: its sensor must name"),
    (dict(sensor="sonar", matrix=np.zeros((M, N))), "sensor must be one of"),
])
def test_bad_fused_histories_are_refused_by_name(kwargs, message):
    with pytest.raises(ValueError, match=message):
        History(**_kw(**kwargs))


def test_build_map_takes_a_fused_history_directly_with_the_set_default():
    h = _camera()
    m = build_map(h, h.anchor_ids, h.anchor_positions)
    assert m.method == "LOC-SMA" and m.sensor == "range-bearing"
    ref = build_map({"range": h.matrix["range"], "bearing": h.matrix["bearing"]}, h.anchor_ids,
                    h.anchor_positions, mask={"range": h.mask["range"], "bearing": h.mask["bearing"]})
    np.testing.assert_array_equal(m.positions, ref.positions)
    err = np.linalg.norm(m.positions - h.object_positions, axis=1)
    assert np.nanmax(err) < 1e-6  # noise-free law-of-cosines distances: exact up to the solver
    with pytest.raises(ValueError, match="does not map range-bearing histories"):
        build_map(h, h.anchor_ids, h.anchor_positions, "CAL-SMA")
    with pytest.raises(ValueError, match="does not name the sensors"):
        build_map(h, h.anchor_ids, h.anchor_positions, sensor="range")


def test_lfmdr_map_on_a_fused_file(tmp_path, capsys):
    path = _camera().save(tmp_path / "cam.npz")
    assert main(["map", str(path), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "sensor='range-bearing'" in out and "LOC-SMA" in out and "MPE 0.0000 m" in out
    rows = (tmp_path / "out" / "map.csv").read_text().splitlines()
    assert rows[0] == "object,x,y,true_x,true_y,anchor" and len(rows) == M + 1
    assert (tmp_path / "out" / "map.png").stat().st_size > 0
    assert main(["map", str(path), "--method", "VB-SMA", "--out", str(tmp_path / "o2")]) == 2
    assert "does not map" in capsys.readouterr().err


def test_a_fused_history_pickles():
    import pickle

    h = _camera()
    back = pickle.loads(pickle.dumps(h))
    assert back.sensor == h.sensor and back.sensors == h.sensors
    for s in h.sensors:
        np.testing.assert_array_equal(back.matrix[s], h.matrix[s])
        np.testing.assert_array_equal(back.mask[s], h.mask[s])


def test_a_compact_masked_fused_recording_keeps_sparse_masks_through_a_file(tmp_path):
    # #12's fused histories meet #13's sparse masks: each sensor's mask stays sparse in the
    # recording and in the file (version 3), and equals the dense recording's
    import gymnasium as gym

    import lfmdr_gym  # noqa: F401
    from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
    from lfmdr_gym.histories.recording import collect

    env = gym.make("LFMDR-RangeBearing-v0", fov_deg=90, max_range=1.5)
    small = collect(env, RandomWalkPolicy.for_env(env), 300, seed=3, compact=True)
    dense = collect(env, RandomWalkPolicy.for_env(env), 300, seed=3, compact=False)
    small.save(tmp_path / "h.npz")
    back = History.load(tmp_path / "h.npz")
    for name in ("range", "bearing"):
        assert back.parts[name].sparse_mask is not None
        assert not isinstance(back.parts[name].__dict__["_mask"], np.ndarray)
        np.testing.assert_array_equal(back.parts[name].mask, dense.parts[name].mask)
        np.testing.assert_allclose(back.parts[name].matrix, dense.parts[name].matrix, atol=1e-6)
    assert back.head(100).masked
    with pytest.raises(ValueError, match="parts"):
        _ = back.sparse_mask
    result = build_map(back, back.anchor_ids, back.anchor_positions)
    assert result.method == "LOC-SMA"
