"""The mapper example runs and prints a row per method (examples double as documentation)."""

import runpy

from paths import EXAMPLES

from mappers import METHODS, methods_for


def test_map_synthetic_example_runs(capsys):
    runpy.run_path(str(EXAMPLES / "map_synthetic.py"))
    out = capsys.readouterr().out
    table, _, tail = out.partition("\n\n")
    rows = [line.split() for line in table.splitlines()[1:]
            if not line.lstrip().startswith("warning:")]  # a map's warnings, printed under its row
    assert [r[0] for r in rows] == [m for m in methods_for("visibility", masked=False)
                                    if not METHODS[m].takes_masks]
    assert {"CAL-SMA", "SDE", "LPCA"} <= {r[0] for r in rows} and "UNFOLD" not in [r[0] for r in rows]
    assert all(0 <= float(r[1]) < 2.0 and 0 <= float(r[2]) <= 100 for r in rows)
    assert float(dict((r[0], r[1]) for r in rows)["SMA(WGT)"]) < 0.2
    assert "range histories, UNFOLD" in tail and float(tail.split("MPE ")[1].split()[0]) < 1e-6
