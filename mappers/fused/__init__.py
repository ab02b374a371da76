"""Fused histories: several sensors' histories of the same objects mapped together (range + bearing, visibility + bearing).
"""

from __future__ import annotations

from mappers.fused.law_of_cosines import (
    frame_triangles,
    frame_values,
    handedness_votes,
    pooled_frame_distances,
    sample_variance_model,
)
from mappers.fused.loc_sma import LawOfCosinesSMACOF, RigidityWarning, pair_weights
from mappers.fused.rigidity import anchored_components, flexible_objects
from mappers.fused.vb_sma import VisibilityBearingSMACOF, joined_rows

__all__ = [
    "frame_triangles", "frame_values", "handedness_votes", "pooled_frame_distances",
    "sample_variance_model",
    "LawOfCosinesSMACOF", "RigidityWarning", "pair_weights",
    "anchored_components", "flexible_objects",
    "VisibilityBearingSMACOF", "joined_rows",
]
