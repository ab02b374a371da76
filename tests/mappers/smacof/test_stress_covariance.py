"""The weighted stress's Hessian and the minimiser's linear response to its targets
(mappers.smacof.stress_covariance)."""

import numpy as np
import pytest

from mappers.smacof import euclidean_distance_matrix, raw_stress, weighted_smacof
from mappers.smacof.stress_covariance import stress_hessian, stress_response


def _problem(seed=0, m=12, noise=0.05):
    """Points in the unit square, noisy targets on all pairs, the first three held."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(0.0, 1.0, (m, 2))
    D = euclidean_distance_matrix(P)
    E = rng.normal(0.0, noise, D.shape)
    T = np.maximum(D * (1.0 + 0.5 * (E + E.T)), 0.0)
    np.fill_diagonal(T, 0.0)
    W = rng.uniform(0.5, 1.5, D.shape)
    W = 0.5 * (W + W.T)
    np.fill_diagonal(W, 0.0)
    X, _, _ = weighted_smacof(T, W, P, fixed=np.arange(3), max_iter=5000, tol=1e-15)
    return X, T, W


def test_hessian_is_the_stress_second_derivative():
    X, T, W = _problem(1)
    H = stress_hessian(X, T, W)
    h = 1e-5
    num = np.zeros_like(H)
    flat = X.ravel()

    def f(a, b, da, db):
        Y = flat.copy()
        Y[a] += da
        Y[b] += db
        return raw_stress(T, W, Y.reshape(X.shape))

    for a in range(flat.size):
        for b in range(a, flat.size):
            num[a, b] = num[b, a] = (f(a, b, h, h) - f(a, b, h, -h) - f(a, b, -h, h)
                                     + f(a, b, -h, -h)) / (4 * h * h)
    np.testing.assert_allclose(H, num, rtol=1e-4, atol=1e-4 * np.abs(H).max())


def test_response_is_the_move_of_the_refitted_minimiser():
    """Small target changes: the predicted move matches SMACOF run again to convergence."""
    X, T, W = _problem(2)
    free = np.arange(3, len(X))
    rng = np.random.default_rng(5)
    i, j = np.triu_indices(len(X), 1)
    dt = rng.normal(0.0, 1e-3, (3, len(i)))
    moves, loose = stress_response(X, T, W, free, (i, j), dt)
    assert not loose.any()
    np.testing.assert_array_equal(moves[:, :3], 0.0)
    for b in range(len(dt)):
        dT = np.zeros_like(T)
        dT[i, j] = dT[j, i] = dt[b]
        Xb, _, _ = weighted_smacof(T + dT, W, X, fixed=np.arange(3), max_iter=20000,
                                   tol=1e-16)
        actual = Xb - X
        assert np.linalg.norm(actual) > 1e-4  # the targets' change does move the map
        np.testing.assert_allclose(moves[b], actual, atol=0.03 * np.abs(actual).max())


def test_a_point_held_by_one_pair_is_loose():
    """A point tied to a single held point can turn about it: no curvature, unbounded."""
    X, T, W = _problem(3, m=6)
    W = W.copy()
    W[5, :] = W[:, 5] = 0.0
    W[5, 0] = W[0, 5] = 1.0
    X[5] = X[0] + T[0, 5] * np.array([1.0, 0.0])  # at its target distance from point 0
    _, loose = stress_response(X, T, W, np.arange(3, 6), ([0], [5]), np.array([[0.01]]))
    assert loose[5] and not loose[3:5].any()


def test_bad_shapes_are_refused():
    X, T, W = _problem(4, m=5)
    with pytest.raises(ValueError, match="targets and weights"):
        stress_hessian(X, T[:4, :4], W)
    with pytest.raises(ValueError, match="delta_targets"):
        stress_response(X, T, W, np.arange(3, 5), ([0, 1], [2, 3]), np.zeros((4, 3)))
