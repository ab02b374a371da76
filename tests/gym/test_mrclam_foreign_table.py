"""A log written by somebody else's converter maps as well as the project's own (issue 33's goal):
MRCLAM sightings parsed here with plain numpy and csv — no code of the project — as a table
``time, robot, landmark, range, bearing``, mapped by ``lfmdr map``, must give range and
range + bearing maps within 10 % of ``lfmdr mrclam``'s MPE (non-anchor landmarks, same anchors,
same ground truth).

The foreign converter knows nothing of the loader's filtering: it keeps the detector's exact
repeats and maps each barcode to its landmark through ``Barcodes.dat``, dropping robots and
barcodes without ground truth, as anyone reading the dataset's README would.
"""

from __future__ import annotations

import csv
import json
import warnings

import numpy as np
import pytest
from paths import SHARED_DATA

from lfmdr_gym.cli import main

MRCLAM = SHARED_DATA / "mrclam"
RUNS = ("MRCLAM_Dataset1", "MRCLAM_Dataset2", "MRCLAM_Dataset3", "MRCLAM_Dataset6")
TOLERANCE = 0.10

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not MRCLAM.is_dir(),
                                 reason=f"the MRCLAM data folder {MRCLAM} is absent")]


def _foreign_table(run, path):
    """The sightings of ``run`` as a CSV, parsed with numpy alone (4-line # header, CRLF)."""
    barcodes = np.loadtxt(run / "Barcodes.dat", comments="#", ndmin=2).astype(int)
    subject_of = {int(b): int(s) for s, b in barcodes}
    landmarks = set(np.loadtxt(run / "Landmark_Groundtruth.dat", comments="#",
                               ndmin=2)[:, 0].astype(int).tolist())
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["time", "robot", "landmark", "range", "bearing"])
        for robot in range(1, 6):
            rows = np.loadtxt(run / f"Robot{robot}_Measurement.dat", comments="#", ndmin=2)
            for t, barcode, rng, bearing in rows.tolist():
                subject = subject_of.get(int(barcode))
                if subject in landmarks:
                    writer.writerow([repr(t), robot, subject, repr(rng), repr(bearing)])


def _landmark_csv(path, subjects, xy):
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["landmark", "x", "y"])
        writer.writerows([int(s), repr(float(x)), repr(float(y))] for s, (x, y) in zip(subjects, xy, strict=True))


@pytest.mark.parametrize("sensor", ["range", "range-bearing"])
@pytest.mark.parametrize("name", RUNS)
def test_foreign_table_maps_within_ten_percent_of_lfmdr_mrclam(tmp_path, name, sensor, capsys):
    from lfmdr_gym.experiments.mrclam import map_mrclam_run

    run = MRCLAM / name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ours = map_mrclam_run(run, sensor)
    _foreign_table(run, tmp_path / "log.csv")
    anchor = np.isin(ours.subjects, ours.anchor_subjects)
    # the same anchors and the same ground truth (DS1's documented swap fixed) as lfmdr mrclam
    _landmark_csv(tmp_path / "anchors.csv", ours.subjects[anchor], ours.truth[anchor])
    _landmark_csv(tmp_path / "truth.csv", ours.subjects, ours.truth)
    assert main(["map", str(tmp_path / "log.csv"), "--anchors", str(tmp_path / "anchors.csv"),
                 "--truth", str(tmp_path / "truth.csv"), "--sensor", sensor,
                 "--out", str(tmp_path / "map")]) == 0
    capsys.readouterr()
    scores = json.loads((tmp_path / "map" / "scores.json").read_text())
    assert scores["missing_from_truth"] == [] and scores["unmapped"] == []
    assert scores["mpe_nonanchor"] <= (1 + TOLERANCE) * ours.mpe, (
        f"{name} {sensor}: foreign table MPE {scores['mpe_nonanchor']:.4f} m, "
        f"lfmdr mrclam {ours.mpe:.4f} m")
