"""Compact histories: the same matrices and maps as dense ones, files old and new, memory bounds."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from paths import TEST_DATA

import mappers
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.histories.compact import DenseTooLargeError
from lfmdr_gym.histories.history import History
from lfmdr_gym.histories.recording import collect

DATA = TEST_DATA


@pytest.mark.parametrize(
    ("env_id", "kwargs", "stored"),
    [("LFMDR-Visibility-v0", {}, "csr"), ("LFMDR-Bearing-v0", {}, "float32"),
     ("LFMDR-Range-v0", {"max_range": 0.8}, "csr")],
)
def test_compact_and_dense_histories_give_the_same_matrix_and_map(env_id, kwargs, stored):
    dense = collect(env_id, RandomWalkPolicy(seed=0), 400, seed=21, make_kwargs=kwargs)
    small = collect(env_id, RandomWalkPolicy(seed=0), 400, seed=21, make_kwargs=kwargs, compact=True)
    assert not dense.compact and small.compact
    data = small.__dict__["_data"]
    assert sp.issparse(data) if stored == "csr" else data.dtype == np.float32
    np.testing.assert_array_equal(small.matrix, dense.matrix)
    np.testing.assert_array_equal(small.sparse.toarray(), dense.matrix)
    assert small.shape == dense.matrix.shape and small.n_steps == 400
    a = mappers.build_map(dense, dense.anchor_ids, dense.anchor_positions)
    b = mappers.build_map(small, small.anchor_ids, small.anchor_positions)
    assert a.method == b.method
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(small.head(50).matrix, dense.head(50).matrix)


def test_compact_history_file_round_trip(tmp_path):
    h = collect("LFMDR-Visibility-v0", RandomWalkPolicy(seed=0), 200, seed=5, compact=True)
    path = h.save(tmp_path / "c.npz")
    with np.load(path, allow_pickle=False) as data:
        assert "matrix" not in data.files and int(data["format_version"]) == 2
        assert data["matrix_data"].size == h.sparse.nnz
    back = History.load(path)
    assert back.compact
    np.testing.assert_array_equal(back.matrix, h.matrix)
    dense_path = collect("LFMDR-Visibility-v0", RandomWalkPolicy(seed=0), 20, seed=5).save(tmp_path / "d.npz")
    with np.load(dense_path, allow_pickle=False) as data:  # dense files keep today's format
        assert int(data["format_version"]) == 1 and "matrix" in data.files


@pytest.mark.parametrize(
    ("name", "env_id", "n_objects", "n_steps", "seed"),
    [("visibility", "LFMDR-Visibility-v0", 12, 40, 11), ("bearing", "LFMDR-Bearing-v0", 8, 20, 12)],
)
def test_files_written_before_compact_histories_still_load(name, env_id, n_objects, n_steps, seed):
    # written by lfmdr before compact histories existed (format version 1)
    old = History.load(DATA / f"history_v1_{name}.npz")
    assert not old.compact
    again = collect(env_id, RandomWalkPolicy(seed=0), n_steps, seed=seed,
                    make_kwargs={"n_objects": n_objects})
    np.testing.assert_array_equal(old.robot_poses, again.robot_poses)
    if name == "visibility":  # 0/1 readings: exact
        np.testing.assert_array_equal(old.matrix, again.matrix)
    else:  # float32 bearings written on another machine: to a few units in their last place
        # (2**-23 ~ 1.2e-7 at 1; cos/sin and BLAS differ across CPUs, see test_trajectory_identity)
        np.testing.assert_allclose(old.matrix, again.matrix, rtol=0, atol=1e-6)


def test_a_dense_matrix_beyond_the_budget_is_refused_naming_the_sparse_accessor():
    m, d = 10_000, 400_000  # 32 GB as float64
    rows = np.arange(0, m, 7)
    data = sp.csr_array((np.ones(rows.size, np.int8), (rows, rows * 3)), shape=(m, d))
    h = History(sensor="visibility", matrix=data, object_positions=np.zeros((m, 2)),
                anchor_ids=np.arange(3), anchor_positions=np.zeros((3, 2)))
    assert h.n_objects == m and h.n_steps == d
    with pytest.raises(DenseTooLargeError, match="History.sparse"):
        h.matrix  # noqa: B018
    assert h.sparse.nnz == rows.size
    with pytest.raises(ValueError, match="History.sparse"):
        h.dense(max_bytes=1024)


def test_compact_argument_is_checked():
    with pytest.raises(ValueError, match="compact"):
        collect("LFMDR-Visibility-v0", RandomWalkPolicy(seed=0), 5, seed=1, compact="yes")


def test_build_map_maps_a_history_beyond_the_budget_without_the_dense_matrix(monkeypatch):
    from lfmdr_gym.histories import compact
    from mappers import fitting

    h = collect("LFMDR-Visibility-v0", RandomWalkPolicy(seed=0), 600, seed=8,
                make_kwargs={"anchors": "random", "n_anchors": 6}, compact=True)
    monkeypatch.setattr(compact, "MAX_DENSE_BYTES", 1024)  # far below this history's 240 kB
    monkeypatch.setattr(fitting, "DENSE_BUDGET_BYTES", 1024)
    with pytest.raises(DenseTooLargeError, match="History.sparse"):
        h.matrix  # noqa: B018
    built = mappers.build_map(h, h.anchor_ids, h.anchor_positions, method="CAL-SMA", sparse=True)
    assert built.method == "CAL-SMA" and built.params["sparse"] is True
    assert np.isfinite(built.positions).all()
    with pytest.raises(ValueError, match="'CAL-SMA' with sparse=True"):
        mappers.build_map(h, h.anchor_ids, h.anchor_positions, method="CAL-SMA")


@pytest.mark.parametrize(("env_id", "kwargs"), [
    ("LFMDR-Bearing-v0", {"max_range": 1.5}),
    ("LFMDR-Visibility-v0", {"fov_deg": 120.0, "miss_rate": 0.1}),
])
def test_masked_compact_histories_keep_a_sparse_mask(tmp_path, env_id, kwargs):
    dense = collect(env_id, RandomWalkPolicy(seed=0), 300, seed=4, make_kwargs=kwargs)
    small = collect(env_id, RandomWalkPolicy(seed=0), 300, seed=4, make_kwargs=kwargs,
                    compact=True)
    assert small.is_sparse and small.masked and sp.issparse(small.__dict__["_mask"])
    assert small.sparse_mask.nnz == dense.mask.sum()
    np.testing.assert_array_equal(small.mask, dense.mask)  # dense on demand
    np.testing.assert_array_equal(small.matrix, dense.matrix)
    np.testing.assert_array_equal(small.head(120).mask, dense.head(120).mask)
    loaded = History.load(small.save(tmp_path / "h.npz"))  # format version 3: the mask's structure
    assert sp.issparse(loaded.__dict__["_mask"])
    np.testing.assert_array_equal(loaded.mask, dense.mask)
    np.testing.assert_array_equal(loaded.matrix, dense.matrix)
    assert "masked=True" in repr(loaded)


def test_replace_keeps_a_compact_history_compact(monkeypatch):
    # dataclasses.replace reads matrix and mask through their properties (densifying);
    # History.replace passes the stored forms on, so a history beyond the budget survives it.
    h = collect("LFMDR-Bearing-v0", RandomWalkPolicy(seed=0), 200, seed=2,
                make_kwargs={"max_range": 1.5}, compact=True)
    monkeypatch.setattr(sp.csr_array, "toarray", lambda *a, **k: pytest.fail("densified"))
    new = h.replace(meta={**h.meta, "note": "relabelled"})
    assert new.meta["note"] == "relabelled" and new.compact and new.is_sparse
    for key in ("_data", "_mask"):
        stored = new.__dict__[key]
        assert sp.issparse(stored) and (stored != h.__dict__[key]).nnz == 0
    monkeypatch.undo()
    np.testing.assert_array_equal(new.mask, h.mask)
    assert not h.replace(mask=None).masked
    with pytest.raises(ValueError, match="no field.*'colour'"):
        h.replace(colour="red")
