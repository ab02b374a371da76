"""Where MRCLAM runs come from and the folder layout the loader expects; a missing folder or file
is reported by name, with where to get the data.

The UTIAS Multi-Robot Cooperative Localization and Mapping dataset (Leung, Halpern, Barfoot and
Liu, IJRR 30(8):969-974, 2011) is published at :data:`MRCLAM_URL`, one archive per run; each
unpacks to a folder ``MRCLAM_DatasetN`` holding the files of :data:`RUN_FILES` (and odometry and
robot ground truth, which localisation-free mapping does not read).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

__all__ = ["MRCLAM_URL", "RUN_FILES", "MRCLAMLayoutError", "check_run_layout"]

MRCLAM_URL = "http://asrl.utias.utoronto.ca/datasets/mrclam/"
"""The dataset's home page (the runs, their README and the paper)."""

RUN_FILES = ("Barcodes.dat", "Landmark_Groundtruth.dat", "Robot{robot}_Measurement.dat")
"""The files of a run folder the loader reads (``{robot}``: each robot number used, 1-5)."""


class MRCLAMLayoutError(FileNotFoundError, ValueError):
    """A run folder that is missing or lacks a file the loader reads (a FileNotFoundError, and a
    ValueError as a robot number without its file always was)."""


def _where() -> str:
    return (f"MRCLAM runs are published at {MRCLAM_URL}: unpack a run (e.g. MRCLAM_Dataset1) "
            "and pass its folder, which holds Barcodes.dat, Landmark_Groundtruth.dat and "
            "Robot1_Measurement.dat ... Robot5_Measurement.dat")


def check_run_layout(run_dir: str | Path, robots: Sequence[int]) -> None:
    """Raise :class:`MRCLAMLayoutError` naming what is missing from ``run_dir`` (the folder itself, or
    the files of :data:`RUN_FILES` for ``robots``) and where to get the dataset."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        what = "is not a folder" if run_dir.exists() else "does not exist"
        raise MRCLAMLayoutError(f"MRCLAM run folder {run_dir} {what}. {_where()}")
    names = [n.format(robot=r) for n in RUN_FILES for r in (robots if "{" in n else [0])]
    missing = [n for n in names if not (run_dir / n).is_file()]
    if missing:
        raise MRCLAMLayoutError(f"{run_dir} is not an MRCLAM run folder: it lacks "
                                f"{', '.join(missing)}. {_where()}")
