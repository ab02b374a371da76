"""Damaged history files, fuzzed (issue 35): truncated, bit-flipped and mislabelled ``.npz``
histories give :class:`HistoryFileError` within seconds, or (where the damage missed everything
the history is made of) the very history that was saved; never a hang, a crash of the
interpreter, another exception or a silently different history.

The files are read in a child process (``tests/fuzzing.py``), a batch at a time, so that a hang
or a crash fails the test naming the file. The default run reads a few hundred files (cut points
spread over the file, a few hundred random flips, every field of three kinds of history replaced
by each of a list of wrong values); ``-m slow`` cuts at every byte and flips thousands.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from fuzzing import (
    bit_flipped,
    npz_arrays,
    npz_bytes,
    read_all,
    summary_of,
    truncated,
)

from lfmdr_gym.histories.history import History, HistoryFileError

ERRORS = ["lfmdr_gym.histories.history.HistoryFileError"]
READER = "fuzzing:history_summary"


def _histories() -> dict[str, History]:
    """A dense masked bearing history (with poses and a timeline), a compact (sparse) masked
    visibility one and a fused range-bearing one: between them every field a file can hold."""
    rng = np.random.default_rng(0)
    m = rng.normal(size=(6, 8))
    common = {"object_positions": rng.uniform(-1, 1, (6, 2)), "anchor_ids": np.array([0, 2, 5]),
              "anchor_positions": rng.uniform(-1, 1, (3, 2)), "meta": {"seed": 3, "n": [1, 2]}}
    return {
        "dense": History(sensor="bearing", matrix=m, robot_poses=rng.uniform(-1, 1, (4, 3)),
                         mask=rng.uniform(size=m.shape) > 0.3,
                         timeline=np.column_stack([np.zeros(4, int), np.arange(4)]), **common),
        "sparse": History(sensor="visibility",
                          matrix=sp.csr_array((rng.uniform(size=(6, 8)) > 0.6).astype(float)),
                          mask=sp.csr_array(rng.uniform(size=(6, 8)) > 0.2), **common),
        "fused": History(sensor="range-bearing",
                         matrix={"range": np.abs(m), "bearing": np.repeat(m, 2, axis=1)},
                         mask={"range": rng.uniform(size=m.shape) > 0.3, "bearing": None},
                         **common),
    }


HISTORIES = _histories()


DEFAULT_AND_MANY = pytest.mark.parametrize(
    "slow", [False, pytest.param(True, marks=pytest.mark.slow)], ids=["default", "many"])
"""A fuzz test's default run, and its many-cases run under ``-m slow``."""


def _read_checked(paths: list, expected: dict, slow: bool) -> tuple[list, dict]:
    """``(paths, outcomes)``: every file read in a child process (:func:`read_all`), each
    outcome checked against ``expected`` (:func:`_check`)."""
    outcomes = read_all(paths, READER, ERRORS, time_limit=600.0 if slow else 120.0)
    _check(outcomes, expected)
    return paths, outcomes


def _check(outcomes: dict, expected: dict) -> None:
    """Every file gave HistoryFileError, or read back as ``expected[path]`` (None: any history
    the reader accepted)."""
    unexpected = {p: o for p, o in outcomes.items() if "unexpected" in o}
    assert not unexpected, f"{len(unexpected)} file(s) raised another error, e.g. " \
                           f"{next(iter(unexpected.items()))}"
    for path, outcome in outcomes.items():
        if "read" in outcome and expected[path] is not None:
            assert outcome["summary"] == expected[path], f"{path} read as another history"


def _damaged(tmp_path, slow: bool) -> tuple[list, dict]:
    """Truncated and bit-flipped copies of each history's file: the paths and, for each, the
    history it must read as if it reads at all."""
    rng = np.random.default_rng(35)
    paths, expected = [], {}
    for name, history in HISTORIES.items():
        good = history.save(tmp_path / f"{name}.npz").read_bytes()
        want = summary_of(history)
        cuts = range(len(good)) if slow else np.linspace(0, len(good) - 1, 40).astype(int)
        copies = [(f"cut{k}", truncated(good, k)) for k in cuts]
        for k in range(1000 if slow else 70):
            bits = rng.integers(0, 8 * len(good), rng.integers(1, 4))
            copies.append((f"flip{k}", bit_flipped(good, bits)))
        for label, data in copies:
            path = tmp_path / f"{name}-{label}.npz"
            path.write_bytes(data)
            paths.append(path)
            expected[str(path)] = want
    return paths, expected


@DEFAULT_AND_MANY
def test_truncated_and_bit_flipped_files(tmp_path, slow):
    paths, outcomes = _read_checked(*_damaged(tmp_path, slow), slow)
    errors = sum("error" in o for o in outcomes.values())
    assert errors > 0.8 * len(paths)  # the damage is real: most files are refused


WRONG_VALUES = [
    np.array("x"), np.array(b"\xff"), np.array(3), np.array(-1), np.array(2**62), np.array(1.5),
    np.array(np.nan), np.array([]), np.zeros((0, 2)), np.zeros((2, 2, 2)), np.array([1, 2]),
    np.array(["range", "x"]), np.array([True]), np.array([1 + 2j]), np.full((6, 2), np.inf),
    np.array([10**12, 10**12]), np.array([-3, 4]), np.ones((6, 16)), np.ones(7),
    np.array('{"a":'), np.array("[1, 2]"), np.array([0, 2**40]), np.array([[0, 1], [2, 3]]),
]
"""Values put in place of a field: strings where numbers belong, numbers where strings do,
wrong shapes and sizes, negative, huge and non-finite numbers, broken JSON."""


def _mislabelled(tmp_path, slow: bool) -> tuple[list, dict]:
    """Each history's file with a field dropped, replaced by a wrong value, or swapped with
    another: all of them with ``slow``, else every field dropped, every field given every
    fourth wrong value (a different quarter for each field) and 15 swaps per history."""
    rng = np.random.default_rng(35)
    paths, expected = [], {}
    for name, history in HISTORIES.items():
        arrays = npz_arrays(history.save(tmp_path / f"{name}.npz").read_bytes())
        variants = [(f"{field}-dropped", {k: v for k, v in arrays.items() if k != field})
                    for field in arrays]
        variants += [(f"{field}-{j}", {**arrays, field: value})
                     for f, field in enumerate(arrays) for j, value in enumerate(WRONG_VALUES)
                     if slow or (j + f) % 4 == 0 or field in _CHECKED]
        swaps = [(a, b) for a in arrays for b in arrays if a < b]
        if not slow:
            swaps = [swaps[k] for k in rng.choice(len(swaps), 15, replace=False)]
        variants += [(f"{a}-as-{b}", {**arrays, a: arrays[b], b: arrays[a]}) for a, b in swaps]
        for label, fields in variants:
            path = tmp_path / f"{name}-{label}.npz"
            path.write_bytes(npz_bytes(fields))
            paths.append(path)
            expected[str(path)] = None  # a wrong value may still make a valid history
    return paths, expected


_CHECKED = ("format_version", "sensors", "meta", "mask_shape", "matrix_shape")
"""The fields :func:`test_mislabelled_fields` checks by name: given every wrong value."""


@DEFAULT_AND_MANY
def test_mislabelled_fields(tmp_path, slow):
    paths, outcomes = _read_checked(*_mislabelled(tmp_path, slow), slow)
    read = [p for p, o in outcomes.items() if "read" in o]
    assert len(read) < 0.05 * len(paths)  # nearly every such file is refused
    # each of these is a history of another shape or kind: refused, never read half-way
    for label in ("format_version-5", "sensors-0", "meta-7", "meta-20",
                  "mask_shape-dropped", "mask_indptr-dropped", "matrix_shape-16"):
        name = "fused" if label.startswith("sensors") else \
            "sparse" if label.startswith(("mask_", "matrix_shape")) else "dense"
        outcome = outcomes[str(tmp_path / f"{name}-{label}.npz")]
        assert "error" in outcome, (label, outcome)


def test_load_names_the_field_of_the_wrong_kind(tmp_path):
    arrays = npz_arrays(HISTORIES["sparse"].save(tmp_path / "h.npz").read_bytes())
    for field, value, words in [
        ("format_version", np.array(1.5), "no integer format version"),
        ("meta", np.array("[1, 2]"), "JSON object"),
        ("mask_shape", np.array([[6], [8]]), "'mask_shape' must be two non-negative integers"),
        ("matrix_shape", np.array([-6, 8]), "'matrix_shape' must be two non-negative integers"),
    ]:
        path = tmp_path / f"{field}.npz"
        path.write_bytes(npz_bytes({**arrays, field: value}))
        with pytest.raises(HistoryFileError, match=words):
            History.load(path)
    path = tmp_path / "orphan.npz"  # a sparse mask's entries without its shape: not dropped
    path.write_bytes(npz_bytes({k: v for k, v in arrays.items() if k != "mask_shape"}))
    with pytest.raises(HistoryFileError, match="mask_shape"):
        History.load(path)
