"""Loaders for logged robot data that produce :class:`lfmdr_gym.histories.history.History`
objects."""

from lfmdr_gym.datasets.mrclam import (
    DEFAULT_BIN_WIDTH,
    MRCLAMDataWarning,
    MRCLAMReport,
    MRCLAMRun,
    bin_run,
    check_groundtruth,
    corner_anchors,
    load_mrclam,
    read_run,
)
from lfmdr_gym.datasets.mrclam_table import mrclam_anchors, mrclam_landmarks, mrclam_observations

__all__ = [
    "DEFAULT_BIN_WIDTH", "MRCLAMDataWarning", "MRCLAMReport", "MRCLAMRun", "bin_run",
    "check_groundtruth", "corner_anchors", "load_mrclam", "mrclam_anchors", "mrclam_landmarks",
    "mrclam_observations", "read_run",
]
