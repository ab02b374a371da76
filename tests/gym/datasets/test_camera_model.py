"""The camera measurement behind LFMDR-Camera-v0 (lfmdr_gym.datasets.camera_model): it recovers
a known camera from a synthetic MRCLAM-format run, and on a real run gives the preset's figures."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from paths import SHARED_DATA

from lfmdr_gym.datasets.camera_model import image_residuals, main, measure_camera
from lfmdr_gym.sim.camera import CAMERA_PRESET

DATA = SHARED_DATA / "mrclam"
HEADER = "# synthetic\n# run\n# for\n# tests\n"


def _write_run(root: Path, sd_range: float, sd_bearing: float, half_fov: float, max_range: float,
               seed: int = 0) -> Path:
    """An MRCLAM-layout run of a known camera: 15 landmarks, five robots (400 readings each:
    about 315 images of 3+ landmarks, each fitted 4 times by least squares; 600 readings took
    1.6x the CPU for estimates as close), Gaussian noise."""
    rng = np.random.default_rng(seed)
    root.mkdir()
    landmarks = rng.uniform((0.0, 0.0), (10.0, 6.0), (15, 2))
    subjects = np.arange(6, 21)
    barcodes = {s: 10 + 3 * s for s in range(1, 21)}
    (root / "Barcodes.dat").write_text(HEADER + "".join(f"{s} {b}\n" for s, b in barcodes.items()))
    (root / "Landmark_Groundtruth.dat").write_text(HEADER + "".join(
        f"{s} {x:.6f} {y:.6f} 0.0001 0.0001\n" for s, (x, y) in zip(subjects, landmarks, strict=True)))
    for robot in range(1, 6):
        lines, t = [], 1000.0 * robot
        while len(lines) < 400:
            pose = np.array([*rng.uniform((0.0, 0.0), (10.0, 6.0)), rng.uniform(-np.pi, np.pi)])
            d = landmarks - pose[:2]
            r = np.hypot(d[:, 0], d[:, 1])
            b = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - pose[2])))
            seen = (np.abs(b) <= half_fov) & (r <= max_range) & (r > 0.8)
            t += 0.5
            for j in np.flatnonzero(seen):
                lines.append(f"{t:.3f} {barcodes[subjects[j]]} {r[j] + rng.normal(0, sd_range):.4f} "
                             f"{b[j] + rng.normal(0, sd_bearing):.5f}\n")
        (root / f"Robot{robot}_Measurement.dat").write_text(HEADER + "".join(lines))
    return root


@pytest.fixture(scope="module")
def synthetic_run(tmp_path_factory):
    return _write_run(tmp_path_factory.mktemp("runs") / "MRCLAM_Synthetic", sd_range=0.05,
                      sd_bearing=math.radians(0.5), half_fov=math.radians(30.0), max_range=6.0)


def test_a_known_camera_is_recovered_from_a_synthetic_run(synthetic_run):
    cam = measure_camera([synthetic_run])
    assert cam.images_fitted > 250
    assert cam.bearing_noise_deg == pytest.approx(0.5, rel=0.15)
    assert cam.range_noise == pytest.approx(0.05, rel=0.15)
    assert cam.range_noise_all == pytest.approx(0.05, rel=0.15)
    assert 59.0 < cam.fov_deg <= 64.0  # the extreme bearings, noise (0.5 deg) included
    assert 5.5 < cam.max_range <= 6.1
    assert abs(cam.range_bias) < 0.01 and abs(cam.bearing_bias_deg) < 0.1
    assert set(cam.preset()) == {"fov_deg", "max_range", "bearing_noise_deg", "range_noise"}
    assert cam.per_run[0][0] == "MRCLAM_Synthetic"


def test_no_run_or_no_image_of_enough_landmarks_is_refused(synthetic_run):
    with pytest.raises(ValueError, match="at least one MRCLAM run directory"):
        measure_camera([])
    with pytest.raises(ValueError, match="no camera image with 16 or more distinct landmarks"):
        image_residuals([synthetic_run], min_landmarks=16)


@pytest.mark.slow
@pytest.mark.skipif(not (DATA / "MRCLAM_Dataset1").is_dir(), reason="MRCLAM data not present")
def test_the_runs_give_the_preset(capsys):
    """The preset's figures are what the script prints for the four runs (about 2 minutes)."""
    runs = sorted(DATA.glob("MRCLAM_Dataset*"))
    assert main([str(r) for r in runs]) == 0
    out = capsys.readouterr().out
    keywords = out.split("LFMDR-Camera-v0 keywords: ")[1].strip()
    got = dict(kv.split("=") for kv in keywords.split(", "))
    for name, value in got.items():
        assert float(value) == pytest.approx(CAMERA_PRESET[name], abs=1e-9)
