"""Maps in 3-D (issue 34): the dimension comes from the anchors, (A, 3) positions give a 3-D map.

Rays (and ranges) -> SPATIAL-BA, the 6-DoF viewpoint bundle adjustment started from frames
registered to one another by their common objects; sightings -> COVIS-3D, co-observation
embedded in three dimensions, or FRUSTUM-BA, the frustum adjustment of a planar robot's
calibrated camera (FRUSTUM-BA-WALK: with the walk prior on the viewpoints of an ordered
walk), or COVIS-3D-MEDIAN, the median of four co-observation embeddings of ordered steps;
ranges alone -> RANGE-3D, the range-only adjustment of the objects and the
viewpoints' positions. No odometry, no motion model.
"""

from __future__ import annotations

from mappers.spatial.adjustment import AdjustmentResult, adjust_viewpoints
from mappers.spatial.covisibility_3d import CoVisibility3D
from mappers.spatial.frustum import FrustumAdjustment
from mappers.spatial.frustum_walk import FrustumWalkAdjustment
from mappers.spatial.pipeline_3d import METHODS_3D, anchor_dimension, build_map_3d
from mappers.spatial.range_3d import Range3D
from mappers.spatial.rays import RAY_COLUMNS, RayObservations, ray_observations
from mappers.spatial.registration import (
    orthogonal_iteration,
    register_points,
    register_rays,
    triangulate,
)
from mappers.spatial.sightings_median_3d import SightingsMedian3D
from mappers.spatial.spatial_ba import SpatialAdjustment

__all__ = [
    "AdjustmentResult", "adjust_viewpoints", "CoVisibility3D", "FrustumAdjustment", "FrustumWalkAdjustment",
    "METHODS_3D", "anchor_dimension", "build_map_3d", "Range3D",
    "RAY_COLUMNS", "RayObservations", "ray_observations",
    "orthogonal_iteration", "register_points", "register_rays", "triangulate",
    "SightingsMedian3D", "SpatialAdjustment",
]
