"""lfmdr mappers: observation histories -> 2-D maps by dimensionality reduction (paper §3).

Arrays in, maps out: this package never imports gymnasium or lfmdr_gym, so it serves logged
data as well as the simulator. Every method is a :class:`MethodSpec` in :data:`METHODS`;
:func:`build_map` picks one by what it accepts (sensor; complete or masked history).

The names below are loaded on first use (PEP 562), so that importing the package, or only its
sensor vocabulary (:mod:`mappers.sensors`, which the world uses), does not load scikit-learn
and cvxpy.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY: dict[str, str] = {
    "COLUMNS_PER_STEP": "mappers.sensors",
    "SENSORS": "mappers.sensors",
    "infer_sensor": "mappers.sensors",
    "DEFAULT_METHODS": "mappers.registry",
    "METHODS": "mappers.registry",
    "MappingError": "mappers.registry",
    "MethodSpec": "mappers.registry",
    "methods_for": "mappers.registry",
    "register_method": "mappers.registry",
    "resolve_method": "mappers.registry",
    "Map": "mappers.pipeline",
    "build_map": "mappers.pipeline",
    "default_method": "mappers.pipeline",
    "apply_affine": "mappers.align",
    "fit_affine": "mappers.align",
    "mean_orientation_error": "mappers.scores",
    "mean_position_error": "mappers.scores",
    "sampled_orientation_error": "mappers.scores",
    "GraphRepairWarning": "mappers.graph",
    "LaplacianEigenmap": "mappers.methods",
    "LocallyLinear": "mappers.methods",
    "WeightedSMACOF": "mappers.smacof",
    "weighted_smacof": "mappers.smacof",
    "MaximumVarianceUnfolding": "mappers.mvu",
    "CalibratedSMACOF": "mappers.calibrated",
    "FoldWarning": "mappers.calibrated",
    "ClassicalUnfolding": "mappers.unfolding",
    "MaskedMap": "mappers.masked",
    "MaskedMapWarning": "mappers.masked",
    "masked_embedding": "mappers.masked",
    "CovisEnsemble": "mappers.ensemble",
    "DROPOUT_DEFAULTS": "mappers.registry",
    "flicker_rate": "mappers.flicker",
    "DropoutBlend": "mappers.dropout_blend",
    "VisibilityAdjustment": "mappers.visibility_adjustment",
    "OnlineMapper": "mappers.online",
    "BearingAdjustment": "mappers.bearing_adjustment",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'mappers' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
