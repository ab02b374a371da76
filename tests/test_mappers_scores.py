"""MPE / MOE against hand-computed examples and a brute-force loop; the affine fit."""

import itertools

import numpy as np
import pytest

from mappers import apply_affine, fit_affine, mean_orientation_error, mean_position_error


def test_mpe_hand_example():
    truth = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    est = truth + np.array([[3.0, 4.0], [0.0, 0.0], [0.0, -1.0]])  # errors 5, 0, 1
    assert mean_position_error(est, truth) == pytest.approx(2.0)
    assert mean_position_error(est, truth, exclude=[0]) == pytest.approx(0.5)
    assert mean_position_error(est, truth, exclude=np.array([1, 2])) == pytest.approx(5.0)


def test_mpe_nan_rows_must_be_excluded():
    truth = np.zeros((4, 2))
    est = np.zeros((4, 2))
    est[2] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        mean_position_error(est, truth)
    assert mean_position_error(est, truth, exclude=(2,)) == 0.0


@pytest.mark.parametrize(
    "est, truth, exclude, match",
    [
        (np.zeros((3, 3)), np.zeros((3, 3)), None, "shape"),
        (np.zeros((3, 2)), np.zeros((4, 2)), None, "truth"),
        (np.zeros((3, 2)), np.zeros((3, 2)), [5], "out of range"),
        (np.zeros((3, 2)), np.zeros((3, 2)), [0.5], "integer"),
        (np.zeros((3, 2)), np.zeros((3, 2)), [0, 1, 2], "no objects"),
    ],
)
def test_mpe_bad_input(est, truth, exclude, match):
    with pytest.raises(ValueError, match=match):
        mean_position_error(est, truth, exclude=exclude)


def test_moe_hand_examples():
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    assert mean_orientation_error(tri, tri) == 0.0
    assert mean_orientation_error(tri * [-1, 1], tri) == 100.0  # mirror flips the only triangle
    # square 0..3 (all triangles anticlockwise); move point 3 = (0, 1) to (2, -1):
    # (0,1,3): (1,0)x(2,-1) = -1, (0,2,3): (1,1)x(2,-1) = -3, (1,2,3): (0,1)x(1,-1) = -1 all
    # flip; (0,1,2) is untouched -> 3 of 4 wrong.
    sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    moved = sq.copy()
    moved[3] = [2.0, -1.0]
    assert mean_orientation_error(moved, sq) == pytest.approx(75.0)
    # a degenerate (collinear) true triangle vs a proper one counts as wrong
    line = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    assert mean_orientation_error(tri, line) == 100.0
    # any rotation, scaling, translation keeps all orientations
    c, s = np.cos(0.7), np.sin(0.7)
    assert mean_orientation_error(sq @ np.array([[c, -s], [s, c]]) * 3 + 5, sq) == 0.0


def _moe_brute(a, b):
    def orient(P, i, j, k):
        return np.sign((P[j, 0] - P[i, 0]) * (P[k, 1] - P[i, 1]) - (P[j, 1] - P[i, 1]) * (P[k, 0] - P[i, 0]))

    trip = list(itertools.combinations(range(len(a)), 3))
    return 100.0 * sum(orient(a, *t) != orient(b, *t) for t in trip) / len(trip)


@pytest.mark.parametrize("n", [3, 5, 12, 41])
def test_moe_matches_brute_force(n):
    rng = np.random.default_rng(n)
    truth = rng.normal(size=(n, 2))
    est = truth + 0.5 * rng.normal(size=(n, 2))
    assert mean_orientation_error(est, truth) == pytest.approx(_moe_brute(est, truth))


def test_moe_exclude_and_errors():
    rng = np.random.default_rng(1)
    truth = rng.normal(size=(10, 2))
    est = truth + rng.normal(size=(10, 2))
    keep = [i for i in range(10) if i not in (2, 7)]
    assert mean_orientation_error(est, truth, exclude=[2, 7]) == pytest.approx(
        _moe_brute(est[keep], truth[keep])
    )
    with pytest.raises(ValueError, match="at least 3"):
        mean_orientation_error(est[:2], truth[:2])
    est[4] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        mean_orientation_error(est, truth)


def test_moe_large_m_runs_bounded():
    rng = np.random.default_rng(2)
    truth = rng.uniform(size=(300, 2))
    assert mean_orientation_error(truth, truth) == 0.0
    assert mean_orientation_error(truth * [1, -1], truth) == 100.0


def test_fit_affine_recovers_transform():
    rng = np.random.default_rng(3)
    src = rng.normal(size=(6, 2))
    A = np.array([[2.0, 0.5], [-0.3, 1.5]])
    dst = src @ A + [1.0, -2.0]
    T = fit_affine(src, dst)
    np.testing.assert_allclose(T[:2], A, atol=1e-12)
    np.testing.assert_allclose(apply_affine(src, T), dst, atol=1e-12)


@pytest.mark.parametrize(
    "src, dst, match",
    [
        ([[0, 0], [1, 1], [2, 2]], [[0, 0], [1, 0], [0, 1]], "embedded points are collinear"),
        ([[0, 0], [1, 0], [0, 1]], [[0, 0], [1, 1], [3, 3]], r"world\) are collinear"),
        ([[0, 0], [1, 0]], [[0, 0], [1, 0]], "at least 3"),
        ([[0, 0], [1, 0], [0, 1]], [[0, 0], [1, 0]], "same shape"),
    ],
)
def test_fit_affine_bad_input(src, dst, match):
    with pytest.raises(ValueError, match=match):
        fit_affine(np.asarray(src, float), np.asarray(dst, float))


@pytest.mark.parametrize(
    ("ids", "pos", "match"),
    [
        ([0, 1], [[0, 0], [1, 0]], "at least 3 anchors"),
        ([0, 1, 9], [[0, 0], [1, 0], [0, 1]], "out of range"),
        ([0, 1, 1], [[0, 0], [1, 0], [0, 1]], "distinct"),
        ([True, False, True], [[0, 0], [1, 0], [0, 1]], "integer"),
        ([0, 1, 2], [[0, 0], [1, 0]], "shape"),
        ([0, 1, 2], [[0, 0], [1, 0], [0, np.inf]], "NaN or inf"),
        ([0, 1, 2], [[0, 0], [1, 0], [2, 0]], "collinear"),
    ],
)
def test_check_anchors_rejects_bad_anchors(ids, pos, match):
    from mappers.align import check_anchors

    with pytest.raises(ValueError, match=match):
        check_anchors(ids, pos, 5)


def test_check_anchors_returns_int64_ids_and_float_positions():
    from mappers.align import check_anchors

    ids, pos = check_anchors(np.array([4, 0, 2], dtype=np.int32), [[0, 0], [1, 0], [0, 1]], 5)
    assert ids.dtype == np.int64 and ids.tolist() == [4, 0, 2]
    assert pos.dtype == np.float64 and pos.shape == (3, 2)
