"""Fused range + bearing on MRCLAM runs (``lfmdr mrclam RUN --sensor range-bearing``) and
visibility + bearing fusion (VB-SMA)."""

import subprocess
import sys
import warnings

import numpy as np
import pytest
from paths import ROOT

from lfmdr_gym.datasets.mrclam import MRCLAMDataWarning
from lfmdr_gym.experiments.mrclam import map_mrclam_run
from mappers import build_map, mean_position_error

DATA = ROOT.parent / "shared" / "data" / "mrclam"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"MRCLAM data not found at {DATA}")


@needs_data
def test_range_bearing_maps_a_real_run_to_a_decimetre(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MRCLAMDataWarning)
        res = map_mrclam_run(DATA / "MRCLAM_Dataset3", "range-bearing", out=tmp_path, plot=False)
    assert res.sensor == "range-bearing" and res.method == "LOC-SMA"
    assert res.history_meta["bin_width"] == 0.25 and res.params["min_count"] == 3
    assert res.mpe < 0.15 and res.centroid_mpe > 2.0
    rows = (tmp_path / "map.csv").read_text().splitlines()
    assert rows[0] == "subject,x,y" and len(rows) == 1 + len(res.subjects)


@needs_data
@pytest.mark.slow
def test_range_bearing_on_the_clustered_run_warns_and_stays_right():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MRCLAMDataWarning)
        res = map_mrclam_run(DATA / "MRCLAM_Dataset6", "range-bearing")
    assert any("fall apart into 2 groups" in w for w in res.warnings)
    assert res.mpe < 0.2


@needs_data
@pytest.mark.slow
def test_cli_range_bearing(tmp_path):
    out = subprocess.run(
        [sys.executable, "-m", "lfmdr_gym.cli", "mrclam", str(DATA / "MRCLAM_Dataset1"),
         "--mode", "range-bearing", "--out", str(tmp_path), "--param", "min_count=1"],
        capture_output=True, text=True, cwd=ROOT, check=True).stdout
    assert "(range-bearing), LOC-SMA (min_count=1" in out and "MPE 0.0" in out
    assert (tmp_path / "map.png").is_file()


def test_vb_sma_maps_joined_visibility_and_bearing():
    rng = np.random.default_rng(3)
    P = rng.uniform(-1, 1, (40, 2))
    P[:4] = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    poses = np.column_stack([rng.uniform(-1, 1, (1500, 2)), rng.uniform(-np.pi, np.pi, 1500)])
    rel = P[:, None] - poses[None, :, :2]
    V = (np.hypot(rel[..., 0], rel[..., 1]) < 0.55).astype(float)
    th = np.arctan2(rel[..., 1], rel[..., 0]) - poses[None, :, 2]
    B = np.stack([np.cos(th), np.sin(th)], -1).reshape(len(P), -1)
    anchors = np.arange(4)
    m = build_map({"visibility": V, "bearing": B}, anchors, P[anchors])
    assert m.method == "VB-SMA" and m.sensor == "visibility-bearing"
    assert mean_position_error(m.positions, P, exclude=list(anchors)) < 0.12  # centroid: ~0.75
    with pytest.raises(ValueError, match="bearing_weight"):
        build_map({"visibility": V, "bearing": B}, anchors, P[anchors], bearing_weight=-1.0)
    with pytest.raises(ValueError, match="methods that do"):
        build_map({"visibility": V, "bearing": B}, anchors, P[anchors],
                  mask={"visibility": V > 0, "bearing": np.repeat(V > 0, 2, axis=1)}, method="VB-SMA")
