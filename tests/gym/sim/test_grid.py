"""The cell grid and the grid layout sampler: same readings and layouts as a scan of every object."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfmdr_gym.env import LFMDREnv
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.sim.grid import CellGrid, sample_separated
from lfmdr_gym.sim.world import GRID_SAMPLER_MIN_OBJECTS, World


@pytest.mark.parametrize("n_objects", [50, 400])
def test_grid_observations_equal_the_full_scan(n_objects):
    size = 2.5 * math.sqrt(n_objects / 50)
    fast, plain = LFMDREnv(n_objects=n_objects, arena_size=size), LFMDREnv(n_objects=n_objects, arena_size=size)
    obs_fast, _ = fast.reset(seed=3)
    obs_plain, _ = plain.reset(seed=3)
    assert fast._grid is not None
    plain._grid = None  # scan every object
    agent = RandomWalkPolicy.for_env(fast, seed=3)
    for _ in range(300):
        action = agent(obs_fast)
        obs_fast, *_ = fast.step(action)
        obs_plain, *_ = plain.step(action)
        for key in obs_fast:
            assert np.array_equal(obs_fast[key], obs_plain[key])
            assert obs_fast[key].dtype == obs_plain[key].dtype


def test_grid_near_holds_every_point_within_reach():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-5, 5, size=(2000, 2))
    grid = CellGrid(pts, 5.0, 0.7)
    for q in rng.uniform(-5, 5, size=(200, 2)):
        near = grid.near(*q)
        within = np.flatnonzero(np.hypot(*(pts - q).T) < 0.7)
        assert set(within) <= set(near.tolist())
        assert np.all(np.diff(near) > 0)
    with pytest.raises(ValueError, match="reach"):
        CellGrid(pts, 5.0, 0.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_grid_sampler_equals_the_dense_one(seed):
    w = World(n_objects=300, arena_size=2.5 * math.sqrt(6))
    dense, _ = w._sample_dense(np.random.default_rng(seed), 300, w.place_half, 10**7)
    grid, _ = sample_separated(np.random.default_rng(seed), 300, w.place_half, w.min_separation, 64, 10**7)
    assert np.array_equal(dense, grid)


def test_large_layout_keeps_clearances():
    m = 2 * GRID_SAMPLER_MIN_OBJECTS
    w = World(n_objects=m, arena_size=2.5 * math.sqrt(m / 50))
    pts = w.sample_objects(np.random.default_rng(5))
    from scipy.spatial import cKDTree

    dist, _ = cKDTree(pts).query(pts, k=2)
    assert dist[:, 1].min() >= w.min_separation
    assert np.abs(pts).max() <= w.place_half


def test_grid_anchors_spread_over_the_arena():
    w = World(n_objects=800, arena_size=2.5 * 4, anchors="grid", n_anchors=16)
    layout = w.layout(np.random.default_rng(1))
    ids = layout.anchor_ids
    assert len(set(ids.tolist())) == 16
    anchors = layout.object_positions[ids]
    # one anchor near each of the 4 x 4 lattice points, so every quarter of the arena holds four
    for sx in (-1, 1):
        for sy in (-1, 1):
            assert np.sum((np.sign(anchors[:, 0]) == sx) & (np.sign(anchors[:, 1]) == sy)) == 4
    np.testing.assert_allclose(anchors, w.grid_targets(), atol=0.5)
