"""CAL-SMA's linearised block jackknife (mappers.calibrated.cal_sma_uncertainty) and
``build_map(uncertainty=True)`` on visibility histories, which uses it."""

import warnings

import numpy as np
import pytest

from mappers import build_map
from mappers.calibrated.cal_sma_uncertainty import (
    has_linear_jackknife,
    jackknife_targets,
    linear_jackknife_covariances,
)
from mappers.covariances import JACKKNIFE_INFLATION
from mappers.pipeline import _build_2d
from mappers.smacof import weighted_smacof
from mappers.smacof.stress_covariance import stress_response
from tests.synthetic_walk import ANCHORS, layout, sensed, walk


def _visibility(seed, n_objects=16, n_steps=400, radius=0.4):
    P, poses = layout(n_objects, seed), walk(n_steps, seed=seed)
    return P, (sensed(P, poses)[0] < radius).astype(float)


def _quiet(*args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return build_map(*args, **kwargs)


def _fitted(P, X):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _build_2d(X, ANCHORS, P[ANCHORS], None, "visibility", None, None, None, 0, False,
                         {})


def test_linear_moves_follow_the_re_embedded_replicates():
    """Each deleted block's predicted move is what SMACOF finds when it minimises the
    replicate's stress again from the map (to within a fifth of the move)."""
    P, X = _visibility(0)
    m, est, mapped = _fitted(P, X)
    assert has_linear_jackknife(est) and len(mapped) == len(P)
    T, W, (i, j), dt, few = jackknife_targets(est, X, X.shape[1])
    assert not few.any() and dt.shape == (20, len(i)) and np.all(i < j)
    np.testing.assert_array_equal(est.neighbors_[i, j], True)
    Y = est.embedding_
    moves, loose = stress_response(Y, T, W, np.arange(4, len(P)), (i, j), dt)
    assert not loose.any()
    X0, _, _ = weighted_smacof(T, W, Y, fixed=ANCHORS, max_iter=5000, tol=1e-14)
    for b in (0, 7, 13):
        dT = np.zeros_like(T)
        dT[i, j] = dT[j, i] = dt[b]
        Xb, _, _ = weighted_smacof(T + dT, W, X0, fixed=ANCHORS, max_iter=5000, tol=1e-14)
        actual = Xb - X0
        assert np.abs(actual).max() > 1e-4
        np.testing.assert_allclose(moves[b], actual, atol=0.2 * np.abs(actual).max())


def test_true_picks_the_jackknife_for_visibility():
    P, X = _visibility(1)
    plain = _quiet(X, ANCHORS, P[ANCHORS])
    m = _quiet(X, ANCHORS, P[ANCHORS], uncertainty=True)
    jk = _quiet(X, ANCHORS, P[ANCHORS], uncertainty="jackknife")
    assert m.method == "CAL-SMA"
    np.testing.assert_array_equal(plain.positions, m.positions)
    np.testing.assert_array_equal(m.covariances, jk.covariances)
    cov = m.covariances
    np.testing.assert_array_equal(cov[ANCHORS], 0.0)
    others = cov[4:]
    np.testing.assert_allclose(others, others.transpose(0, 2, 1), atol=1e-15)
    assert np.all(np.linalg.eigvalsh(others) > 0)
    # the widened jackknife of the estimator, carried by the anchor fit
    _, est, _ = _fitted(P, X)
    raw, _ = linear_jackknife_covariances(est, X, X.shape[1], ANCHORS)
    L = np.asarray(m.affine)[:2]
    np.testing.assert_allclose(cov, JACKKNIFE_INFLATION * np.einsum("ji,mjk,kl->mil", L, raw, L),
                               rtol=1e-10, atol=1e-15)


def test_jackknife_ellipses_are_the_size_of_the_errors():
    """Six small layouts: centimetres of spread for centimetres of error, and most true
    positions inside their 95 % regions."""
    from mappers.core.uncertainty import coverage

    inside, radius, error = [], [], []
    for seed in range(6):
        P, X = _visibility(seed + 10)
        m = _quiet(X, ANCHORS, P[ANCHORS], uncertainty=True)
        inside.append(coverage(m.positions, m.covariances, P, np.arange(4, len(P))))
        radius.append(np.sqrt(np.trace(m.covariances[4:], axis1=1, axis2=2)).mean())
        error.append(np.linalg.norm(m.positions[4:] - P[4:], axis=1).mean())
    assert 0.7 <= np.mean(inside) <= 1.0
    assert 0.5 < np.mean(radius) / np.mean(error) < 5.0


def test_an_object_seen_in_one_block_gets_nan_and_a_note():
    P, X = _visibility(2)
    X[7] = 0.0
    X[7, 41:44] = 1.0  # seen only in steps 41-43: one block of 20
    m = _quiet(X, ANCHORS, P[ANCHORS], uncertainty=True)
    assert np.isnan(m.covariances[7]).all()
    assert np.all(np.isfinite(m.covariances[np.setdiff1d(np.arange(len(P)), [7])]))
    assert any("objects [7]" in w and "jackknife" in w for w in m.warnings)


def test_jackknife_is_refused_where_it_does_not_apply():
    P, poses = layout(12, 3), walk(150, seed=3)
    _, b, _ = sensed(P, poses)
    B = np.stack([np.cos(b), np.sin(b)], -1).reshape(len(P), -1)
    with pytest.raises(ValueError, match="jackknife.*CAL-SMA"):
        _quiet(B, ANCHORS, P[ANCHORS], "CAL-SMA", uncertainty="jackknife")
    _, est, _ = _fitted(*_visibility(4))
    with pytest.raises(ValueError, match="n_steps"):
        jackknife_targets(est, np.ones((len(est.embedding_), 10)), 3)
