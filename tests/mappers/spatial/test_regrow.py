"""Growing a rays-only map: a consensus intersection ignores a wrongly posed step."""

import numpy as np
import pytest

from mappers.spatial import ray_observations
from mappers.spatial.regrow import intersect_by_consensus, step_ray_errors


def _scene(n=12, seed=0):
    """One object at (1, 2, 0.5) seen by n cameras around it (identity rotations: rays in the
    world), plus a step whose pose is wrong by 3 m."""
    rng = np.random.default_rng(seed)
    p = np.array([1.0, 2.0, 0.5])
    C = p + rng.uniform(-3, 3, (n, 3))
    R = np.repeat(np.eye(3)[None], n, axis=0)
    X = np.zeros((1, 3 * n))
    u = (p - C) / np.linalg.norm(p - C, axis=1, keepdims=True)
    X[0] = u.ravel()
    obs = ray_observations(X, None)
    C_bad = C.copy()
    C_bad[0] += [3.0, 0.0, 0.0]
    return p, obs, R, C, C_bad


def test_consensus_intersection_and_step_errors():
    p, obs, R, C, C_bad = _scene()
    P0 = np.full((1, 3), np.nan)
    P = intersect_by_consensus(obs, P0, R, C_bad, np.deg2rad(2.0))
    np.testing.assert_allclose(P[0], p, atol=1e-9)
    err = step_ray_errors(obs, P, R, C_bad)
    assert err[0] > np.deg2rad(10.0) and np.all(err[1:] < 1e-6)
    assert np.isnan(step_ray_errors(obs, P0, R, C)).all()  # nothing placed: nothing to compare
    with pytest.raises(ValueError, match="max_angle"):
        intersect_by_consensus(obs, P0, R, C, 0.0)
