"""The paper's ten dimensionality-reduction methods (Yairi 2007, Table 1) and maximum variance unfolding.

scikit-learn provides most of them; LLE, LEM and MVU are wrapped or written here with the paper's graph.
"""

from __future__ import annotations

from mappers.paper.methods import LaplacianEigenmap, LocallyLinear
from mappers.paper.mvu import MaximumVarianceUnfolding, mvu_constraint_matrix

__all__ = [
    "LaplacianEigenmap", "LocallyLinear",
    "MaximumVarianceUnfolding", "mvu_constraint_matrix",
]
