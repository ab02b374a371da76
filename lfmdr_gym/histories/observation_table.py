"""The observation table: one row per sighting, as CSV or Parquet (issue 33).

A robot's log of "at time t, robot r saw landmark k at bearing b (and range d)" is a
``pandas.DataFrame`` with these columns (the guide ``docs/guide/observations.md`` has examples):

| column | meaning |
|---|---|
| ``time`` | [s], required. |
| ``landmark`` | required; integer or string id (strings stay strings, also in maps). |
| ``robot`` | optional integer or string id; absent: one robot. |
| ``frame`` | optional integer; rows with the same ``robot`` and ``frame`` were taken from one pose (absent: rows with the same ``robot`` and ``time``). |
| ``bearing`` | [rad], sensor frame, counter-clockwise, 2-D; within [-2 pi, 2 pi]. |
| ``bearing_cos``, ``bearing_sin`` | the bearing as its unit vector (cos, sin), instead of or beside ``bearing``: kept bit for bit (what ``history_to_observations`` writes). |
| ``ray_x``, ``ray_y``, ``ray_z`` | a direction in the sensor's frame (3-D, any length but not 0); camera optical frame: z forward, x right, y down. With 2-D anchors it is projected to ``bearing = atan2(-ray_x, ray_z)``. |
| ``range`` | [m], >= 0. |
| ``visible`` | optional 0/1: 0 marks an observed entry that did not see the landmark (a camera that looked and missed); absent: every row is a sighting. |

Any subset of the measurements may be given (none: visibility only). Other columns are allowed,
kept, and not used; a column that differs from a known name only in case or spaces is an error.

Metadata (``DataFrame.attrs``, a JSON-serialisable dict: ``source``, ``sensor``, ``bin_width``,
...) is stored in Parquet's schema metadata (key ``lfmdr``) and in CSV as leading comment lines
``# key: json-value``. Anchors and ground truth are small tables ``landmark, x, y`` (and ``z`` in
3-D): :func:`read_landmarks`.

Every reader checks what it reads (:func:`check_observations`, :func:`check_landmarks`); a
problem is an :class:`ObservationTableError` naming the file's line (or the row) and the column.
Writers write atomically (:mod:`lfmdr_gym.atomic`).
"""

from __future__ import annotations

import json
import math
import os
import re
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from lfmdr_gym.atomic import atomic_write

__all__ = [
    "LANDMARK_COLUMNS",
    "MEASUREMENT_COLUMNS",
    "ObservationTableError",
    "check_landmarks",
    "check_observations",
    "checked_ids",
    "read_landmarks",
    "read_observations",
    "write_landmarks",
    "write_observations",
]

REQUIRED_COLUMNS = ("time", "landmark")
KEY_COLUMNS = ("robot", "frame")
MEASUREMENT_COLUMNS = ("bearing", "bearing_cos", "bearing_sin", "ray_x", "ray_y", "ray_z",
                       "range", "visible")
"""The measurement columns a table may hold (any subset)."""
LANDMARK_COLUMNS = ("landmark", "x", "y", "z")
"""Columns of an anchors or ground-truth table (``z`` only in 3-D)."""
KNOWN_COLUMNS = REQUIRED_COLUMNS + KEY_COLUMNS + MEASUREMENT_COLUMNS
GROUPS = (("bearing_cos", "bearing_sin"), ("ray_x", "ray_y", "ray_z"))
"""Columns that only come together."""
MAX_BEARING = 2 * math.pi
UNIT_TOLERANCE = 1e-6
"""``bearing_cos, bearing_sin`` must be a unit vector to this tolerance."""
BEARING_AGREEMENT = 1e-6
"""[rad] how far two givens of one bearing (angle, unit vector, ray) may differ."""
CSV_SUFFIXES = (".csv", ".tsv", ".txt")
PARQUET_SUFFIXES = (".parquet", ".pq")
PARQUET_KEY = b"lfmdr"
_INT = re.compile(r"^-?(0|[1-9][0-9]*)$")


class ObservationTableError(ValueError):
    """An observation, anchors or ground-truth table that cannot be used (the message names the
    file, line or row, and column)."""


# ------------------------------------------------------------------------------ locations
class _Where:
    """How errors name a row: a file's line (CSV), or a row number (Parquet, a DataFrame)."""

    def __init__(self, name: str | None, first_line: int | None) -> None:
        self.name, self.first_line = name, first_line

    def __call__(self, position: int, column: str | None = None) -> str:
        at = (f"line {position + self.first_line}" if self.first_line is not None
              else f"row {position}")
        where = f"{self.name} {at}" if self.name else at
        return where + (f", column {column!r}" if column else "")

    def table(self) -> str:
        return self.name or "the table"


def _show(value: Any) -> str:
    """A value as errors quote it (numpy scalars as plain Python ones)."""
    return repr(value.item() if isinstance(value, np.generic) else value)


def _fail(where: _Where, position: int, column: str | None, message: str,
          n_bad: int = 1) -> None:
    more = f" ({n_bad - 1} more row(s) like it)" if n_bad > 1 else ""
    raise ObservationTableError(f"{where(position, column)}: {message}{more}")


# ----------------------------------------------------------------------------- ids
def normalise_ids(values: pd.Series, what: str, where: _Where) -> pd.Series:
    """Ids as int64, or as Python strings (a string that spells an integer canonically, "7" not
    "007", becomes that integer, so a CSV's ids read as they were written); missing or other
    types are an error naming the row."""
    missing = values.isna().to_numpy()
    if missing.any():
        pos = int(np.flatnonzero(missing)[0])
        _fail(where, pos, what, f"missing {what} id", int(missing.sum()))
    if pd.api.types.is_bool_dtype(values.dtype):
        raise ObservationTableError(f"{where.table()}: column {what!r} holds booleans; ids are "
                                    "integers or strings")
    if pd.api.types.is_integer_dtype(values.dtype):
        return values.astype(np.int64)
    if pd.api.types.is_float_dtype(values.dtype):
        arr = values.to_numpy()
        bad = arr != np.round(arr)
        if bad.any():
            pos = int(np.flatnonzero(bad)[0])
            _fail(where, pos, what, f"{what} id {_show(arr[pos])} is neither an integer nor a string",
                  int(bad.sum()))
        return values.astype(np.int64)
    # the types are checked on the distinct ids, not row by row (a log has few landmarks)
    codes, uniques = pd.factorize(values)
    arr = np.asarray(uniques, dtype=object)
    is_str = np.fromiter((isinstance(v, str) for v in arr), bool, len(arr))
    is_int = np.fromiter((isinstance(v, int | np.integer) and not isinstance(v, bool | np.bool_)
                          for v in arr), bool, len(arr))
    if is_int.all():
        return pd.Series(arr.astype(np.int64)[codes], index=values.index)
    bad = ~(is_str | is_int)
    if bad.any():
        rows = bad[codes]
        pos = int(np.flatnonzero(rows)[0])
        v = arr[codes[pos]]
        _fail(where, pos, what, f"{what} id {_show(v)} ({type(v).__name__}) is neither an "
              "integer nor a string", int(rows.sum()))
    if not is_str.all():
        rows = ~is_str[codes]
        pos = int(np.flatnonzero(rows)[0])
        _fail(where, pos, what, f"{what} ids mix integers and strings ({_show(arr[codes[pos]])} "
              "among strings); give them all as one or the other", int(rows.sum()))
    if len(arr) and pd.Series(arr).str.fullmatch(_INT).all():
        # a string of 19 or more digits may be beyond int64 (astype would raise OverflowError)
        big = [k for k, v in enumerate(arr) if len(v) > 18 and not -2**63 <= int(v) < 2**63]
        if big:
            rows = np.isin(codes, big)
            pos = int(np.flatnonzero(rows)[0])
            _fail(where, pos, what, f"{what} id {arr[codes[pos]]} does not fit in 64 bits",
                  int(rows.sum()))
        return pd.Series(arr.astype(np.int64)[codes], index=values.index)
    return pd.Series(arr[codes], index=values.index, dtype=object)


# ------------------------------------------------------------------------------ checks
def _numeric(table: pd.DataFrame, column: str, where: _Where) -> np.ndarray:
    """A column as finite float64, else an error naming the first bad line."""
    col = table[column]
    if pd.api.types.is_bool_dtype(col.dtype):
        raise ObservationTableError(f"{where.table()}: column {column!r} holds booleans, "
                                    "not numbers")
    values = pd.to_numeric(col, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
    bad = ~np.isfinite(values)
    if bad.any():
        pos = int(np.flatnonzero(bad)[0])
        raw = col.iloc[pos]
        kind = ("missing" if pd.isna(raw) else "not a number" if np.isnan(values[pos]) else
                "not finite")
        _fail(where, pos, column, f"{_show(raw)} is {kind}; every {column} must be a finite number",
              int(bad.sum()))
    return values


def _first(where: _Where, bad: np.ndarray, column: str, message: Callable[[int], str]) -> None:
    if bad.any():
        pos = int(np.flatnonzero(bad)[0])
        _fail(where, pos, column, message(pos), int(bad.sum()))


def _check_columns(table: pd.DataFrame, where: _Where) -> None:
    if not isinstance(table, pd.DataFrame):
        raise ObservationTableError(f"an observation table is a pandas DataFrame, got "
                                    f"{type(table).__name__}")
    names = [str(c) for c in table.columns]
    if len(set(names)) != len(names):
        dup = sorted({c for c in names if names.count(c) > 1})
        raise ObservationTableError(f"{where.table()}: duplicate column(s) {dup}")
    missing = [c for c in REQUIRED_COLUMNS if c not in names]
    if missing:
        raise ObservationTableError(
            f"{where.table()}: missing required column(s) {missing}; columns found: {names}")
    for name in names:
        if name in KNOWN_COLUMNS:
            continue
        near = name.strip().lower().replace(" ", "_")
        if near in KNOWN_COLUMNS:
            raise ObservationTableError(f"{where.table()}: column {name!r} is not a known column; "
                                        f"did you mean {near!r}? Known: {list(KNOWN_COLUMNS)}")
    for group in GROUPS:
        have = [c for c in group if c in names]
        if have and len(have) != len(group):
            raise ObservationTableError(
                f"{where.table()}: columns {list(group)} come together; found {have}, missing "
                f"{[c for c in group if c not in have]}")


def _check_bearings(table: pd.DataFrame, where: _Where, cols: dict[str, np.ndarray]) -> None:
    names = set(table.columns)
    if "bearing" in names:
        b = cols["bearing"] = _numeric(table, "bearing", where)
        _first(where, np.abs(b) > MAX_BEARING, "bearing", lambda i: (
            f"bearing {_show(b[i])} is outside [-2 pi, 2 pi]: radians expected; degrees suspected"))
    if "bearing_cos" in names:
        c = cols["bearing_cos"] = _numeric(table, "bearing_cos", where)
        s = cols["bearing_sin"] = _numeric(table, "bearing_sin", where)
        norm = np.hypot(c, s)
        _first(where, np.abs(norm - 1.0) > UNIT_TOLERANCE, "bearing_cos", lambda i: (
            f"(bearing_cos, bearing_sin) = ({_show(c[i])}, {_show(s[i])}) is not a unit vector "
            f"(length {norm[i]:.9g})"))
    if "ray_x" in names:
        x, y, z = (_numeric(table, k, where) for k in ("ray_x", "ray_y", "ray_z"))
        cols.update(ray_x=x, ray_y=y, ray_z=z)
        _first(where, (x == 0) & (y == 0) & (z == 0), "ray_x",
               lambda i: "zero-length ray (ray_x = ray_y = ray_z = 0) has no direction")
    given = [(k, v) for k, v in (
        ("bearing", cols.get("bearing")),
        ("bearing_cos", None if "bearing_cos" not in cols else
         np.arctan2(cols["bearing_sin"], cols["bearing_cos"])),
        ("ray_x", None if "ray_x" not in cols else np.arctan2(-cols["ray_x"], cols["ray_z"])),
    ) if v is not None]
    for (k1, b1), (k2, b2) in zip(given, given[1:], strict=False):
        if k2 == "ray_x":  # a vertical ray has no horizontal bearing to agree with
            ok = (cols["ray_x"] != 0) | (cols["ray_z"] != 0)
        else:
            ok = np.ones(len(b1), bool)
        diff = np.abs(np.angle(np.exp(1j * (b1 - b2))))
        _first(where, ok & (diff > BEARING_AGREEMENT), k2, lambda i, k1=k1, k2=k2, d=diff: (
            f"the bearing given by {k2!r} disagrees with {k1!r} by {d[i]:.3g} rad"))


def check_observations(table: pd.DataFrame, *, name: str | None = None,
                       first_line: int | None = None) -> pd.DataFrame:
    """Check an observation table; returns it unchanged, or raises :class:`ObservationTableError`.

    Checks: the required columns (the error lists the columns found); ids present and integers
    or strings; every measurement a finite number (the error names the line and column); ranges
    >= 0; bearings within [-2 pi, 2 pi] (radians expected; degrees suspected); unit-vector
    bearings of length 1; rays not of zero length; ``frame`` integers; ``visible`` 0/1; the
    same bearing given twice (angle, unit vector, ray) agreeing to 1e-6 rad.

    Args:
        table: the observation table.
        name: how errors name the table (a file name), if given.
        first_line: the file line of the first row (CSV); None names rows by position.
    """
    checked_ids(table, name=name, first_line=first_line)
    return table


def checked_ids(table: pd.DataFrame, *, name: str | None = None,
                first_line: int | None = None) -> tuple[pd.Series, pd.Series | None]:
    """:func:`check_observations`, returning the table's landmark and robot ids (None without a
    ``robot`` column) as :func:`normalise_ids` gives them (so a caller need not convert twice)."""
    where = _Where(name, first_line)
    _check_columns(table, where)
    names = set(table.columns)
    landmark = normalise_ids(table["landmark"], "landmark", where)
    robot = normalise_ids(table["robot"], "robot", where) if "robot" in names else None
    _numeric(table, "time", where)
    if "frame" in names:
        frame = table["frame"]
        if not pd.api.types.is_integer_dtype(frame.dtype) or pd.api.types.is_bool_dtype(frame.dtype):
            values = pd.to_numeric(frame, errors="coerce").to_numpy(np.float64, na_value=np.nan)
            bad = ~(np.isfinite(values) & (values == np.round(values)))
            if not bad.any():  # integral floats: still not integers (a frame is a count)
                bad = np.ones(len(values), bool)
            _first(where, bad, "frame", lambda i: f"frame {_show(frame.iloc[i])}: frames are integers "
                                                  f"(the column is {frame.dtype})")
    if "range" in names:
        r = _numeric(table, "range", where)
        _first(where, r < 0, "range", lambda i: f"negative range {_show(r[i])} m (a distance is >= 0)")
    if "visible" in names:
        v = table["visible"]
        values = pd.to_numeric(v, errors="coerce").to_numpy(np.float64, na_value=np.nan)
        _first(where, ~np.isin(values, (0.0, 1.0)), "visible",
               lambda i: f"visible is 0 or 1, got {_show(v.iloc[i])}")
    _check_bearings(table, where, {})
    return landmark, robot


def check_landmarks(table: pd.DataFrame, *, what: str = "landmarks", name: str | None = None,
                    first_line: int | None = None) -> pd.DataFrame:
    """Check an anchors or ground-truth table (``landmark, x, y`` and maybe ``z``): distinct ids,
    finite coordinates. Returns it with the ids normalised (integers, or strings)."""
    where = _Where(name, first_line)
    if not isinstance(table, pd.DataFrame):
        raise ObservationTableError(f"{what} must be a pandas DataFrame, got {type(table).__name__}")
    names = [str(c) for c in table.columns]
    missing = [c for c in ("landmark", "x", "y") if c not in names]
    if missing:
        raise ObservationTableError(f"{where.table()}: {what} table lacks column(s) {missing}; "
                                    f"columns found: {names} (expected landmark, x, y[, z])")
    out = pd.DataFrame({"landmark": normalise_ids(table["landmark"], "landmark", where)})
    for c in ("x", "y", "z"):
        if c in names:
            out[c] = _numeric(table, c, where)
    dup = out["landmark"].duplicated().to_numpy()
    _first(where, dup, "landmark", lambda i: f"landmark {_show(out['landmark'].iloc[i])} is "
                                             "listed twice")
    out.attrs = dict(table.attrs)
    return out


# ------------------------------------------------------------------------------ files
def _kind(path: Path) -> str:
    suffixes = [s.lower() for s in path.suffixes]
    if suffixes and suffixes[-1] in PARQUET_SUFFIXES:
        return "parquet"
    if suffixes and (suffixes[-1] in CSV_SUFFIXES or suffixes[-2:-1] == [".csv"]):
        return "csv"  # (also .csv.gz: pandas decompresses by suffix)
    raise ObservationTableError(f"{path}: unknown table format {''.join(path.suffixes)!r}; "
                                f"use CSV ({', '.join(CSV_SUFFIXES)}) or Parquet "
                                f"({', '.join(PARQUET_SUFFIXES)})")


def _read_comments(path: Path) -> tuple[dict[str, Any], int]:
    """The leading ``# key: json-value`` lines of a CSV file and how many lines they take."""
    import gzip

    attrs: dict[str, Any] = {}
    opener = gzip.open if path.suffix.lower() == ".gz" else open
    n = 0
    with opener(path, "rt", encoding="utf-8", newline="") as fh:
        for line in fh:
            if not line.startswith("#"):
                break
            n += 1
            text = line[1:].strip()
            if not text:
                continue
            key, sep, value = text.partition(":")
            if not sep:
                raise ObservationTableError(f"{path} line {n}: a comment line holds metadata as "
                                            f"'# key: json-value', got {line.rstrip()!r}")
            try:
                attrs[key.strip()] = json.loads(value)
            except json.JSONDecodeError as exc:
                raise ObservationTableError(f"{path} line {n}: the value of {key.strip()!r} is "
                                            f"not JSON: {exc}") from exc
    return attrs, n


def _read(path: str | os.PathLike, id_columns: tuple[str, ...]) -> tuple[pd.DataFrame, _Where]:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no table at {path}")
    kind = _kind(path)
    if kind == "parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        try:
            arrow = pq.read_table(path)
        except (pa.ArrowException, OSError) as exc:
            raise ObservationTableError(f"{path} is not a readable Parquet file: {exc}") from exc
        try:
            # a damaged schema or metadata (pandas' own or ours): bad JSON or UTF-8 (ValueError),
            # an unknown dtype name (TypeError), a missing key
            table = arrow.to_pandas()
            raw = (arrow.schema.metadata or {}).get(PARQUET_KEY)
            attrs = json.loads(raw) if raw else {}
        except (pa.ArrowException, ValueError, TypeError, KeyError) as exc:
            raise ObservationTableError(f"{path} is not a readable Parquet file (damaged schema "
                                        f"or metadata): {exc!r}") from exc
        if not isinstance(attrs, dict):
            raise ObservationTableError(f"{path}: its lfmdr metadata is not a JSON object")
        table.attrs = attrs
        return table, _Where(str(path), None)
    try:
        attrs, n_comments = _read_comments(path)
    except (UnicodeDecodeError, OSError, EOFError, zlib.error) as exc:  # (OSError: bad gzip)
        raise ObservationTableError(f"{path} is not a readable CSV table: {exc}") from exc
    sep = "\t" if path.suffix.lower() == ".tsv" else ","
    try:
        # ids as text (made integers where they spell one: normalise_ids). Floats must read back
        # to the bits written: pandas >= 3 parses them correctly rounded by default, older
        # pandas only with float_precision="round_trip" (deprecated in 3).
        exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
        table = pd.read_csv(path, skiprows=n_comments, sep=sep, **exact,
                            dtype={c: str for c in id_columns}, keep_default_na=False,
                            na_values=["", "NaN", "nan", "NA"])
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, OSError,
            EOFError, zlib.error) as exc:  # (OSError, EOFError, zlib.error: a damaged .csv.gz)
        raise ObservationTableError(f"{path} is not a readable CSV table: {exc}") from exc
    table.columns = [str(c) for c in table.columns]
    table.attrs = attrs
    return table, _Where(str(path), n_comments + 2)  # line 1 after the comments is the header


def read_observations(path: str | os.PathLike) -> pd.DataFrame:
    """Read an observation table (CSV: ``.csv``, ``.csv.gz``, ``.tsv``; Parquet: ``.parquet``,
    ``.pq``), metadata into ``attrs``; checked (:func:`check_observations`), errors naming the
    file's line and column. Ids come back as integers, or as strings where any is not one."""
    table, where = _read(path, ("landmark", "robot"))
    check_observations(table, name=where.name, first_line=where.first_line)
    table["landmark"] = normalise_ids(table["landmark"], "landmark", where)
    if "robot" in table.columns:
        table["robot"] = normalise_ids(table["robot"], "robot", where)
    return table


def read_landmarks(path: str | os.PathLike, *, what: str = "landmarks") -> pd.DataFrame:
    """Read an anchors or ground-truth table (``landmark, x, y`` and maybe ``z``; CSV or Parquet),
    checked by :func:`check_landmarks`. ``what`` names it in errors ("anchors", "truth")."""
    table, where = _read(path, ("landmark",))
    return check_landmarks(table, what=what, name=where.name, first_line=where.first_line)


def _check_attrs(attrs: dict[str, Any]) -> str:
    try:
        text = json.dumps(attrs, sort_keys=True)
    except (TypeError, ValueError) as exc:
        raise ObservationTableError(f"table attrs must be JSON-serialisable: {exc}") from exc
    for key in attrs:
        if not isinstance(key, str) or ":" in key or "\n" in key or not key.strip():
            raise ObservationTableError(f"attrs keys must be non-empty strings without ':' or "
                                        f"newlines, got {key!r}")
    return text


def _write(table: pd.DataFrame, path: str | os.PathLike) -> Path:
    path = Path(path)
    kind = _kind(path)
    meta = _check_attrs(dict(table.attrs))
    plain = pd.DataFrame(table, copy=False)
    if kind == "parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        arrow = pa.Table.from_pandas(plain, preserve_index=False)
        arrow = arrow.replace_schema_metadata({**(arrow.schema.metadata or {}),
                                               PARQUET_KEY: meta.encode()})
        with atomic_write(path, "wb") as fh:
            pq.write_table(arrow, fh)
        return path
    if path.suffix.lower() == ".gz":
        raise ObservationTableError(f"{path}: write CSV uncompressed (.csv) or use Parquet")
    sep = "\t" if path.suffix.lower() == ".tsv" else ","
    with atomic_write(path, "w") as fh:
        for key, value in table.attrs.items():
            fh.write(f"# {key}: {json.dumps(value, sort_keys=True)}\n")
        # floats as the shortest text that reads back to the same bits (Python's repr)
        plain.to_csv(fh, index=False, sep=sep, lineterminator="\n")
    return path


def write_observations(table: pd.DataFrame, path: str | os.PathLike) -> Path:
    """Check ``table`` (:func:`check_observations`) and write it to ``path`` atomically (CSV or
    Parquet by suffix), ``attrs`` included; a table that fails its check writes nothing."""
    check_observations(table)
    return _write(table, path)


def write_landmarks(table: pd.DataFrame, path: str | os.PathLike, *,
                    what: str = "landmarks") -> Path:
    """Check an anchors or ground-truth table (:func:`check_landmarks`) and write it atomically."""
    checked = check_landmarks(table, what=what)
    return _write(checked, path)
