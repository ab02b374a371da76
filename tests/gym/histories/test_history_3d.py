"""3-D histories: positions (M, 3), bearing as 3 columns per step, files of version 4; 2-D unchanged."""

from __future__ import annotations

import numpy as np
import pytest
from paths import TEST_DATA

from lfmdr_gym.histories.history import READABLE_VERSIONS, History, step_columns


def _rays(rng, m, n):
    v = rng.normal(size=(m, n, 3))
    return (v / np.linalg.norm(v, axis=-1, keepdims=True)).reshape(m, 3 * n)


def _history_3d(sensor="bearing", masked=True):
    rng = np.random.default_rng(0)
    m, n = 7, 5
    matrix = {"bearing": _rays(rng, m, n), "range": rng.uniform(0.1, 2, (m, n))}
    seen = rng.uniform(size=(m, n)) > 0.3
    masks = {"bearing": np.repeat(seen, 3, axis=1), "range": seen}
    fused = sensor == "range-bearing"
    return History(
        sensor=sensor,
        matrix=matrix if fused else matrix[sensor],
        object_positions=rng.uniform(-1, 1, (m, 3)),
        anchor_ids=np.array([0, 2, 4, 6]),
        anchor_positions=rng.uniform(-1, 1, (4, 3)),
        robot_poses=rng.uniform(-1, 1, (n, 3)),
        mask=(masks if fused else masks[sensor]) if masked else None,
        meta={"world": "3-D"},
    )


def test_dimension_and_columns_per_step():
    h = _history_3d()
    assert h.dimension == 3 and h.columns_per_step == 3 and h.n_steps == 5 and h.shape == (7, 15)
    fused = _history_3d("range-bearing")
    assert fused.dimension == 3 and fused.columns_per_step == 4 and fused.n_steps == 5
    assert step_columns("bearing", 3) == 3 and step_columns("bearing", 2) == 2
    assert step_columns("range", 3) == 1 and step_columns("visibility", 3) == 1
    with pytest.raises(ValueError, match="dimension"):
        step_columns("bearing", 4)
    head = h.head(2)
    assert head.shape == (7, 6) and np.array_equal(head.matrix, h.matrix[:, :6])
    assert head.dimension == 3


def test_3d_shapes_are_checked():
    h = _history_3d()
    with pytest.raises(ValueError, match="not a multiple of 3"):
        h.replace(matrix=h.matrix[:, :14], mask=None, robot_poses=None)
    with pytest.raises(ValueError, match=r"anchor_positions must have shape \(4, 3\)"):
        h.replace(anchor_positions=h.anchor_positions[:, :2])
    with pytest.raises(ValueError, match=r"\(M, 2\) or, for a 3-D history, \(M, 3\)"):
        h.replace(object_positions=np.zeros((7, 4)))
    with pytest.raises(ValueError, match="robot_poses has 5 rows for 7 steps"):
        h.replace(matrix=np.zeros((7, 21)), mask=None)  # 21 columns: 7 steps of 3


@pytest.mark.parametrize("sensor", ["bearing", "range", "range-bearing"])
@pytest.mark.parametrize("masked", [False, True])
def test_3d_round_trip_writes_version_4(tmp_path, sensor, masked):
    h = _history_3d(sensor, masked)
    path = h.save(tmp_path / "h3.npz")
    with np.load(path) as data:
        assert int(data["format_version"]) == 4 and data["object_positions"].shape == (7, 3)
    back = History.load(path)
    assert back.dimension == 3 and back.sensor == sensor and back.meta == h.meta
    for name in ("object_positions", "anchor_ids", "anchor_positions", "robot_poses"):
        np.testing.assert_array_equal(getattr(back, name), getattr(h, name))
    for part in h.sensors:
        a = h.parts[part] if h.fused else h
        b = back.parts[part] if back.fused else back
        np.testing.assert_array_equal(a.matrix, b.matrix)
        assert (b.mask is None) == (not masked)
        if masked:
            np.testing.assert_array_equal(a.mask, b.mask)


@pytest.mark.parametrize("name", ["history_v1_bearing.npz", "history_v1_visibility.npz"])
def test_2d_files_keep_their_version_and_fields(tmp_path, name):
    """Old (v1) files still load; saved again, a 2-D history writes the same fields and values
    under the same version as before (3-D alone bumped the format)."""
    assert 4 in READABLE_VERSIONS and 1 in READABLE_VERSIONS
    old = History.load(TEST_DATA / name)
    assert old.dimension == 2
    path = old.save(tmp_path / name)
    with np.load(TEST_DATA / name) as before, np.load(path) as after:
        assert sorted(before.files) == sorted(after.files)
        for key in before.files:
            assert before[key].dtype == after[key].dtype, key
            np.testing.assert_array_equal(before[key], after[key], err_msg=key)
