"""The 3-D camera's geometry: its frame, rays and ranges, field of view, range and occlusion."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfmdr_gym.sim import view3d
from lfmdr_gym.sim.view3d import CameraModel

R = 0.024  # post radius


def _ray(pose, tag, height=0.3, pitch_deg=0.0):
    centre, rot = view3d.camera_frame(pose, height, math.radians(pitch_deg))
    rays, dist = view3d.rays_and_ranges(centre, rot, np.array([tag], dtype=float))
    return rays[0], dist[0]


def test_frame_axes_z_forward_x_right_y_down():
    ahead, d = _ray((0.0, 0.0, 0.0), (2.0, 0.0, 0.3))
    np.testing.assert_allclose(ahead, (0, 0, 1), atol=1e-12)
    assert d == pytest.approx(2.0)
    left, _ = _ray((0.0, 0.0, 0.0), (1.0, 1.0, 0.3))  # to the robot's left: x < 0 (image left)
    np.testing.assert_allclose(left, (-math.sqrt(0.5), 0, math.sqrt(0.5)), atol=1e-12)
    up, _ = _ray((0.0, 0.0, 0.0), (1.0, 0.0, 1.3))  # above: y < 0 (image up)
    np.testing.assert_allclose(up, (0, -math.sqrt(0.5), math.sqrt(0.5)), atol=1e-12)
    # heading pi/2 (facing +y): a tag at +y straight ahead, one at +x to the right
    np.testing.assert_allclose(_ray((0.0, 0.0, math.pi / 2), (0.0, 1.5, 0.3))[0], (0, 0, 1), atol=1e-12)
    np.testing.assert_allclose(_ray((0.0, 0.0, math.pi / 2), (1.0, 0.0, 0.3))[0], (1, 0, 0), atol=1e-12)


def test_pitch_tilts_the_optical_axis_up():
    tag = (1.0, 0.0, 0.3 + math.tan(math.radians(25.0)))  # 25 degrees above the horizontal
    np.testing.assert_allclose(_ray((0.0, 0.0, 0.0), tag, pitch_deg=25.0)[0], (0, 0, 1), atol=1e-12)
    level = _ray((0.0, 0.0, 0.0), (1.0, 0.0, 0.3), pitch_deg=25.0)[0]  # level: below the axis
    np.testing.assert_allclose(level, (0, math.sin(math.radians(25)), math.cos(math.radians(25))),
                               atol=1e-12)


def test_rotation_is_proper_and_rays_invert_to_the_tags():
    rng = np.random.default_rng(0)
    for _ in range(20):
        pose = rng.uniform(-1, 1, 3) * (1, 1, math.pi)
        centre, rot = view3d.camera_frame(pose, 0.4, rng.uniform(-1.2, 1.2))
        np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(rot) == pytest.approx(1.0)
        tags = rng.uniform(-1, 1, (7, 3))
        rays, dist = view3d.rays_and_ranges(centre, rot, tags)
        np.testing.assert_allclose(np.linalg.norm(rays, axis=1), 1.0, rtol=1e-12)
        np.testing.assert_allclose(centre + dist[:, None] * (rays @ rot), tags, atol=1e-12)


def test_field_of_view_and_range_limit():
    cam = CameraModel(height=0.3, pitch_deg=0.0, hfov_deg=60.0, vfov_deg=40.0, max_range=2.0)
    pose = (0.0, 0.0, 0.0)
    h30, v20 = math.tan(math.radians(30.0)), math.tan(math.radians(20.0))
    tags = np.array([
        (1.0, 0.0, 0.3),                      # ahead: in view
        (1.0, -0.99 * h30, 0.3),              # just inside the right edge
        (1.0, -1.01 * h30, 0.3),              # just outside it
        (1.0, 0.0, 0.3 + 0.99 * v20),         # just inside the top edge
        (1.0, 0.0, 0.3 + 1.01 * v20),         # just outside it
        (-1.0, 0.0, 0.3),                     # behind
        (2.1, 0.0, 0.3),                      # ahead, beyond the range limit
        (1.9, 0.0, 0.3),                      # ahead, within it
    ])
    rays, dist, seen = view3d.view(pose, tags, -np.ones(len(tags), int), np.zeros((0, 2)), R, cam)
    assert seen.tolist() == [True, True, False, True, False, False, False, True]
    no_limit = CameraModel(height=0.3, pitch_deg=0.0, hfov_deg=60.0, vfov_deg=40.0, max_range=None)
    assert view3d.view(pose, tags, -np.ones(len(tags), int), np.zeros((0, 2)), R, no_limit)[2][6]


def test_posts_hide_tags_behind_them_but_not_their_own():
    posts = np.array([(1.0, 0.0), (2.0, 0.0), (1.0, 0.3), (3.0, 0.0)])
    tags = np.array([
        (2.0, 0.0, 1.5),    # on post 1, behind post 0: hidden (whatever the height)
        (1.0, 0.0, 0.2),    # on post 0 itself: not hidden by its own post
        (1.0, 0.3, 1.0),    # on post 2, clear line of sight
        (0.5, 0.0, 1.0),    # free tag before post 0: post 0 lies beyond it, not hidden
        (2.0, R * 3, 0.5),  # wide of post 0's disc... but post 1 (nearby) is beyond it: clear
    ])
    hosts = np.array([1, 0, 2, -1, -1])
    hidden = view3d.hidden_by_posts((0.0, 0.0), tags, hosts, posts, R)
    assert hidden.tolist() == [True, False, False, False, False]
    # grazing: the line passes just inside / just outside post 0's radius
    inside = np.array([(2.0, 2 * 0.99 * R, 1.0)])
    outside = np.array([(2.0, 2 * 1.01 * R, 1.0)])
    assert view3d.hidden_by_posts((0.0, 0.0), inside, [-1], posts[:1], R)[0]
    assert not view3d.hidden_by_posts((0.0, 0.0), outside, [-1], posts[:1], R)[0]


def test_view_applies_occlusion_only_when_on():
    posts = np.array([(1.0, 0.0), (2.0, 0.0)])
    tags = np.array([(2.0, 0.0, 0.5), (1.0, 0.0, 0.5)])
    hosts = np.array([1, 0])
    on = CameraModel(pitch_deg=0.0, occlusion=True)
    off = CameraModel(pitch_deg=0.0, occlusion=False)
    assert view3d.view((0, 0, 0), tags, hosts, posts, R, on)[2].tolist() == [False, True]
    assert view3d.view((0, 0, 0), tags, hosts, posts, R, off)[2].tolist() == [True, True]


@pytest.mark.parametrize("kwargs, name", [
    ({"height": 0.0}, "camera_height"), ({"pitch_deg": 90.0}, "pitch_deg"),
    ({"hfov_deg": 0.0}, "hfov_deg"), ({"vfov_deg": 180.0}, "vfov_deg"),
    ({"max_range": -1.0}, "max_range"), ({"occlusion": 1}, "occlusion"),
])
def test_camera_model_refuses_bad_values(kwargs, name):
    with pytest.raises(ValueError, match=name):
        CameraModel(**kwargs)


def test_view_refuses_tags_that_are_not_3d():
    with pytest.raises(ValueError, match=r"\(M, 3\)"):
        view3d.view((0, 0, 0), np.zeros((3, 2)), [-1] * 3, np.zeros((0, 2)), R, CameraModel())
