"""MRCLAM through the observation table (lfmdr_gym/datasets/mrclam_table.py) gives the histories
the loader gives (load_mrclam / bin_run), bit for bit."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from paths import SHARED_DATA

import lfmdr_gym.datasets.mrclam as mrclam
from lfmdr_gym.datasets.mrclam import DEFAULT_BIN_WIDTH, MRCLAMReport, MRCLAMRun, bin_run
from lfmdr_gym.datasets.mrclam_table import mrclam_anchors, mrclam_landmarks, mrclam_observations
from lfmdr_gym.histories.observation_table import read_observations, write_observations
from lfmdr_gym.histories.observations import history_to_observations, observations_to_history

DATA = SHARED_DATA / "mrclam"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"MRCLAM data not found at {DATA}")
SENSORS = ("visibility", "bearing", "range", "range-bearing")


def _same(a, b) -> None:
    assert a.sensor == b.sensor and a.shape == b.shape
    for s in a.sensors:
        pa, pb = (a.parts[s], b.parts[s]) if a.fused else (a, b)
        assert pa.matrix.tobytes() == pb.matrix.tobytes(), s
        np.testing.assert_array_equal(pa.mask, pb.mask)
    np.testing.assert_array_equal(a.timeline, b.timeline)
    np.testing.assert_array_equal(a.anchor_ids, b.anchor_ids)
    assert a.object_positions.tobytes() == b.object_positions.tobytes()
    assert a.anchor_positions.tobytes() == b.anchor_positions.tobytes()


def _synthetic_run() -> MRCLAMRun:
    rng = np.random.default_rng(5)
    rows = [(r, t, lm, rng.uniform(0.3, 5.0), rng.uniform(-0.6, 0.6))
            for r in (3, 1) for t in np.sort(rng.uniform(0, 30, 80))
            for lm in rng.choice(7, size=rng.integers(1, 4), replace=False)]
    obs = np.array(rows)  # robot 3's rows, then robot 1's: the loader's order for robots (3, 1)
    report = MRCLAMReport(run="synthetic", robots=(3, 1), rows=len(obs), robot_rows=0,
                          unknown_barcode_rows=0, repeat_rows=0, landmark_rows=len(obs),
                          per_robot_landmark_rows={}, groundtruth_fix="none")
    subjects = np.array([6, 8, 9, 10, 11, 12, 14, 20])  # subject 20 is never sighted
    return MRCLAMRun("synthetic", subjects, rng.uniform(-3, 3, (8, 2)), obs,
                     np.zeros(len(obs), np.int64), report)


@pytest.mark.parametrize("sensor", ["visibility", "bearing", "range"])
def test_synthetic_run_through_the_table_equals_bin_run(sensor):
    run = _synthetic_run()
    table = mrclam_observations(run)
    assert table.attrs["robots"] == [3, 1] and table.attrs["landmarks"][-1] == 20
    h = observations_to_history(table, mrclam_anchors(run), truth=mrclam_landmarks(run),
                                sensor=sensor, bin_width=0.8)
    matrix, mask, _, timeline = bin_run(run, sensor, 0.8)
    assert h.matrix.tobytes() == matrix.tobytes()
    np.testing.assert_array_equal(h.mask, mask)
    np.testing.assert_array_equal(h.timeline, timeline)
    assert h.n_objects == 8 and h.meta["landmarks"][-1] == 20
    assert not h.mask[-1].any()


def test_anchors_by_subject_number():
    run = _synthetic_run()
    anchors = mrclam_anchors(run, [14, 6, 9])
    assert anchors["landmark"].tolist() == [14, 6, 9]
    np.testing.assert_array_equal(anchors[["x", "y"]].to_numpy(), run.truth[[6, 0, 2]])
    with pytest.raises(ValueError, match=r"anchors \[7\] are not landmark subjects"):
        mrclam_anchors(run, [6, 7, 9])


def _check_runs(runs, monkeypatch, tmp_path):
    for name in runs:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run = mrclam.read_run(DATA / name)
        # load_mrclam reads the run again for every sensor: hand it the one read here
        monkeypatch.setattr(mrclam, "read_run", lambda *a, _run=run, **k: _run)
        table = mrclam_observations(run)
        path = write_observations(table, tmp_path / f"{name}.csv")
        table = read_observations(path)  # through a file: the same bits
        for sensor in SENSORS:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                want = mrclam.load_mrclam(DATA / name, sensor)
            got = observations_to_history(table, mrclam_anchors(run), truth=mrclam_landmarks(run),
                                          sensor=sensor, bin_width=DEFAULT_BIN_WIDTH[sensor])
            _same(want, got)
            # and the loader's history written as a table reads back the same (robots 1-5 kept)
            log = history_to_observations(want)
            assert log.observations.attrs["robots"] == list(run.report.robots)
            _same(want, observations_to_history(log.observations, log.anchors, truth=log.truth))
        monkeypatch.undo()


@needs_data
def test_real_run_through_the_table_gives_the_loaders_histories(monkeypatch, tmp_path):
    _check_runs(["MRCLAM_Dataset1"], monkeypatch, tmp_path)


@needs_data
@pytest.mark.slow
def test_every_real_run_through_the_table_gives_the_loaders_histories(monkeypatch, tmp_path):
    _check_runs(["MRCLAM_Dataset2", "MRCLAM_Dataset3", "MRCLAM_Dataset6"], monkeypatch, tmp_path)
