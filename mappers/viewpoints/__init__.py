"""Maps refined by estimating the viewpoints from the observations alone (no odometry, no motion model): one bundle-adjustment engine and the adjustments on it.
"""

from __future__ import annotations

from mappers.viewpoints import engine
from mappers.viewpoints.bearing import BearingAdjustment, BearingAdjustmentWarning
from mappers.viewpoints.engine import *  # noqa: F403 (its __all__, re-exported below)
from mappers.viewpoints.marginals import (
    adjustment_covariances,
    has_model_covariances,
    held_out_anchors,
    model_covariances,
    released_anchor,
    released_steps,
    restricted_parts,
    schur_information,
    step_blocks,
)
from mappers.viewpoints.range_bearing import RangeBearingAdjustment
from mappers.viewpoints.start_map import anchored_start, fit_start, free_objects, keep_if_better
from mappers.viewpoints.view_cone import (
    MAX_FOV_DEG,
    MAX_FREE_OBJECTS,
    VIEWPOINT_SEARCH_CONSTRAINTS,
    ConeProblem,
    ViewAdjustment,
    ViewAdjustmentWarning,
    estimate_fov,
    search_cells,
    search_poses,
    view_cone_score,
)
from mappers.viewpoints.visibility import (
    VisibilityAdjustment,
    VisibilityAdjustmentWarning,
    visibility_bits,
)
from mappers.viewpoints.walk_prior import forward_backward, gaussian_taps

__all__ = [
    "BearingAdjustment", "BearingAdjustmentWarning",
    *engine.__all__,
    "adjustment_covariances", "has_model_covariances", "held_out_anchors", "model_covariances",
    "released_anchor", "released_steps", "restricted_parts", "schur_information",
    "step_blocks",
    "RangeBearingAdjustment",
    "anchored_start", "fit_start", "free_objects", "keep_if_better",
    "MAX_FOV_DEG", "MAX_FREE_OBJECTS", "VIEWPOINT_SEARCH_CONSTRAINTS", "ConeProblem",
    "ViewAdjustment", "ViewAdjustmentWarning", "estimate_fov", "search_cells", "search_poses",
    "view_cone_score",
    "VisibilityAdjustment", "VisibilityAdjustmentWarning", "visibility_bits",
    "forward_backward", "gaussian_taps",
]
