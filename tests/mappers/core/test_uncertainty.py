"""mappers.core.uncertainty: marginals of a normal matrix, bootstrap draws, sample covariances
and their widening, coverage and ellipse radius."""

import numpy as np
import pytest

from mappers.core.uncertainty import (
    block_marginals,
    check_uncertainty,
    chi2_quantile,
    coverage,
    mahalanobis_squared,
    moving_blocks,
    rms_radius,
    sample_covariances,
    sample_size_factor,
    systematic_floor,
    transform_covariances,
)


@pytest.mark.parametrize("d", [2, 3])
def test_block_marginals_are_the_diagonal_blocks_of_the_inverse(d):
    rng = np.random.default_rng(0)
    A = rng.normal(size=(4 * d, 4 * d))
    S = A @ A.T + np.eye(4 * d)
    blocks = block_marginals(S, d)
    inv = np.linalg.inv(S)
    for k in range(4):
        np.testing.assert_allclose(blocks[k], inv[k * d:(k + 1) * d, k * d:(k + 1) * d],
                                   rtol=1e-9, atol=1e-12)


def test_block_marginals_of_an_unconstrained_object_are_infinite():
    S = np.diag([4.0, 4.0, 1.0, 0.0])  # the second object's y is not pinned down
    blocks = block_marginals(S, 2)
    np.testing.assert_allclose(blocks[0], np.eye(2) / 4.0)
    assert np.isinf(blocks[1]).any()


def test_check_uncertainty_names_the_modes():
    assert check_uncertainty(False) is False and check_uncertainty("bootstrap") == "bootstrap"
    with pytest.raises(ValueError, match="uncertainty must be one of"):
        check_uncertainty("laplace")


def test_moving_blocks_are_runs_of_consecutive_steps():
    steps = moving_blocks(100, 10, np.random.default_rng(1))
    assert steps.shape == (100,) and steps.min() >= 0 and steps.max() < 100
    runs = steps.reshape(10, 10)
    assert np.all(np.diff(runs, axis=1) == 1)
    with pytest.raises(ValueError, match="block"):
        moving_blocks(10, 11, np.random.default_rng(0))


def test_sample_covariances_match_numpy_and_skip_unplaced_rows():
    rng = np.random.default_rng(2)
    reps = rng.normal(size=(30, 3, 2)) * [1.0, 0.1]
    reps[:25, 2] = np.nan  # placed in 5 replicates only
    cov = sample_covariances(reps, min_replicates=10)
    np.testing.assert_allclose(cov[0], np.cov(reps[:, 0].T), rtol=1e-12)
    assert np.isnan(cov[2]).all()


def test_sample_size_factor_is_hotellings_and_tends_to_one():
    assert sample_size_factor(20, 2) == pytest.approx(1.25, abs=0.01)
    assert 1.0 < sample_size_factor(2000, 2) < 1.01
    # the widened region holds 95 % of fresh draws when the covariance comes from 20 samples
    x = np.random.default_rng(3).normal(size=(4000, 21, 2))
    cov = sample_covariances(x[:, :20].transpose(1, 0, 2), 20) * sample_size_factor(20, 2)
    q = np.einsum("ni,nij,nj->n", x[:, 20], np.linalg.inv(cov), x[:, 20])
    assert np.mean(q <= chi2_quantile(2)) == pytest.approx(0.95, abs=0.015)


def test_transform_covariances_is_the_linear_map_of_row_vectors():
    rng = np.random.default_rng(4)
    x = rng.normal(size=(5000, 2)) @ np.array([[1.0, 0.3], [0.0, 0.5]])
    A = np.array([[0.0, -2.0], [1.0, 0.5]])
    cov = transform_covariances(np.cov(x.T)[None], A)[0]
    np.testing.assert_allclose(cov, np.cov((x @ A).T), rtol=1e-9)


def test_coverage_and_radius_of_calibrated_gaussians():
    rng = np.random.default_rng(5)
    m = 4000
    cov = np.tile(np.diag([0.04, 0.01]), (m, 1, 1))
    truth = rng.normal(size=(m, 2)) * [0.2, 0.1]
    c = coverage(np.zeros((m, 2)), cov, truth, np.arange(m))
    assert c == pytest.approx(0.95, abs=0.012)
    # an ellipse of semi-axes a, b: RMS radius sqrt((a^2 + b^2) / 2)
    q = chi2_quantile(2)
    assert rms_radius(cov[:1])[0] == pytest.approx(np.sqrt(q * (0.04 + 0.01) / 2))


def test_mahalanobis_of_singular_and_infinite_covariances():
    cov = np.array([np.diag([1.0, 0.0]), np.diag([1.0, 0.0]), np.diag([np.inf, 1.0])])
    e = np.array([[1.0, 0.0], [0.0, 1.0], [5.0, 5.0]])
    q = mahalanobis_squared(e, cov)
    assert q[0] == pytest.approx(1.0) and np.isinf(q[1]) and q[2] == 0.0


def test_step_blocks_keep_robots_apart():
    from mappers.viewpoints.marginals import step_blocks

    assert np.array_equal(step_blocks(9), np.repeat([0, 1, 2], 3))
    timeline = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [0, 2], [1, 2], [0, 3], [1, 3]])
    b = step_blocks(8, timeline)  # blocks of 3 steps, each robot's own
    assert len(set(b[timeline[:, 0] == 0]) & set(b[timeline[:, 0] == 1])) == 0
    assert b[0] == b[2] == b[4] != b[6]


def test_systematic_floor_adds_a_share_of_the_anchors_extent():
    # anchors 0, 1, 2 at most 5 m apart: 0.3 % of 5 m = 1.5 cm per axis on the other objects;
    # anchors, unbounded and NaN covariances kept; the floor scales with the map
    pos = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 4.0], [1.0, 1.0], [2.0, 1.0], [2.0, 2.0]])
    cov = np.zeros((6, 2, 2))
    cov[3:] = 1e-4 * np.eye(2)
    cov[4] = np.inf
    cov[5] = np.nan
    out = systematic_floor(cov, pos, [0, 1, 2], 0.003)
    np.testing.assert_allclose(out[3], (1e-4 + 0.015**2) * np.eye(2), rtol=1e-12)
    np.testing.assert_array_equal(out[:3], 0.0)
    assert np.all(np.isinf(out[4])) and np.all(np.isnan(out[5]))
    scaled = systematic_floor(4.0 * cov, 2.0 * pos, [0, 1, 2], 0.003)
    np.testing.assert_allclose(scaled[3], 4.0 * out[3], rtol=1e-12)
    np.testing.assert_array_equal(cov[3], 1e-4 * np.eye(2))  # the input is not changed
    with pytest.raises(ValueError, match="two placed anchors"):
        systematic_floor(cov, pos, [0], 0.003)
    with pytest.raises(ValueError, match="share"):
        systematic_floor(cov, pos, [0, 1], -0.1)
