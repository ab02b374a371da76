"""The generated benchmarks page is what the committed result files give (it cannot go stale)."""

import runpy
import shutil

import pytest
from paths import ROOT

REPORT = runpy.run_path(str(ROOT / "benchmarks" / "report.py"))


def test_committed_page_is_the_rendered_one():
    committed = (ROOT / "docs" / "benchmarks.md").read_text(encoding="utf-8")
    assert REPORT["render"](ROOT) == committed, (
        "docs/benchmarks.md is stale: run python benchmarks/report.py and commit the page"
    )


def test_every_source_is_on_the_page_with_its_command():
    page = REPORT["render"](ROOT)
    sources = [*REPORT["PROTOCOL"].values(), REPORT["SENSING"],
               *(s for s, _ in REPORT["VIS_BA"]), *REPORT["UNCERTAINTY"],
               *REPORT["EXPLORATION_CAL_SMA"],
               *(s for s, _ in REPORT["EXPLORATION_OTHER"])]
    for source in sources:
        assert (ROOT / source.path).is_file()
        assert source.command in page


def test_missing_csv_is_a_clear_error(tmp_path):
    for part in ("docs/results", "docs/exploration"):
        shutil.copytree(ROOT / part, tmp_path / part)
    (tmp_path / "docs" / "exploration" / "rl.csv").unlink()
    with pytest.raises(FileNotFoundError, match=r"docs/exploration/rl\.csv.*missing.*--policies rl"):
        REPORT["render"](tmp_path)


def test_check_mode_reports_a_stale_page(tmp_path, capsys):
    for part in ("docs/results", "docs/exploration"):
        shutil.copytree(ROOT / part, tmp_path / part)
    (tmp_path / "docs" / "benchmarks.md").write_text("# stale\n", encoding="utf-8")
    assert REPORT["main"](["--check", "--root", str(tmp_path)]) == 1
    assert "stale" in capsys.readouterr().err
    assert REPORT["main"](["--root", str(tmp_path)]) == 0
    assert REPORT["main"](["--check", "--root", str(tmp_path)]) == 0
