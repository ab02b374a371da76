"""The rays-only start by incremental structure from motion with merging
(mappers.spatial.incremental): a scene where two pieces must be merged."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mappers.spatial import SpatialAdjustment
from mappers.spatial.incremental import register_incremental
from mappers.spatial.rays import RayObservations
from mappers.spatial.registration import register_rays

# the camera looking along the world's +y: sensor x -> world x, y (down) -> -z, z -> +y
_FACING = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def _two_rooms(noise_deg: float = 0.0, seed: int = 0):
    """Objects 0-9 on the left wall (x 0-4 m), 14-23 on the right (x 6-10 m), 10-13 between
    them (x 4.5-5.5 m). A left step sees the left objects and two of the middle ones, a right
    step the right objects and two of the middle ones: no step sees three objects of the other
    side, so what grows from the left cannot resect a right step; the two sides share only the
    middle objects (each intersected on both sides)."""
    rng = np.random.default_rng(seed)
    X = np.concatenate([rng.uniform([0, 0, 0], [4, 2, 2], (10, 3)),
                        rng.uniform([4.5, 0, 0], [5.5, 2, 2], (4, 3)),
                        rng.uniform([6, 0, 0], [10, 2, 2], (10, 3))])
    step, obj, C, R = [], [], [], []
    for (lo, hi), own in (((0.0, 5.0), np.arange(10)), ((5.0, 10.0), np.arange(14, 24))):
        for _ in range(30):
            t = len(C)
            C.append([rng.uniform(lo, hi), rng.uniform(-5.0, -3.0), rng.uniform(0.5, 1.5)])
            R.append(Rotation.from_rotvec(rng.normal(0, 0.05, 3)).as_matrix() @ _FACING)
            middle = 10 + rng.choice(4, 2, replace=False)
            seen = np.concatenate([own, middle])
            step += [t] * seen.size
            obj += seen.tolist()
    step, obj, C, R = np.array(step), np.array(obj), np.array(C), np.array(R)
    ray = np.einsum("kji,kj->ki", R[step], X[obj] - C[step])
    ray /= np.linalg.norm(ray, axis=1)[:, None]
    ray += rng.normal(0.0, np.deg2rad(noise_deg), ray.shape)
    ray /= np.linalg.norm(ray, axis=1)[:, None]
    return RayObservations(step, obj, ray, np.full(step.size, np.nan), len(C), len(X)), X


ANCHORS = np.array([0, 3, 6, 9])  # all on the left


def test_the_scene_needs_a_merge():
    """From the anchors, resection and intersection place no object of the right side."""
    obs, X = _two_rooms()
    P, _, _ = register_rays(obs, ANCHORS, X[ANCHORS])
    assert not np.isfinite(P[14:, 0]).any()
    assert np.isfinite(P[:14, 0]).all()


def test_register_incremental_merges_the_pieces():
    obs, X = _two_rooms()
    P, R, C = register_incremental(obs, ANCHORS, X[ANCHORS], noise=np.deg2rad(0.1))
    assert np.isfinite(P).all() and np.isfinite(C).all()
    assert np.abs(P - X).max() < 1e-6


def test_spatial_ba_incremental_start_maps_both_sides():
    obs, X = _two_rooms(noise_deg=0.2, seed=1)
    H = np.zeros((obs.n_objects, 3 * obs.n_steps))
    for k in range(3):
        H[obs.obj, 3 * obs.step + k] = obs.ray[:, k]
    Y = SpatialAdjustment(start="incremental", bearing_noise=np.deg2rad(0.2)).fit_transform(
        H, anchor_ids=ANCHORS, anchor_positions=X[ANCHORS])
    assert np.isfinite(Y).all()
    assert np.linalg.norm(Y - X, axis=1).mean() < 0.05


def test_register_incremental_without_three_anchors_in_a_piece_places_nothing():
    obs, X = _two_rooms()
    P, R, C = register_incremental(obs, np.array([0, 20]), X[[0, 20]], noise=np.deg2rad(0.1))
    assert not np.isfinite(P).any() and not np.isfinite(C).any()


@pytest.mark.parametrize("kw, match", [({"min_shared": 7}, "min_shared must be >= 8"),
                                       ({"noise": 0.0}, "noise must be > 0"),
                                       ({"merge_tol": 0.0}, "merge_tol and max_angle")])
def test_register_incremental_refuses_bad_settings(kw, match):
    obs, X = _two_rooms()
    with pytest.raises(ValueError, match=match):
        register_incremental(obs, ANCHORS, X[ANCHORS], **{"noise": 0.01, **kw})
