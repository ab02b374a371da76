"""BEARING-BA on the sparse Schur engine (issue 34): a masked history mapped through the sparse
step (forced by ``dense_coupling_bytes=0``) and from a ``scipy.sparse`` history maps as the
dense path does."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from map_errors import non_anchor_error
from synthetic_camera import camera_bearings

from mappers.viewpoints.bearing import BearingAdjustment

pytestmark = pytest.mark.usefixtures("one_blas_thread")


def _masked_camera(n_obj=40, n_steps=500, max_range=1.4, noise_deg=0.0, seed=0):
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1.5, 1.5, size=(n_obj, 2))
    P[:6] = [(-1.5, -1.5), (1.5, -1.5), (1.5, 1.5), (-1.5, 1.5), (0.0, 0.0), (0.0, 1.5)]
    poses = np.column_stack([rng.uniform(-1.4, 1.4, (n_steps, 2)), rng.uniform(-np.pi, np.pi, n_steps)])
    X, seen = camera_bearings(P, poses, 360.0, max_range, noise_deg, rng)
    return P, X, np.repeat(seen, 2, axis=1), np.arange(6)


def _fit(X, mask, P, ids, start, **kw):
    est = BearingAdjustment(**kw)
    return est, est.fit_transform(X, mask=mask, anchor_ids=ids, anchor_positions=P[ids],
                                  start_positions=start)


@pytest.mark.parametrize("solver", ["lu", "cg"])
def test_the_sparse_step_maps_as_the_dense_one(solver):
    P, X, mask, ids = _masked_camera(noise_deg=1.0)
    start = P + np.random.default_rng(1).normal(scale=0.05, size=P.shape)
    dense_est, dense = _fit(X, mask, P, ids, start)
    sparse_est, sparse = _fit(X, mask, P, ids, start, dense_coupling_bytes=0, schur_solver=solver)
    assert dense_est.refined_ and sparse_est.refined_
    assert non_anchor_error(start, P, ids) > 0.03
    assert non_anchor_error(dense, P, ids) < 0.02  # 1 degree of noise: mapped well
    np.testing.assert_allclose(sparse, dense, rtol=0, atol=1e-6)
    assert sparse_est.n_rounds_ == dense_est.n_rounds_


def test_a_scipy_sparse_history_gives_the_dense_historys_map():
    P, X, mask, ids = _masked_camera()
    start = P + np.random.default_rng(2).normal(scale=0.05, size=P.shape)
    _, dense = _fit(X, mask, P, ids, start, max_rounds=20)
    _, sparse = _fit(sp.csr_array(X), sp.csr_array(mask), P, ids, start, max_rounds=20,
                     dense_coupling_bytes=0)
    _, same = _fit(sp.csr_array(X), sp.csr_array(mask), P, ids, start, max_rounds=20)
    assert np.array_equal(same, dense)  # the same observations, in the same order: bit for bit
    assert np.abs(dense - P).max() < 1e-6  # exact bearings: the layout itself
    np.testing.assert_allclose(sparse, dense, rtol=0, atol=1e-8)


def test_gain_tol_stops_once_a_round_gains_little():
    P, X, mask, ids = _masked_camera()
    start = P + np.random.default_rng(5).normal(scale=0.05, size=P.shape)
    full, Y = _fit(X, mask, P, ids, start, max_rounds=20, dense_coupling_bytes=0, schur_solver="cg")
    early, Z = _fit(X, mask, P, ids, start, max_rounds=20, dense_coupling_bytes=0,
                    schur_solver="cg", schur_rtol=1e-3, gain_tol=1e-2)
    assert 2 <= early.n_rounds_ < full.n_rounds_
    assert non_anchor_error(start, P, ids) > 0.03
    assert non_anchor_error(Z, P, ids) < 1e-3  # exact bearings: close to the layout already
    assert non_anchor_error(Y, P, ids) < 1e-6


def test_start_params_reach_the_start_method():
    P, X, mask, ids = _masked_camera()

    def start_of(**kw):
        est = BearingAdjustment(start="COVIS-SPARSE", max_rounds=1, **kw)
        return est.fit(X, mask=mask, anchor_ids=ids, anchor_positions=P[ids]).start_

    a, b = start_of(), start_of(start_params={"n_rounds": 1})
    assert np.isfinite(a).all() and np.isfinite(b).all()
    assert np.abs(a - b).max() > 1e-6  # one calibration round instead of ten
    with pytest.raises(ValueError, match="n_round"):
        start_of(start_params={"n_round": 1})


def test_a_sparse_history_of_non_unit_pairs_is_refused():
    P, X, mask, ids = _masked_camera()
    with pytest.raises(ValueError, match="unit"):
        _fit(sp.csr_array(2.0 * X), sp.csr_array(mask), P, ids, P)


@pytest.mark.slow
def test_three_hundred_objects_on_the_sparse_engine():
    P, X, mask, ids = _masked_camera(n_obj=300, n_steps=6000, max_range=0.8, noise_deg=0.5, seed=3)
    start = P + np.random.default_rng(4).normal(scale=0.03, size=P.shape)
    est, Y = _fit(sp.csr_array(X), sp.csr_array(mask), P, ids, start, dense_coupling_bytes=0,
                  schur_solver="cg")
    assert est.refined_ and non_anchor_error(Y, P, ids) < 0.3 * non_anchor_error(start, P, ids)
