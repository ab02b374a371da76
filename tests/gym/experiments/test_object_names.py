"""lfmdr_gym.experiments.object_names: a map's warnings name landmark ids, not history rows."""

from types import SimpleNamespace

import numpy as np
import pytest
from paths import SHARED_DATA

from lfmdr_gym.experiments.object_names import landmark_notes, rows_with_data

STARLOC_EIGHT = SHARED_DATA / "starloc" / "data" / "eight_s3"


def _history(matrix, mask=None):
    return SimpleNamespace(matrix=np.asarray(matrix, dtype=float), mask=mask)


def test_rows_become_the_logs_ids_and_a_methods_rows_count_those_with_data():
    ids = ["door", "desk", 7, np.int64(12)]
    h = _history([[0, 0], [1, 0], [0, 1], [1, 1]])  # "door" has no observation
    notes = ["objects [0, 3] could not be placed from their histories",
             "LOC-SMA: RigidityWarning: groups [[0], [1, 2]] fall apart",
             "2 of 4 anchors kept; sizes [3, 1]"]
    said = landmark_notes(notes, ids, h)
    assert said[0] == "landmarks [door, 12] could not be placed from their histories"
    # the method was given rows 1-3 (those with data): its row 0 is "desk"
    assert said[1] == "LOC-SMA: RigidityWarning: groups of landmarks [[desk], [7, 12]] fall apart"
    assert said[2] == notes[2]  # no object phrase: left as it is


def test_the_rows_with_data_of_a_fused_history_are_those_of_any_part():
    bearing = _history([[1, 0], [0, 0], [0, 0]])
    rng = _history([[0, 0], [0, 2.0], [0, 3.0]], mask=np.array([[1, 1], [1, 1], [0, 0]], bool))
    np.testing.assert_array_equal(rows_with_data({"bearing": bearing, "range": rng}), [0, 1])


@pytest.mark.skipif(not STARLOC_EIGHT.is_dir(), reason="no STAR-loc data here")
def test_lfmdr_map_prints_the_unplaced_tags_by_their_ids(tmp_path, capsys):
    from lfmdr_gym.cli import main

    table = tmp_path / "eight.csv"
    assert main(["convert", "starloc", str(STARLOC_EIGHT), "--out", str(table), "--landmarks",
                 str(tmp_path / "survey.csv"), "--anchors", str(tmp_path / "anchors.csv")]) == 0
    assert main(["map", str(table), "--anchors", str(tmp_path / "anchors.csv"),
                 "--out", str(tmp_path / "m")]) == 0
    out = capsys.readouterr().out
    unmapped = next(line for line in out.splitlines() if line.startswith("unmapped landmarks: "))
    ids = unmapped.removeprefix("unmapped landmarks: ")
    assert f"warning: landmarks {ids} could not be placed" in out, out
