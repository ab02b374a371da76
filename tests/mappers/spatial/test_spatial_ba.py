"""SPATIAL-BA and COVIS-3D on a small camera world: exact rays give the map, bad input is named."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mappers import build_map
from mappers.core.scores_3d import mean_position_error_3d
from mappers.spatial import ray_observations


def camera_world(m=30, n=60, seed=0, noise_deg=0.0, range_noise=0.0):
    """Objects in a 6 x 6 x 2 m room seen by a camera at random poses: a 60 degree cone, 4 m."""
    rng = np.random.default_rng(seed)
    P = rng.uniform([-3, -3, 0], [3, 3, 2], (m, 3))
    C = rng.uniform([-2, -2, 0.5], [2, 2, 1.5], (n, 3))
    R = Rotation.random(n, random_state=seed + 1).as_matrix()
    X, Rg = np.zeros((m, 3 * n)), np.zeros((m, n))
    for t in range(n):
        v = (P - C[t]) @ R[t]
        d = np.linalg.norm(v, axis=1)
        see = (v[:, 2] > 0.5 * d) & (d < 4.0)
        u = v[see] / d[see, None]
        if noise_deg:
            u = Rotation.from_rotvec(rng.normal(0, np.deg2rad(noise_deg), u.shape)).apply(u)
        X[see, 3 * t:3 * t + 3] = u
        Rg[see, t] = d[see] + rng.normal(0, range_noise, see.sum()) if range_noise else d[see]
    return P, X, Rg


ANCHORS = np.arange(6)


def test_rays_and_ranges_map_exactly():
    P, X, Rg = camera_world()
    m = build_map({"bearing": X, "range": Rg}, ANCHORS, P[ANCHORS])
    assert m.method == "SPATIAL-BA" and m.positions.shape == P.shape
    placed = np.setdiff1d(np.arange(len(P)), [*m.unmapped, *ANCHORS])
    assert len(placed) >= 0.9 * (len(P) - 6)
    assert mean_position_error_3d(m.positions, P, [*m.unmapped, *ANCHORS]) < 1e-6


def test_an_unplaced_object_is_named_by_its_id_as_in_2d():
    """Map.warnings names the unmapped objects by id, in the 2-D notes' words ("objects [...]
    could not be placed"), so a caller that renames object ids (MRCLAM's subjects) reads both."""
    P, X, Rg = camera_world()
    X[[7, 12]], Rg[[7, 12]] = 0.0, 0.0  # never seen
    m = build_map({"bearing": X, "range": Rg}, ANCHORS, P[ANCHORS])
    assert {7, 12} <= set(m.unmapped)
    assert f"objects {list(m.unmapped)} could not be placed from their histories" in m.warnings


def test_rays_alone_map_closely():
    # exact rays: the adjustment from the resection-and-intersection start comes within a
    # centimetre (it stalls there: bearing-only converges slowly; 60 iterations as 200)
    P, X, _ = camera_world()
    m = build_map(X, ANCHORS, P[ANCHORS], sensor="bearing", max_iter=60)
    assert len(m.unmapped) <= 8
    assert mean_position_error_3d(m.positions, P, [*m.unmapped, *ANCHORS]) < 0.01


def test_noisy_rays_and_ranges():
    P, X, Rg = camera_world(noise_deg=1.0, range_noise=0.02)
    m = build_map({"bearing": X, "range": Rg}, ANCHORS, P[ANCHORS])
    assert mean_position_error_3d(m.positions, P, [*m.unmapped, *ANCHORS]) < 0.05


def test_sightings_map_roughly():
    P, X, _ = camera_world(m=40, n=400)
    vis = (np.abs(X[:, 0::3]) + np.abs(X[:, 2::3]) > 0).astype(float)
    m = build_map(vis, ANCHORS, P[ANCHORS])
    assert m.method == "COVIS-3D"
    centroid = np.linalg.norm(P[6:] - P[ANCHORS].mean(axis=0), axis=1).mean()
    assert mean_position_error_3d(m.positions, P, [*m.unmapped, *ANCHORS]) < 0.8 * centroid


def test_two_d_bearing_history_with_3d_anchors_refused():
    a = np.random.default_rng(0).uniform(-3, 3, (10, 4))
    X2 = np.stack([np.cos(a), np.sin(a)], axis=-1).reshape(10, 8)
    with pytest.raises(ValueError, match="2-D bearing history|cos, sin"):
        build_map(X2, [0, 1, 2, 3], np.eye(4, 3) + [0, 0, 0.5], sensor="bearing")


def test_zero_length_ray_refused():
    P, X, _ = camera_world()
    mask = np.ones(X.shape, dtype=bool)
    with pytest.raises(ValueError, match="length 0"):
        ray_observations(X, mask)  # the unseen (0, 0, 0) rays are observed by this mask


def test_coplanar_anchors_refused_for_sightings():
    P, X, _ = camera_world(m=40, n=200)
    vis = (np.abs(X[:, 0::3]) + np.abs(X[:, 2::3]) > 0).astype(float)
    flat = P[ANCHORS] * [1, 1, 0]
    with pytest.raises(ValueError, match="one plane"):
        build_map(vis, ANCHORS, flat)


def test_the_sparse_engine_maps_as_the_dense_one():
    """Issue 34: the 6-DoF adjustment through the sparse Schur step (forced) gives the dense
    step's map, to rounding."""
    P, X, Rg = camera_world(noise_deg=1.0, range_noise=0.02)
    dense = build_map({"bearing": X, "range": Rg}, ANCHORS, P[ANCHORS], method="SPATIAL-BA")
    sparse = build_map({"bearing": X, "range": Rg}, ANCHORS, P[ANCHORS], method="SPATIAL-BA",
                       dense_coupling_bytes=0)
    assert mean_position_error_3d(dense.positions, P, [*dense.unmapped, *ANCHORS]) < 0.05
    assert dense.unmapped == sparse.unmapped
    np.testing.assert_allclose(sparse.positions, dense.positions, rtol=0, atol=1e-7)


def test_spatial_ba_model_covariances_shapes_anchors_and_coverage():
    # noisy rays and ranges (1 degree, 2 cm: the adjustment's own noise model): (M, 3, 3) in the
    # map's frame, zero for the anchors, symmetric positive semi-definite, and the truth inside
    # the 95 % ellipsoid of most objects (3 worlds pooled; a calibrated model gives 0.95)
    from mappers.core.uncertainty import chi2_quantile, mahalanobis_squared

    q = []
    for seed in range(3):
        P, X, Rg = camera_world(seed=seed, noise_deg=1.0, range_noise=0.02)
        plain = build_map({"bearing": X, "range": Rg}, ANCHORS, P[ANCHORS])
        m = build_map({"bearing": X, "range": Rg}, ANCHORS, P[ANCHORS], uncertainty=True)
        assert np.array_equal(m.positions, plain.positions, equal_nan=True)
        assert m.covariances.shape == (len(P), 3, 3)
        assert np.all(m.covariances[ANCHORS] == 0.0)
        free = np.setdiff1d(np.arange(len(P)), [*ANCHORS, *m.unmapped])
        cov = m.covariances[free]
        assert np.allclose(cov, cov.transpose(0, 2, 1))
        assert np.all(np.linalg.eigvalsh(cov) > 0)
        q.append(mahalanobis_squared(m.positions[free] - P[free], cov))
    share = np.mean(np.concatenate(q) <= chi2_quantile(3))
    assert 0.7 <= share <= 1.0


def test_spatial_ba_covariances_nan_for_unmapped_and_carried_by_the_similarity():
    # anchor_noise places the adjusted map on the anchors by a similarity: the covariances are
    # carried by it (the same objects' ellipsoids as without it, up to the map's change); an
    # object never seen is unmapped and its covariance NaN
    P, X, Rg = camera_world(seed=4, noise_deg=1.0, range_noise=0.02)
    X[-1], Rg[-1] = 0.0, 0.0
    m = build_map({"bearing": X, "range": Rg}, ANCHORS, P[ANCHORS], uncertainty="model",
                  anchor_noise=0.03)
    assert len(P) - 1 in m.unmapped
    assert np.all(np.isnan(m.covariances[list(m.unmapped)]))
    assert np.all(m.covariances[ANCHORS] == 0.0)
    fixed = build_map({"bearing": X, "range": Rg}, ANCHORS, P[ANCHORS], uncertainty="model")
    free = np.setdiff1d(np.arange(len(P)), [*ANCHORS, *m.unmapped, *fixed.unmapped])
    ratio = np.trace(m.covariances[free], axis1=1, axis2=2) / np.trace(
        fixed.covariances[free], axis1=1, axis2=2)
    assert 0.3 < np.median(ratio) < 3.0


@pytest.mark.slow  # 21 COVIS-3D maps: about 50 s on a loaded machine
def test_covis_3d_bootstrap_covariances():
    P, X, _ = camera_world(m=30, n=300, seed=2)
    vis = (np.abs(X[:, 0::3]) + np.abs(X[:, 2::3]) > 0).astype(float)
    m = build_map(vis, ANCHORS, P[ANCHORS], uncertainty=True, max_iter=50)
    assert m.method == "COVIS-3D" and m.covariances.shape == (len(P), 3, 3)
    assert np.all(m.covariances[ANCHORS] == 0.0)
    free = np.setdiff1d(np.arange(len(P)), [*ANCHORS, *m.unmapped])
    assert np.all(np.linalg.eigvalsh(m.covariances[free]) > 0)
    with pytest.raises(ValueError, match="model"):
        build_map(vis, ANCHORS, P[ANCHORS], uncertainty="model")




def test_model_covariances_beyond_the_dense_coupling_are_refused():
    P, X, Rg = camera_world()
    with pytest.raises(ValueError, match="dense_coupling_bytes"):
        build_map({"bearing": X, "range": Rg}, ANCHORS, P[ANCHORS], uncertainty="model",
                  dense_coupling_bytes=0)
