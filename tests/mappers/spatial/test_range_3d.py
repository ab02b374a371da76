"""RANGE-3D (issue 34): ranges alone with 3-D anchors, complete or masked, and its refusals."""

import numpy as np
import pytest

from mappers import build_map
from mappers.spatial import METHODS_3D, Range3D
from mappers.spatial.range_3d import fit_steps, same_side, viewpoint_plane

ANCHORS = np.arange(5)


def range_world(m=16, n=120, seed=0, noise=0.0, planar=False, max_range=None):
    """Objects in a 2.5 x 2.5 x 2 m room ranged from viewpoints that span space (a drone) or, with
    ``planar``, all at 0.3 m (a camera on a planar robot); ``max_range`` masks the far ones."""
    rng = np.random.default_rng(seed)
    P = rng.uniform([0, 0, 0], [2.5, 2.5, 2], (m, 3))
    P[:5] = [[0, 0, 0], [2.5, 0, 0.5], [0, 2.5, 1.0], [2.5, 2.5, 2.0], [1.2, 1.2, 1.9]]
    C = rng.uniform([0.2, 0.2, 0.2], [2.3, 2.3, 1.8], (n, 3))
    if planar:
        C[:, 2] = 0.3
    D = np.linalg.norm(P[:, None] - C[None], axis=2)
    R = np.abs(D + rng.normal(0.0, noise, D.shape)) if noise else D.copy()
    mask = None if max_range is None else D < max_range
    return P, C, (R if mask is None else np.where(mask, R, 0.0)), mask


def mpe(Y, P):
    rest = np.setdiff1d(np.arange(len(P)), ANCHORS)
    return float(np.linalg.norm(Y[rest] - P[rest], axis=1).mean())


def test_complete_ranges_from_viewpoints_that_span_space_map_exactly():
    P, C, R, _ = range_world()
    m = build_map(R, ANCHORS, P[ANCHORS], sensor="range")
    assert m.method == "RANGE-3D" and m.positions.shape == P.shape and not m.unmapped
    assert mpe(m.positions, P) < 1e-6
    np.testing.assert_allclose(m.positions[ANCHORS], P[ANCHORS])


def test_noisy_complete_ranges_start_from_the_unfolding_and_the_adjustment_improves_it():
    P, C, R, _ = range_world(noise=0.01, seed=1)
    est = Range3D().fit(R, anchor_ids=ANCHORS, anchor_positions=P[ANCHORS])
    assert mpe(est.embedding_, P) < 0.02
    assert mpe(est.embedding_, P) < mpe(est.start_, P)
    assert est.notes_ == ()
    fitted = np.all(np.isfinite(est.step_positions_), axis=1)
    assert fitted.mean() > 0.9
    assert np.median(np.linalg.norm(est.step_positions_[fitted] - C[fitted], axis=1)) < 0.03


def test_masked_ranges_with_a_range_limit_map_in_3d():
    P, C, R, mask = range_world(n=200, seed=2, noise=0.005, max_range=2.2)
    assert 0.3 < mask.mean() < 0.95  # a real mask: far objects not ranged
    m = build_map(R, ANCHORS, P[ANCHORS], sensor="range", mask=mask)
    assert m.method == "RANGE-3D"
    assert mpe(m.positions, P) < 0.02


def test_fit_steps_multilaterates_each_step():
    P, C, R, _ = range_world(n=30, seed=3)
    rows, cols = np.nonzero(np.ones(R.shape, dtype=bool))
    fitted = fit_steps(P, rows, cols, R[rows, cols], R.shape[1])
    np.testing.assert_allclose(fitted, C, atol=1e-6)


def test_complete_ranges_from_one_plane_are_refused_naming_the_mirror_ambiguity():
    P, C, R, _ = range_world(planar=True, seed=4)
    with pytest.raises(ValueError, match="lie on one plane.*mirror image"):
        build_map(R, ANCHORS, P[ANCHORS], sensor="range")


def test_masked_ranges_from_one_plane_say_the_side_is_not_measured():
    P, C, R, mask = range_world(n=200, planar=True, seed=5, max_range=2.5)
    with pytest.warns(UserWarning, match="viewpoints lie on one plane"):
        m = build_map(R, ANCHORS, P[ANCHORS], sensor="range", mask=mask)
    assert any("mirror image" in w for w in m.warnings)
    # what the ranges do measure: each object's distance from the viewpoints' plane
    rest = np.setdiff1d(np.arange(len(P)), ANCHORS)
    folded = np.abs(m.positions[rest, 2] - 0.3) - np.abs(P[rest, 2] - 0.3)
    assert np.median(np.abs(folded)) < 0.05


def test_bad_input_is_refused_naming_the_problem():
    P, C, R, mask = range_world()
    with pytest.raises(ValueError, match="at least 4"):
        build_map(R, ANCHORS[:3], P[:3], sensor="range")
    flat = P[ANCHORS].copy()
    flat[:, 2] = 1.0
    with pytest.raises(ValueError, match="lie on one plane"):
        build_map(R, ANCHORS, flat, sensor="range")
    with pytest.raises(ValueError, match="does not map in 3-D"):
        build_map(R, ANCHORS, P[ANCHORS], method="UNFOLD", sensor="range")
    with pytest.raises(ValueError, match="'RANGE-3D' does not map visibility"):
        build_map((R < 2).astype(float), ANCHORS, P[ANCHORS], method="RANGE-3D")
    zero = R.copy()
    zero[7, 3] = 0.0
    with pytest.raises(ValueError, match="observed range is <= 0"):
        Range3D().fit(zero, mask=np.ones(R.shape, dtype=bool), anchor_ids=ANCHORS,
                      anchor_positions=P[ANCHORS])
    with pytest.raises(ValueError, match="start='unfold' needs every object"):
        Range3D(start="unfold").fit(np.where(R < 2, R, 0), mask=R < 2, anchor_ids=ANCHORS,
                                    anchor_positions=P[ANCHORS])
    assert METHODS_3D["RANGE-3D"] is Range3D
    # a plain array of ranges is not guessed to be ranges: refused, saying how to pass them
    for columns in (R, R[:, :119]):  # a multiple of 3 columns (not unit rays), and not
        with pytest.raises(ValueError, match="sensor='range'"):
            build_map(columns, ANCHORS, P[ANCHORS])


def test_an_object_carried_across_the_viewpoints_plane_goes_back_to_its_start_side():
    rng = np.random.default_rng(6)
    steps = np.column_stack([rng.uniform(0, 2, (50, 2)), np.full(50, 0.3)])
    steps[:3, 2] = 1.5  # a few steps stuck at a mirror image do not hide the plane
    centre, normal = viewpoint_plane(steps)
    assert abs(abs(normal[2]) - 1.0) < 1e-9 and centre[2] == pytest.approx(0.3, abs=0.1)
    start = np.array([[1.0, 1.0, 1.2], [0.5, 0.5, 0.1], [1.5, 0.2, 0.9]])
    Y = np.array([[1.0, 1.0, -0.5], [0.5, 0.5, 0.45], [1.5, 0.2, 0.8]])
    out = same_side(Y, start, (np.array([0.0, 0.0, 0.3]), normal), np.arange(3))
    np.testing.assert_allclose(out, [[1.0, 1.0, 1.1], [0.5, 0.5, 0.15], [1.5, 0.2, 0.8]])
    spread = np.column_stack([rng.uniform(0, 2, (50, 2)), rng.uniform(0.2, 1.8, 50)])
    assert viewpoint_plane(spread) is None
