"""3-D anchors: the affine and similarity fits, and the refusals naming which fit needs what."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mappers.core.align_3d import (
    apply_affine_3d,
    check_anchors_3d,
    fit_affine_3d,
    fit_similarity_3d,
)
from mappers.core.scores_3d import mean_position_error_3d, tetrahedron_orientation_error

RNG = np.random.default_rng(3)
CUBE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1.0]])


def test_affine_recovers_a_map_of_space():
    A = RNG.normal(size=(3, 3)) + 2 * np.eye(3)
    dst = CUBE @ A.T + [1.0, -2.0, 0.5]
    T = fit_affine_3d(CUBE, dst)
    np.testing.assert_allclose(apply_affine_3d(CUBE, T), dst, atol=1e-9)


def test_similarity_recovers_rotation_scale_translation():
    R = Rotation.from_rotvec([0.3, -0.2, 1.1]).as_matrix()
    dst = 2.5 * CUBE[:3] @ R.T + [3.0, 1.0, -1.0]
    T = fit_similarity_3d(CUBE[:3], dst)
    np.testing.assert_allclose(apply_affine_3d(CUBE[:3], T), dst, atol=1e-9)


def test_coplanar_anchors_refused_for_affine_naming_the_plane():
    flat = CUBE.copy()
    flat[:, 2] = 0.0
    with pytest.raises(ValueError, match="one plane.*4 anchors not on one plane"):
        fit_affine_3d(flat, flat)
    with pytest.raises(ValueError, match="one plane"):
        check_anchors_3d([0, 1, 2, 3, 4], flat, 10, fit="affine")
    check_anchors_3d([0, 1, 2, 3, 4], flat, 10, fit="similarity")  # a plane is enough for it


def test_collinear_anchors_refused_for_similarity():
    line = np.outer(np.arange(4.0), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="one line.*3 anchors not on one line"):
        check_anchors_3d([0, 1, 2, 3], line, 10)


def test_two_d_anchor_shape_refused():
    with pytest.raises(ValueError, match=r"shape \(3, 3\)"):
        check_anchors_3d([0, 1, 2], np.zeros((3, 2)), 10)


def test_anchor_positions_checked_as_in_2d():
    """Not numeric, or NaN/inf: refused naming anchor_positions (the check the 2-D anchors use)."""
    with pytest.raises(ValueError, match=r"anchor_positions must be a numeric \(A, 3\) array"):
        check_anchors_3d([0, 1, 2], [["a", "b", "c"]] * 3, 10)
    bad = np.eye(3)
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match="anchor_positions contain NaN or inf"):
        check_anchors_3d([0, 1, 2], bad, 10)


def test_scores_3d():
    P = RNG.normal(size=(12, 3))
    assert mean_position_error_3d(P + [0.0, 0.0, 0.1], P) == pytest.approx(0.1)
    assert tetrahedron_orientation_error(P, P) == 0.0
    assert tetrahedron_orientation_error(P * [1, 1, -1], P) == 100.0  # a mirror turns every one
    shuffled = tetrahedron_orientation_error(RNG.normal(size=(12, 3)), P)
    assert 30.0 < shuffled < 70.0
    sampled = tetrahedron_orientation_error(P * [1, 1, -1], P, max_quadruples=100)
    assert sampled == 100.0
    with pytest.raises(ValueError, match="NaN"):
        mean_position_error_3d(np.full((3, 3), np.nan), P[:3])
