"""Which objects sightings can place: those linked by sightings to three anchors off a line."""

import numpy as np
import pytest
from scipy.sparse import csr_matrix

from mappers.spatial import SpatialAdjustment
from mappers.spatial.anchored import anchored_objects


def _seen(groups, n_objects):
    """A sighting matrix with one step per listed group of objects."""
    S = np.zeros((n_objects, len(groups)))
    for j, g in enumerate(groups):
        S[g, j] = 1.0
    return S


ANCHORS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def test_groups_without_three_anchors_off_a_line_are_not_anchored():
    # objects 0-3 linked through steps to anchors 0, 1, 2; objects 4-6 hold one anchor (4);
    # objects 7, 8 hold none; object 9 is never seen
    S = _seen([[0, 1, 3], [1, 2], [3], [4, 5], [5, 6], [7, 8]], 10)
    out = anchored_objects(S, np.array([0, 1, 2, 4]), ANCHORS)
    np.testing.assert_array_equal(out, [1, 1, 1, 1, 0, 0, 0, 0, 0, 0])
    # the same from a sparse matrix, and a NaN entry counts as not seen
    np.testing.assert_array_equal(anchored_objects(csr_matrix(S), np.array([0, 1, 2, 4]),
                                                   ANCHORS), out)
    S2 = S.copy()
    S2[3, 0] = np.nan
    assert not anchored_objects(S2, np.array([0, 1, 2, 4]), ANCHORS)[3]


def test_two_anchors_or_anchors_on_a_line_leave_a_group_free():
    S = _seen([[0, 1, 2, 3]], 4)
    assert not anchored_objects(S, np.array([0, 1]), ANCHORS[:2]).any()
    on_line = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    assert not anchored_objects(S, np.array([0, 1, 2]), on_line).any()
    assert anchored_objects(S, np.array([0, 1, 2]), ANCHORS[:3]).all()
    # planar anchors (2-D) off a line fix a planar group alike
    assert anchored_objects(S, np.array([0, 1, 2]), ANCHORS[:3, :2]).all()


def test_bad_input_is_named():
    S = _seen([[0, 1, 2]], 3)
    with pytest.raises(ValueError, match="seen"):
        anchored_objects(np.zeros(3), np.array([0, 1, 2]), ANCHORS[:3])
    with pytest.raises(ValueError, match="anchor_ids"):
        anchored_objects(S, np.array([0, 1, 5]), ANCHORS[:3])
    with pytest.raises(ValueError, match="anchor_positions"):
        anchored_objects(S, np.array([0, 1, 2]), ANCHORS[:2])
    with pytest.raises(ValueError, match="NaN"):
        anchored_objects(S, np.array([0, 1, 2]), np.full((3, 3), np.nan))


def test_spatial_ba_leaves_an_unanchored_group_unmapped_and_says_so():
    """Stereo sightings of two groups of tags: one with the three anchors, one linked to none.
    The second cannot be placed, whatever its sightings; the map says why."""
    rng = np.random.default_rng(3)
    P = rng.uniform(-1.0, 1.0, (10, 3)) + [0.0, 0.0, 4.0]  # in front of cameras at the origin
    groups = [[0, 1, 2, 3, 4], [2, 3, 4, 5], [0, 4, 5, 1], [6, 7, 8, 9], [7, 8, 9, 6]]
    n = len(groups)
    rays = np.zeros((10, 3 * n))  # a zero ray: not seen
    ranges = np.zeros((10, n))
    for j, g in enumerate(groups):
        shift = rng.normal(0.0, 0.1, 3)  # each step a little elsewhere, unturned
        v = P[g] - shift
        ranges[g, j] = np.linalg.norm(v, axis=1)
        rays[g, 3 * j:3 * j + 3] = v / ranges[g, j][:, None]
    est = SpatialAdjustment(loss=None).fit({"bearing": rays, "range": ranges},
                                           anchor_ids=[0, 1, 2], anchor_positions=P[:3])
    np.testing.assert_array_equal(est.unanchored_, [6, 7, 8, 9])
    assert np.isnan(est.embedding_[6:]).all()
    np.testing.assert_allclose(est.embedding_[:6], P[:6], atol=1e-6)
    assert "[6, 7, 8, 9]" in est.notes_[0]
