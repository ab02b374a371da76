"""A resumable, crash-safe store of protocol results (one row per finished unit of work).

Why a journal: a protocol run takes minutes and must survive Ctrl-C and SIGKILL without losing or
duplicating a finished result. Every batch of rows is appended to ``journal.csv`` in one
``write`` and ``fsync``-ed before the call returns; each line ends with a CRC-32 of its text, so a
line torn by a crash (or by a full disk) is recognised, dropped and cut off on the next open.
``results.csv`` is a tidy, sorted copy of the journal rewritten atomically (temp file + rename)
at the end of a run and whenever asked; it is never the only copy of anything.

A run directory also holds ``manifest.json``: the settings that determine the rows. Opening the
directory with other settings raises :class:`SettingsMismatchError`, so runs are never mixed.
An exclusive advisory lock (``flock``) keeps two live runs from writing the same directory.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tempfile
import zlib
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from lfmdr_gym.atomic import atomic_write_text

try:  # advisory locking is POSIX-only; elsewhere the store simply runs unlocked
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

KEY_COLUMNS: tuple[str, ...] = ("sensor", "layout", "pose", "method", "param", "n_steps")
"""The columns that identify one unit of work: a row is written once per key (again only to
replace a failed one)."""

VALUE_COLUMNS: tuple[str, ...] = ("mpe", "moe", "mpe_nonanchor", "unmapped", "seconds", "error")
"""Scores of a unit (MPE [m] over the mapped objects, MOE [%], MPE over the mapped non-anchor
objects), how many objects were left unmapped (never sensed), the mapper's wall time [s], and the
error message when the mapper failed (empty otherwise; the scores are then NaN)."""

COLUMNS: tuple[str, ...] = KEY_COLUMNS + VALUE_COLUMNS

_INT_COLUMNS = frozenset({"layout", "pose", "n_steps", "unmapped"})
_FLOAT_COLUMNS = frozenset({"mpe", "moe", "mpe_nonanchor", "seconds"})

MANIFEST = "manifest.json"
JOURNAL = "journal.csv"
RESULTS = "results.csv"
_JOURNAL_HEADER = ",".join(COLUMNS) + ",crc\n"
# Before the sensor vocabulary was unified the first column was called "mode"; such run
# directories still resume.
_LEGACY = {"mode": "sensor"}
_LEGACY_HEADER = _JOURNAL_HEADER.replace("sensor,", "mode,", 1)


class SettingsMismatchError(ValueError):
    """The run directory was started with other settings; its rows must not be mixed with these."""


class StoreLockedError(ValueError):
    """Another live process is writing to the same run directory."""


Row = dict[str, Any]
Key = tuple[Any, ...]


def row_key(row: Mapping[str, Any]) -> Key:
    """The identity of a row: its (sensor, layout, pose, method, param, n_steps)."""
    return tuple(row[c] for c in KEY_COLUMNS)


def _format(value: Any) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else repr(value)  # repr round-trips exactly
    return str(value)


def _parse(column: str, text: str) -> Any:
    if column in _INT_COLUMNS:
        return int(text)
    if column in _FLOAT_COLUMNS:
        return float(text)
    return text


def _csv_line(values: Sequence[str]) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(values)
    return buf.getvalue()


def _journal_line(row: Mapping[str, Any]) -> bytes:
    body = _csv_line([_format(row[c]) for c in COLUMNS])[:-1]
    crc = zlib.crc32(body.encode())
    return f"{body},{crc:08x}\n".encode()


def _parse_journal_line(line: bytes) -> Row | None:
    """The row of one complete journal line, or None if it is torn or damaged."""
    try:
        text = line.decode()
    except UnicodeDecodeError:
        return None
    body, sep, crc = text.rpartition(",")
    if not sep or len(crc) != 8:
        return None
    try:
        if int(crc, 16) != zlib.crc32(body.encode()):
            return None
        values = next(csv.reader([body]))
        if len(values) != len(COLUMNS):
            return None
        return {c: _parse(c, v) for c, v in zip(COLUMNS, values, strict=True)}
    except (ValueError, StopIteration):
        return None


def _canonical(settings: Mapping[str, Any]) -> dict[str, Any]:
    """Settings as they read back from JSON (tuples become lists, keys strings; legacy names)."""
    out = json.loads(json.dumps(settings, sort_keys=True))
    return {_LEGACY.get(k, k): v for k, v in out.items()}


def ensure_writable_dir(path: str | os.PathLike) -> Path:
    """Create ``path`` if needed and check that files can be written in it (clear error if not)."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".write-probe.", dir=path)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ValueError(f"cannot write to output directory {str(path)!r}: {exc.strerror or exc}") from exc
    return path


class ResultStore:
    """Rows of finished work units in a run directory, appended durably and read back on resume.

    Args:
        directory: the run directory (created if missing; must be writable).
        settings: JSON-serialisable settings that determine the rows. Stored in
            ``manifest.json`` on first use; a later open with different settings raises
            :class:`SettingsMismatchError`.
        sort_key: optional function of a row giving the order of ``results.csv``
            (default: the key columns).

    Use as a context manager (or call :meth:`close`): it holds the journal open and locked.
    """

    def __init__(
        self,
        directory: str | os.PathLike,
        settings: Mapping[str, Any],
        *,
        sort_key: Any = None,
    ) -> None:
        self.directory = ensure_writable_dir(directory)
        self.settings = _canonical(settings)
        self._sort_key = sort_key or row_key
        self._rows: dict[Key, Row] = {}
        self.dropped_lines = 0
        """Torn or damaged journal lines found (and discarded) when the store was opened."""
        self._check_manifest()
        self._fh = open(self.directory / JOURNAL, "a+b")  # noqa: SIM115 - held for the store's life
        try:
            self._lock()
            self._load_journal()
        except BaseException:
            self._fh.close()
            raise

    # ------------------------------------------------------------------ opening
    def _check_manifest(self) -> None:
        path = self.directory / MANIFEST
        if path.exists():
            try:
                stored = _canonical(json.loads(path.read_text(encoding="utf-8")))
            except (OSError, ValueError) as exc:
                raise SettingsMismatchError(
                    f"{path} is unreadable ({exc}); this is not a usable lfmdr run directory"
                ) from exc
            if stored != self.settings:
                diffs = [
                    f"{k}: {json.dumps(stored.get(k))} in the directory, {json.dumps(self.settings.get(k))} now"
                    for k in sorted(set(stored) | set(self.settings))
                    if stored.get(k) != self.settings.get(k)
                ]
                raise SettingsMismatchError(
                    f"{self.directory} holds a run made with other settings ("
                    + "; ".join(diffs)
                    + "). Rerun with the same options to resume it, or choose another output directory."
                )
        else:
            if (self.directory / JOURNAL).exists():
                raise SettingsMismatchError(
                    f"{self.directory} holds a journal but no {MANIFEST}; refusing to mix results "
                    "(choose another output directory)"
                )
            atomic_write_text(path, json.dumps(self.settings, indent=2, sort_keys=True) + "\n")

    def _lock(self) -> None:
        if fcntl is None:  # pragma: no cover
            return
        try:
            fcntl.flock(self._fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError as exc:
            raise StoreLockedError(
                f"another lfmdr run is writing to {self.directory}; wait for it or stop it first"
            ) from exc

    def _load_journal(self) -> None:
        self._fh.seek(0)
        data = self._fh.read()
        if not data:
            self._append(_JOURNAL_HEADER.encode())
            return
        good_end = 0
        pos = 0
        while pos < len(data):
            nl = data.find(b"\n", pos)
            if nl < 0:  # a last line without its newline was torn by a crash
                self.dropped_lines += 1
                break
            line = data[pos:nl]
            if pos == 0:
                if (line + b"\n").decode(errors="replace") not in (_JOURNAL_HEADER, _LEGACY_HEADER):
                    raise SettingsMismatchError(
                        f"{self.directory / JOURNAL} has an unknown header; not an lfmdr journal"
                    )
            else:
                row = _parse_journal_line(line)
                if row is None:
                    self.dropped_lines += 1
                    pos = nl + 1
                    continue  # keep reading: only this line is damaged
                key = row_key(row)
                if key not in self._rows or self._rows[key]["error"]:
                    self._rows[key] = row  # a later row replaces a failed one
            pos = nl + 1
            good_end = pos
        if good_end < len(data):
            # Cut the torn tail off so that the next append starts on a fresh line.
            self._fh.truncate(good_end)
            self._fh.flush()
            os.fsync(self._fh.fileno())

    # ------------------------------------------------------------------ use
    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Release the journal (and its lock)."""
        if not self._fh.closed:
            self._fh.close()

    def __len__(self) -> int:
        return len(self._rows)

    def __contains__(self, key: object) -> bool:
        return key in self._rows

    @property
    def done(self) -> frozenset[Key]:
        """Keys of every unit already stored."""
        return frozenset(self._rows)

    @property
    def failed(self) -> frozenset[Key]:
        """Keys of the stored units whose mapper failed (a resume computes them again)."""
        return frozenset(k for k, r in self._rows.items() if r["error"])

    def rows(self) -> list[Row]:
        """All stored rows, sorted for ``results.csv``."""
        return sorted(self._rows.values(), key=self._sort_key)

    def _append(self, data: bytes) -> None:
        self._fh.seek(0, os.SEEK_END)
        self._fh.write(data)
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def add(self, rows: Iterable[Mapping[str, Any]]) -> int:
        """Durably append the rows not stored yet, or replacing a failed one (one write + fsync);
        return how many were new."""
        new: dict[Key, Row] = {}
        for row in rows:
            missing = [c for c in COLUMNS if c not in row]
            if missing:
                raise ValueError(f"row lacks the columns {missing}: {dict(row)}")
            # One line per row in the journal: multi-line text (an error message) is flattened.
            clean = {
                c: " ".join(row[c].split()) if isinstance(row[c], str) else row[c] for c in COLUMNS
            }
            key = row_key(clean)
            if (key not in self._rows or self._rows[key]["error"]) and key not in new:
                new[key] = clean
        if new:
            self._append(b"".join(_journal_line(r) for r in new.values()))
            self._rows.update(new)
        return len(new)

    def write_results(self) -> Path:
        """Atomically (re)write ``results.csv`` from every stored row; return its path."""
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(COLUMNS)
        for row in self.rows():
            writer.writerow([_format(row[c]) for c in COLUMNS])
        path = self.directory / RESULTS
        atomic_write_text(path, buf.getvalue())
        return path


def read_results(path: str | os.PathLike) -> list[Row]:
    """Rows of a ``results.csv`` with typed values (ints, floats; NaN for failed units)."""
    path = Path(path)
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        names = [_LEGACY.get(c, c) for c in reader.fieldnames or ()]
        if names[: len(COLUMNS)] != list(COLUMNS):
            raise ValueError(f"{path} is not an lfmdr results.csv (columns {reader.fieldnames})")
        return [{c: _parse(c, v) for c, v in zip(names, r.values(), strict=False) if c in COLUMNS}
                for r in reader]
