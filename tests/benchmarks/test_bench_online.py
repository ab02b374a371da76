"""benchmarks/bench_online.py end to end on a short run, and its --env checks."""

from __future__ import annotations

import os
import subprocess
import sys

from paths import ROOT


def _run(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_online.py"), *args],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=600)


def test_a_run_whose_only_checkpoint_is_n_reports_its_goals():
    # 500 steps: N is the only checkpoint (this used to end in "max() arg is an empty sequence")
    out = _run("--runs", "1", "--steps", "500", "--sensors", "visibility", "--reference-lag", "50")
    assert out.returncode == 0, out.stderr
    assert "no checkpoint before N" in out.stdout
    assert "final MPE <= 1.05 x offline (" in out.stdout
    # the offline map 50 steps earlier over the checkpoint's: a positive ratio in its own column
    header = next(line for line in out.stdout.splitlines() if "online MPE" in line)
    row = next(line for line in out.stdout.splitlines() if line.split()[:1] == ["500"])
    assert header.split()[-4:] == ["offline", "N-50", "/", "N"]
    assert float(row.split()[-1]) > 0


def test_env_keywords_are_checked_against_the_environment():
    bad = _run("--runs", "1", "--sensors", "visibility", "--env", "fov=90")
    assert bad.returncode == 2 and "unknown env keyword 'fov'" in bad.stderr
    twice = _run("--runs", "1", "--env", "fov_deg=90", "--env", "fov_deg=60")
    assert twice.returncode == 2 and "'fov_deg' is given twice" in twice.stderr
    no_value = _run("--runs", "1", "--env", "fov_deg")
    assert no_value.returncode == 2 and "NAME=VALUE" in no_value.stderr
