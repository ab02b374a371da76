"""``lfmdr map LOG`` (an observation table) and ``lfmdr convert``: the same map as the history it
came from, the files it writes, and the errors that leave ``--out`` as it was (issue 33)."""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pandas as pd
import pytest
from paths import SHARED_DATA

from lfmdr_gym.cli import main
from lfmdr_gym.experiments.episodes import collect_history
from lfmdr_gym.experiments.map_log import map_observation_log
from lfmdr_gym.experiments.mapping import map_history_file
from lfmdr_gym.histories.observation_table import (
    read_landmarks,
    read_observations,
    write_landmarks,
    write_observations,
)
from lfmdr_gym.histories.observations import history_to_observations

MRCLAM = SHARED_DATA / "mrclam"


def _episode(tmp_path, env_id, steps=200, seed=1):
    """A saved env history, its observation table, and its anchors and truth tables (landmark
    ids: the object rows)."""
    history = collect_history(env_id, steps, seed)
    npz = history.save(tmp_path / "episode.npz")
    tables = history_to_observations(history)
    log, anchors, truth = (tmp_path / n for n in ("episode.csv", "anchors.csv", "truth.csv"))
    write_observations(tables.observations, log)
    write_landmarks(tables.anchors, anchors)
    write_landmarks(tables.truth, truth)
    return history, npz, log, anchors, truth


@pytest.mark.parametrize("env_id", ["LFMDR-Visibility-v0", "LFMDR-Bearing-v0"])
def test_a_log_maps_as_the_history_it_came_from(tmp_path, env_id):
    history, npz, log, anchors, truth = _episode(tmp_path, env_id)
    from_npz = map_history_file(npz, out=tmp_path / "npz")
    from_log = map_observation_log(log, anchors, truth=truth, out=tmp_path / "log", plot=False)
    assert from_log.method == from_npz["method"]
    np.testing.assert_array_equal(from_log.map.positions, from_npz["map"].positions)
    assert from_log.scores["mpe"] == pytest.approx(from_npz["mpe"], rel=1e-12)
    assert from_log.scores["moe"] == pytest.approx(from_npz["moe"], rel=1e-12)
    assert from_log.scores["missing_from_truth"] == []


def test_cli_writes_the_set_and_prints_scores(tmp_path, capsys):
    history, _, log, anchors, truth = _episode(tmp_path, "LFMDR-Visibility-v0", steps=150)
    out = tmp_path / "out"
    assert main(["map", str(log), "--anchors", str(anchors), "--truth", str(truth),
                 "--method", "SMA(WGT)", "--out", str(out), "--frame", "arena"]) == 0
    printed = capsys.readouterr().out
    assert "MPE" in printed and "SMA(WGT)" in printed
    assert {p.name for p in out.iterdir()} == {"map.csv", "map.json", "map.yaml", "map.png",
                                               "scores.json"}
    with open(out / "map.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == history.n_objects
    assert sum(int(r["anchor"]) for r in rows) == len(history.anchor_ids)
    doc = json.loads((out / "map.json").read_text())
    assert doc["frame"] == "arena" and len(doc["landmarks"]) == history.n_objects


def test_string_ids_stay_strings(tmp_path):
    history, _, log, anchors, truth = _episode(tmp_path, "LFMDR-Visibility-v0", steps=150)
    name = {k: f"tag_{k:02d}" for k in range(history.n_objects)}
    log_table = read_observations(log)  # (its attrs kept: a complete history's table)
    log_table["landmark"] = log_table["landmark"].map(name)
    log_table.attrs["landmarks"] = [name[k] for k in log_table.attrs["landmarks"]]
    write_observations(log_table, log)
    for path in (anchors, truth):
        table = read_landmarks(path)
        table["landmark"] = table["landmark"].map(name)
        write_landmarks(table, path)
    run = map_observation_log(log, anchors, truth=truth, method="SMA(WGT)",
                              out=tmp_path / "m", plot=False)
    with open(tmp_path / "m" / "map.csv", newline="") as fh:
        ids = [r["landmark"] for r in csv.DictReader(fh)]
    assert sorted(ids) == sorted(name.values())
    assert run.scores["n_scored"] == history.n_objects


def _bad_anchor_tables(tmp_path, anchors):
    table = pd.read_csv(anchors)
    cases = {}
    absent = table.copy()
    absent.loc[0, "landmark"] = 999
    cases["absent"] = (absent, r"anchors \[999\] are never sighted in the log")
    cases["few"] = (table.iloc[:2], "at least 3")
    line = table.copy()
    line["y"] = 2.0 * line["x"] + 1.0
    cases["collinear"] = (line, "collinear")
    paths = {}
    for key, (frame, match) in cases.items():
        paths[key] = (tmp_path / f"anchors-{key}.csv", match)
        frame.to_csv(paths[key][0], index=False)
    return paths


def test_bad_anchors_are_refused_and_out_is_left_as_it_was(tmp_path, capsys):
    _, _, log, anchors, _ = _episode(tmp_path, "LFMDR-Visibility-v0", steps=100)
    out = tmp_path / "out"
    out.mkdir()
    (out / "map.csv").write_text("an older map\n")
    for path, match in _bad_anchor_tables(tmp_path, anchors).values():
        assert main(["map", str(log), "--anchors", str(path), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("lfmdr map: error: ")
        assert re.search(match, err), err
        assert [p.name for p in out.iterdir()] == ["map.csv"]
        assert (out / "map.csv").read_text() == "an older map\n"


def test_truth_missing_landmarks_scores_those_present(tmp_path, capsys):
    history, _, log, anchors, truth = _episode(tmp_path, "LFMDR-Visibility-v0", steps=150)
    table = pd.read_csv(truth)
    table[table["landmark"] != 7].to_csv(truth, index=False)
    assert main(["map", str(log), "--anchors", str(anchors), "--truth", str(truth),
                 "--method", "SMA(WGT)", "--out", str(tmp_path / "m")]) == 0
    assert "not scored, missing from" in capsys.readouterr().out
    scores = json.loads((tmp_path / "m" / "scores.json").read_text())
    assert scores["missing_from_truth"] == [7]
    assert scores["n_scored"] == history.n_objects - 1


def test_log_options_need_a_log_and_a_log_needs_anchors(tmp_path, capsys):
    _, npz, log, anchors, _ = _episode(tmp_path, "LFMDR-Visibility-v0", steps=100)
    assert main(["map", str(npz), "--anchors", str(anchors)]) == 2
    assert "apply to an observation log" in capsys.readouterr().err
    assert main(["map", str(log), "--out", str(tmp_path / "m")]) == 2
    assert "--anchors" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()


@pytest.mark.skipif(not MRCLAM.is_dir(), reason=f"the MRCLAM data folder {MRCLAM} is absent")
def test_convert_mrclam_writes_a_table_and_landmarks(tmp_path, capsys):
    from lfmdr_gym.histories.observation_table import read_landmarks, read_observations

    out, marks = tmp_path / "ds2.parquet", tmp_path / "ds2-landmarks.csv"
    assert main(["convert", "mrclam", str(MRCLAM / "MRCLAM_Dataset2"), "--out", str(out),
                 "--landmarks", str(marks)]) == 0
    table = read_observations(out)
    assert {"time", "robot", "landmark", "range", "bearing"} <= set(table.columns)
    assert set(table["robot"].unique()) == {1, 2, 3, 4, 5}
    assert set(table["landmark"].unique()) <= set(range(6, 21))
    assert len(read_landmarks(marks)) == 15
    assert "wrote" in capsys.readouterr().out


def test_convert_rosbag_then_map(tmp_path, capsys):
    """A ROS 1 bag of AprilTag poses (simulated) -> lfmdr convert rosbag -> lfmdr map."""
    pytest.importorskip("rosbags")
    from lfmdr_gym.datasets.rosbag_write import camera_detections, write_detection_bag

    rng = np.random.default_rng(3)
    steps, landmarks = 150, rng.uniform(-2.0, 2.0, (10, 2))
    poses = np.column_stack([rng.uniform(-2.5, 2.5, (steps, 2)), rng.uniform(-np.pi, np.pi, steps)])
    det = camera_detections(1_700_000_000.0 + 0.1 * np.arange(steps), poses, landmarks,
                            ids=np.arange(10) + 100, fov=np.radians(120))
    bag = write_detection_bag(tmp_path / "run.bag", det)
    log = tmp_path / "run.parquet"
    assert main(["convert", "rosbag", str(bag), "--topic", "/tag_detections",
                 "--out", str(log)]) == 0
    assert "wrote" in capsys.readouterr().out
    ids = np.arange(10) + 100
    pd.DataFrame({"landmark": ids[:4], "x": landmarks[:4, 0], "y": landmarks[:4, 1]}).to_csv(
        tmp_path / "anchors.csv", index=False)
    pd.DataFrame({"landmark": ids, "x": landmarks[:, 0], "y": landmarks[:, 1]}).to_csv(
        tmp_path / "truth.csv", index=False)
    assert main(["map", str(log), "--anchors", str(tmp_path / "anchors.csv"), "--truth",
                 str(tmp_path / "truth.csv"), "--sensor", "range-bearing",
                 "--out", str(tmp_path / "m")]) == 0
    capsys.readouterr()
    scores = json.loads((tmp_path / "m" / "scores.json").read_text())
    assert scores["n_scored"] == 10
    assert scores["mpe_nonanchor"] < 0.01  # exact poses from the camera: an exact map


def test_out_that_is_a_file_is_refused(tmp_path, capsys):
    _, _, log, anchors, _ = _episode(tmp_path, "LFMDR-Visibility-v0", steps=100)
    blocker = tmp_path / "blocker"
    blocker.write_text("mine")
    assert main(["map", str(log), "--anchors", str(anchors), "--out", str(blocker)]) == 2
    assert "cannot write to output directory" in capsys.readouterr().err
    assert blocker.read_text() == "mine"


STARLOC = SHARED_DATA / "starloc"


@pytest.mark.skipif(not STARLOC.is_dir(), reason=f"the STAR-loc data folder {STARLOC} is absent")
def test_convert_starloc_then_map_in_3d(tmp_path, capsys):
    from lfmdr_gym.datasets.starloc import read_starloc
    from lfmdr_gym.histories.observation_table import read_landmarks, read_observations

    seq = STARLOC / "data" / "eight_s3"
    rays = tmp_path / "rays.parquet"
    assert main(["convert", "starloc", str(seq), "--sensor", "bearing", "--out", str(rays)]) == 0
    table = read_observations(rays)
    assert list(table.columns) == ["time", "landmark", "frame", "ray_x", "ray_y", "ray_z"]
    np.testing.assert_array_equal(table[["ray_x", "ray_y", "ray_z"]].to_numpy(),
                                  read_starloc(seq, "bearing")[["ray_x", "ray_y", "ray_z"]].to_numpy())
    out, truth, anchors = tmp_path / "obs.csv", tmp_path / "t.csv", tmp_path / "a.csv"
    assert main(["convert", "starloc", str(seq), "--out", str(out), "--landmarks", str(truth),
                 "--anchors", str(anchors), "--disparity-offset", "0.5"]) == 0
    np.testing.assert_allclose(read_observations(out)["range"].to_numpy(),
                               read_starloc(seq, "range-bearing", 0.5)["range"].to_numpy(),
                               rtol=1e-9)
    a, t = read_landmarks(anchors), read_landmarks(truth)
    assert list(a.columns) == ["landmark", "x", "y", "z"] and len(a) == 6
    assert set(a["landmark"]) <= set(read_observations(out)["landmark"]) <= set(t["landmark"])
    assert "eight_s3" in capsys.readouterr().out
    # the stereo log mapped in 3-D with the settings of the STAR-loc benchmark (its 0.027 m)
    params = ["bearing_noise=0.00349", "range_noise=0.01", "range_growth=0.008", "loss=huber",
              "anchor_noise=0.03", "fit_range_scale=True"]
    assert main(["map", str(out), "--anchors", str(anchors), "--truth", str(truth),
                 "--out", str(tmp_path / "m"), *(f"--param={p}" for p in params)]) == 0
    scores = json.loads((tmp_path / "m" / "scores.json").read_text())
    assert scores["mpe_nonanchor"] < 0.05 and scores["moe"] is None
    rows = list(csv.DictReader(open(tmp_path / "m" / "map.csv", newline="")))
    assert {"landmark", "x", "y", "z", "anchor", "mapped"} <= set(rows[0])


def test_a_recorded_3d_history_is_mapped_scored_and_drawn_in_3d(tmp_path, capsys):
    """``lfmdr collect --env LFMDR-Camera3D-v0`` then ``lfmdr map``: 3-D scores and files."""
    npz = tmp_path / "c3.npz"
    assert main(["collect", "--env", "LFMDR-Camera3D-v0", "--steps", "200", "--seed", "2",
                 "--env-kw", "bearing_noise_deg=1.0", "--env-kw", "range_noise=0.02",
                 "--out", str(npz)]) == 0
    assert main(["map", str(npz), "--out", str(tmp_path / "m")]) == 0
    printed = capsys.readouterr().out
    mpe, moe = re.search(r"MPE ([\d.]+) m .* tetrahedron orientation error ([\d.]+) %",
                         printed).groups()
    assert 0 < float(mpe) < 0.05 and float(moe) < 5.0, printed
    with open(tmp_path / "m" / "map.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["object", "x", "y", "z", "true_x", "true_y", "true_z", "anchor"]
    err = [np.linalg.norm([float(r[a]) - float(r[f"true_{a}"]) for a in "xyz"]) for r in rows]
    assert np.mean(err) == pytest.approx(float(mpe), abs=1e-4)  # the printed MPE, all objects


def test_uncertainty_puts_covariances_in_the_files_of_a_log_and_of_a_history(tmp_path, capsys):
    history, npz, log, anchors, _ = _episode(tmp_path, "LFMDR-Bearing-v0", steps=150)
    assert main(["map", str(log), "--anchors", str(anchors), "--out", str(tmp_path / "log"),
                 "--uncertainty", "model"]) == 0
    assert main(["map", str(npz), "--out", str(tmp_path / "npz"), "--uncertainty"]) == 0
    for out, key in ((tmp_path / "log", "landmark"), (tmp_path / "npz", "object")):
        with open(out / "map.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        assert list(rows[0])[-3:] == ["cov_xx", "cov_xy", "cov_yy"]
        anchor = np.array([r["anchor"] == "1" for r in rows])
        var = np.array([[float(r["cov_xx"]), float(r["cov_yy"])] for r in rows])
        assert np.all(var[anchor] == 0) and np.all(var[~anchor] > 0), out
        assert [int(r[key]) for r in rows] == list(range(history.n_objects))
    doc = json.loads((tmp_path / "log" / "map.json").read_text())
    assert all(len(e["covariance"]) == 2 for e in doc["landmarks"])
    with pytest.raises(SystemExit) as stop:
        main(["map", str(npz), "--uncertainty", "sandwich"])
    assert stop.value.code == 2
    assert "'sandwich' is not a kind of uncertainty" in capsys.readouterr().err
