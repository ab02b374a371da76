"""The compiled 6-DoF normal equations and Schur step (mappers/spatial/adjustment_kernels.py)
give the numpy expressions' numbers to rounding: the blocks of ``normal_blocks`` and the step
of the dense ``schur_step``, with and without ranges, with fixed and free objects."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mappers.spatial.adjustment import (
    Problem,
    _compiled_blocks,
    _compiled_step,
    adjust_viewpoints,
    normal_blocks,
)
from mappers.spatial.rays import RayObservations
from mappers.viewpoints import robust_weights, schur_step


def _problem(seed=0, m=25, n=80, per=9, ranged=0.6):
    """Random points and poses; each step sees ``per`` distinct objects, some with a range; the
    rays noisy, so the residuals are not zero."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(-3, 3, (m, 3))
    C = rng.uniform(-1, 1, (n, 3))
    R = Rotation.random(n, random_state=seed).as_matrix()
    step = np.repeat(np.arange(n), per)
    obj = np.concatenate([np.sort(rng.choice(m, per, replace=False)) for _ in range(n)])
    v = np.einsum("kji,kj->ki", R[step], P[obj] - C[step])
    d = np.linalg.norm(v, axis=1)
    ray = Rotation.from_rotvec(rng.normal(0, 0.02, v.shape)).apply(v / d[:, None])
    rng_k = np.where(rng.random(step.size) < ranged, d + rng.normal(0, 0.02, d.shape), np.nan)
    obs = RayObservations(step, obj, ray, rng_k, n, m)
    return obs, P, R, C


@pytest.mark.parametrize("ranged", [0.0, 0.6])
def test_the_compiled_blocks_and_step_are_the_dense_ones(ranged):
    obs, P, R, C = _problem(ranged=ranged)
    keep = np.arange(len(obs.step))
    prob = Problem(obs, keep, np.deg2rad(1.0), 0.02, 0.01)
    res = prob.residuals(P, R, C)
    e = res[0]
    w = robust_weights(np.linalg.norm(e, axis=1), 3.0, "cauchy")
    assert np.ptp(w) > 0.1  # the weights matter
    free_index = np.full(obs.n_objects, -1)
    free_index[4:] = np.arange(obs.n_objects - 4)  # four fixed objects
    n_free = obs.n_objects - 4
    indptr = np.zeros(obs.n_steps + 1, dtype=np.int64)
    np.cumsum(np.bincount(obs.step, minlength=obs.n_steps), out=indptr[1:])
    Jc, Jp = prob.jacobians(R, *res[1:])
    want = normal_blocks(prob, e, w, Jc, Jp, obs.step, free_index, obs.n_steps, n_free)
    got = _compiled_blocks(prob, res, w, R, obs.step, free_index, indptr, obs.n_steps, n_free)
    for name, a, b in zip("UVWgh", got, want, strict=True):
        if name == "W":  # per sighting against the dense (N, 6, 3F) array
            dense = np.zeros((obs.n_steps, 6, n_free, 3))
            k = a.free >= 0
            dense[obs.step[k], :, a.free[k], :] = a.blocks[k]
            assert np.all(a.blocks[~k] == 0)
            a = dense.reshape(b.shape)
        assert np.abs(b).max() > 0.1
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-10 * np.abs(b).max())
    for lam in (1e-3, 10.0):
        dc, dp = _compiled_step(*got, lam)
        dc0, dp0 = schur_step(*want, lam)
        assert np.abs(dp0).max() > 1e-4
        np.testing.assert_allclose(dp, dp0, rtol=1e-7, atol=1e-9 * np.abs(dp0).max())
        np.testing.assert_allclose(dc, dc0, rtol=1e-7, atol=1e-9 * np.abs(dc0).max())


def test_the_adjustment_takes_sightings_in_any_order():
    """The compiled step reads each step's sightings as one run; sightings given in another
    order are taken by step first: the same adjustment to rounding."""
    obs, P, R, C = _problem(seed=1, ranged=0.5)
    rng = np.random.default_rng(2)
    fixed = np.zeros(obs.n_objects, dtype=bool)
    fixed[:5] = True
    start = P + np.where(fixed[:, None], 0.0, rng.normal(0, 0.05, P.shape))
    a = adjust_viewpoints(obs, start, R, C, fixed, bearing_noise=0.02, max_iter=5)
    order = rng.permutation(len(obs.step))
    shuffled = obs._replace(step=obs.step[order], obj=obs.obj[order], ray=obs.ray[order],
                            range=obs.range[order])
    b = adjust_viewpoints(shuffled, start, R, C, fixed, bearing_noise=0.02, max_iter=5)
    assert a.n_iter == b.n_iter and np.abs(a.points - start).max() > 1e-3
    np.testing.assert_allclose(b.points, a.points, atol=1e-9)
    np.testing.assert_allclose(b.positions, a.positions, atol=1e-9)


def test_the_compiled_resection_is_the_one_step_orthogonal_iteration():
    """The batched resection's compiled iterations give each step the pose of the one-step
    orthogonal iteration to rounding, in any order of the sightings."""
    from mappers.spatial.registration import orthogonal_iteration
    from mappers.spatial.resection import orthogonal_iteration_batch

    obs, P, R, C = _problem(seed=3, n=40, per=6)
    noisy = P + np.random.default_rng(4).normal(0, 0.05, P.shape)  # the rays miss a little
    order = np.random.default_rng(5).permutation(len(obs.step))
    Rb, cb, rms = orthogonal_iteration_batch(obs.step[order], noisy[obs.obj[order]],
                                             obs.ray[order], obs.n_steps)
    for t in range(obs.n_steps):
        k = obs.step == t
        R1, c1, rms1 = orthogonal_iteration(noisy[obs.obj[k]], obs.ray[k])
        np.testing.assert_allclose(Rb[t], R1, atol=1e-9)
        np.testing.assert_allclose(cb[t], c1, atol=1e-9)
        assert rms1 > 1e-3 and abs(rms[t] - rms1) < 1e-6
    assert np.abs(Rb - R).max() < 0.2  # near the true poses: a real resection


def test_gain_tol_stops_an_adjustment_early_near_its_end():
    obs, P, R, C = _problem(seed=6, ranged=0.0)
    fixed = np.zeros(obs.n_objects, dtype=bool)
    fixed[:5] = True
    start = P + np.where(fixed[:, None], 0.0, np.random.default_rng(7).normal(0, 0.05, P.shape))
    kw = {"bearing_noise": 0.02, "max_iter": 100, "tol": 1e-12}
    full = adjust_viewpoints(obs, start, R, C, fixed, **kw)
    early = adjust_viewpoints(obs, start, R, C, fixed, gain_tol=1e-3, **kw)
    assert early.n_iter < full.n_iter
    assert early.cost <= full.cost * (1 + 1e-2)
    assert np.abs(early.points - full.points).max() < 0.1 * np.abs(start - full.points).max()
    with pytest.raises(ValueError, match="gain_tol"):
        adjust_viewpoints(obs, start, R, C, fixed, gain_tol=1.0, **kw)
