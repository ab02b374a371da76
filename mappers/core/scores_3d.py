"""Map scores in 3-D: the mean position error, and an orientation error for space.

The paper's orientation error (§4.3.2) counts the triangles of objects whose vertices turn the
other way in the map than in truth: a reflection or a fold of the plane. In space the analogue of
a triangle's turn is a tetrahedron's handedness: the sign of ``det[p_j - p_i, p_k - p_i, p_l -
p_i]`` for objects ``i < j < k < l``. The *tetrahedron orientation error* is the share [%] of the
object quadruples whose tetrahedron has the opposite sign in the map; a mirrored map scores
100 %, a correct one 0 %, a random one about 50 %. There are C(M, 4) quadruples (230,300 at M =
50), so the score is exact up to a number of quadruples and estimated from a uniform sample
above it.
"""

from __future__ import annotations

from collections.abc import Iterable
from itertools import combinations

import numpy as np

from mappers.core.scores import check_scored_pair

__all__ = ["mean_position_error_3d", "tetrahedron_orientation_error"]

_EXACT_MAX_QUADRUPLES = 2_000_000
"""Up to this many quadruples every one is scored; above it a uniform sample of this many."""


def mean_position_error_3d(estimate, truth, exclude: Iterable[int] | None = None) -> float:
    """Mean Euclidean distance [m] between estimated and true (M, 3) positions, leaving out the
    ids in ``exclude`` (anchors, unmapped objects: NaN rows must be excluded)."""
    est, tru = check_scored_pair(estimate, truth, exclude, dim=3)
    if len(est) == 0:
        raise ValueError("no objects left to score after exclude")
    return float(np.mean(np.linalg.norm(est - tru, axis=1)))


def _signs(P: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Handedness (-1, 0, 1) of the tetrahedra with vertex ids ``q`` (K, 4)."""
    a = P[q[:, 1]] - P[q[:, 0]]
    b = P[q[:, 2]] - P[q[:, 0]]
    c = P[q[:, 3]] - P[q[:, 0]]
    return np.sign(np.einsum("kj,kj->k", a, np.cross(b, c)))


def tetrahedron_orientation_error(estimate, truth, exclude: Iterable[int] | None = None, *,
                                  max_quadruples: int = _EXACT_MAX_QUADRUPLES,
                                  random_state: int | None = 0) -> float:
    """Share [%] of object quadruples whose tetrahedron has the opposite handedness in
    ``estimate`` than in ``truth`` (see the module's docstring); quadruples flat in truth (sign
    0) are not counted. Exact up to ``max_quadruples`` quadruples, else estimated from that many
    drawn uniformly (distinct ids) with ``random_state``."""
    est, tru = check_scored_pair(estimate, truth, exclude, dim=3)
    n = len(est)
    if n < 4:
        raise ValueError(f"need at least 4 objects for the orientation error in 3-D, got {n}")
    if isinstance(max_quadruples, bool) or int(max_quadruples) < 1:
        raise ValueError(f"max_quadruples must be a positive integer, got {max_quadruples!r}")
    total = n * (n - 1) * (n - 2) * (n - 3) // 24
    if total <= max_quadruples:
        q = np.fromiter((v for c in combinations(range(n), 4) for v in c), dtype=np.int64,
                        count=4 * total).reshape(total, 4)
    else:
        rng = np.random.default_rng(random_state)
        q = _draw_distinct(rng, n, int(max_quadruples))
    s_true = _signs(tru, q)
    counted = s_true != 0
    if not counted.any():
        raise ValueError("every tetrahedron of the true positions is flat: they lie on one plane")
    return 100.0 * float(np.mean(_signs(est, q)[counted] != s_true[counted]))


def _draw_distinct(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    """``k`` quadruples of distinct ids in [0, n), each equally likely (rejection of repeats)."""
    out = np.empty((0, 4), dtype=np.int64)
    while len(out) < k:
        q = rng.integers(0, n, size=(2 * k, 4))
        s = np.sort(q, axis=1)
        q = q[np.all(s[:, 1:] != s[:, :-1], axis=1)]
        out = np.vstack([out, q])
    return out[:k]
