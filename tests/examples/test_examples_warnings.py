"""Every example that builds a map prints the map's warnings (``Map.warnings``): a fold, a graph
that falls apart or an object left unmapped is said where the map's error is printed."""

from __future__ import annotations

import dataclasses
import runpy
import sys

import pytest
from paths import ROOT, SHARED_DATA

import mappers

NOTE = "a note from the mapper"
MRCLAM = SHARED_DATA / "mrclam" / "MRCLAM_Dataset2"

# example -> its arguments for a short run (None: a script without main, run as it is)
EXAMPLES = {
    "quickstart": ["--steps", "300", "--out", "{tmp}/h.npz"],
    "calibrated_map": ["--steps", "300"],
    "limited_camera": ["--steps", "300", "--out", "{tmp}/m.png"],
    "mrclam_camera": ["--steps", "300", "--out", "{tmp}/cam.npz"],
    "levy_policy": ["--seeds", "1", "--steps", "100"],
    "online_map": ["--steps", "100"],
    "map_synthetic": None,
    "mrclam_map": [str(MRCLAM), "--sensor", "range"],
    "map_rosbag": ["--steps", "300", "--container", "mcap", "--msgtype", "apriltag_msgs"],
    "camera3d_map": ["--steps", "300", "--out", "{tmp}/c.png"],
}


@pytest.fixture
def noted(monkeypatch):
    """build_map and OnlineMapper.update return their maps with one more warning."""
    build, update = mappers.build_map, mappers.OnlineMapper.update

    def note(m):
        return dataclasses.replace(m, warnings=(*m.warnings, NOTE))

    monkeypatch.setattr(mappers, "build_map", lambda *a, **k: note(build(*a, **k)))
    monkeypatch.setattr(mappers.OnlineMapper, "update", lambda self, *a, **k: note(update(self, *a, **k)))


@pytest.mark.parametrize("name", EXAMPLES)
def test_the_example_prints_the_map_warnings(name, noted, tmp_path, monkeypatch, capsys):
    if name == "mrclam_map" and not MRCLAM.is_dir():
        pytest.skip("no MRCLAM data here")
    script = ROOT / "examples" / f"{name}.py"
    args = EXAMPLES[name]
    if args is None:
        runpy.run_path(str(script))
    else:
        argv = [a.format(tmp=tmp_path) for a in args]
        monkeypatch.setattr(sys, "argv", [str(script), *argv])
        runpy.run_path(str(script), run_name="__main__")
    out = capsys.readouterr().out
    assert f"warning: {NOTE}" in out or f": {NOTE}" in out, out[-2000:]
