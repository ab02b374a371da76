"""The engine's Schur-complement step equals the damped Gauss-Newton step of the whole system,
for the planar poses (3, 2) and the 6-DoF ones (6, 3)."""

import numpy as np
import pytest

from mappers.viewpoints.engine import joint_step, schur_step


def _system(n, f, p, d, seed):
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(4 * (n * p + f * d), n * p + f * d))  # a full-rank Jacobian
    H, g = J.T @ J, rng.normal(size=n * p + f * d)
    U = np.stack([H[k * p:(k + 1) * p, k * p:(k + 1) * p] for k in range(n)])
    off = n * p
    V = np.stack([H[off + k * d:off + (k + 1) * d, off + k * d:off + (k + 1) * d] for k in range(f)])
    # the poses couple to one another and the objects to one another only through each other
    H[:off, :off] = 0.0
    H[off:, off:] = 0.0
    for k in range(n):
        H[k * p:(k + 1) * p, k * p:(k + 1) * p] = U[k]
    for k in range(f):
        H[off + k * d:off + (k + 1) * d, off + k * d:off + (k + 1) * d] = V[k]
    return H, g, U, V, H[:off, off:].reshape(n, p, f * d), g[:off].reshape(n, p), g[off:].reshape(f, d)


@pytest.mark.parametrize(("p", "d"), [(3, 2), (6, 3)])
def test_schur_step_is_the_full_damped_step(p, d):
    n, f, lam = 5, 4, 0.3
    H, g, U, V, W, gc, gp = _system(n, f, p, d, seed=p)
    damped = H + lam * np.diag(np.diag(H))
    full = -np.linalg.solve(damped, g)
    dc, dp = schur_step(U, V, W, gc, gp, lam)
    np.testing.assert_allclose(dc.ravel(), full[:n * p], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(dp.ravel(), full[n * p:], rtol=1e-6, atol=1e-9)


def test_joint_step_is_the_planar_schur_step():
    H, g, U, V, W, gc, gp = _system(4, 3, 3, 2, seed=1)
    a, b = joint_step(U, V, W, gc, gp, 0.1), schur_step(U, V, W, gc, gp, 0.1)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
