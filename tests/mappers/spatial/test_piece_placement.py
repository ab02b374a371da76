"""Placing a rigid piece of the stereo start by its placed points and pose-free distances
(:func:`mappers.spatial.registration._fit_piece`): unique fits are placed, ambiguous ones refused."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from mappers.spatial.registration import _fit_piece


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
