"""Helpers to fuzz the project's file readers (issue 35): damaged copies of a good file, and a
reader run over many files in a child process with a time limit.

A reader given a damaged file must either read it (then what it read is checked by the test) or
raise the project's own error (``HistoryFileError``, ...) within seconds: never hang, crash the
interpreter, or raise anything else. The child process makes a hang or a crash a test failure
naming the file instead of taking the test run down with it; one child reads a whole batch of
files, so hundreds of cases cost one interpreter start.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import subprocess
import sys
import textwrap
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
from paths import ROOT

TIME_LIMIT = 60.0
"""Seconds a child may take for a whole batch (a few hundred reads, each well under a second):
a hang shows up as a timeout naming the file being read."""


def truncated(data: bytes, length: int) -> bytes:
    """The first ``length`` bytes of ``data`` (a file cut short, as by a full disk or a copy
    interrupted)."""
    return data[:length]


def bit_flipped(data: bytes, bits: Iterable[int]) -> bytes:
    """``data`` with each bit whose index (0 .. 8 * len(data) - 1) is in ``bits`` inverted."""
    out = bytearray(data)
    for bit in bits:
        out[bit // 8] ^= 1 << (bit % 8)
    return bytes(out)


def npz_bytes(arrays: Mapping[str, np.ndarray], compressed: bool = True) -> bytes:
    """An .npz archive of ``arrays`` (as ``numpy.savez[_compressed]`` writes it), in memory."""
    buffer = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buffer, **arrays)
    return buffer.getvalue()


def npz_arrays(data: bytes) -> dict[str, np.ndarray]:
    """The arrays of an .npz archive held in memory."""
    with np.load(io.BytesIO(data), allow_pickle=False) as archive:
        return {name: archive[name] for name in archive.files}


_READER = textwrap.dedent("""
    import importlib, json, sys, traceback
    module, name, expected = sys.argv[1:4]
    reader = getattr(importlib.import_module(module), name)
    errors = tuple(getattr(importlib.import_module(m), n)
                   for m, n in (e.rsplit(".", 1) for e in expected.split(",")))
    for line in sys.stdin:
        path = line.strip()
        print(json.dumps({"path": path, "start": True}), flush=True)
        try:
            result = reader(path)
        except errors as exc:
            outcome = {"error": type(exc).__name__, "message": str(exc)[:300]}
        except BaseException as exc:  # anything else is a finding: reported, not raised
            outcome = {"unexpected": type(exc).__name__, "message": str(exc)[:300],
                       "traceback": traceback.format_exc()[-2000:]}
        else:
            outcome = {"read": True, "summary": result}
        print(json.dumps({"path": path, **outcome}, default=repr), flush=True)
""")


def read_all(paths: list[Path], reader: str, errors: Iterable[str],
             time_limit: float = TIME_LIMIT) -> dict[str, dict]:
    """Read each of ``paths`` with ``reader`` (``"module:function"``, a function of a path that
    returns something JSON can write, a summary of what it read) in one child process; return
    path -> outcome: ``{"read": True, "summary": ...}``, ``{"error": name, "message": ...}`` for
    an exception of ``errors`` (dotted names), or ``{"unexpected": name, ...}`` for any other.

    Raises AssertionError naming the file when the child hangs (beyond ``time_limit`` seconds for
    the batch) or dies (a crash of the interpreter)."""
    module, name = reader.split(":")
    env_path = os.pathsep.join([str(ROOT), str(ROOT / "tests")])
    try:
        run = subprocess.run(
            [sys.executable, "-c", _READER, module, name, ",".join(errors)],
            input="".join(f"{p}\n" for p in paths), capture_output=True, text=True,
            timeout=time_limit, cwd=ROOT, env={**_env(), "PYTHONPATH": env_path},
        )
        stdout, code = run.stdout, run.returncode
    except subprocess.TimeoutExpired as exc:
        stdout = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        raise AssertionError(f"reading hung (over {time_limit} s): last file started "
                             f"{_last_started(stdout)}") from exc
    if code != 0:
        raise AssertionError(f"the reader's interpreter died (exit code {code}) reading "
                             f"{_last_started(stdout)}: {run.stderr[-2000:]}")
    outcomes = {}
    for line in stdout.splitlines():
        record = json.loads(line)
        if "start" not in record:
            outcomes[record.pop("path")] = record
    missing = [str(p) for p in paths if str(p) not in outcomes]
    assert not missing, f"no outcome for {missing[:3]}"
    return outcomes


def _last_started(stdout: str) -> str:
    starts = [json.loads(line)["path"] for line in stdout.splitlines()
              if line.strip() and '"start"' in line]
    return starts[-1] if starts else "(none)"


def _env() -> dict[str, str]:
    # one BLAS thread: the child only reads files
    return {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


def _digest(value) -> str | None:
    if value is None:
        return None
    if isinstance(value, Mapping):
        return json.dumps({k: _digest(v) for k, v in sorted(value.items())})
    value = np.asarray(value)
    return f"{value.dtype}{value.shape}:{hashlib.sha256(value.tobytes()).hexdigest()[:16]}"


def history_summary(path) -> dict:
    """What :meth:`lfmdr_gym.histories.history.History.load` read from ``path``, as digests of
    its fields (dense matrix and mask included), to compare with the history saved."""
    from lfmdr_gym.histories.history import History

    history = History.load(path)
    return summary_of(history)


def summary_of(history) -> dict:
    """Digests of a history's fields (see :func:`history_summary`)."""
    return {"sensor": history.sensor, "meta": json.dumps(history.meta, sort_keys=True),
            **{name: _digest(getattr(history, name)) for name in (
                "matrix", "mask", "object_positions", "anchor_ids", "anchor_positions",
                "robot_poses", "timeline")}}


def table_summary(path) -> dict:
    """What :func:`lfmdr_gym.histories.observation_table.read_observations` read from
    ``path``: its size, columns and attrs (a damaged CSV can read as another valid table: CSV
    has no checksum)."""
    from lfmdr_gym.histories.observation_table import read_observations

    table = read_observations(path)
    return {"rows": len(table), "columns": list(table.columns), "attrs": table.attrs}


BAG_TOPIC = "/tag_detections"
"""The detection topic of the fuzzed bags (``rosbag_write.write_detection_bag``'s default)."""


def rosbag_summary(path) -> dict:
    """What :func:`lfmdr_gym.datasets.rosbag.read_rosbag` read from the bag at ``path`` (its
    detections on :data:`BAG_TOPIC`, pixels through ``/camera_info``): size and columns."""
    from lfmdr_gym.datasets.rosbag import read_rosbag

    table = read_rosbag(path, BAG_TOPIC, camera_info_topic="/camera_info")
    return {"rows": len(table), "columns": list(table.columns)}
