"""``mappers.viewpoints.engine.scatter_sum`` with no observations (issue 35: BEARING-BA crashed
with a reshape error when no observation involved a free object)."""

import numpy as np
from synthetic_walk import ANCHORS, history, layout, walk

from mappers import build_map
from mappers.viewpoints.engine import scatter_sum


def test_scatter_sum_of_no_values_is_zeros_of_the_full_shape():
    out = scatter_sum(np.array([], dtype=int), np.zeros((0, 2, 2)), 3)
    assert out.shape == (3, 2, 2) and not out.any()
    out = scatter_sum(np.array([0, 2, 2]), np.arange(12.0).reshape(3, 2, 2), 3)
    np.testing.assert_array_equal(out[2], [[12.0, 14.0], [16.0, 18.0]])
    np.testing.assert_array_equal(out[1], 0.0)


def test_masked_bearing_default_maps_a_short_walk():
    # 15 objects, 30 steps through a 120-degree view: no step pins a free object down, which
    # crashed BEARING-BA's joint step (found by tests/mappers/test_symmetries.py)
    P = layout(15, seed=0)
    X, mask = history(P, walk(30, seed=100), "bearing", masked=True)
    result = build_map(X, ANCHORS, P[ANCHORS], mask=mask)
    assert result.method == "BEARING-BA"
    np.testing.assert_allclose(result.positions[ANCHORS], P[ANCHORS])
