"""The pymunk world: layouts, anchors, user layouts, argument checks and blocked moves."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfmdr_gym.sim import world as world_module
from lfmdr_gym.sim.world import BACKOFF, CONTACT_MARGIN, Layout, World, wrap_angle


def built(world: World, positions, pose, anchors=None) -> World:
    pos = np.asarray(positions, dtype=float)
    ids = np.arange(3) if anchors is None else np.asarray(anchors)
    world.build(Layout(pos, ids, np.asarray(pose, dtype=float)))
    return world


def test_random_layout_respects_clearances_and_is_reproducible():
    w = World()
    lay = w.layout(np.random.default_rng(5))
    pos = lay.object_positions
    assert pos.shape == (50, 2)
    d = np.hypot(*(pos[:, None] - pos[None]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    assert d.min() >= 0.048 + 0.15
    assert np.abs(pos).max() <= 1.25 - 0.024 - 0.15
    # start pose clear of everything
    x, y, h = lay.robot_pose
    assert np.hypot(*(pos - (x, y)).T).min() > 0.024 + 0.05
    assert max(abs(x), abs(y)) < 1.25 - 0.05 and -math.pi < h <= math.pi
    again = w.layout(np.random.default_rng(5))
    np.testing.assert_array_equal(again.object_positions, pos)
    np.testing.assert_array_equal(again.robot_pose, lay.robot_pose)
    other = w.layout(np.random.default_rng(6))
    assert not np.array_equal(other.object_positions, pos)


def test_corner_anchors_are_the_objects_nearest_each_corner():
    w = World()
    for seed in range(5):
        lay = w.layout(np.random.default_rng(seed))
        for corner, anchor in zip([(-1.25, -1.25), (1.25, -1.25), (1.25, 1.25), (-1.25, 1.25)],
                                  lay.anchor_ids, strict=True):
            dists = [math.dist(corner, p) for p in lay.object_positions]
            assert anchor == int(np.argmin(dists))


def test_more_anchors_and_random_anchors():
    w = World(n_anchors=8)
    targets = w.anchor_targets()
    np.testing.assert_allclose(targets[::2], [(-1.25, -1.25), (1.25, -1.25), (1.25, 1.25), (-1.25, 1.25)])
    lay = w.layout(np.random.default_rng(0))
    assert len(set(lay.anchor_ids.tolist())) == 8
    w = World(anchors="random", n_anchors=5)
    a = w.layout(np.random.default_rng(1)).anchor_ids
    b = w.layout(np.random.default_rng(1)).anchor_ids
    np.testing.assert_array_equal(a, b)
    assert len(set(a.tolist())) == 5


def test_collinear_anchors_are_refused():
    w = World(n_objects=5, object_clearance=0.0)
    line = np.array([[x, 0.0] for x in (-1.0, -0.5, 0.0, 0.5, 1.0)])
    with pytest.raises(ValueError, match="collinear"):
        w.layout(np.random.default_rng(0), {"object_positions": line})
    w = World(n_objects=5, anchors="random", n_anchors=3, object_clearance=0.0)
    with pytest.raises(ValueError, match="n_anchors"):
        w.layout(np.random.default_rng(0), {"object_positions": line})
    ok = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0], [0.0, 0.0]])
    with pytest.raises(ValueError, match="anchor_ids"):
        w.layout(np.random.default_rng(0), {"object_positions": ok, "anchor_ids": [0, 2, 4]})


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"n_objects": 2}, "n_objects"),
        ({"n_objects": 50.0}, "n_objects"),
        ({"n_objects": 200}, "n_objects"),  # more than fit with the clearances
        ({"arena_size": -2.5}, "arena_size"),
        ({"arena_size": float("nan")}, "arena_size"),
        ({"object_diameter": 0.0}, "object_diameter"),
        ({"object_diameter": -0.048}, "object_diameter"),
        ({"robot_radius": -0.05}, "robot_radius"),
        ({"robot_radius": 2.0}, "robot_radius"),
        ({"object_clearance": -0.1}, "object_clearance"),
        ({"wall_clearance": -0.1}, "wall_clearance"),
        ({"wall_clearance": 2.0}, "wall_clearance"),
        ({"n_anchors": 2}, "n_anchors"),
        ({"n_anchors": 60}, "n_anchors"),
        ({"anchors": "nearest"}, "anchors"),
    ],
)
def test_bad_arguments_raise_naming_them(kwargs, name):
    with pytest.raises(ValueError, match=name):
        World(**kwargs)


def test_check_real_states_the_bounds():
    from lfmdr_gym.checks import check_real

    with pytest.raises(ValueError, match=r"x must be > 0, got 0"):
        check_real("x", 0, low=0.0, low_open=True)
    with pytest.raises(ValueError, match=r"x must be >= 0, got -1"):
        check_real("x", -1, low=0.0)
    with pytest.raises(ValueError, match=r"x must be < 2, got 2"):
        check_real("x", 2, high=2.0, high_open=True)
    with pytest.raises(ValueError, match=r"x must be in \(0, 1\], got 1.5"):
        check_real("x", 1.5, low=0.0, low_open=True, high=1.0)
    with pytest.raises(ValueError, match="x must be a finite number, got True"):
        check_real("x", True, low=0.0)


def test_layout_search_failure_names_n_objects(monkeypatch):
    # Allow a layout denser than random placement can reach: the search must give up clearly.
    monkeypatch.setattr(world_module, "RANDOM_COVERAGE", 0.95)
    w = World(n_objects=60, arena_size=1.6)
    with pytest.raises(ValueError, match="n_objects=60"):
        w.layout(np.random.default_rng(0))


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"object_positions": np.zeros((49, 2))}, "object_positions"),
        ({"object_positions": np.full((50, 2), np.nan)}, "object_positions"),
        ({"anchor_ids": [0, 1]}, "anchor_ids"),
        ({"anchor_ids": [0, 1, 1, 2]}, "anchor_ids"),
        ({"anchor_ids": [0, 1, 50]}, "anchor_ids"),
        ({"anchor_ids": [0.0, 1.0, 2.0]}, "anchor_ids"),
        ({"robot_pose": [0.0, 0.0]}, "robot_pose"),
        ({"robot_pose": [1.24, 0.0, 0.0]}, "robot_pose"),
        ({"seed": 3}, "unknown reset option"),
    ],
)
def test_bad_user_layouts_raise(options, match):
    with pytest.raises(ValueError, match=match):
        World().layout(np.random.default_rng(0), options)


def test_user_layout_checks_overlap_walls_and_robot():
    w = World(n_objects=3, n_anchors=3, object_clearance=0.0)
    good = np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 0.5]])
    lay = w.layout(np.random.default_rng(0), {"object_positions": good, "robot_pose": [-0.5, -0.5, 4.0]})
    np.testing.assert_array_equal(lay.object_positions, good)
    assert lay.robot_pose[2] == pytest.approx(4.0 - 2 * math.pi)
    with pytest.raises(ValueError, match="overlap"):
        w.layout(np.random.default_rng(0), {"object_positions": good * 0.01})
    with pytest.raises(ValueError, match="inside the walls"):
        w.layout(np.random.default_rng(0), {"object_positions": good + 1.0})
    with pytest.raises(ValueError, match="overlaps object 1"):
        w.layout(np.random.default_rng(0), {"object_positions": good, "robot_pose": [0.45, 0.0, 0.0]})


def test_wrap_angle_range():
    for a in (-math.pi, math.pi, 3 * math.pi, -3 * math.pi, 0.0, -1e-17, 7.0, -7.0):
        w = wrap_angle(a)
        assert -math.pi < w <= math.pi
        assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-12)
        assert math.isclose(math.sin(w), math.sin(a), abs_tol=1e-12)


# ----------------------------------------------------------------------------- moves
OBJECTS = [[0.0, 0.0], [0.8, 0.8], [-0.8, 0.8]]
CONTACT = 0.024 + 0.05


def clearance(w: World) -> float:
    """Smallest gap between the robot's disc and any object or wall."""
    d_obj = np.hypot(*(w.object_positions - (w.x, w.y)).T).min() - CONTACT
    d_wall = w.arena_half - w.robot_radius - max(abs(w.x), abs(w.y))
    return min(d_obj, d_wall)


def test_free_move_turns_then_advances():
    w = built(World(n_objects=3, n_anchors=3), OBJECTS, [-0.5, -0.5, 0.0])
    assert w.move(math.pi / 4, 0.2) is False
    np.testing.assert_allclose(w.pose, [-0.5 + 0.2 / math.sqrt(2), -0.5 + 0.2 / math.sqrt(2), math.pi / 4])
    assert tuple(w.body.position) == pytest.approx((w.x, w.y))


def test_head_on_move_stops_just_short_of_an_object():
    w = built(World(n_objects=3, n_anchors=3), OBJECTS, [-0.2, 0.0, 0.0])
    assert w.move(0.0, 0.2) is True
    assert w.x == pytest.approx(-CONTACT - BACKOFF, abs=1e-12)
    assert w.y == 0.0
    # Pushing again does not move it, and it never overlaps.
    for _ in range(5):
        assert w.move(0.0, 0.2) is True
        assert clearance(w) >= CONTACT_MARGIN


def test_grazing_and_wall_moves_keep_a_gap():
    # Robot passing the object with its edge a hair's breadth inside the contact distance.
    w = built(World(n_objects=3, n_anchors=3), OBJECTS, [-0.3, CONTACT - 1e-7, 0.0])
    assert w.move(0.0, 0.6) is True
    assert w.x < 0.0 and clearance(w) >= CONTACT_MARGIN
    # ... and a hair's breadth outside: it passes.
    w = built(World(n_objects=3, n_anchors=3), OBJECTS, [-0.3, CONTACT + 1e-7, 0.0])
    assert w.move(0.0, 0.6) is False and w.x == pytest.approx(0.3)
    # Into the wall at a shallow angle, repeatedly.
    w = built(World(n_objects=3, n_anchors=3), OBJECTS, [-1.1, -1.17, -0.05])
    blocked = [w.move(0.0, 0.2) for _ in range(20)]
    assert blocked[:2] == [False, False] and all(blocked[3:])
    assert clearance(w) >= CONTACT_MARGIN
    assert w.y + 1.25 - 0.05 < 1e-4  # it did reach the wall
    # The swept disc (not just its centre line) is checked: a wall the centre line never reaches.
    w = built(World(n_objects=3, n_anchors=3), OBJECTS, [0.0, -1.12, -0.5])
    assert w.move(0.0, 0.2) is True
    assert w.y >= -1.25 + 0.05 + CONTACT_MARGIN


def test_built_says_whether_a_space_exists_without_syncing_the_body():
    w = World(n_objects=3, n_anchors=3)
    assert not w.built and w.space is None
    built(w, [(-0.5, -0.5), (0.5, -0.5), (0.0, 0.5)], (0.0, 0.0, 0.0))
    assert w.built
    w.move(0.0, 0.2)
    assert w._body_stale  # asking `built` must not have moved the pymunk body
    assert w.body.position.x == pytest.approx(0.2)
