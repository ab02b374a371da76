"""Maps that calibrate history dissimilarities against distance: CAL-SMA (dense, or sparse with
``sparse=True``) and UNFOLD for ranges.
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
from mappers.calibrated.factory import dense_keywords
from mappers.calibrated.unfolding import ClassicalUnfolding

__all__ = [
    "CalibratedSMACOF", "CalibrationFit", "FoldWarning", "fit_calibration", "fold_score",
    "history_dissimilarity", "log_floor",
    "SparseCalibratedSMACOF",
    "dense_keywords",
    "ClassicalUnfolding",
]
