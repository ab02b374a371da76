"""The held-out anchors' check of a map's covariances (mappers.core.held_out_anchors)."""

import numpy as np
import pytest
from scipy import stats

from mappers.core.held_out_anchors import held_out_factor, held_out_floor
from mappers.core.uncertainty import chi2_quantile, mahalanobis_squared


def test_distances_the_model_explains_keep_it():
    # chi2(2) draws of a typical size: the test passes, the factor is 1
    factor, k = held_out_factor(np.array([1.0, 2.5, 0.8, 3.1]), 2)
    assert factor == 1.0 and k == pytest.approx(7.4 / 8)


def test_distances_far_above_the_model_scale_it_with_the_f_widening():
    q = 40.0 * np.array([1.0, 2.5, 0.8, 3.1])
    factor, k = held_out_factor(q, 2)
    assert k == pytest.approx(q.sum() / 8)
    widen = 2 * stats.f.ppf(0.95, 2, 8) / stats.chi2.ppf(0.95, 2)
    assert factor == pytest.approx(k * widen) and widen > 1.4


def test_the_factor_calibrates_scaled_gaussian_errors():
    # errors k times wider than the model, 4 anchors per map: the scaled 95 % region holds a new
    # object's error at least 95 % of the time (the F law accounts for the 4 anchors' noise)
    rng = np.random.default_rng(0)
    inside = []
    for _ in range(600):
        q = 30.0 * rng.chisquare(3, size=4)
        factor, _ = held_out_factor(q, 3)
        inside.append(30.0 * rng.chisquare(3) <= factor * stats.chi2.ppf(0.95, 3))
    assert 0.925 <= np.mean(inside) <= 0.975


def test_bad_input_named():
    with pytest.raises(ValueError, match="no held-out anchor"):
        held_out_factor(np.array([np.nan, np.nan]), 2)
    with pytest.raises(ValueError, match="level"):
        held_out_factor(np.array([1.0, 2.0]), 2, level=1.5)


def test_errors_within_their_covariances_get_no_floor():
    cov = np.tile(np.diag([4e-4, 1e-4]), (4, 1, 1))
    errors = np.array([[0.01, 0.005], [-0.02, 0.0], [0.0, -0.01], [0.015, 0.01]])
    assert mahalanobis_squared(errors, cov).sum() <= 8
    assert held_out_floor(errors, cov) == (0.0, 4)


def test_the_floor_makes_the_anchors_distances_average_d_then_widens_it():
    rng = np.random.default_rng(1)
    cov = np.einsum("aij,akj->aik", *(2 * [rng.normal(0, 0.003, (5, 3, 3))])) + 1e-6 * np.eye(3)
    errors = rng.normal(0.0, 0.05, (5, 3))
    variance, used = held_out_floor(errors, cov)
    widen = 3 * stats.f.ppf(0.95, 3, 15) / chi2_quantile(3)
    s2 = variance / widen
    assert used == 5 and s2 > 0
    assert mahalanobis_squared(errors, cov + s2 * np.eye(3)).sum() == pytest.approx(15, rel=1e-9)


def test_the_floor_leaves_out_anchors_without_a_finite_error_or_covariance():
    cov = np.tile(1e-6 * np.eye(2), (4, 1, 1))
    errors = np.array([[0.1, 0.0], [0.0, 0.1], [np.nan, np.nan], [-0.1, 0.1]])
    cov[3] = np.inf
    assert held_out_floor(errors, cov)[1] == 2
    with pytest.raises(ValueError, match="at least two"):
        held_out_floor(errors[:1], cov[:1])
    with pytest.raises(ValueError, match="level"):
        held_out_floor(errors, cov, level=1.0)


def test_the_estimated_floor_calibrates_a_systematic_error():
    # the model's covariances tiny, each map's objects off by a systematic error of a random
    # size per map (as a logged run's): the floor from 4 held-out anchors holds a new object's
    # error about 95 % of the time
    rng = np.random.default_rng(2)
    inside = []
    for _ in range(400):
        sigma = rng.uniform(0.01, 0.1)
        cov = np.tile(1e-8 * np.eye(2), (4, 1, 1))
        variance, _ = held_out_floor(rng.normal(0.0, sigma, (4, 2)), cov)
        e = rng.normal(0.0, sigma, 2)
        inside.append(e @ e <= (variance + 1e-8) * chi2_quantile(2))
    assert 0.92 <= np.mean(inside) <= 0.98
