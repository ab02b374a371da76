"""The obstacle map a policy builds from its rings: cylinders fitted to the hits, where a move
stops among them, the walls' bounds, and its use in the even policy's plans."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_even import RANGE, _ring

from lfmdr_gym.exploration.even import EvenPolicy
from lfmdr_gym.exploration.obstacles import ObstacleMap, advance
from lfmdr_gym.exploration.walls import WallFrame

R = 0.024  # the env's objects' radius


def _seen_from(obstacles, poses, discs, half=5.0):
    for x, y, h in poses:
        obstacles.add(_ring(x, y, h, half=half, discs=discs), np.array([x, y, h]))


def _around(cx, cy, n=8, seed=0):
    """n poses 0.15-0.35 m from (cx, cy) on its left half, headings at random."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(0.6 * math.pi, 1.4 * math.pi, n)
    d = rng.uniform(0.15, 0.35, n)
    return np.column_stack([cx + d * np.cos(a), cy + d * np.sin(a), rng.uniform(-3, 3, n)])


def test_hits_from_several_viewpoints_fit_the_cylinder():
    obstacles = ObstacleMap(R, RANGE)
    cyl = (0.3, 0.1, R)
    _seen_from(obstacles, _around(0.3, 0.1), [cyl])
    assert obstacles.n_hits >= 3
    centres = obstacles.centres(np.zeros(2), 1.0)
    assert centres.shape == (1, 2)
    np.testing.assert_allclose(centres[0], cyl[:2], atol=1e-6)  # exact rings: an exact fit
    # hits beyond the reach are left out; reset forgets them all
    assert obstacles.centres(np.array([3.0, 3.0]), 1.0).shape == (0, 2)
    obstacles.reset()
    assert obstacles.n_hits == 0 and obstacles.centres(np.zeros(2), 1.0).shape == (0, 2)


def test_a_lone_hit_or_a_cluster_off_any_circle_stands_for_a_cylinder_behind_each_hit():
    obstacles = ObstacleMap(R, RANGE)
    ring = np.full(32, RANGE)
    ring[0] = 0.3  # one ray ahead hits something at 0.3 m
    obstacles.add(ring, np.zeros(3))
    np.testing.assert_allclose(obstacles.centres(np.zeros(2), 1.0), [[0.3 + R, 0.0]])
    # two touching cylinders: their hits link into one cluster that fits no single circle
    two = ObstacleMap(R, RANGE)
    discs = [(0.3, 0.0, R), (0.3, 0.05, R)]
    _seen_from(two, [(0.0, 0.0, 0.0), (0.05, 0.2, -0.5), (0.05, -0.2, 0.5), (0.0, 0.03, 0.2)], discs)
    centres = two.centres(np.zeros(2), 1.0)
    assert len(centres) == two.n_hits > 2  # one per hit...
    for c in centres:  # ...each a radius behind its hit: within a diameter of a true centre
        assert min(math.dist(c, d[:2]) for d in discs) < 2 * R


def test_skipped_rays_and_dropped_points_are_left_out():
    obstacles = ObstacleMap(R, RANGE)
    ring = np.full(32, RANGE)
    ring[[0, 8]] = 0.3
    obstacles.add(ring, np.zeros(3), skip=np.arange(32) == 8)
    assert obstacles.n_hits == 1
    assert obstacles.centres(np.zeros(2), 1.0, drop=lambda p: p[:, 0] > 0.2).shape == (0, 2)


def test_advance_stops_at_the_first_predicted_contact():
    centres = np.array([[1.0, 0.0]])
    start = np.zeros((4, 2))
    units = np.array([[1.0, 0.0], [0.0, 1.0], [math.cos(0.3), math.sin(0.3)], [-1.0, 0.0]])
    went = advance(start, units, 2.0, centres, 0.1)
    assert went[0] == pytest.approx(0.9)  # head on: stops at the reach
    assert went[1] == 2.0  # sideways: never closer than 1 m
    assert went[2] == 2.0  # passes 1 m x sin(0.3) = 0.30 m from the centre: clear
    assert went[3] == 2.0  # away from it
    # a bound p_x <= 0.5 (normal -x, offset -0.5): the move along +x stops there
    went = advance(start[:1], units[:1], 2.0, np.zeros((0, 2)), 0.1, [(np.array([-1.0, 0.0]), -0.5)])
    assert went[0] == pytest.approx(0.5)
    # inside the reach already: moving further in is stopped at once, moving out is not
    near = np.array([[0.95, 0.0], [0.95, 0.0]])
    went = advance(near, np.array([[1.0, 0.0], [-1.0, 0.0]]), 0.2, centres, 0.1)
    assert went.tolist() == [0.0, 0.2]


def test_wall_frame_bounds_the_centre_and_finds_hits_on_walls():
    frame = WallFrame(2.5, 0.05, RANGE, sightings=1)
    assert frame.halfplanes() == [] and not frame.on_walls(np.zeros((1, 2)), 0.01).any()
    frame.observe(_ring(1.0, 0.0, 0.0), np.array([1.0, 0.0, 0.0]))  # the wall x = 1.25
    bounds = frame.halfplanes()
    assert len(bounds) == 2  # one axis seen: its two walls
    inside, outside = np.array([1.19, 0.0]), np.array([1.21, 0.0])  # centre bound 1.25 - 0.05
    assert all(n @ inside >= o for n, o in bounds)
    assert not all(n @ outside >= o for n, o in bounds)
    on = frame.on_walls(np.array([[1.25, 0.3], [-1.255, 0.0], [1.2, 0.0]]), 0.01)
    assert on.tolist() == [True, True, False]


def test_even_plans_stop_at_the_cylinders_it_has_seen():
    policy = EvenPolicy(fan=3, lookahead=1, seed=0)
    disc = (0.45, 0.0, R)
    for x, y, h in _around(*disc[:2]):  # the hits of eight viewpoints near it
        policy.odometry = np.array([x, y, h])
        policy._remember(_ring(x, y, h, half=5.0, discs=[disc]))
    policy.odometry = np.array([0.15, 0.0, 0.0])
    np.testing.assert_allclose(policy.obstacles.centres(np.zeros(2), 1.0), [disc[:2]], atol=1e-6)
    turns = np.array([-policy.max_turn, 0.0, policy.max_turn])
    _, wx, wy, blocked = policy._plans(np.full(32, RANGE), turns, policy._later)
    straight = 3 * 1 + 1  # first move straight ahead, then straight again
    stop = disc[0] - R - policy.robot_radius - policy.stop_margin
    assert not blocked[straight, 0] and blocked[straight, 1]
    assert wx[straight, 1] == pytest.approx(stop) and wy[straight, 1] == pytest.approx(0.0)
    assert not blocked[0].any()  # turned away: both moves full


@pytest.mark.parametrize("args, kwargs, name", [
    ((-0.01, RANGE), {}, "obstacle_radius"), ((R, 0.0), {}, "proximity_range"),
    ((R, RANGE), {"link": -0.1}, "link"), ((R, RANGE), {"tolerance": float("nan")}, "tolerance"),
])
def test_obstacle_map_refuses_bad_arguments(args, kwargs, name):
    with pytest.raises(ValueError, match=name):
        ObstacleMap(*args, **kwargs)
