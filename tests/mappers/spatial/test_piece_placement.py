"""The rigid pieces of the stereo start (:mod:`mappers.spatial.registration`): placed by their
placed points and pose-free distances when the fit is unique, refused when ambiguous, and adjusted
in their own frame before that."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from mappers.core.align_3d import umeyama
from mappers.spatial.rays import RayObservations
from mappers.spatial.registration import _fit_piece, _groups, _grow_piece, _refine_piece


def _world_and_piece(seed=0):
    rng = np.random.default_rng(seed)
    world = rng.uniform(-2.0, 2.0, size=(10, 3))
    turn = Rotation.from_rotvec([0.4, -1.1, 2.0]).as_matrix()
    local = (world - [0.3, 1.0, -0.5]) @ turn  # the piece's frame: world = local @ turn.T + shift
    return world, local


def _pairs(world, links):
    return {(i, j): float(np.linalg.norm(world[i] - world[j])) for i, j in links}


def test_two_points_and_distances_place_a_piece_exactly():
    world, local = _world_and_piece()
    piece = np.zeros(10, dtype=bool)
    piece[:6] = True  # the piece holds objects 0-5; 0 and 1 are placed, 6-9 placed outside it
    P = np.full_like(world, np.nan)
    P[[0, 1, 6, 7, 8, 9]] = world[[0, 1, 6, 7, 8, 9]]
    loc = np.where(piece[:, None], local, np.nan)
    known = np.all(np.isfinite(P), axis=1)
    found = _fit_piece(loc, P, np.array([0, 1]), piece & ~known, known & ~piece,
                       _pairs(world, [(2, 6), (3, 7), (4, 8), (5, 9), (2, 8)]), 1.0)
    assert found is not None
    R, s, t = found
    np.testing.assert_allclose(s * local[:6] @ R.T + t, world[:6], atol=1e-5)


def test_a_turn_one_distance_cannot_fix_is_refused():
    world, local = _world_and_piece(1)
    piece = np.zeros(10, dtype=bool)
    piece[:3] = True  # two placed points and one distance: two mirror turns about their line fit
    P = np.full_like(world, np.nan)
    P[[0, 1, 6]] = world[[0, 1, 6]]
    loc = np.where(piece[:, None], local, np.nan)
    known = np.all(np.isfinite(P), axis=1)
    assert _fit_piece(loc, P, np.array([0, 1]), piece & ~known, known & ~piece,
                      _pairs(world, [(2, 6)]), 1.0) is None


def test_distances_that_do_not_fit_are_refused():
    world, local = _world_and_piece(2)
    piece = np.zeros(10, dtype=bool)
    piece[:6] = True
    P = np.full_like(world, np.nan)
    P[[0, 1, 6, 7, 8, 9]] = world[[0, 1, 6, 7, 8, 9]]
    loc = np.where(piece[:, None], local, np.nan)
    known = np.all(np.isfinite(P), axis=1)
    pairs = {k: d + 1.0 for k, d in _pairs(world, [(2, 6), (3, 7), (4, 8), (5, 9)]).items()}
    assert _fit_piece(loc, P, np.array([0, 1]), piece & ~known, known & ~piece, pairs,
                      1.0) is None


def test_a_chained_piece_is_refined_to_its_sightings_shape():
    """Steps chained one after another along a strip drift; the adjustment of the piece in its
    own frame brings it closer to the true shape."""
    rng = np.random.default_rng(7)
    world = np.column_stack([np.linspace(0.0, 12.0, 40), rng.uniform(-1, 1, 40),
                             rng.uniform(0, 2, 40)])  # a long strip: a chain runs along it
    step, obj, ray, rng_ = [], [], [], []
    for t, x in enumerate(np.linspace(0.0, 12.0, 60)):
        c = np.array([x, -3.0, 1.0])
        near = np.flatnonzero(np.abs(world[:, 0] - x) < 1.6)
        v = world[near] - c  # the sensor's frame = the world's (no turn): the chain still drifts
        r = np.linalg.norm(v, axis=1)
        u = v / r[:, None] + rng.normal(0, 0.003, v.shape)
        step += [t] * near.size
        obj += near.tolist()
        ray += (u / np.linalg.norm(u, axis=1, keepdims=True)).tolist()
        rng_ += (r + rng.normal(0, 0.02, r.size)).tolist()
    obs = RayObservations(np.array(step), np.array(obj), np.array(ray), np.array(rng_), 60, 40)
    pts = obs.ray * obs.range[:, None]
    groups = _groups(obs)
    piece = _grow_piece(obs, pts, groups, np.ones(60, dtype=bool), 0)

    def shape_error(p):
        total, count, _ = p
        mine = count > 0
        local = total[mine] / count[mine, None]
        R, s, t = umeyama(local, world[mine], True)
        return np.linalg.norm(s * local @ R.T + t - world[mine], axis=1).mean()

    refined = _refine_piece(obs, piece, {"bearing_noise": 0.003, "range_noise": 0.02})
    assert len(piece[2]) == 60
    assert shape_error(refined) < 0.6 * shape_error(piece)  # 0.032 -> 0.013 m here
