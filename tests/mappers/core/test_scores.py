"""MPE / MOE against hand-computed examples and a brute-force loop; the affine fit."""

import itertools

import numpy as np
import pytest

from mappers import apply_affine, fit_affine, mean_orientation_error, mean_position_error
from mappers.core import scores
from mappers.core.scores import _moe_bruteforce, _moe_fast


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


def test_a_3d_map_given_to_the_2d_scores_is_sent_to_the_3d_ones():
    """A newcomer's (M, 3) map given to the paper's scores: the error names the 3-D scores."""
    for score in (mean_position_error, mean_orientation_error):
        with pytest.raises(ValueError, match=r"got \(4, 3\): a 3-D map is scored by "
                                             r"mappers.mean_position_error_3d"):
            score(np.zeros((4, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match=r"got \(4, 4\)$"):  # no 3-D hint for other shapes
        mean_position_error(np.zeros((4, 4)), np.zeros((4, 4)))


@pytest.mark.parametrize(
    "exclude, match",
    [([5], "out of range"), ([0.5], "integer"), (None, "NaN/inf rows")],
)
def test_mpe_3d_checks_its_input_as_the_2d_score_does(exclude, match):
    """The 3-D score refuses what the 2-D one does (one shared check, scores.check_scored_pair)."""
    from mappers.core.scores_3d import mean_position_error_3d

    truth = np.zeros((3, 3))
    est = truth.copy()
    est[1] = np.nan
    with pytest.raises(ValueError, match=match):
        mean_position_error_3d(est, truth, exclude=exclude)
    with pytest.raises(ValueError, match=r"\(M, 3\)"):
        mean_position_error_3d(np.zeros((3, 2)), np.zeros((3, 2)))
    assert mean_position_error_3d(est + [3.0, 4.0, 0.0], truth, exclude=[1]) == pytest.approx(5.0)


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


# ---- the fast MOE against the O(M^3) reference: exact integer counts --------------------------


def _triangles(n):
    return n * (n - 1) * (n - 2) // 6


def test_moe_large_m_matches_brute_force_exactly():
    rng = np.random.default_rng(4)
    truth = rng.uniform(size=(300, 2))
    est = truth + 0.1 * rng.normal(size=truth.shape)
    expected = 100.0 * _moe_bruteforce(est, truth) / _triangles(300)
    assert mean_orientation_error(est, truth) == expected


def _rotation(theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def _random_estimate(rng, truth):
    """Noise, reflection, rotation and scaling of the truth, or an unrelated layout."""
    n = len(truth)
    kind = rng.integers(5)
    if kind == 0:
        return rng.normal(size=(n, 2))
    est = truth @ _rotation(rng.uniform(0, 2 * np.pi)) * rng.choice([0.01, 1.0, 300.0])
    est = est * rng.choice([-1.0, 1.0], size=2) + rng.normal(size=2)
    if kind >= 2:
        est = est + rng.choice([1e-6, 0.05, 0.5]) * np.std(est) * rng.normal(size=(n, 2))
    return est


def _layouts(seed, count):
    """(estimate, truth) pairs, many of them degenerate, M = 3..60."""
    rng = np.random.default_rng(seed)
    for t in range(count):
        n = int(rng.integers(3, 61))
        kind = t % 7
        if kind == 0:  # general position
            truth = rng.normal(size=(n, 2))
            yield _random_estimate(rng, truth), truth
        elif kind == 1:  # integer grids: many exactly collinear triples, also through the apex
            truth = rng.integers(0, 5, size=(n, 2)).astype(float)
            est = rng.integers(0, 5, size=(n, 2)).astype(float)
            yield (est if rng.random() < 0.5 else truth @ _rotation(np.pi / 2)), truth
        elif kind == 2:  # duplicates (points equal to the apex), in one map or both
            base = rng.normal(size=(max(2, n // 4), 2))
            truth = base[rng.integers(len(base), size=n)]
            est = truth + (rng.random((n, 1)) < 0.5) * rng.normal(size=(n, 2))
            yield (est, truth) if rng.random() < 0.5 else (truth, est)
        elif kind == 3:  # a few lines through a point, plus jitter down to below one ulp
            dirs = rng.normal(size=(int(rng.integers(1, 4)), 2))
            pts = dirs[rng.integers(len(dirs), size=n)] * rng.normal(size=(n, 1))
            jitter = rng.choice([0.0, 1e-17, 1e-15, 1e-13], size=(n, 1))
            pts = pts + jitter * rng.normal(size=(n, 2))
            yield _random_estimate(rng, pts), pts
        elif kind == 4:  # decimal grid: collinear in the reals, only nearly so in floats
            truth = rng.integers(-5, 6, size=(n, 2)) * 0.1
            est = rng.integers(-5, 6, size=(n, 2)) * 0.1 + rng.choice([0.0, 1e-16, 1e-15])
            yield est, truth
        elif kind == 5:  # far from the origin: the differences p_j - p_i are rounded
            u = rng.normal(size=n)
            truth = rng.choice([1e6, 1e12]) + np.c_[u, 3 * u]
            truth = truth + 1e-9 * (rng.random((n, 1)) < 0.5) * rng.normal(size=(n, 2))
            yield truth + 1e-10 * rng.normal(size=(n, 2)), truth
        else:  # directions at the fold (angle 0 / pi), signed zeros, subnormal offsets
            ang = rng.choice([0.0, np.pi, -np.pi], size=n) + 1e-16 * rng.normal(size=n)
            truth = rng.uniform(0.5, 2, size=(n, 1)) * np.c_[np.cos(ang), np.sin(ang)]
            truth[rng.random(n) < 0.2, 1] = -0.0
            est = truth.copy()
            est[:, 1] += rng.choice([0.0, 5e-324, -1e-300, 1e-17], size=n)
            yield est, truth


@pytest.fixture(params=["default", "no_brute_rows_small_batches"])
def moe_settings(request, monkeypatch):
    """Also run with every apex on the fast path and tiny batches, so the exact checks of near
    ties and duplicates and the batching loops are exercised on small inputs."""
    if request.param != "default":
        monkeypatch.setattr(scores, "_BRUTE_SHARE", 0)
        monkeypatch.setattr(scores, "_BATCH", 150)


@pytest.mark.parametrize("seed", [0, 1, *(pytest.param(s, marks=pytest.mark.slow) for s in (2, 3))])
def test_moe_fast_equals_bruteforce(seed, moe_settings):
    """The fast MOE equals the brute force on 70 layouts per seed (every degenerate kind of
    :func:`_layouts` ten times): two seeds in the default run, two more with ``-m slow``."""
    for est, truth in _layouts(seed, 70):
        assert _moe_fast(est, truth) == _moe_bruteforce(est, truth)
        assert _moe_fast(truth, est) == _moe_bruteforce(truth, est)


def test_moe_near_ties_matter_on_these_layouts(monkeypatch):
    # Without the exact checks (no near-tie clusters) the rank model alone gets some of the
    # degenerate layouts above wrong, so the tests do exercise the exact checks.
    monkeypatch.setattr(scores, "_TIE_TOL", -1.0)
    monkeypatch.setattr(scores, "_BRUTE_SHARE", 0)
    layouts = list(_layouts(0, 70))
    assert any(_moe_fast(e, t) != _moe_bruteforce(e, t) for e, t in layouts)


def test_moe_float_degenerate_triangle():
    # (1, fl(1/3)) and (3, 1) are not exactly collinear with the origin, but fl(3 * fl(1/3)) = 1,
    # so the reference (and hence the MOE) calls this triangle degenerate: wrong against a proper
    # one, right against an exactly collinear one.
    tri = np.array([[0.0, 0.0], [1.0, 1 / 3], [3.0, 1.0]])
    assert mean_orientation_error(tri, np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])) == 100.0
    assert mean_orientation_error(tri, np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])) == 0.0


def test_moe_extreme_scales_use_the_brute_force():
    rng = np.random.default_rng(6)
    truth = rng.normal(size=(25, 2)) * rng.choice([1e-200, 1e-160, 1.0, 1e120], size=(25, 1))
    est = truth + rng.normal(size=truth.shape) * 1e-170
    with np.errstate(all="ignore"):  # the reference itself under/overflows here
        assert _moe_fast(est, truth) == _moe_bruteforce(est, truth)


def test_moe_fast_with_exclude_and_collinear_grid():
    g = np.stack(np.meshgrid(np.arange(7.0), np.arange(7.0)), -1).reshape(-1, 2)
    rng = np.random.default_rng(7)
    est = np.round(g + rng.normal(size=g.shape))
    ex = rng.choice(len(g), size=10, replace=False)
    keep = np.setdiff1d(np.arange(len(g)), ex)
    expected = 100.0 * _moe_bruteforce(est[keep], g[keep]) / _triangles(len(keep))
    assert mean_orientation_error(est, g, exclude=ex) == expected
    assert mean_orientation_error(g, g, exclude=ex) == 0.0


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
    from mappers.core.align import check_anchors

    with pytest.raises(ValueError, match=match):
        check_anchors(ids, pos, 5)


def test_check_anchors_returns_int64_ids_and_float_positions():
    from mappers.core.align import check_anchors

    ids, pos = check_anchors(np.array([4, 0, 2], dtype=np.int32), [[0, 0], [1, 0], [0, 1]], 5)
    assert ids.dtype == np.int64 and ids.tolist() == [4, 0, 2]
    assert pos.dtype == np.float64 and pos.shape == (3, 2)


def test_sampled_orientation_error_brackets_the_exact_one():
    from mappers.core.scores import mean_orientation_error, sampled_orientation_error

    rng = np.random.default_rng(4)
    truth = rng.uniform(0, 1, (300, 2))
    est = truth + rng.normal(0, 0.03, truth.shape)
    exact = mean_orientation_error(est, truth, exclude=[0, 1])
    moe, (lo, hi) = sampled_orientation_error(est, truth, exclude=[0, 1], n_triangles=400_000)
    assert lo <= exact <= hi and lo < moe < hi and hi - lo < 0.5
    assert sampled_orientation_error(truth, truth)[0] == 0.0
    with pytest.raises(ValueError, match="confidence"):
        sampled_orientation_error(est, truth, confidence=1.0)
    with pytest.raises(ValueError, match="n_triangles"):
        sampled_orientation_error(est, truth, n_triangles=0)
