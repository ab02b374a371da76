"""isotonic_fit: scikit-learn's IsotonicRegression's values, without its estimator."""

import numpy as np
import pytest
from sklearn.isotonic import IsotonicRegression

from mappers.smacof.isotonic import isotonic_fit


def _case(rng, kind: str, n: int):
    x = {"distinct": rng.random(n),
         "few values": rng.integers(0, 8, n).astype(float),
         "rounded": np.round(rng.random(n), 2),
         "all tied": np.full(n, 0.3)}[kind]
    y = 3.0 * rng.random(n)
    w = rng.random(n) + 0.01
    return x, y, w


@pytest.mark.parametrize("kind", ["distinct", "few values", "rounded", "all tied"])
def test_the_values_are_scikit_learns(kind):
    rng = np.random.default_rng(len(kind))
    for n in (1, 2, 3, 17, 250):
        for _ in range(20):
            x, y, w = _case(rng, kind, n)
            want = IsotonicRegression(increasing=True).fit_transform(x, y, sample_weight=w)
            # the same operations in the same order: equal here; allclose across versions
            np.testing.assert_allclose(isotonic_fit(x, y, w), want, rtol=1e-12, atol=1e-12)


def test_the_fit_is_monotone_and_ties_share_a_value():
    rng = np.random.default_rng(5)
    x = rng.integers(0, 20, 400).astype(float)
    y = x + rng.normal(0.0, 4.0, x.size)
    w = rng.random(x.size) + 0.1
    fit = isotonic_fit(x, y, w)
    order = np.argsort(x, kind="stable")
    assert np.all(np.diff(fit[order]) >= 0.0)
    for value in np.unique(x):
        assert np.ptp(fit[x == value]) == 0.0
    # a fit that is already monotone is returned as it is (ties averaged)
    np.testing.assert_allclose(isotonic_fit(np.arange(5.0), np.arange(5.0) * 2, np.ones(5)),
                               np.arange(5.0) * 2)
