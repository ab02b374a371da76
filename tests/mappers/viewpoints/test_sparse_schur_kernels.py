"""The compiled loops of the sparse route (mappers/viewpoints/sparse_schur_kernels.py) give the
numpy expressions' numbers: the bearing normal equations and the resection's systems bit for bit
(the same sums in the same order), the reduced system's product to rounding."""

import numpy as np
import pytest

from mappers.viewpoints import sparse_schur_kernels as kernels
from mappers.viewpoints.engine import initial_poses, normal_blocks, resect


def _bearing_problem(seed=0, m=40, n=300, per=7):
    """Random objects and viewpoints; each step observes ``per`` distinct objects."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(-2, 2, (m, 2))
    C, phi = rng.uniform(-2, 2, (n, 2)), rng.uniform(-3, 3, n)
    t = np.repeat(np.arange(n), per)
    i = np.concatenate([np.sort(rng.choice(m, per, replace=False)) for _ in range(n)])
    obs = (t, i, rng.uniform(-3, 3, t.size))
    w = rng.uniform(0.2, 1.0, t.size)
    free_index = np.full(m, -1)
    free_index[5:] = np.arange(m - 5)
    return P, C, phi, obs, w, free_index, m - 5


def test_the_compiled_normal_equations_are_the_numpy_ones_bit_for_bit():
    P, C, phi, obs, w, free_index, n_free = _bearing_problem()
    U, V, W, g, h = normal_blocks(P, C, phi, obs, w, free_index, n_free, sparse=True)
    U0, V0, W0, g0, h0 = normal_blocks(P, C, phi, obs, w, free_index, n_free)
    for got, want in [(U, U0), (V, V0), (g, g0), (h, h0)]:
        assert np.abs(want).max() > 0.1
        assert np.array_equal(got, want)
    assert np.array_equal(W.matrix().toarray().reshape(W0.shape), W0)
    assert W.blocks.shape[0] == np.count_nonzero(free_index[obs[1]] >= 0)


def test_the_compiled_resections_are_the_numpy_ones_bit_for_bit():
    P, C, phi, obs, w, _, _ = _bearing_problem(seed=1)
    C0, phi0, ok0 = initial_poses(P + 0.01, obs, len(C))
    for a, b in zip(initial_poses(P + 0.01, obs, len(C), compiled=True), (C0, phi0, ok0),
                    strict=True):
        assert np.array_equal(a, b)
    want = resect(P, C0, phi0, obs, w, 2)
    got = resect(P, C0, phi0, obs, w, 2, compiled=True)
    assert not np.allclose(want[0], C0)  # the resection moved the poses
    for a, b in zip(got, want, strict=True):
        assert np.array_equal(a, b)


@pytest.mark.parametrize(("p", "d"), [(3, 2), (6, 3)])
def test_the_reduced_systems_product_is_the_dense_one(p, d):
    rng = np.random.default_rng(p)
    n, f = 50, 12
    step = np.repeat(np.arange(n), 3)
    step = step[step != 7]  # a step without observations
    free = rng.integers(0, f, step.size)
    blocks = rng.normal(size=(step.size, p, d))
    Ui = np.stack([a.T @ a for a in rng.normal(size=(n, 2 * p, p))])
    Vd = np.stack([a.T @ a for a in rng.normal(size=(f, 2 * d, d))])
    W = np.zeros((n, p, f, d))
    np.add.at(W, (step, slice(None), free, slice(None)), blocks)
    W = W.reshape(n * p, f * d)
    S = _block_diag(Vd) - W.T @ _block_diag(Ui) @ W
    x = rng.normal(size=(f, d))
    out = np.empty((f, d))
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(step, minlength=n), out=indptr[1:])
    kernels.schur_matvec(Ui, blocks, indptr, free.astype(np.int64), Vd, x, out)
    want = S @ x.reshape(-1)
    np.testing.assert_allclose(out.reshape(-1), want, rtol=0, atol=1e-10 * np.abs(want).max())
    diag = np.empty_like(Vd)
    kernels.schur_diagonal(Ui, blocks, step, free.astype(np.int64), Vd, diag)
    own = Vd - np.stack([sum(blocks[k].T @ Ui[step[k]] @ blocks[k] for k in np.flatnonzero(free == j))
                         for j in range(f)])
    np.testing.assert_allclose(diag, own, rtol=0, atol=1e-10 * np.abs(own).max())


def _block_diag(blocks):
    n, a = blocks.shape[:2]
    out = np.zeros((n * a, n * a))
    for k in range(n):
        out[k * a:(k + 1) * a, k * a:(k + 1) * a] = blocks[k]
    return out
