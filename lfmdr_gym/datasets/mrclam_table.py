"""An MRCLAM run as observation tables (issue 33): its sightings, its anchors, its ground truth.

:func:`mrclam_observations` writes the filtered landmark sightings of a run
(:func:`lfmdr_gym.datasets.mrclam.read_run`) as an observation table
(:mod:`lfmdr_gym.histories.observation_table`: ``time, robot, landmark, range, bearing``, ids
the MRCLAM subject numbers); :func:`mrclam_landmarks` its ground truth and
:func:`mrclam_anchors` its anchors, as ``landmark, x, y`` tables. Through
:func:`lfmdr_gym.histories.observations.observations_to_history` with the same bin width they give
the histories :func:`lfmdr_gym.datasets.mrclam.load_mrclam` gives (same matrices, masks,
timeline, positions and anchors): the table keeps the run's robot order and landmark list in its
``attrs``, and its rows in the loader's order (robot, then time), so the bins' sums are taken in
the same order.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
import pandas as pd

from lfmdr_gym.datasets.mrclam import ROBOT_SUBJECTS, MRCLAMRun, corner_anchors, read_run

__all__ = ["mrclam_anchors", "mrclam_landmarks", "mrclam_observations"]


def _run(run: MRCLAMRun | str | os.PathLike, robots: Sequence[int],
         groundtruth_fixes: str) -> MRCLAMRun:
    if isinstance(run, MRCLAMRun):
        return run
    return read_run(run, robots, groundtruth_fixes=groundtruth_fixes)


def mrclam_observations(
    run: MRCLAMRun | str | os.PathLike,
    *,
    robots: Sequence[int] = ROBOT_SUBJECTS,
    groundtruth_fixes: str = "known",
) -> pd.DataFrame:
    """The landmark sightings of an MRCLAM run as an observation table.

    Args:
        run: a run read by :func:`~lfmdr_gym.datasets.mrclam.read_run`, or its directory (then
            read with ``robots`` and ``groundtruth_fixes``, see there).

    Columns ``time`` [s], ``robot`` and ``landmark`` (subject numbers), ``range`` [m] and
    ``bearing`` [rad]; one row per kept measurement, in the loader's order. ``attrs``: ``source``
    ("MRCLAM"), ``run``, ``sensor`` ("range-bearing"), ``robots`` (the robot order of the
    timeline), ``landmarks`` (every landmark with ground truth, sighted or not: the history's
    rows) and the loader's ``report`` (what it dropped and warned about).
    """
    run = _run(run, robots, groundtruth_fixes)
    obs = run.obs
    table = pd.DataFrame({
        "time": obs[:, 1],
        "robot": obs[:, 0].astype(np.int64),
        "landmark": run.subjects[obs[:, 2].astype(np.int64)],
        "range": obs[:, 3],
        "bearing": obs[:, 4],
    })
    table.attrs = {"source": "MRCLAM", "run": run.name, "sensor": "range-bearing",
                   "robots": list(run.report.robots), "landmarks": run.subjects.tolist(),
                   "report": run.report.as_dict()}
    return table


def mrclam_landmarks(run: MRCLAMRun | str | os.PathLike, *,
                     groundtruth_fixes: str = "known") -> pd.DataFrame:
    """The run's landmark ground truth (after ``groundtruth_fixes``) as ``landmark, x, y``."""
    run = _run(run, ROBOT_SUBJECTS, groundtruth_fixes)
    return pd.DataFrame({"landmark": run.subjects, "x": run.truth[:, 0], "y": run.truth[:, 1]})


def mrclam_anchors(run: MRCLAMRun | str | os.PathLike, anchors: Sequence[int] | None = None, *,
                   groundtruth_fixes: str = "known") -> pd.DataFrame:
    """The anchors as ``landmark, x, y``: the given landmark subject numbers, or (None) the 4
    landmarks nearest the corners of the landmarks' bounding box, as the loader picks them."""
    run = _run(run, ROBOT_SUBJECTS, groundtruth_fixes)
    if anchors is None:
        rows = corner_anchors(run.truth)
    else:
        subjects = run.subjects.tolist()
        missing = [int(a) for a in anchors if int(a) not in subjects]
        if missing:
            raise ValueError(f"anchors {missing} are not landmark subjects of {run.name} "
                             f"(landmarks: {subjects})")
        rows = np.array([subjects.index(int(a)) for a in anchors], dtype=np.int64)
    return pd.DataFrame({"landmark": run.subjects[rows], "x": run.truth[rows, 0],
                         "y": run.truth[rows, 1]})
