"""Stress majorisation (SMACOF): weighted, with other links between dissimilarity and distance, and on a sparse graph of pairs.

scikit-learn's ``smacof`` takes no weights; these are written here (de Leeuw 1977; the paper's eq. 6).
"""

from __future__ import annotations

from mappers.smacof.sparse_stress import candidate_pairs, knn_pairs, landmark_mds, sparse_smacof
from mappers.smacof.stress_covariance import stress_hessian, stress_response
from mappers.smacof.variants import bounded_smacof, nonmetric_smacof, power_link_smacof
from mappers.smacof.weighted import (
    GuttmanTransform,
    WeightedSMACOF,
    classical_mds,
    euclidean_distance_matrix,
    raw_stress,
    squared_distance_matrix,
    weighted_smacof,
)

__all__ = [
    "candidate_pairs", "knn_pairs", "landmark_mds", "sparse_smacof",
    "bounded_smacof", "nonmetric_smacof", "power_link_smacof", "stress_hessian", "stress_response",
    "GuttmanTransform", "WeightedSMACOF", "classical_mds", "euclidean_distance_matrix",
    "raw_stress", "squared_distance_matrix", "weighted_smacof",
]
