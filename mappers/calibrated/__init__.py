"""Maps that calibrate history dissimilarities against distance: CAL-SMA (dense, or sparse with
``sparse=True``) and UNFOLD for ranges; CAL-SMA's linearised block jackknife of its positions
(:mod:`mappers.calibrated.cal_sma_uncertainty`).
"""

from __future__ import annotations

from mappers.calibrated.cal_sma import (
    CalibratedSMACOF,
    CalibrationFit,
    FoldWarning,
    fit_calibration,
    fold_score,
    history_dissimilarity,
    log_floor,
)
from mappers.calibrated.cal_sma_sparse import SparseCalibratedSMACOF
from mappers.calibrated.cal_sma_uncertainty import (
    has_linear_jackknife,
    jackknife_targets,
    linear_jackknife_covariances,
)
from mappers.calibrated.factory import dense_keywords
from mappers.calibrated.unfolding import ClassicalUnfolding

__all__ = [
    "CalibratedSMACOF", "CalibrationFit", "FoldWarning", "fit_calibration", "fold_score",
    "history_dissimilarity", "log_floor",
    "SparseCalibratedSMACOF",
    "has_linear_jackknife", "jackknife_targets", "linear_jackknife_covariances",
    "dense_keywords",
    "ClassicalUnfolding",
]
