"""lfmdr mappers: observation histories -> 2-D maps by dimensionality reduction (SPEC §3-4).

Arrays in, maps out: this package never imports gymnasium or lfmdr_gym, so it serves logged
data as well as the simulator.
"""

from mappers.align import apply_affine, fit_affine
from mappers.calibrated import CalibratedSMACOF, FoldWarning  # registers CAL-SMA
from mappers.graph import GraphRepairWarning
from mappers.methods import (
    DEFAULT_METHODS,
    METHODS,
    LaplacianEigenmap,
    LocallyLinear,
    MappingError,
    MethodSpec,
    register_method,
)
from mappers.mvu import MaximumVarianceUnfolding
from mappers.pipeline import SENSORS, Map, build_map, infer_sensor
from mappers.scores import mean_orientation_error, mean_position_error
from mappers.smacof import WeightedSMACOF, weighted_smacof
from mappers.unfolding import ClassicalUnfolding  # registers UNFOLD

__all__ = [
    "CalibratedSMACOF",
    "ClassicalUnfolding",
    "FoldWarning",
    "DEFAULT_METHODS",
    "METHODS",
    "SENSORS",
    "GraphRepairWarning",
    "LaplacianEigenmap",
    "LocallyLinear",
    "Map",
    "MappingError",
    "MaximumVarianceUnfolding",
    "MethodSpec",
    "WeightedSMACOF",
    "apply_affine",
    "build_map",
    "fit_affine",
    "infer_sensor",
    "mean_orientation_error",
    "mean_position_error",
    "register_method",
    "weighted_smacof",
]
