"""The rays-only start by global structure from motion (issue 34): relative rotations, rotation
averaging, positions from known rotations, batched resection, and SPATIAL-BA's ``start``."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mappers.spatial import SpatialAdjustment
from mappers.spatial.global_start import register_global
from mappers.spatial.known_rotations import positions_from_rotations, solvable
from mappers.spatial.rays import RayObservations
from mappers.spatial.registration import orthogonal_iteration
from mappers.spatial.relative_rotations import relative_rotations, view_pairs
from mappers.spatial.resection import orthogonal_iteration_batch
from mappers.spatial.rotation_averaging import average_rotations


def _world(noise_deg: float = 0.0, n_steps: int = 24, m: int = 20, seed: int = 0):
    """Objects in a 4 x 4 x 2 m box, steps on a ring around it looking at its centre (each sees
    every object); rays with ``noise_deg`` of Gaussian noise per axis."""
    rng = np.random.default_rng(seed)
    X = rng.uniform([-2.0, -2.0, 0.0], [2.0, 2.0, 2.0], (m, 3))
    ang = np.linspace(0.0, 2 * np.pi, n_steps, endpoint=False)
    C = np.stack([6 * np.cos(ang), 6 * np.sin(ang), 1.0 + 0.5 * np.sin(3 * ang)], axis=1)
    R = np.empty((n_steps, 3, 3))
    for t in range(n_steps):  # sensor z forward to the centre, a little roll per step
        z = np.array([0.0, 0.0, 1.0]) - C[t]
        z /= np.linalg.norm(z)
        x = np.cross(z, [0.0, 0.0, 1.0])
        x /= np.linalg.norm(x)
        R[t] = np.stack([x, np.cross(z, x), z], axis=1) @ Rotation.from_rotvec(
            [0, 0, 0.1 * np.sin(t)]).as_matrix()
    step = np.repeat(np.arange(n_steps), m)
    obj = np.tile(np.arange(m), n_steps)
    ray = np.einsum("kji,kj->ki", R[step], X[obj] - C[step])
    ray += rng.normal(0.0, np.deg2rad(noise_deg), ray.shape) * np.linalg.norm(ray, axis=1)[:, None]
    ray /= np.linalg.norm(ray, axis=1)[:, None]
    obs = RayObservations(step, obj, ray, np.full(step.size, np.nan), n_steps, m)
    return obs, X, R, C


def _angle(A, B):
    D = np.einsum("kji,kjl->kil", A, B)
    return np.arccos(np.clip((np.trace(D, axis1=1, axis2=2) - 1) / 2, -1, 1))


def _similarity_error(est, truth):
    from mappers.core.align_3d import umeyama
    Rs, s, t = umeyama(est, truth, True)
    return np.linalg.norm(s * est @ Rs.T + t - truth, axis=1).max()


def test_relative_rotations_exact_without_noise():
    obs, _, R, _ = _world()
    a, b, ka, kb, pair = view_pairs(obs, np.arange(obs.n_steps), 8, 4)
    assert len(a) >= obs.n_steps  # every step keeps partners
    pr = relative_rotations(obs, a, b, ka, kb, pair, noise=np.deg2rad(0.1))
    truth = np.einsum("kji,kjl->kil", R[b], R[a])
    assert np.rad2deg(_angle(truth, pr.rotation)).max() < 1e-5
    assert np.all(pr.inliers == obs.n_objects)


def test_rotation_averaging_recovers_rotations_up_to_one_turn():
    obs, _, R, _ = _world()
    a, b, _, _, _ = view_pairs(obs, np.arange(obs.n_steps), 8, 6)
    rel = np.einsum("kji,kjl->kil", R[b], R[a])
    noise = Rotation.from_rotvec(np.random.default_rng(1).normal(0, np.deg2rad(0.5), (len(a), 3)))
    rel = noise.as_matrix() @ rel
    rel[0] = Rotation.from_rotvec([0.0, 1.0, 0.0]).as_matrix() @ rel[0]  # one wrong pair
    Rg, res = average_rotations(a, b, rel, obs.n_steps)
    U, _, Vt = np.linalg.svd(np.einsum("kij,klj->il", Rg, R))  # the world turn, fitted
    G = U @ Vt
    err = np.rad2deg(_angle(np.einsum("ij,kjl->kil", G, R), Rg))
    assert err.max() < 1.0  # each pair 0.5 degrees off
    assert np.rad2deg(res[0]) > 30  # the wrong pair stands out


def test_positions_from_known_rotations_up_to_similarity():
    obs, X, R, C = _world()
    steps, objects = solvable(obs, np.ones(obs.n_steps, dtype=bool))
    assert steps.all() and objects.all()
    P, Ce, err = positions_from_rotations(obs, R, steps, objects, noise=np.deg2rad(0.1))
    both = np.vstack([P, Ce])
    assert _similarity_error(both, np.vstack([X, C])) < 1e-6
    assert np.nanmax(err) < 1e-6


def test_solvable_prunes_single_rays():
    obs, _, _, _ = _world(n_steps=3, m=4)
    keep = obs.obj != 3
    keep[(obs.obj == 3) & (obs.step == 0)] = True  # object 3 seen from one step only
    sub = obs._replace(step=obs.step[keep], obj=obs.obj[keep], ray=obs.ray[keep],
                       range=obs.range[keep])
    steps, objects = solvable(sub, np.ones(3, dtype=bool))
    assert steps.all() and objects.tolist() == [True, True, True, False]


def test_batched_resection_equals_one_by_one():
    obs, X, _, _ = _world(noise_deg=0.5, n_steps=6)
    seg = obs.step
    R, c, rms = orthogonal_iteration_batch(seg, X[obs.obj], obs.ray, obs.n_steps)
    for t in range(obs.n_steps):
        k = obs.step == t
        R1, c1, rms1 = orthogonal_iteration(X[obs.obj[k]], obs.ray[k])
        np.testing.assert_allclose(R[t], R1, atol=1e-9)
        np.testing.assert_allclose(c[t], c1, atol=1e-9)
        assert rms[t] == pytest.approx(rms1, abs=1e-9)


def test_register_global_places_the_world_by_the_anchors():
    obs, X, R, C = _world(noise_deg=0.01)
    ids = np.array([0, 1, 2, 3])
    P, Re, Ce = register_global(obs, ids, X[ids], noise=np.deg2rad(0.01))
    assert np.isfinite(P).all() and np.isfinite(Ce).all()
    assert np.abs(P - X).max() < 0.05
    assert np.rad2deg(_angle(Re, R)).max() < 1.0


def test_register_global_refuses_fewer_than_eight_shared():
    obs, X, _, _ = _world()
    with pytest.raises(ValueError, match="min_shared"):
        register_global(obs, np.arange(4), X[:4], noise=0.01, min_shared=5)


def _history(obs):
    H = np.zeros((obs.n_objects, 3 * obs.n_steps))
    for k in range(3):
        H[obs.obj, 3 * obs.step + k] = obs.ray[:, k]
    return H


def test_spatial_ba_global_start_maps_the_world():
    obs, X, _, _ = _world(noise_deg=0.5)
    ids = np.array([0, 5, 10, 15])
    H = _history(obs)
    Y = SpatialAdjustment(start="global", bearing_noise=np.deg2rad(0.5)).fit_transform(
        H, anchor_ids=ids, anchor_positions=X[ids])
    assert np.isfinite(Y).all()
    assert np.linalg.norm(Y - X, axis=1).mean() < 0.03


def test_spatial_ba_refuses_an_unknown_start():
    obs, X, _, _ = _world(n_steps=4, m=6)
    with pytest.raises(ValueError, match="start must be 'anchors', 'global' or 'incremental'"):
        SpatialAdjustment(start="auto").fit(_history(obs), anchor_ids=np.arange(4),
                                            anchor_positions=X[:4])


def test_spans_batch_agrees_with_spans():
    from mappers.spatial.registration import _spans, _spans_batch
    rng = np.random.default_rng(3)
    pts = [rng.normal(size=(5, 3)), np.outer(np.arange(4.0), [1.0, 2.0, 0.5]), rng.normal(size=(2, 3))]
    step = np.concatenate([np.full(len(p), k) for k, p in enumerate(pts)])
    got = _spans_batch(step, np.vstack(pts), 3)
    assert got.tolist() == [_spans(p) for p in pts] == [True, False, False]
