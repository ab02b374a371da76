"""The sparse Schur step (mappers/viewpoints/sparse_schur.py) equals the dense one, planar (3, 2)
and 6-DoF (6, 3), by sparse LU and by conjugate gradients."""

import numpy as np
import pytest

from mappers.viewpoints.engine import Coupling, schur_step, use_sparse_coupling
from mappers.viewpoints.sparse_schur import sparse_schur_step


def _problem(n, f, p, d, seed):
    """A random joint system in which each step sees a few objects (once or twice each)."""
    rng = np.random.default_rng(seed)
    step = np.repeat(np.arange(n), 4)
    free = rng.integers(0, f, size=step.size)
    free[: 2 * f] = np.repeat(np.arange(f), 2)  # every object seen
    step = np.concatenate([step, step[:5]])  # a pair observed twice: its blocks summed
    free = np.concatenate([free, free[:5]])
    blocks = rng.normal(size=(step.size, p, d))
    U = np.stack([a.T @ a for a in rng.normal(size=(n, 3 * p, p))])
    V = np.stack([a.T @ a for a in rng.normal(size=(f, 6 * d, d))]) + 20.0 * np.eye(d)
    coupling = Coupling(blocks, step, free, n, f)
    dense = np.zeros((n, p, f, d))
    np.add.at(dense, (step, slice(None), free, slice(None)), blocks)
    return U, V, coupling, dense.reshape(n, p, f * d), rng.normal(size=(n, p)), rng.normal(size=(f, d))


@pytest.mark.parametrize(("p", "d"), [(3, 2), (6, 3)])
@pytest.mark.parametrize("solver", ["lu", "cg"])
def test_sparse_step_is_the_dense_step(p, d, solver):
    U, V, coupling, dense, g, h = _problem(40, 12, p, d, seed=p)
    for lam in (1e-4, 0.3):
        dc, dp = schur_step(U, V, dense, g, h, lam)
        sc, sp_ = sparse_schur_step(U, V, coupling, g, h, lam, solver=solver, rtol=1e-13)
        assert np.abs(dp).max() > 1e-3  # a step that says something
        np.testing.assert_allclose(sp_, dp, rtol=0, atol=1e-9 * np.abs(dp).max())
        np.testing.assert_allclose(sc, dc, rtol=0, atol=1e-9 * np.abs(dc).max())


def test_mismatched_coupling_is_refused():
    U, V, coupling, _, g, h = _problem(10, 5, 3, 2, seed=0)
    with pytest.raises(ValueError, match="coupling"):
        sparse_schur_step(U, V[:4], coupling, g, h[:4], 0.1)
    with pytest.raises(ValueError, match="solver"):
        sparse_schur_step(U, V, coupling, g, h, 0.1, solver="qr")


def test_the_threshold_is_the_dense_couplings_memory():
    assert not use_sparse_coupling(8000, 3, 2, 200)  # 77 MB: dense
    assert use_sparse_coupling(20000, 3, 2, 1000)  # 960 MB: sparse
    assert use_sparse_coupling(10, 3, 2, 5, limit=100.0)
