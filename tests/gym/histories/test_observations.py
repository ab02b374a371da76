"""Observation table <-> History (lfmdr_gym/histories/observations.py)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lfmdr_gym
from lfmdr_gym.exploration import RandomWalkPolicy
from lfmdr_gym.histories import collect
from lfmdr_gym.histories.history import History
from lfmdr_gym.histories.observation_table import (
    ObservationTableError,
    read_observations,
    write_landmarks,
    write_observations,
)
from lfmdr_gym.histories.observations import (
    history_to_observations,
    landmark_ids,
    observations_to_history,
)
from mappers.core.sensors import COLUMNS_PER_STEP, sensors_of


def assert_same_history(a: History, b: History) -> None:
    """Matrices (as float64), masks, timeline and anchors equal bit for bit."""
    assert a.sensor == b.sensor and a.shape == b.shape
    for s in a.sensors:
        pa, pb = (a.parts[s], b.parts[s]) if a.fused else (a, b)
        assert pa.matrix.tobytes() == pb.matrix.tobytes(), s
        assert (pa.mask is None) == (pb.mask is None), s
        if pa.mask is not None:
            np.testing.assert_array_equal(pa.mask, pb.mask)
    assert (a.timeline is None) == (b.timeline is None)
    if a.timeline is not None:
        np.testing.assert_array_equal(a.timeline, b.timeline)
    np.testing.assert_array_equal(a.anchor_ids, b.anchor_ids)
    assert a.anchor_positions.tobytes() == b.anchor_positions.tobytes()
    assert a.object_positions.tobytes() == b.object_positions.tobytes()


CASES = [
    ("visibility", {}), ("visibility", {"fov_deg": 90.0, "miss_rate": 0.2, "false_rate": 0.05}),
    ("bearing", {}), ("bearing", {"fov_deg": 120.0, "max_range": 2.0, "bearing_noise_deg": 1.0}),
    ("range", {}), ("range", {"range_noise": 0.05, "max_range": 1.5}),
    ("range-bearing", {}), ("range-bearing", {"fov_deg": 90.0, "line_of_sight": True}),
    ("visibility-bearing", {}), ("visibility-bearing", {"fov_deg": 120.0, "max_range": 2.0}),
]


@pytest.mark.parametrize(("sensor", "limits"), CASES)
def test_env_history_table_history_is_bit_identical(sensor, limits):
    h = collect(lfmdr_gym.env_id_for(sensor), RandomWalkPolicy(), 200, seed=4,
                make_kwargs={"n_objects": 15, **limits})
    assert h.masked == bool(limits)
    log = history_to_observations(h)
    assert log.observations.attrs["complete"] == (not h.masked)
    assert_same_history(h, observations_to_history(log.observations, log.anchors, truth=log.truth))


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_round_trip_through_files_of_a_compact_history(tmp_path, suffix):
    h = collect(lfmdr_gym.env_id_for("range-bearing"), RandomWalkPolicy(), 150, seed=1,
                make_kwargs={"n_objects": 12, "fov_deg": 90.0}, compact=True)
    assert h.compact
    log = history_to_observations(h)
    obs = write_observations(log.observations, tmp_path / f"o{suffix}")
    anchors = write_landmarks(log.anchors, tmp_path / f"a{suffix}")
    truth = write_landmarks(log.truth, tmp_path / f"t{suffix}")
    assert_same_history(h, observations_to_history(read_observations(obs), anchors, truth=truth))


def _logged(seed: int = 0) -> History:
    """A masked range-bearing history of 3 robots with a timeline whose ticks have gaps, and a
    step without any sighting."""
    rng = np.random.default_rng(seed)
    m, n = 8, 30
    seen = rng.random((m, n)) < 0.4
    seen[:, 7] = False
    rng_m = np.where(seen, rng.uniform(0.5, 3, (m, n)), 0.0)
    theta = rng.uniform(-1, 1, (m, n))
    bearing = np.zeros((m, 2 * n))
    bearing[:, 0::2], bearing[:, 1::2] = np.where(seen, np.cos(theta), 0), np.where(seen, np.sin(theta), 0)
    timeline = np.column_stack([np.repeat([0, 1, 3], 10),
                                np.concatenate([np.sort(rng.choice(50, 10, replace=False))
                                                for _ in range(3)])])
    pos = rng.uniform(-2, 2, (m, 2))
    return History(sensor="range-bearing", matrix={"range": rng_m, "bearing": bearing},
                   mask={"range": seen, "bearing": np.repeat(seen, 2, axis=1)},
                   object_positions=pos, anchor_ids=[5, 0, 2], anchor_positions=pos[[5, 0, 2]],
                   timeline=timeline)


def test_timeline_gaps_empty_steps_and_string_ids_survive(tmp_path):
    h = _logged()
    h = h.replace(meta={"robots": ["r0", "r1", "r2", "r3"]})  # the robots' names
    names = [f"tag-{k}" for k in "hgfedcba"]  # not in sorted order: attrs keep the row order
    log = history_to_observations(h, landmarks=names)
    assert log.observations["landmark"].map(type).eq(str).all()
    assert set(log.observations["robot"]) == {"r0", "r1", "r3"}  # r2 took no step
    assert log.observations.attrs["empty_frames"] == [["r0", int(h.timeline[7, 1])]]
    path = write_observations(log.observations, tmp_path / "o.csv")
    back = observations_to_history(read_observations(path), log.anchors, truth=log.truth)
    assert_same_history(h, back)
    assert landmark_ids(back).tolist() == names and back.meta["landmarks"] == names
    assert back.meta["robots"] == ["r0", "r1", "r2", "r3"]


def _sightings() -> pd.DataFrame:
    """Two robots; robot "b" sees landmark "L3" twice in its frame 1 (averaged)."""
    return pd.DataFrame({
        "time": [0.0, 0.0, 0.1, 0.1, 0.1, 0.0, 0.2, 0.2, 0.2],
        "robot": ["a", "a", "a", "a", "a", "b", "b", "b", "b"],
        "landmark": ["L1", "L2", "L1", "L3", "L4", "L2", "L3", "L3", "L4"],
        "range": [1.0, 2.0, 1.1, 3.0, 2.5, 2.2, 1.0, 2.0, 0.9],
        "bearing": [0.1, -0.2, 0.12, 0.5, -0.4, 0.3, 1.0, 1.2, -0.1],
    })


ANCHORS = pd.DataFrame({"landmark": ["L1", "L2", "L4"], "x": [0.0, 2.0, 0.0],
                        "y": [0.0, 0.0, 2.0]})


def test_frames_from_times_rows_sorted_by_id_values_aggregated():
    h = observations_to_history(_sightings(), ANCHORS)
    assert h.sensor == "range-bearing" and h.meta["landmarks"] == ["L1", "L2", "L3", "L4"]
    np.testing.assert_array_equal(h.timeline, [[0, 0], [0, 1], [1, 0], [1, 1]])
    rng, mask = h.parts["range"].matrix, h.parts["range"].mask
    np.testing.assert_array_equal(mask[2], [False, True, False, True])
    assert rng[2, 3] == 1.5  # median of 1.0 and 2.0
    b = h.parts["bearing"].matrix
    np.testing.assert_allclose(np.arctan2(b[2, 7], b[2, 6]), 1.1, atol=1e-12)  # circular mean
    np.testing.assert_array_equal(h.anchor_ids, [0, 1, 3])
    assert np.isnan(h.object_positions[2]).all()  # no truth: only the anchors are placed


def test_the_history_of_a_table_saves_with_its_ids(tmp_path):
    table = _sightings()
    table.attrs = {"source": "a detector", "bag": tmp_path / "run.bag"}  # a Path: kept as text
    h = observations_to_history(table, ANCHORS)
    back = History.load(h.save(tmp_path / "h.npz"))
    assert back.meta["landmarks"] == ["L1", "L2", "L3", "L4"] and back.meta["robots"] == ["a", "b"]
    assert back.meta["table_attrs"]["bag"] == str(tmp_path / "run.bag")
    assert back.meta["source"] == "a detector"


def test_binning_by_time_and_a_chosen_sensor():
    h = observations_to_history(_sightings(), ANCHORS, sensor="visibility", bin_width=1.0)
    assert h.sensor == "visibility" and h.n_steps == 2  # one bin per robot
    np.testing.assert_array_equal(h.matrix, [[1, 0], [1, 1], [1, 1], [1, 1]])
    np.testing.assert_array_equal(h.timeline, [[0, 0], [1, 0]])
    assert h.meta["bin_width"] == 1.0


def test_rays_are_projected_to_bearings_in_the_horizontal_plane():
    b = np.array([0.3, -0.7, 1.2, 0.05, -0.2, 0.4, 0.8, -0.9, 0.1])
    t = _sightings().drop(columns="bearing").assign(ray_x=-np.sin(b) * 2, ray_y=0.5,
                                                    ray_z=np.cos(b) * 2)
    want = observations_to_history(_sightings().assign(bearing=b), ANCHORS, sensor="bearing")
    got = observations_to_history(t, ANCHORS, sensor="bearing")
    np.testing.assert_allclose(got.matrix, want.matrix, atol=1e-12)
    vertical = t.assign(ray_x=[0.0] + [1.0] * 8, ray_z=[0.0] + [1.0] * 8)
    with pytest.raises(ObservationTableError, match="vertical"):
        observations_to_history(vertical, ANCHORS, sensor="bearing")


def test_truth_missing_landmarks_is_reported():
    truth = pd.DataFrame({"landmark": ["L1", "L2", "L4", "L9"], "x": [0.0, 2.0, 0.0, 5.0],
                          "y": [0.0, 0.0, 2.0, 5.0]})
    h = observations_to_history(_sightings(), ANCHORS, truth=truth)
    assert h.meta["truth_missing"] == ["L3"] and h.meta["truth_unused"] == ["L9"]
    assert np.isnan(h.object_positions[2]).all() and h.object_positions[3].tolist() == [0.0, 2.0]


def test_bad_anchors_and_sensors_are_refused():
    with pytest.raises(ValueError, match=r"anchors \['L7'\] are never sighted"):
        observations_to_history(_sightings(), ANCHORS.assign(landmark=["L1", "L2", "L7"]))
    with pytest.raises(ValueError, match="at least 3 points"):
        observations_to_history(_sightings(), ANCHORS.iloc[:2])
    with pytest.raises(ValueError, match="collinear"):
        observations_to_history(_sightings(), ANCHORS.assign(y=[0.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="no rays"):  # 3-D anchors, a log of 2-D bearings
        observations_to_history(_sightings().iloc[:5].drop(columns="robot"), ANCHORS.assign(z=1.0))
    with pytest.raises(ValueError, match="one robot"):  # (3-D logs: one camera)
        observations_to_history(_sightings(), ANCHORS.assign(z=1.0))
    with pytest.raises(ValueError, match="must all be integers or all strings"):
        observations_to_history(_sightings(), ANCHORS.assign(landmark=[1, 2, 4]))
    with pytest.raises(ObservationTableError, match="mix integers and strings"):
        observations_to_history(_sightings().assign(landmark=["L1", 2] + ["L3"] * 7), ANCHORS)
    with pytest.raises(ValueError, match=r"needs \['range'\] readings"):
        observations_to_history(_sightings().drop(columns="range"), ANCHORS, sensor="range")
    with pytest.raises(ValueError, match="no rows"):
        observations_to_history(_sightings().iloc[:0], ANCHORS)
    with pytest.raises(ObservationTableError, match="negative range"):
        observations_to_history(_sightings().assign(range=-1.0), ANCHORS)


def test_history_to_observations_refuses_what_a_table_cannot_hold():
    h = _logged()
    with pytest.raises(ValueError, match="8 distinct ids"):
        history_to_observations(h, landmarks=range(7))
    mask = dict(h.mask)
    mask["range"] = ~mask["range"]
    with pytest.raises(ValueError, match="observed different entries"):
        history_to_observations(h.replace(mask=mask))
    with pytest.raises(ValueError, match="not in \\(robot, tick\\) order"):
        history_to_observations(h.replace(timeline=h.timeline[::-1].copy()))


@st.composite
def histories(draw) -> History:
    """Small random histories: any sensor or fused set, masked or complete, with or without a
    timeline (robots and ticks with gaps); unobserved entries read 0, as every recorder writes."""
    sensor = draw(st.sampled_from(["visibility", "bearing", "range", "range-bearing",
                                   "visibility-bearing"]))
    m, n = draw(st.integers(3, 6)), draw(st.integers(1, 12))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    masked = draw(st.booleans())
    seen = rng.random((m, n)) < draw(st.floats(0.0, 1.0)) if masked else np.ones((m, n), bool)
    matrix, mask = {}, {}
    for s in sensors_of(sensor):
        if s == "visibility":
            value = (rng.random((m, n)) < 0.5).astype(float)
        elif s == "range":
            value = np.where(rng.random((m, n)) < 0.2, 0.0, rng.uniform(0, 5, (m, n)))
        else:
            theta = rng.uniform(-np.pi, np.pi, (m, n))
            value = np.stack([np.cos(theta), np.sin(theta)], axis=-1).reshape(m, 2 * n)
        cols = COLUMNS_PER_STEP[s]
        keep = np.repeat(seen, cols, axis=1)
        matrix[s], mask[s] = np.where(keep, value, 0.0), keep
    timeline = None
    if draw(st.booleans()):
        robots = np.sort(rng.integers(0, 3, n))
        ticks = np.concatenate([np.sort(rng.choice(100, (robots == r).sum(), replace=False))
                                for r in range(3)])
        timeline = np.column_stack([robots, ticks])
    pos = rng.uniform(-3, 3, (m, 2))
    single = len(matrix) == 1
    return History(sensor=sensor, matrix=matrix[sensor] if single else matrix,
                   mask=(mask[sensor] if single else mask) if masked else None,
                   object_positions=pos, anchor_ids=[0, 1, 2], anchor_positions=pos[:3],
                   timeline=timeline)


@settings(max_examples=30, deadline=None)
@given(h=histories())
def test_property_history_table_history_is_bit_identical(h):
    log = history_to_observations(h)
    if not len(log.observations):  # nothing observed: a log of no sightings maps nothing
        with pytest.raises(ValueError, match="no rows: nothing was sighted"):
            observations_to_history(log.observations, log.anchors, truth=log.truth)
        return
    assert_same_history(h, observations_to_history(log.observations, log.anchors, truth=log.truth))


def test_declared_landmarks_and_robots_set_the_order_and_read_like_the_ids(tmp_path):
    path = tmp_path / "o.csv"
    path.write_text('# landmarks: ["9", 3, 5, 7]\n# robots: [2, "1"]\n'
                    "time,robot,landmark,bearing\n0.0,1,3,0.1\n0.0,2,5,0.2\n0.5,2,7,0.3\n")
    anchors = pd.DataFrame({"landmark": [3, 5, 7], "x": [0.0, 1.0, 0.0], "y": [0.0, 0.0, 1.0]})
    h = observations_to_history(read_observations(path), anchors)
    assert h.meta["landmarks"] == [9, 3, 5, 7] and h.meta["robots"] == [2, 1]
    np.testing.assert_array_equal(h.timeline, [[0, 0], [0, 1], [1, 0]])  # robot 2 first
    np.testing.assert_array_equal(h.mask[:, 0::2], [[0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0]])
    path.write_text('# landmarks: [3, 5]\ntime,landmark,bearing\n0.0,3,0.1\n0.0,7,0.2\n')
    with pytest.raises(ValueError, match=r"landmarks \[7\] are in the table but not in its"):
        observations_to_history(read_observations(path), anchors)
