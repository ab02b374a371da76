"""lfmdr mappers: observation histories -> 2-D maps by dimensionality reduction (paper §3), and
3-D maps when the anchors are 3-D (:mod:`mappers.spatial`).

Arrays in, maps out: this package never imports gymnasium or lfmdr_gym, so it serves logged
data as well as the simulator. Every method is a :class:`MethodSpec` in :data:`METHODS`;
:func:`build_map` picks one by what it accepts (sensor; complete or masked history).

The names below are loaded on first use (PEP 562), so that importing the package, or only its
sensor vocabulary (:mod:`mappers.core.sensors`, which the world uses), does not load scikit-learn
and cvxpy.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY: dict[str, str] = {
    "COLUMNS_PER_STEP": "mappers.core.sensors",
    "SENSORS": "mappers.core.sensors",
    "infer_sensor": "mappers.core.sensors",
    "METHODS": "mappers.catalog",
    "MappingError": "mappers.catalog",
    "MethodSpec": "mappers.catalog",
    "methods_for": "mappers.catalog",
    "register_method": "mappers.catalog",
    "resolve_method": "mappers.catalog",
    "DEFAULTS": "mappers.defaults",
    "DEFAULT_METHODS": "mappers.defaults",
    "choose_method": "mappers.defaults",
    "localisation_free": "mappers.defaults",
    "Map": "mappers.pipeline",
    "MapWarning": "mappers.pipeline",
    "build_map": "mappers.pipeline",
    "default_method": "mappers.pipeline",
    "apply_affine": "mappers.core.align",
    "fit_affine": "mappers.core.align",
    "mean_orientation_error": "mappers.core.scores",
    "mean_position_error": "mappers.core.scores",
    "sampled_orientation_error": "mappers.core.scores",
    "GraphRepairWarning": "mappers.core.graph",
    "flicker_rate": "mappers.core.flicker",
    "LaplacianEigenmap": "mappers.paper",
    "LocallyLinear": "mappers.paper",
    "MaximumVarianceUnfolding": "mappers.paper",
    "WeightedSMACOF": "mappers.smacof",
    "weighted_smacof": "mappers.smacof",
    "CalibratedSMACOF": "mappers.calibrated",
    "FoldWarning": "mappers.calibrated",
    "ClassicalUnfolding": "mappers.calibrated",
    "MaskedMap": "mappers.masked",
    "MaskedMapWarning": "mappers.masked",
    "masked_embedding": "mappers.masked",
    "CovisEnsemble": "mappers.masked",
    "DropoutBlend": "mappers.masked",
    "BearingAdjustment": "mappers.viewpoints",
    "VisibilityAdjustment": "mappers.viewpoints",
    "OnlineMapper": "mappers.online",
    "fit_affine_3d": "mappers.core.align_3d",
    "fit_similarity_3d": "mappers.core.align_3d",
    "mean_position_error_3d": "mappers.core.scores_3d",
    "tetrahedron_orientation_error": "mappers.core.scores_3d",
    "SpatialAdjustment": "mappers.spatial",
    "CoVisibility3D": "mappers.spatial",
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
