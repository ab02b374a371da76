"""The ``lfmdr`` command: help, every subcommand end to end, interrupts (SIGKILL, Ctrl-C), bad options."""

from __future__ import annotations

import argparse
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from paths import ROOT, SHARED_DATA

from lfmdr_gym.cli import build_parser, main
from lfmdr_gym.experiments.store import JOURNAL, read_results
from mappers import METHODS

SMALL = ["--sensor", "visibility", "--layouts", "1", "--poses", "2", "--steps", "200",
         "--every", "100", "--methods", "LPCA", "SMA(WGT)", "ISOMAP", "--no-progress"]
# Longer, for the interrupt tests: enough units that a kill lands in the middle.
LONGER = ["--sensor", "visibility", "--layouts", "1", "--poses", "2", "--steps", "200",
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


HANG_GUARD = 900
"""Seconds after which a subprocess that has not done what it should is taken to hang."""


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
        if action.help == argparse.SUPPRESS:  # an older spelling kept working, not advertised
            continue
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


def _without_report(mp: pytest.MonkeyPatch) -> None:
    """The interrupt tests compare results.csv only: the report (a table and three figures,
    about 5 s of CPU a run) is not drawn when they run the command in this process;
    test_reproduce_end_to_end checks it."""
    mp.setattr("lfmdr_gym.experiments.protocol.write_report", lambda config, out, rows: [])


@pytest.fixture(scope="module")
def clean_longer(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli-longer")
    with pytest.MonkeyPatch.context() as mp:
        _without_report(mp)
        assert main(["reproduce", *LONGER, "--out", str(out)]) == 0
    return _comparable(read_results(out / "results.csv"))


def _interrupt_then_resume(tmp_path: Path, sig: int, extra: list[str],
                           group: bool = False) -> tuple[int, int]:
    """Interrupt a run once it has saved a row, then resume it. ``group``: signal the whole
    process group, workers included, as Ctrl-C in a terminal does."""
    journal = tmp_path / JOURNAL
    proc = _lfmdr("reproduce", *LONGER, *extra, "--out", str(tmp_path), start_new_session=group)
    # HANG_GUARD only stops a run that hangs; it is no timing assertion (a run takes about 10 s
    # of CPU, which a loaded shared machine stretches to a minute or more of wall time)
    deadline = time.monotonic() + HANG_GUARD
    while _journal_rows(journal) < 1:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, f"no row was written within {HANG_GUARD} s"
        time.sleep(0.005)
    if group:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    _, err = proc.communicate(timeout=HANG_GUARD)  # a hung worker pool would never return
    if sig != signal.SIGKILL:
        assert "Traceback" not in err, err
    rows_at_stop = _journal_rows(journal)
    if sig == signal.SIGKILL:
        # As if the kill had struck in the middle of a write: a torn last line.
        with open(journal, "ab") as fh:
            fh.write(b"visibility,0,2,ISOMAP,K=")
    # Resume with one process (the worker count is not a setting, so it may change), in this
    # one: the same command through main(), without starting Python and importing the package
    # again (3 s of CPU per test)
    with pytest.MonkeyPatch.context() as mp:
        _without_report(mp)
        assert main(["reproduce", *LONGER, "--out", str(tmp_path)]) == 0
    return proc.returncode, rows_at_stop


@pytest.mark.xdist_group("cli-clean-longer")
def test_sigkill_then_rerun_gives_the_rows_of_a_clean_run(clean_longer, tmp_path):
    code, stopped = _interrupt_then_resume(tmp_path, signal.SIGKILL, [])
    assert code == -signal.SIGKILL
    assert 0 < stopped < len(clean_longer), "the kill did not land in the middle of the run"
    assert _comparable(read_results(tmp_path / "results.csv")) == clean_longer


@pytest.mark.xdist_group("cli-clean-longer")
@pytest.mark.parametrize(("sig", "jobs", "group"),
                         # SIGINT to the main process alone is in -m slow: Ctrl-C to the whole
                         # group interrupts the same two workers through the same handler
                         [pytest.param(signal.SIGINT, "2", False, marks=pytest.mark.slow),
                          (signal.SIGINT, "2", True), (signal.SIGTERM, "1", False)],
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
            run="MRCLAM_X", sensor=sensor, method="RANGE-QUANTILE", params={"quantile": 0.9},
            anchor_subjects=(6, 7, 8, 9), warnings=("clustered layout",), mpe=0.25, moe=3.5,
            centroid_mpe=3.0, csv_path=tmp_path / "o" / "map.csv", png_path=None,
            subjects=np.arange(6, 12), positions=np.array([[0.0, 0]] * 5 + [[np.nan, np.nan]]),
        )

    monkeypatch.setattr(mrclam, "map_mrclam_run", fake)
    assert main(["mrclam", str(tmp_path), "--mode", "range", "--robots", "1,3",
                 "--anchors", "6,7,8,9", "--method", "RANGE-QUANTILE", "--param", "quantile=0.9",
                 "--bin-width", "0.5", "--groundtruth-fixes", "none",
                 "--out", str(tmp_path / "o")]) == 0
    assert seen == {"run_dir": str(tmp_path), "sensor": "range", "robots": [1, 3],
                    "anchors": [6, 7, 8, 9], "method": "RANGE-QUANTILE", "quantile": 0.9,
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


MRCLAM_DATA = SHARED_DATA / "mrclam"


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


# ------------------------------------------------------------------ a new user's first tries (issue 32)
def test_version_prints_the_package_version(capsys):
    from importlib.metadata import version

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"lfmdr {version('lfmdr')}"


@pytest.mark.parametrize("command", ["collect", "run"])
def test_an_unknown_env_id_is_a_clear_error_naming_the_registered_ids(command, tmp_path, capsys):
    from lfmdr_gym import ENV_IDS

    out = str(tmp_path / ("walk.npz" if command == "collect" else "run"))
    err = _error([command, "--env", "LFMDR-Foo-v0", "--steps", "10", "--out", out], capsys)
    assert err.startswith(f"lfmdr {command}: error: unknown env id 'LFMDR-Foo-v0'")
    assert all(env_id in err for env_id in ENV_IDS)
    if command == "collect":
        assert "LFMDR-Camera3D-v0" in err


def test_the_env_id_help_names_every_registered_id():
    from lfmdr_gym import ENV_IDS, ENV_IDS_3D
    from lfmdr_gym.cli import _ENV_ID_HELP

    assert "(" + ", ".join(ENV_IDS) + ")" in _ENV_ID_HELP
    assert "(" + ", ".join(ENV_IDS_3D) + ":" in _ENV_ID_HELP


def test_env_is_an_env_id_and_env_kw_an_env_keyword_in_every_command():
    parser = build_parser()
    commands = parser._subparsers._group_actions[0].choices
    for name in ("reproduce", "run", "collect"):
        shown = {a.option_strings[0]: a.dest for a in commands[name]._actions
                 if a.option_strings and a.help != argparse.SUPPRESS}
        assert shown["--env-kw"] == "env_kwargs", name
        assert shown.get("--env", "env") == "env", name  # never the keywords
    for name in ("run", "collect"):
        args = parser.parse_args([name, "--env", "LFMDR-Bearing-v0", "--env-kw", "fov_deg=90",
                                  "--out", "x.npz"])
        assert (args.env, args.env_kwargs) == ("LFMDR-Bearing-v0", ["fov_deg=90"])
    args = parser.parse_args(["reproduce", "--sensor", "bearing", "--env-kw", "fov_deg=90",
                              "--env-kw", "max_range=1.5"])
    assert args.env_kwargs == ["fov_deg=90", "max_range=1.5"]


def test_reproduce_env_keyword_old_spelling_still_works_with_a_deprecation_message(capsys):
    args = build_parser().parse_args(["reproduce", "--sensor", "bearing", "--env", "fov_deg=90",
                                      "--env-kw", "max_range=1.5"])
    assert args.env_kwargs == ["fov_deg=90", "max_range=1.5"]
    err = capsys.readouterr().err
    assert "--env fov_deg=90 is deprecated" in err and "--env-kw fov_deg=90" in err
    with pytest.raises(SystemExit) as exc:  # an env id is not what reproduce's --env meant
        build_parser().parse_args(["reproduce", "--sensor", "bearing", "--env", "LFMDR-Bearing-v0"])
    assert exc.value.code == 2
    assert "--env-kw NAME=VALUE" in capsys.readouterr().err


def _promised_files(help_text: str) -> set[str]:
    import re

    return set(re.findall(r"\b[a-z_]+\.(?:npz|csv|png|gif)\b", " ".join(help_text.split())))


def test_run_online_writes_every_file_its_help_promises(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    from lfmdr_gym.histories.history import History

    sub = build_parser()._subparsers._group_actions[0].choices["run"]
    online = next(a for a in sub._actions if a.dest == "online")
    promised = _promised_files(online.help)
    assert {"history.npz", "scores.csv", "map.csv", "map.png", "live.gif"} <= promised
    # 20 steps (a GIF frame each), updated every 10: 40 took twice the CPU for the same files
    assert main(["run", "--online", "--env", "LFMDR-Bearing-v0", "--steps", "20", "--every", "10",
                 "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "online BEARING-BA" in out  # the default online method of bearing histories
    for name in promised:
        assert (tmp_path / name).stat().st_size > 0, name
        assert name in out
    history = History.load(tmp_path / "history.npz")
    assert history.sensor == "bearing" and history.n_steps == 20
    scores = (tmp_path / "scores.csv").read_text().splitlines()
    assert scores[0] == "n_steps,method,param,mpe_nonanchor,mapped,note" and len(scores) == 1 + 2
    assert len((tmp_path / "map.csv").read_text().splitlines()) == 1 + history.n_objects
    # the history written is the episode mapped: lfmdr map reads it like any other
    assert main(["map", str(tmp_path / "history.npz"), "--out", str(tmp_path / "again")]) == 0


def test_run_online_says_why_there_is_no_map_instead_of_nan(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    # 20 steps (a GIF frame each): 2.6 s of CPU, 60 took 7 s for the same message
    assert main(["run", "--online", "--env-kw", "fov_deg=90", "--steps", "20", "--every", "10",
                 "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    table = [line for line in out.splitlines() if line.strip()[:2].isdigit()]
    assert table and all("nan" not in line for line in table), out
    assert all(line.endswith("no map yet") for line in table), out
    why = next(line for line in out.splitlines() if line.startswith("no map at 20 steps: "))
    assert "sensed so far" in why  # the mapper's reason: too few anchors sensed yet
    assert why.split(": ", 1)[1] in (tmp_path / "scores.csv").read_text()  # the note column


def test_a_method_without_parameters_is_shown_by_its_name_alone(tmp_path, capsys):
    path = tmp_path / "walk.npz"
    assert main(["collect", "--steps", "100", "--out", str(path)]) == 0
    assert main(["map", str(path), "--method", "CAL-SMA", "--out", str(tmp_path / "m")]) == 0
    out = capsys.readouterr().out
    assert ": CAL-SMA\n" in out and "(-)" not in out
    assert main(["run", "--method", "LPCA", "--steps", "100", "--every", "100",
                 "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert "seed 0, LPCA\n" in out and "(-)" not in out


def test_run_and_map_print_the_map_warnings(tmp_path, capsys, monkeypatch):
    import mappers

    real = mappers.build_map

    def warned(*args, **kwargs):
        import dataclasses

        return dataclasses.replace(real(*args, **kwargs), warnings=("a note from the mapper",))

    monkeypatch.setattr(mappers, "build_map", warned)
    assert main(["run", "--steps", "100", "--every", "100", "--out", str(tmp_path / "r")]) == 0
    assert "warning: a note from the mapper" in capsys.readouterr().out
    assert "a note from the mapper" in (tmp_path / "r" / "scores.csv").read_text()
    assert main(["map", str(tmp_path / "r" / "history.npz"), "--out", str(tmp_path / "m")]) == 0
    assert "warning: a note from the mapper" in capsys.readouterr().out


def test_the_live_gif_panels_show_the_walls_and_every_estimate(monkeypatch):
    """The arena panel keeps its one-pixel walls when scaled down; the map panel widens beyond
    the walls to show estimates that fall outside the arena (they used to be cut off)."""
    from types import SimpleNamespace

    import mappers
    from lfmdr_gym.experiments.live import online_episode
    from lfmdr_gym.render import ESTIMATE, WALL

    class Far:  # a map whose estimates lie outside the arena, as an early online map's may
        def __init__(self, anchor_ids, anchor_positions, **kwargs):
            self.anchors = np.asarray(anchor_ids)

        def update(self, columns, mask=None):
            positions = np.tile([[2.0, 0.0]], (50, 1))
            positions[self.anchors] = [[0.0, 0.0]]
            return SimpleNamespace(positions=positions, warnings=())

    monkeypatch.setattr(mappers, "OnlineMapper", Far)
    frames, rows, _ = online_episode("LFMDR-Visibility-v0", 20, frame_every=20, size=240)
    frame = frames[-1][1]
    arena, picture = frame[:, :240], frame[:, 240:]
    dark = np.all(arena < 200, axis=2)  # walls (drawn dark, averaged with the background)
    assert dark[:, -8:].sum(axis=0).max() > 200 and dark[-8:].sum(axis=1).max() > 200
    wall = np.argwhere(np.all(picture == WALL, axis=2))
    blue = np.argwhere(np.all(picture == ESTIMATE, axis=2))
    assert blue.size and blue[:, 1].max() > wall[:, 1].max()  # drawn, right of the east wall
    assert rows[-1]["mapped"] == 50


def test_the_table_footer_says_plainly_what_the_paper_text_lacks(tmp_path):
    from lfmdr_gym.experiments.figures import write_table

    rows = [{"method": "LPCA", "param": "-", "n_steps": 100, "mpe": 1.0, "moe": 10.0,
             "mpe_nonanchor": 1.1, "error": ""}]
    for sensor in ("visibility", "bearing"):
        write_table(rows, tmp_path, sensor=sensor, n_steps=100, methods=["LPCA"])
        footer = (tmp_path / "table.md").read_text().splitlines()[-1]
        assert footer.startswith("Paper: Yairi 2007, Table") and "seed" not in footer
    assert "numbers are missing" in footer
    write_table(rows, tmp_path, sensor="visibility", n_steps=100, methods=["LPCA"])
    footer = (tmp_path / "table.md").read_text().splitlines()[-1]
    assert "only three of its five graph-based methods" in footer and "without saying" in footer


@pytest.mark.parametrize("missing", ["pygame", "display"])
def test_human_rendering_without_pygame_or_a_display_names_the_project_extra(missing, monkeypatch):
    import gymnasium as gym

    from lfmdr_gym import ENV_IDS

    if missing == "pygame":
        monkeypatch.setitem(sys.modules, "pygame", None)  # import pygame -> ImportError
    else:
        pytest.importorskip("pygame")
        for name in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER"):
            monkeypatch.delenv(name, raising=False)
        monkeypatch.setattr(sys, "platform", "linux")
    for env_id in ENV_IDS:
        # gym.make hands "human" to the env (no HumanRendering wrapper, whose error asked for
        # gymnasium[classic-control] at the first step): the env says what to install
        with pytest.raises(Exception) as exc:
            env = gym.make(env_id, render_mode="human")
            env.reset(seed=0)
            env.step(env.action_space.sample())
        assert 'pip install "lfmdr[human]"' in str(exc.value), str(exc.value)
        assert "classic-control" not in str(exc.value)


def test_both_packages_ship_py_typed():
    import tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    data = config["tool"]["setuptools"]["package-data"]
    for package in ("lfmdr_gym", "mappers"):
        assert (ROOT / package / "py.typed").is_file(), package
        assert "py.typed" in data.get(package, []), package


def test_the_policy_contract_gives_the_proximity_rays_layout_and_it_is_true():
    import gymnasium as gym

    from lfmdr_gym.exploration.contract import Policy

    doc = " ".join(Policy.__doc__.split())
    for fact in ("2 pi k / n_rays", "counter-clockwise", "ray 0 straight ahead",
                 "proximity_range", "step_length + robot_radius", "[m]"):
        assert fact in doc, fact
    readme = " ".join((ROOT / "docs" / "guide" / "extending.md").read_text().split())
    assert "ray k points at `heading + 2 pi k / 32`" in readme
    # the truth: the robot facing north (+y) near the east wall, nothing else around
    env = gym.make("LFMDR-Visibility-v0")
    a = env.unwrapped.world.arena_half
    objects = np.array([[-a + 0.3 + 0.2 * (k % 5), -a + 0.3 + 0.2 * (k // 5)] for k in range(50)])
    obs, _ = env.reset(seed=0, options={"object_positions": objects,
                                        "robot_pose": np.array([a - 0.2, 0.5, np.pi / 2])})
    ray = obs["proximity"]
    n = env.unwrapped.n_proximity_rays
    assert ray.shape == (n,) == (32,) and ray.dtype == np.float32
    assert ray[3 * n // 4] == pytest.approx(0.2, abs=1e-5)  # to the right: the east wall, 0.2 m
    assert ray[0] == ray[n // 4] == ray[n // 2] == pytest.approx(0.5)  # ahead, left, behind: free
    assert ray.max() <= env.unwrapped.proximity_range == 0.5
    env.close()
