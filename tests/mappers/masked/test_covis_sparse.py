"""COVIS-SPARSE: the masked co-observation map from sparse products, against the dense path."""

import numpy as np
import pytest
import scipy.sparse as sp

import mappers
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.histories.recording import collect
from mappers.core.scores import mean_position_error
from mappers.core.sensors import step_observations
from mappers.masked.coobservation import (
    angle_covisibility_dissimilarity,
    covisibility_dissimilarity,
)
from mappers.masked.covis_sparse import _steps, sparse_co_observation


@pytest.fixture(scope="module")
def limited():
    """A bearing history with a 1.5 m range (masked), dense and compact (sparse) forms."""
    kw = {"max_range": 1.5, "anchors": "random", "n_anchors": 8}
    dense = collect("LFMDR-Bearing-v0", RandomWalkPolicy(seed=0), 2000, seed=5, make_kwargs=kw)
    small = collect("LFMDR-Bearing-v0", RandomWalkPolicy(seed=0), 2000, seed=5, make_kwargs=kw,
                    compact=True)
    return dense, small


@pytest.mark.parametrize("sensor", ["bearing", "visibility"])
def test_sparse_coefficient_equals_the_dense_one(limited, sensor):
    dense, small = limited
    if sensor == "bearing":
        X, mask, S, M = dense.matrix, dense.mask, small.sparse, small.sparse_mask
        seen, values = step_observations(X, mask, sensor)
        delta, C = angle_covisibility_dissimilarity(seen, values)
    else:  # a masked visibility history: what was looked at (mask) and seen (1)
        rng = np.random.default_rng(0)
        X = (rng.random((30, 400)) < 0.2).astype(float)
        mask = rng.random(X.shape) < 0.6
        S, M = sp.csr_array(X), sp.csr_array(mask)
        seen, _ = step_observations(X, mask, sensor)
        delta, C = covisibility_dissimilarity(seen)
    i, j, och, count, n = sparse_co_observation(S, M, sensor=sensor)
    together = np.argwhere(np.triu(C, 1) > 0)
    np.testing.assert_array_equal(np.column_stack([i, j]), together)  # the same pairs, in order
    np.testing.assert_array_equal(count, C[i, j])
    np.testing.assert_array_equal(n, np.diag(C))
    dense_och = np.exp(-delta[i, j])
    big = och > 1e-6
    np.testing.assert_allclose(och[big], dense_och[big], rtol=1e-9, atol=1e-12)


def _non_canonical(A):
    """The same matrix, flagged as possibly unsorted: read by the general (COO) path."""
    A = sp.csr_array(A, copy=True)
    A.has_canonical_format = False
    return A


@pytest.mark.parametrize("mask_kind", ["recorded", "other", "none"])
def test_the_canonical_bearing_path_gives_the_general_paths_matrices(limited, mask_kind):
    _, small = limited
    X, mask = small.sparse, small.sparse_mask
    if mask_kind == "other":  # a mask with its own pattern: half the readings masked out
        keep = np.random.default_rng(1).random(mask.nnz) < 0.5
        mask = sp.csr_array((mask.data & keep, mask.indices.copy(), mask.indptr.copy()),
                            shape=mask.shape)
        mask.eliminate_zeros()  # in place: on copies, not on the fixture's arrays
    elif mask_kind == "none":
        mask = None
    fast = _steps(X, mask, "bearing")
    slow = _steps(_non_canonical(X), None if mask is None else _non_canonical(mask), "bearing")
    assert fast[0].nnz > 1000
    for a, b in zip(fast, slow, strict=True):
        b = sp.csr_array(b)
        b.sort_indices()
        assert np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)
        assert np.array_equal(a.data, b.data)  # value for value


def test_covis_sparse_maps_as_well_as_the_dense_default(limited):
    dense, small = limited
    ids, pos, truth = dense.anchor_ids, dense.anchor_positions, dense.object_positions
    ref = mappers.build_map(dense, ids, pos, "COVIS-AUTO")  # the dense co-observation map
    assert ref.method == "COVIS-AUTO"
    got = mappers.build_map(small, ids, pos, method="COVIS-SPARSE")  # sparse in, sparse path
    again = mappers.build_map(dense, ids, pos, method="COVIS-SPARSE")  # dense in: the same map
    np.testing.assert_allclose(again.positions, got.positions, atol=1e-9)
    ex = sorted({*ids.tolist(), *ref.unmapped, *got.unmapped})
    err = {name: mean_position_error(m.positions, truth, exclude=ex)
           for name, m in (("dense", ref), ("sparse", got))}
    assert err["sparse"] < 1.5 * err["dense"] and err["sparse"] < 0.15, err
    np.testing.assert_allclose(got.positions[ids], pos, atol=1e-9)  # anchors held
    # the two maps are close object by object, not merely equally good
    both = np.setdiff1d(np.arange(len(truth)), ex)
    gap = np.hypot(*(got.positions[both] - ref.positions[both]).T)
    assert np.median(gap) < 0.1, np.median(gap)


def test_large_masked_bearing_default_is_bearing_ba_from_covis_sparse():
    spec = mappers.catalog.resolve_method(None, "bearing", masked=True, n_objects=1000)
    assert spec.label == "BEARING-BA" and spec.sparse  # issue 34: it takes compact histories
    assert spec.defaults["start"] == "COVIS-SPARSE" and spec.defaults["schur_solver"] == "cg"
    assert mappers.catalog.resolve_method(None, "bearing", masked=True, n_objects=50).label == "BEARING-BA"


def test_the_large_default_maps_a_compact_history_as_a_dense_one(limited):
    """The large default's pipeline (BEARING-BA from COVIS-SPARSE, sparse Schur engine forced)
    on the compact history equals its map of the dense history, and refines its start."""
    dense, small = limited
    ids, pos, truth = dense.anchor_ids, dense.anchor_positions, dense.object_positions
    params = {**mappers.catalog.resolve_method(None, "bearing", masked=True, n_objects=1000).defaults,
              "dense_coupling_bytes": 0}
    got = mappers.build_map(small, ids, pos, method="BEARING-BA", **params)
    again = mappers.build_map(dense, ids, pos, method="BEARING-BA", **params)
    start = mappers.build_map(small, ids, pos, method="COVIS-SPARSE")
    np.testing.assert_allclose(got.positions, again.positions, rtol=0, atol=1e-9)
    ex = sorted({*ids.tolist(), *got.unmapped, *start.unmapped})
    err = mean_position_error(got.positions, truth, exclude=ex)
    assert err < 0.1 * mean_position_error(start.positions, truth, exclude=ex), err


def test_a_dense_masked_method_gets_the_sparse_history_densified(limited):
    dense, small = limited
    a = mappers.build_map(small, dense.anchor_ids, dense.anchor_positions, method="COVIS-AUTO")
    b = mappers.build_map(dense, dense.anchor_ids, dense.anchor_positions, method="COVIS-AUTO")
    np.testing.assert_array_equal(a.positions, b.positions)


def test_a_sparse_mask_that_is_not_boolean_is_refused(limited):
    _, small = limited
    ids, pos = small.anchor_ids, small.anchor_positions
    numbers = sp.csr_array(small.sparse_mask, dtype=float)  # 1.0 / 0.0, not True / False
    with pytest.raises(ValueError, match="mask must be a boolean array.*float64"):
        mappers.build_map(small.sparse, ids, pos, mask=numbers, sensor="bearing")
