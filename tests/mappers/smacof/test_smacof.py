"""Weighted SMACOF: monotone stress, fixed points, exact recovery, the LPCA-start fold, checks."""

import numpy as np
import pytest

from mappers import WeightedSMACOF, weighted_smacof
from mappers.smacof.weighted import classical_mds, raw_stress


def _points(n=30, seed=0):
    return np.random.default_rng(seed).uniform(-1, 1, (n, 2))


def _dist(X):
    return np.linalg.norm(X[:, None] - X[None], axis=2)


def _knn_weights(D, k):
    idx = np.argsort(D, axis=1)[:, 1 : k + 1]
    W = np.zeros_like(D)
    W[np.repeat(np.arange(len(D)), k), idx.ravel()] = 1.0
    return np.maximum(W, W.T)


@pytest.mark.parametrize("kind", ["equal", "knn", "random", "fixed"])
def test_stress_never_increases(kind):
    rng = np.random.default_rng(1)
    P = _points()
    delta = _dist(P) * rng.uniform(0.8, 1.2, (30, 30))
    delta = (delta + delta.T) / 2
    np.fill_diagonal(delta, 0)
    W = {
        "equal": 1 - np.eye(30),
        "knn": _knn_weights(delta, 5),
        "random": (lambda R: (R + R.T) / 2)(rng.uniform(0, 2, (30, 30))),
        "fixed": _knn_weights(delta, 6),
    }[kind]
    fixed = [0, 5, 9] if kind == "fixed" else None
    history = []
    init = rng.normal(size=(30, 2))
    X, stress, n_iter = weighted_smacof(
        delta, W, init, fixed=fixed, max_iter=200, tol=0.0,
        callback=lambda i, X, s: history.append(s),
    )
    history = [raw_stress(delta, W, init if fixed is None else init)] + history
    assert len(history) == n_iter + 1 and n_iter > 10
    assert np.all(np.diff(history) <= 1e-10 * history[0]), np.diff(history).max()
    assert history[-1] < 0.9 * history[0]
    assert stress == pytest.approx(raw_stress(delta, W, X))
    if fixed is not None:
        np.testing.assert_array_equal(X[fixed], init[fixed])


def test_equal_weights_closed_form_matches_pinv():
    P = _points(12)
    delta = _dist(P) + 0.1 * (1 - np.eye(12))
    init = np.random.default_rng(0).normal(size=(12, 2))
    X1, s1, _ = weighted_smacof(delta, 1 - np.eye(12), init, max_iter=1)
    W = 1 - np.eye(12)
    W[0, 1] = W[1, 0] = 1 + 1e-15  # not exactly equal -> the general pseudo-inverse route
    X2, s2, _ = weighted_smacof(delta, W, init, max_iter=1)
    np.testing.assert_allclose(X1, X2, atol=1e-10)


@pytest.mark.parametrize("kind", ["equal", "knn", "fixed"])
def test_guttman_transform_kept_across_targets_matches_a_fresh_one(kind):
    # the SMACOF variants keep one GuttmanTransform while their targets change: each of its
    # steps must be the step weighted_smacof takes from scratch, bit for bit
    from mappers.smacof.weighted import GuttmanTransform, euclidean_distance_matrix

    rng = np.random.default_rng(3)
    P = _points()
    W = np.ones((30, 30)) if kind == "equal" else _knn_weights(_dist(P), 6)
    np.fill_diagonal(W, 0.0)
    free = np.arange(30) >= (3 if kind == "fixed" else 0)
    X = rng.uniform(-1, 1, (30, 2))
    X[~free] = P[~free]
    guttman = GuttmanTransform(W, free, X)
    for step in range(3):
        targets = _dist(P) * (1.0 + 0.1 * step)
        kept = guttman(W * targets, euclidean_distance_matrix(X), X)
        fresh, _, _ = weighted_smacof(targets, W, X, fixed=np.flatnonzero(~free), max_iter=1,
                                      tol=0.0)
        np.testing.assert_array_equal(kept, fresh)
        np.testing.assert_array_equal(kept[~free], P[~free])
        assert not np.array_equal(kept, X)  # a step was taken
        X = kept


def test_recovers_euclidean_configuration_and_fixed_anchors():
    P = _points(25, seed=3)
    D = _dist(P)
    W = _knn_weights(D, 6)
    fixed = np.array([0, 1, 2, 3])
    init = P + 0.05 * np.random.default_rng(0).normal(size=P.shape)
    X, stress, _ = weighted_smacof(
        D, W, init, fixed=fixed, fixed_positions=P[fixed], max_iter=2000, tol=1e-12
    )
    np.testing.assert_allclose(X[fixed], P[fixed])
    assert stress < 1e-8
    np.testing.assert_allclose(X, P, atol=1e-4)


def test_core_bad_input():
    D = _dist(_points(5))
    W = 1 - np.eye(5)
    with pytest.raises(ValueError, match="delta"):
        weighted_smacof(D[:4], W, np.zeros((5, 2)))
    with pytest.raises(ValueError, match="weights"):
        weighted_smacof(D, -W, np.zeros((5, 2)))
    with pytest.raises(ValueError, match="init"):
        weighted_smacof(D, W, np.zeros((4, 2)))
    with pytest.raises(ValueError, match="fixed"):
        weighted_smacof(D, W, np.zeros((5, 2)), fixed=[7])
    with pytest.raises(ValueError, match="fixed_positions"):
        weighted_smacof(D, W, np.zeros((5, 2)), fixed=[0, 1], fixed_positions=np.zeros((3, 2)))


def test_estimator_precomputed_and_init_array():
    P = _points(20, seed=5)
    D = _dist(P)
    Y = WeightedSMACOF(dissimilarity="precomputed", n_neighbors=6).fit_transform(D)
    assert Y.shape == (20, 2)
    est = WeightedSMACOF(n_neighbors=6, init=P.copy(), max_iter=5).fit(P)
    assert est.stress_ < 1e-12  # already optimal
    with pytest.raises(ValueError, match="init array"):
        WeightedSMACOF(init=np.zeros((3, 2))).fit(P)
    assert classical_mds(D).shape == (20, 2)


def _folding_histories(seed):
    """Visibility-like histories with occlusion: the case where the LPCA start folds."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1.1, 1.1, (50, 2))
    R = rng.uniform(-1.2, 1.2, (2000, 2))
    d = P[:, None] - R[None]
    dist = np.hypot(d[..., 0], d[..., 1])
    Y = (dist < 0.55).astype(float)
    # occlusion by the nearer object in (almost) the same direction, vectorised per object
    ang = np.arctan2(d[..., 1], d[..., 0])
    for j in range(50):
        dang = np.abs(np.angle(np.exp(1j * (ang - ang[j]))))
        nearer = (dist < dist[j]) & (dang < np.arcsin(np.minimum(0.024 / dist, 1)))
        nearer[j] = False
        Y[j, nearer.any(axis=0)] = 0
    return Y / np.linalg.norm(Y, axis=1, keepdims=True), P


def test_default_start_unfolds_where_lpca_start_may_not():
    from mappers import apply_affine, fit_affine, mean_position_error

    errors = {"lpca": [], "unweighted": []}
    for seed in range(3):
        X, P = _folding_histories(seed)
        anchors = [int(np.argmin(np.linalg.norm(P - c, axis=1))) for c in [(-1, -1), (1, -1), (1, 1), (-1, 1)]]
        for init in errors:
            Y = WeightedSMACOF(n_neighbors=5, init=init).fit_transform(X)
            errors[init].append(mean_position_error(apply_affine(Y, fit_affine(Y[anchors], P[anchors])), P))
    assert max(errors["unweighted"]) < 0.3, errors
    assert np.mean(errors["unweighted"]) < np.mean(errors["lpca"]), errors


def test_euclidean_distance_matrix_matches_sklearn():
    from sklearn.metrics import pairwise_distances

    from mappers.smacof.weighted import euclidean_distance_matrix

    X = np.random.default_rng(3).normal(size=(25, 4))
    D = euclidean_distance_matrix(X)
    np.testing.assert_allclose(D, pairwise_distances(X), atol=1e-12)
    assert np.all(np.diag(D) == 0.0) and np.array_equal(D, D.T)


def test_weighted_smacof_warns_when_it_joins_a_disconnected_knn_graph():
    from mappers import GraphRepairWarning

    rng = np.random.default_rng(4)
    X = np.vstack([rng.normal(size=(10, 2)), rng.normal(size=(10, 2)) + 100.0])
    with pytest.warns(GraphRepairWarning, match=r"K=3.*1 closest-pair edge"):
        est = WeightedSMACOF(n_neighbors=3).fit(X)
    assert len(est.added_edges_) == 1
    i, j = est.added_edges_[0]
    assert est.weights_[i, j] == est.weights_[j, i] == 1.0
