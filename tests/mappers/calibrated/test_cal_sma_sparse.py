"""The sparse mapping pipeline (CAL-SMA with sparse=True) against the dense one, and the size
limits."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import mappers
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.histories.recording import collect
from mappers.calibrated.cal_sma import history_dissimilarity
from mappers.catalog import METHODS, check_size, resolve_method
from mappers.core.graph import informative_pairs, knn_mask
from mappers.core.scores import mean_position_error
from mappers.defaults import DENSE_MAX_OBJECTS, SCALABLE_ABOVE_OBJECTS
from mappers.smacof.sparse_stress import candidate_pairs, knn_pairs, sparse_smacof
from mappers.smacof.weighted import weighted_smacof


@pytest.fixture(scope="module")
def history():
    return collect("LFMDR-Visibility-v0", RandomWalkPolicy(seed=0), 2000, seed=31,
                   make_kwargs={"anchors": "random", "n_anchors": 6}, compact=True)


def test_sparse_pairs_and_neighbours_equal_the_dense_ones(history):
    X = history.matrix
    X = X[np.any(X != 0, axis=1)]
    D, _ = history_dissimilarity(X, "cosine")
    i, j, delta = candidate_pairs(sp.csr_array(X), "cosine", 36)
    keep = delta < 1.0 - 1e-9
    i, j, delta = i[keep], j[keep], delta[keep]
    valid = informative_pairs(D)
    assert set(zip(*np.nonzero(np.triu(valid, 1)), strict=True)) == set(zip(i.tolist(), j.tolist(), strict=True))
    np.testing.assert_allclose(delta, D[i, j], atol=1e-12)
    loc = knn_pairs(i, j, delta, len(X), 12)
    dense_loc = knn_mask(D, valid, 12)
    assert set(zip(i[loc].tolist(), j[loc].tolist(), strict=True)) == set(zip(*np.nonzero(np.triu(dense_loc, 1)), strict=True))


def test_sparse_smacof_equals_dense_weighted_smacof_with_fixed_points():
    rng = np.random.default_rng(0)
    P = rng.uniform(0, 1, (30, 2))
    i, j = np.triu_indices(30, 1)
    t = np.hypot(*(P[i] - P[j]).T) * rng.uniform(0.9, 1.1, i.size)
    w = rng.uniform(0.5, 1.5, i.size)
    T = np.zeros((30, 30))
    W = np.zeros((30, 30))
    T[i, j] = T[j, i] = t
    W[i, j] = W[j, i] = w
    init = P + rng.normal(0, 0.1, P.shape)
    fixed = np.array([0, 5, 9])
    init[fixed] = P[fixed]
    a, sa, _ = sparse_smacof(i, j, t, w, init, fixed, max_iter=300, tol=1e-12)
    b, sb, _ = weighted_smacof(T, W, init, fixed=fixed, max_iter=300, tol=1e-12)
    np.testing.assert_allclose(a, b, atol=1e-6)
    np.testing.assert_array_equal(a[fixed], P[fixed])


def test_sparse_and_dense_cal_sma_give_maps_of_the_same_quality(history):
    ids, pos = history.anchor_ids, history.anchor_positions
    dense = mappers.build_map(history, ids, pos, method="CAL-SMA")
    sparse = mappers.build_map(history, ids, pos, method="CAL-SMA", sparse=True)
    assert sparse.method == dense.method == "CAL-SMA"
    assert sparse.params["sparse"] is True and dense.params["sparse"] is False
    err = {name: mean_position_error(m.positions, history.object_positions, exclude=ids)
           for name, m in (("dense", dense), ("sparse", sparse))}
    assert err["sparse"] < 1.5 * err["dense"] and err["sparse"] < 0.15, err
    np.testing.assert_allclose(sparse.positions[ids], pos, atol=1e-9)  # anchors held
    # a dense matrix in gives the same map as the sparse one
    again = mappers.build_map(history.matrix, ids, pos, method="CAL-SMA", sparse=True)
    np.testing.assert_allclose(again.positions, sparse.positions, atol=1e-9)
    # a sparse History without sparse=True is densified (within the budget): the dense map
    densified = mappers.build_map(history.matrix, ids, pos, method="CAL-SMA")
    np.testing.assert_array_equal(densified.positions, dense.positions)


def test_the_old_sparse_label_is_cal_sma_with_sparse_true(history):
    ids, pos = history.anchor_ids, history.anchor_positions
    with pytest.warns(FutureWarning, match="'CAL-SMA-SPARSE' is now spelled 'CAL-SMA' with sparse=True"):
        old = mappers.build_map(history, ids, pos, method="CAL-SMA-SPARSE")
    new = mappers.build_map(history, ids, pos, method="CAL-SMA", sparse=True)
    assert old.method == "CAL-SMA" and old.params == new.params
    np.testing.assert_array_equal(old.positions, new.positions)
    with pytest.raises(ValueError, match="fold_threshold"):  # the dense form's guard only
        mappers.build_map(history, ids, pos, method="CAL-SMA", sparse=True, fold_threshold=0.1)


def test_build_map_picks_the_scalable_method_by_size():
    assert resolve_method(None, "visibility").label == "CAL-SMA"
    assert resolve_method(None, "visibility", n_objects=SCALABLE_ABOVE_OBJECTS).label == "CAL-SMA"
    big = resolve_method(None, "visibility", n_objects=SCALABLE_ABOVE_OBJECTS + 1)
    assert big.label == "CAL-SMA" and big.defaults["sparse"] is True
    assert big.takes_sparse(big.resolved_params()) and big.object_limit(big.resolved_params()) is None
    assert METHODS["CAL-SMA"].scalable == {"sparse": True} and not METHODS["CAL-SMA"].sparse
    assert resolve_method(None, "range", n_objects=10**4).label == "UNFOLD"  # no scalable default


def test_dense_methods_refuse_what_they_cannot_hold():
    m = DENSE_MAX_OBJECTS + 1
    rows = np.arange(m)
    X = sp.csr_array((np.ones(2 * m), (np.concatenate([rows, rows]), np.concatenate([rows, rows + 1]))),
                     shape=(m, m + 1))
    ids, pos = np.arange(3), np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match=r"'CAL-SMA' maps at most 5000 objects.*pass sparse=True"):
        mappers.build_map(X, ids, pos, method="CAL-SMA")
    with pytest.raises(ValueError, match=r"at most 5000 objects.*'CAL-SMA with sparse=True'"):
        mappers.build_map(X, ids, pos, method="LEM")
    check_size(METHODS["CAL-SMA"], m, {"sparse": True})  # the sparse form takes any number
    wide = sp.csr_array((np.ones(3), ([0, 1, 2], [0, 1, 2])), shape=(4000, 200_000))
    with pytest.raises(ValueError, match="GiB.*'CAL-SMA' with sparse=True"):
        mappers.build_map(wide, ids, pos, method="LEM")
