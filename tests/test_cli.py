"""The ``lfmdr`` command: help, every subcommand end to end, interrupts (SIGKILL, Ctrl-C), bad options."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lfmdr_gym.cli import build_parser, main
from lfmdr_gym.experiments.store import JOURNAL, read_results
from mappers import METHODS

ROOT = Path(__file__).resolve().parents[1]
SMALL = ["--sensor", "visibility", "--layouts", "1", "--poses", "2", "--steps", "200",
         "--every", "100", "--methods", "LPCA", "SMA(WGT)", "ISOMAP", "--no-progress"]
# Longer, for the interrupt tests: enough units that a kill lands in the middle.
LONGER = ["--sensor", "visibility", "--layouts", "1", "--poses", "2", "--steps", "300",
          "--every", "50", "--methods", "LPCA,SMA(WGT),ISOMAP,LLE", "--no-progress"]


def _lfmdr(*args: str, **kwargs) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.Popen([sys.executable, "-m", "lfmdr_gym.cli", *args], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs)


def _comparable(rows):
    out = []
    for r in rows:
        r = {k: v for k, v in r.items() if k != "seconds"}
        out.append({k: ("nan" if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()})
    return out


def _journal_rows(path: Path) -> int:
    try:
        return max(0, path.read_bytes().count(b"\n") - 1)
    except FileNotFoundError:
        return 0


# ------------------------------------------------------------------ help
@pytest.mark.parametrize("command", ["reproduce", "run", "map", "collect", "mrclam"])
def test_help_explains_every_option(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    sub = build_parser()._subparsers._group_actions[0].choices[command]
    for action in sub._actions:
        if action.option_strings and action.dest != "help":
            assert action.help, f"{command} {action.option_strings} has no help"
            assert action.option_strings[0] in text


def test_top_level_help_lists_the_commands(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    for command in ("reproduce", "run", "map", "collect", "mrclam"):
        assert command in text


# ------------------------------------------------------------------ reproduce end to end
@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli-clean")
    assert main(["reproduce", *SMALL, "--out", str(out)]) == 0
    return out


@pytest.mark.xdist_group("cli-clean")
def test_reproduce_end_to_end(clean, capsys):
    rows = read_results(clean / "results.csv")
    # per run: LPCA at N=100, 200; SMA(WGT), ISOMAP: their K grid at N=200 + the default at N=100
    n_k = len(METHODS["SMA(WGT)"].grid["n_neighbors"])
    assert n_k == len(METHODS["ISOMAP"].grid["n_neighbors"])
    assert len(rows) == 2 * (2 + 2 * (n_k + 1))
    assert {r["method"] for r in rows} == {"LPCA", "SMA(WGT)", "ISOMAP"}
    for name in ("table.md", "table.csv", "mpe_vs_n.png", "map_lpca.png"):
        assert (clean / name).stat().st_size > 200
    # Run again: everything is resumed, nothing recomputed.
    assert main(["reproduce", *SMALL, "--out", str(clean)]) == 0
    assert "0 computed now" in capsys.readouterr().out


@pytest.fixture(scope="module")
def clean_longer(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli-longer")
    assert main(["reproduce", *LONGER, "--out", str(out)]) == 0
    return _comparable(read_results(out / "results.csv"))


def _interrupt_then_resume(tmp_path: Path, sig: int, extra: list[str],
                           group: bool = False) -> tuple[int, int]:
    """Interrupt a run once it has saved a row, then resume it. ``group``: signal the whole
    process group, workers included, as Ctrl-C in a terminal does."""
    journal = tmp_path / JOURNAL
    proc = _lfmdr("reproduce", *LONGER, *extra, "--out", str(tmp_path), start_new_session=group)
    deadline = time.monotonic() + 60
    while _journal_rows(journal) < 1:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "no row was written within 60 s"
        time.sleep(0.005)
    if group:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)  # promptly: never the minutes of a hung worker pool
    if sig != signal.SIGKILL:
        assert "Traceback" not in err, err
    rows_at_stop = _journal_rows(journal)
    if sig == signal.SIGKILL:
        # As if the kill had struck in the middle of a write: a torn last line.
        with open(journal, "ab") as fh:
            fh.write(b"visibility,0,2,ISOMAP,K=")
    # Resume in one process (the worker count is not a setting, so it may change).
    resume = _lfmdr("reproduce", *LONGER, "--out", str(tmp_path))
    out, err = resume.communicate(timeout=120)
    assert resume.returncode == 0, err
    return proc.returncode, rows_at_stop


@pytest.mark.xdist_group("cli-clean-longer")
def test_sigkill_then_rerun_gives_the_rows_of_a_clean_run(clean_longer, tmp_path):
    code, stopped = _interrupt_then_resume(tmp_path, signal.SIGKILL, [])
    assert code == -signal.SIGKILL
    assert 0 < stopped < len(clean_longer), "the kill did not land in the middle of the run"
    assert _comparable(read_results(tmp_path / "results.csv")) == clean_longer


@pytest.mark.xdist_group("cli-clean-longer")
@pytest.mark.parametrize(("sig", "jobs", "group"),
                         [(signal.SIGINT, "2", False), (signal.SIGINT, "2", True),
                          (signal.SIGTERM, "1", False)],
                         ids=["ctrl-c-2-workers", "ctrl-c-to-the-process-group", "sigterm"])
def test_ctrl_c_then_rerun_gives_the_rows_of_a_clean_run(clean_longer, tmp_path, sig, jobs, group):
    code, stopped = _interrupt_then_resume(tmp_path, sig, ["--jobs", jobs], group)
    assert code == 130
    assert 0 < stopped < len(clean_longer), "Ctrl-C did not land in the middle of the run"
    assert _comparable(read_results(tmp_path / "results.csv")) == clean_longer


# ------------------------------------------------------------------ bad options
def _error(argv, capsys) -> str:
    code = main(argv)
    assert code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


def test_unknown_method_is_refused(tmp_path, capsys):
    err = _error(["reproduce", "--mode", "visibility", "--methods", "LPCA", "MAGIC",
                  "--out", str(tmp_path)], capsys)
    assert "unknown method 'MAGIC'" in err


def test_steps_not_a_multiple_of_every_is_refused(tmp_path, capsys):
    err = _error(["reproduce", "--mode", "bearing", "--steps", "450", "--out", str(tmp_path)], capsys)
    assert "steps (450) must be a multiple of every (200)" in err


def test_unwritable_out_is_refused(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    err = _error(["reproduce", *SMALL, "--out", str(blocker / "run")], capsys)
    assert "cannot write to output directory" in err


@pytest.mark.xdist_group("cli-clean")
def test_changed_settings_on_same_out_are_refused(clean, capsys):
    args = [a if a != "200" else "300" for a in SMALL]
    err = _error(["reproduce", *args, "--out", str(clean)], capsys)
    assert "other settings" in err and "steps: 200 in the directory, 300 now" in err


@pytest.mark.parametrize("argv", [
    ["reproduce", "--mode", "visibility", "--layouts", "0"],
    ["reproduce", "--mode", "visibility", "--poses", "-2"],
    ["reproduce", "--mode", "visibility", "--jobs", "0"],
    ["reproduce", "--mode", "smell"],
    ["reproduce"],
])
def test_argparse_rejects_bad_values(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert "error:" in capsys.readouterr().err


def test_unknown_method_in_run_and_map(tmp_path, capsys):
    err = _error(["run", "--steps", "20", "--method", "nope", "--out", str(tmp_path)], capsys)
    assert "unknown method 'nope'" in err
    err = _error(["map", str(tmp_path / "missing.npz"), "--method", "LPCA"], capsys)
    assert "no history file" in err
    err = _error(["run", "--steps", "20", "--method", "SDE", "--param", "sigma2=1",
                  "--out", str(tmp_path)], capsys)
    assert "unknown parameter(s) ['sigma2'] for method 'SDE'" in err


def _table_with(fresh: Path, column: str, method: str, change) -> None:
    """docs/results/visibility's table.csv written to ``fresh`` with one cell changed."""
    lines = (ROOT / "docs" / "results" / "visibility" / "table.csv").read_text().splitlines()
    header = lines[0].split(",")
    col, method_col = header.index(column), header.index("method")
    rows = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        if cells[method_col] == method:
            cells[col] = repr(change(float(cells[col])))
        rows.append(",".join(cells))
    fresh.mkdir(exist_ok=True)
    (fresh / "table.csv").write_text("\n".join(rows) + "\n")


def test_compare_accepts_a_reproduction_and_names_what_moved(tmp_path, capsys):
    ref = ROOT / "docs" / "results" / "visibility"
    fresh = tmp_path / "fresh"

    def write(shift):
        _table_with(fresh, "mpe_mean", "LLE", lambda v: v + shift)

    write(0.001)  # within the stated tolerance (0.002 m)
    assert main(["compare", str(fresh), str(ref)]) == 0
    assert "reproduces" in capsys.readouterr().out
    write(0.05)
    assert main(["compare", str(fresh), str(ref)]) == 1
    out = capsys.readouterr().out
    assert "does not reproduce" in out and "LLE: mpe_mean" in out and "SDE" not in out
    assert main(["compare", str(fresh), str(ref), "--mpe-abs", "0.1"]) == 0


def test_compare_moe_within_points_or_a_fraction(tmp_path, capsys):
    ref = ROOT / "docs" / "results" / "visibility"
    fresh = tmp_path / "fresh"
    # KPCA(POLY)'s MOE is about 15 %: 1 % of it is 0.15 points
    _table_with(fresh, "moe_mean", "KPCA(POLY)", lambda v: v * 1.01)
    assert main(["compare", str(fresh), str(ref)]) == 0  # within 2 % of the reference
    capsys.readouterr()
    assert main(["compare", str(fresh), str(ref), "--moe-rel", "0"]) == 1  # beyond 0.1 points
    assert "KPCA(POLY): moe_mean" in capsys.readouterr().out


# ------------------------------------------------------------------ single runs
def test_collect_then_map(tmp_path, capsys):
    path = tmp_path / "walk.npz"
    assert main(["collect", "--steps", "150", "--seed", "3", "--out", str(path)]) == 0
    out = capsys.readouterr().out
    assert "steps=150" in out and "sightings per object" in out
    assert path.is_file()
    assert main(["map", str(path), "--method", "isomap", "--param", "K=7",
                 "--out", str(tmp_path / "m")]) == 0
    out = capsys.readouterr().out
    assert "MPE" in out and "ISOMAP (n_neighbors=7)" in out
    lines = (tmp_path / "m" / "map.csv").read_text().splitlines()
    assert lines[0] == "object,x,y,true_x,true_y,anchor" and len(lines) == 51
    assert (tmp_path / "m" / "map.png").stat().st_size > 10_000


def test_map_and_run_without_method_use_the_default(tmp_path, capsys):
    path = tmp_path / "walk.npz"
    assert main(["collect", "--steps", "150", "--seed", "3", "--out", str(path)]) == 0
    assert main(["map", str(path), "--out", str(tmp_path / "m")]) == 0
    assert "CAL-SMA" in capsys.readouterr().out  # the visibility default
    assert main(["run", "--env", "LFMDR-Range-v0", "--steps", "100", "--every", "100",
                 "--out", str(tmp_path / "r")]) == 0
    assert "UNFOLD" in capsys.readouterr().out  # the range default


def test_run_prints_scores_at_each_checkpoint(tmp_path, capsys):
    assert main(["run", "--env", "LFMDR-Visibility-v0", "--steps", "200", "--every", "100",
                 "--method", "LPCA", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    table = [line.split() for line in out.splitlines() if line.strip()[:3].isdigit()]
    assert [int(t[0]) for t in table] == [100, 200]
    assert all(0 <= float(t[1]) < 3 for t in table)
    for name in ("history.npz", "scores.csv", "map.csv", "map.png"):
        assert (tmp_path / name).is_file()


def test_mrclam_passes_its_options_to_the_loader(monkeypatch, tmp_path, capsys):
    from types import SimpleNamespace

    mrclam = pytest.importorskip("lfmdr_gym.experiments.mrclam")
    seen = {}

    def fake(run_dir, sensor, **kwargs):
        seen.update(kwargs, run_dir=run_dir, sensor=sensor)
        return SimpleNamespace(
            run="MRCLAM_X", sensor=sensor, method="range-quantile", params={"quantile": 0.9},
            anchor_subjects=(6, 7, 8, 9), warnings=("clustered layout",), mpe=0.25, moe=3.5,
            centroid_mpe=3.0, csv_path=tmp_path / "o" / "map.csv", png_path=None,
            subjects=np.arange(6, 12), positions=np.array([[0.0, 0]] * 5 + [[np.nan, np.nan]]),
        )

    monkeypatch.setattr(mrclam, "map_mrclam_run", fake)
    assert main(["mrclam", str(tmp_path), "--mode", "range", "--robots", "1,3",
                 "--anchors", "6,7,8,9", "--method", "range-quantile", "--param", "quantile=0.9",
                 "--bin-width", "0.5", "--groundtruth-fixes", "none",
                 "--out", str(tmp_path / "o")]) == 0
    assert seen == {"run_dir": str(tmp_path), "sensor": "range", "robots": [1, 3],
                    "anchors": [6, 7, 8, 9], "method": "range-quantile", "quantile": 0.9,
                    "bin_width": 0.5, "out": str(tmp_path / "o"), "groundtruth_fixes": "none",
                    "zero_fill": False}
    out = capsys.readouterr().out
    assert "MPE 0.250 m, MOE 3.50 %" in out and "warning: clustered layout" in out
    assert "centroid baseline: MPE 3.000 m" in out
    assert "over the 1 mapped (of 2) non-anchor landmarks" in out  # subject 11 unmapped


def test_mrclam_bad_robots_is_an_argparse_error(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["mrclam", "somewhere", "--mode", "range", "--robots", "one,two"])
    assert exc.value.code == 2
    assert "expected numbers like 1,2,3" in capsys.readouterr().err


MRCLAM_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "mrclam"


def test_mrclam_on_a_real_run(tmp_path, capsys):
    runs = sorted(p for p in MRCLAM_DATA.glob("*") if p.is_dir()) if MRCLAM_DATA.is_dir() else []
    if not runs:
        pytest.skip("no MRCLAM data here")
    assert main(["mrclam", str(runs[0]), "--mode", "range", "--out", str(tmp_path)]) == 0
    assert "MPE" in capsys.readouterr().out
    assert (tmp_path / "map.csv").read_text().splitlines()[0].startswith("subject")


def test_the_policy_help_names_every_registered_policy():
    from lfmdr_gym import POLICIES
    from lfmdr_gym.cli import _POLICY_HELP

    assert _POLICY_HELP.endswith("(" + ", ".join(POLICIES) + ")")
