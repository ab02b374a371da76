"""ResultStore: durable appends, torn-line recovery, no duplicates, settings guard, atomic results."""

from __future__ import annotations

import math
import os

import pytest

from lfmdr_gym.experiments.store import (
    COLUMNS,
    JOURNAL,
    RESULTS,
    ResultStore,
    SettingsMismatchError,
    StoreLockedError,
    read_results,
    row_key,
)

SETTINGS = {"sensor": "visibility", "steps": 200, "methods": ["LPCA", "SDE"]}


def _row(layout: int, pose: int, method: str = "LPCA", param: str = "-", n: int = 100, **kw):
    row = {
        "sensor": "visibility",
        "layout": layout,
        "pose": pose,
        "method": method,
        "param": param,
        "n_steps": n,
        "mpe": 0.1 + layout + pose / 10,
        "moe": 2.5,
        "mpe_nonanchor": 0.12,
        "unmapped": 0,
        "seconds": 0.01,
        "error": "",
    }
    row.update(kw)
    return row


def test_rows_survive_reopen_and_are_not_duplicated(tmp_path):
    with ResultStore(tmp_path, SETTINGS) as store:
        assert store.add([_row(0, 0), _row(0, 1)]) == 2
        assert store.add([_row(0, 0), _row(1, 0)]) == 1  # (0, 0) already there
    with ResultStore(tmp_path, SETTINGS) as store:
        assert len(store) == 3
        assert row_key(_row(1, 0)) in store.done
        assert store.add([_row(0, 1)]) == 0
        store.write_results()
    rows = read_results(tmp_path / RESULTS)
    assert [(r["layout"], r["pose"]) for r in rows] == [(0, 0), (0, 1), (1, 0)]
    assert rows[0]["mpe"] == _row(0, 0)["mpe"]  # floats round-trip exactly


def test_failed_unit_keeps_nan_and_message(tmp_path):
    with ResultStore(tmp_path, SETTINGS) as store:
        store.add([_row(0, 0, mpe=math.nan, moe=math.nan, error='boom, "quoted"\nline')])
    with ResultStore(tmp_path, SETTINGS) as store:
        (row,) = store.rows()
    assert math.isnan(row["mpe"]) and row["error"] == 'boom, "quoted" line'


def test_failed_unit_is_replaced_by_a_later_result(tmp_path):
    """An interrupted worker's "failure" must not stick: resume computes it again."""
    with ResultStore(tmp_path, SETTINGS) as store:
        store.add([_row(0, 0, mpe=math.nan, error="KeyboardInterrupt"), _row(0, 1)])
        assert store.failed == {row_key(_row(0, 0))} and len(store) == 2
        assert store.add([_row(0, 1, mpe=9.0)]) == 0  # a good row is never replaced
    with ResultStore(tmp_path, SETTINGS) as store:
        assert store.failed == {row_key(_row(0, 0))}
        assert store.add([_row(0, 0)]) == 1
        assert not store.failed
    with ResultStore(tmp_path, SETTINGS) as store:  # the journal keeps both; the later one wins
        rows = {(r["layout"], r["pose"]): r for r in store.rows()}
        assert rows[(0, 0)]["error"] == "" and rows[(0, 0)]["mpe"] == _row(0, 0)["mpe"]
        assert rows[(0, 1)]["mpe"] == _row(0, 1)["mpe"] and len(store) == 2


def test_run_written_with_the_old_mode_column_resumes(tmp_path):
    """Run directories from before "mode" was renamed "sensor" still open and resume."""
    with ResultStore(tmp_path, SETTINGS) as store:
        store.add([_row(0, 0)])
        store.write_results()
    for name in (JOURNAL, RESULTS):
        path = tmp_path / name
        path.write_text(path.read_text().replace("sensor,", "mode,", 1))
    manifest = tmp_path / "manifest.json"
    manifest.write_text(manifest.read_text().replace('"sensor"', '"mode"'))
    with ResultStore(tmp_path, SETTINGS) as store:
        assert len(store) == 1 and store.add([_row(0, 1)]) == 1
    assert [r["sensor"] for r in read_results(tmp_path / RESULTS)] == ["visibility"]
    with ResultStore(tmp_path, SETTINGS) as store:
        assert len(store) == 2


def test_torn_last_line_is_dropped_and_cut_off(tmp_path):
    with ResultStore(tmp_path, SETTINGS) as store:
        store.add([_row(0, 0), _row(0, 1)])
    journal = tmp_path / JOURNAL
    data = journal.read_bytes()
    # Simulate a crash in the middle of writing the last line.
    journal.write_bytes(data[:-7])
    with ResultStore(tmp_path, SETTINGS) as store:
        assert store.dropped_lines == 1
        assert len(store) == 1
        store.add([_row(0, 1)])
    with ResultStore(tmp_path, SETTINGS) as store:
        assert store.dropped_lines == 0  # the torn tail was cut, the re-added row is intact
        assert len(store) == 2


def test_damaged_line_with_valid_shape_is_rejected_by_crc(tmp_path):
    with ResultStore(tmp_path, SETTINGS) as store:
        store.add([_row(0, 0), _row(0, 1)])
    journal = tmp_path / JOURNAL
    lines = journal.read_bytes().split(b"\n")
    lines[1] = lines[1].replace(b"0.1,", b"0.7,", 1)  # a flipped digit keeps the CSV shape
    journal.write_bytes(b"\n".join(lines))
    with ResultStore(tmp_path, SETTINGS) as store:
        assert store.dropped_lines == 1
        assert len(store) == 1


def test_other_settings_are_refused(tmp_path):
    with ResultStore(tmp_path, SETTINGS) as store:
        store.add([_row(0, 0)])
    with pytest.raises(SettingsMismatchError, match="steps: 200 in the directory, 400 now"):
        ResultStore(tmp_path, {**SETTINGS, "steps": 400})
    # tuples and lists are the same setting once stored as JSON
    ResultStore(tmp_path, {**SETTINGS, "methods": ("LPCA", "SDE")}).close()


def test_second_live_writer_is_refused(tmp_path):
    with ResultStore(tmp_path, SETTINGS):
        with pytest.raises(StoreLockedError, match="another lfmdr run"):
            ResultStore(tmp_path, SETTINGS)
    ResultStore(tmp_path, SETTINGS).close()  # lock released on close


def test_unwritable_directory_is_a_clear_error(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    with pytest.raises(ValueError, match="cannot write to output directory"):
        ResultStore(blocker / "run", SETTINGS)


def test_incomplete_row_is_refused(tmp_path):
    with ResultStore(tmp_path, SETTINGS) as store:
        row = _row(0, 0)
        del row["moe"]
        with pytest.raises(ValueError, match="moe"):
            store.add([row])


def test_results_csv_is_replaced_atomically(tmp_path):
    with ResultStore(tmp_path, SETTINGS) as store:
        store.add([_row(0, 0)])
        store.write_results()
        store.add([_row(0, 1)])
        store.write_results()
    text = (tmp_path / RESULTS).read_text()
    assert text.splitlines()[0] == ",".join(COLUMNS)
    assert len(text.splitlines()) == 3
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]
