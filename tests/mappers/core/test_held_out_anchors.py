"""The held-out anchors' check of a map's covariances (mappers.core.held_out_anchors)."""

import numpy as np
import pytest
from scipy import stats

from mappers.core.held_out_anchors import held_out_factor


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
