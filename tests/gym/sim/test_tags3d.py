"""Tags in 3-D: placement on posts and walls, users' tags, and the anchors' rule."""

from __future__ import annotations

import numpy as np
import pytest

from lfmdr_gym.sim import tags3d


def test_place_tags_on_post_axes_and_walls_within_the_band():
    rng = np.random.default_rng(1)
    posts = rng.uniform(-1, 1, (6, 2))
    tags, hosts = tags3d.place_tags(rng, posts, 1.25, tags_per_post=3, n_wall_tags=40,
                                    heights=(0.2, 1.8), corner_margin=0.1)
    assert tags.shape == (58, 3) and hosts.tolist() == [k for k in range(6) for _ in range(3)] + [-1] * 40
    np.testing.assert_array_equal(tags[:18, :2], np.repeat(posts, 3, axis=0))
    wall = tags[18:]
    on_wall = np.isclose(np.abs(wall[:, :2]), 1.25).any(axis=1)
    assert on_wall.all()
    assert (np.abs(wall[:, :2]) <= 1.25 + 1e-12).all()
    assert (np.sort(np.abs(wall[:, :2]), axis=1)[:, 0] <= 1.15 + 1e-12).all()  # corner margin
    assert ((tags[:, 2] >= 0.2) & (tags[:, 2] <= 1.8)).all()
    sides = {(round(x, 6) == 1.25, round(x, 6) == -1.25, round(y, 6) == 1.25) for x, y, _ in wall}
    assert len(sides) >= 3  # tags on several walls


def test_anchors_lowest_then_farthest_point():
    pts = np.array([(0, 0, 1.0), (0, 0, 0.1), (3, 0, 0.5), (0, 3, 0.5), (1, 1, 2.0), (0.1, 0, 0.2)])
    ids = tags3d.choose_anchors(pts, 4)
    assert ids[0] == 1  # the lowest
    d = np.linalg.norm(pts - pts[1], axis=1)
    assert ids[1] == int(np.argmax(d))
    assert len(set(ids.tolist())) == 4 and not tags3d.coplanar(pts[ids])


def test_anchors_on_one_plane_are_refused():
    flat = np.column_stack((np.random.default_rng(0).uniform(-1, 1, (10, 2)), np.full(10, 0.5)))
    with pytest.raises(ValueError, match="one plane"):
        tags3d.choose_anchors(flat, 5)
    with pytest.raises(ValueError, match="one plane"):
        tags3d.check_anchor_ids([0, 1, 2, 3], flat)
    with pytest.raises(ValueError, match="at least 4"):
        tags3d.check_anchor_ids([0, 1, 2], flat)


def test_user_tags_are_checked():
    posts = np.array([(0.0, 0.0), (0.5, 0.5)])
    good = np.array([(0.0, 0.0, 1.0), (0.5, 0.5, 0.2), (1.25, 0.3, 1.0), (0.2, -0.4, 0.7)])
    pos, hosts = tags3d.check_tags(good, posts, 0.024, 1.25)
    assert hosts.tolist() == [0, 1, -1, -1]
    with pytest.raises(ValueError, match="outside the walls"):
        tags3d.check_tags(good + (0.1, 0, 0), posts, 0.024, 1.25)
    inside = good.copy()
    inside[3] = (0.01, 0.0, 0.5)
    with pytest.raises(ValueError, match="inside post 0"):
        tags3d.check_tags(inside, posts, 0.024, 1.25)
    with pytest.raises(ValueError, match=r"\(M, 3\)"):
        tags3d.check_tags(good[:, :2], posts, 0.024, 1.25)


def test_height_band_is_checked():
    assert tags3d.check_heights((0, 2)) == (0.0, 2.0)
    with pytest.raises(ValueError, match="tag_heights"):
        tags3d.check_heights((1.0, 1.0))
    with pytest.raises(ValueError, match="pair"):
        tags3d.check_heights(2.0)
