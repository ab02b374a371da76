"""Maps of histories with missing observations (paper §5.1): co-observation statistics and the maps built on them.
"""

from __future__ import annotations

from mappers.masked.coobservation import (
    angle_covisibility_dissimilarity,
    co_observation_components,
    co_observation_counts,
    covisibility_dissimilarity,
    masked_euclidean_dissimilarity,
    pair_components,
    range_pair_bounds,
    range_pair_distances,
)
from mappers.masked.covis_auto import CovisAuto, CovisCalibrated, co_observation_coefficient
from mappers.masked.covis_sparse import SparseCovis, sparse_co_observation
from mappers.masked.dropout_blend import WALK_PERSISTENCE, DropoutBlend, smooth_steps
from mappers.masked.ensemble import (
    CovisEnsemble,
    ensemble_embedding,
    geometric_median,
    window_steps,
)
from mappers.masked.pair_maps import (
    MASKED_METHODS,
    MaskedMap,
    MaskedMapper,
    MaskedMapWarning,
    masked_embedding,
)

__all__ = [
    "angle_covisibility_dissimilarity", "co_observation_components", "co_observation_counts",
    "covisibility_dissimilarity", "masked_euclidean_dissimilarity", "pair_components",
    "range_pair_bounds", "range_pair_distances",
    "CovisAuto", "CovisCalibrated", "co_observation_coefficient",
    "SparseCovis", "sparse_co_observation",
    "WALK_PERSISTENCE", "DropoutBlend", "smooth_steps",
    "CovisEnsemble", "ensemble_embedding", "geometric_median", "window_steps",
    "MASKED_METHODS", "MaskedMap", "MaskedMapper", "MaskedMapWarning", "masked_embedding",
]
