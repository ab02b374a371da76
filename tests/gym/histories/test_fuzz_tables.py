"""Damaged observation tables, fuzzed (issue 35): truncated and bit-flipped CSV, gzipped CSV and
Parquet files, and CSV files with bad cells, give :class:`ObservationTableError` within seconds,
or read as a table that passes the table's checks (CSV has no checksum: a flipped digit is
another valid number, a file cut after a row another valid table); never a hang, a crash of the
interpreter or another exception. Read in a child process (``tests/fuzzing.py``); ``-m slow``
cuts at every byte and flips many more.
"""

from __future__ import annotations

import gzip

import numpy as np
import pandas as pd
import pytest
from fuzzing import bit_flipped, read_all, truncated

from lfmdr_gym.histories.observation_table import write_observations

ERRORS = ["lfmdr_gym.histories.observation_table.ObservationTableError"]
READER = "fuzzing:table_summary"


def _table(n: int = 40) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    table = pd.DataFrame({"time": np.arange(n) * 0.25, "robot": rng.integers(1, 3, n),
                          "landmark": rng.integers(5, 12, n), "range": rng.uniform(0.5, 4, n),
                          "bearing": rng.uniform(-0.5, 0.5, n)})
    table.attrs = {"source": "fuzz", "n": [1, 2]}
    return table


def _check(outcomes: dict) -> dict:
    unexpected = {p: o for p, o in outcomes.items() if "unexpected" in o}
    assert not unexpected, f"{len(unexpected)} file(s) raised another error, e.g. " \
                           f"{next(iter(unexpected.items()))}"
    return outcomes


@pytest.mark.parametrize("slow", [False, pytest.param(True, marks=pytest.mark.slow)],
                         ids=["default", "many"])
def test_truncated_and_bit_flipped_tables(tmp_path, slow):
    rng = np.random.default_rng(35)
    paths = []
    for suffix in (".csv", ".csv.gz", ".parquet"):
        written = write_observations(_table(), tmp_path / f"good{suffix.replace('.gz', '')}")
        good = gzip.compress(written.read_bytes()) if suffix.endswith(".gz") else \
            written.read_bytes()
        cuts = range(len(good)) if slow else np.linspace(0, len(good) - 1, 30).astype(int)
        copies = [(f"cut{k}", truncated(good, k)) for k in cuts]
        copies += [(f"flip{k}", bit_flipped(good, rng.integers(0, 8 * len(good),
                                                               rng.integers(1, 4))))
                   for k in range(1000 if slow else 70)]
        for label, data in copies:
            path = tmp_path / f"{label}{suffix}"
            path.write_bytes(data)
            paths.append(path)
    outcomes = _check(read_all(paths, READER, ERRORS, time_limit=600.0 if slow else 120.0))
    for suffix in (".csv.gz", ".parquet"):  # compressed or checksummed: mostly refused
        mine = [o for p, o in outcomes.items() if p.endswith(suffix)]
        assert sum("error" in o for o in mine) > 0.5 * len(mine), suffix


BAD_CELLS = ["", "nan", "inf", "-inf", "1e999", "x", "1,5", "--1", "0x10", "1.5.2", "True",
             "\"", "'", "#", "\t", "1e-400", "-0", "9" * 40, "é", "\\N", "NULL", "[1]", "{}"]
"""Cells put in place of one cell of a CSV table: empty, non-finite, overflowing, not a
number, quotes, a separator, a comment sign, a huge integer, non-ASCII text."""


STILL_VALID = {"-0", "1e-400", "9" * 40}
"""Bad-looking cells that still spell a valid number (0; 1e-400, which reads as 0; 1e40)."""


def test_bad_cells(tmp_path):
    text = write_observations(_table(8), tmp_path / "good.csv").read_text().splitlines()
    start = next(k for k, line in enumerate(text) if not line.startswith("#")) + 1
    paths = []
    for column in range(5):
        for j, cell in enumerate(BAD_CELLS):
            lines = list(text)
            cells = lines[start + 3].split(",")
            cells[column] = cell
            lines[start + 3] = ",".join(cells)
            path = tmp_path / f"c{column}-{j}.csv"
            path.write_text("\n".join(lines) + "\n", encoding="utf-8")
            paths.append(path)
    outcomes = _check(read_all(paths, READER, ERRORS))
    # a bad cell in time, range or bearing (columns 0, 3, 4) is refused, naming line and column
    for column, name in ((0, "time"), (3, "range"), (4, "bearing")):
        for j, cell in enumerate(BAD_CELLS):
            outcome = outcomes[str(tmp_path / f"c{column}-{j}.csv")]
            if cell not in STILL_VALID:
                assert "error" in outcome, (name, cell, outcome)
    refused = [o for o in outcomes.values() if "error" in o]
    assert len(refused) > 0.6 * len(paths)
    assert any(f"line {start + 4}" in o["message"] for o in refused)
