"""Sensors against brute-force geometry written out object by object and ray by ray."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfmdr_gym.sim import sensors

R = 0.024  # object radius
THRESHOLD = math.radians(5.0)


def non_overlapping(rng, m, spread, min_sep, robot_clear, centre=(0.0, 0.0)):
    """m centres within +-spread of centre, pairwise >= min_sep, all >= robot_clear from centre."""
    pts: list[np.ndarray] = []
    while len(pts) < m:
        p = np.asarray(centre) + rng.uniform(-spread, spread, 2)
        if np.hypot(*(p - centre)) < robot_clear:
            continue
        if all(np.hypot(*(p - q)) >= min_sep for q in pts):
            pts.append(p)
    return np.array(pts)


def brute_visibility(pose, objects, radius, threshold, occlusion):
    """Object by object: visual angle 2 asin(r/d) > threshold, and no other disc meets the sight line."""
    x, y = pose[0], pose[1]
    out = np.zeros(len(objects), dtype=np.int8)
    for j, (cx, cy) in enumerate(objects):
        d = math.hypot(cx - x, cy - y)
        angle = 2.0 * math.asin(min(radius / d, 1.0))
        if not angle > threshold:
            continue
        blocked = False
        if occlusion:
            for k, (kx, ky) in enumerate(objects):
                if k == j:
                    continue
                # distance from k's centre to the segment robot -> j's centre
                sx, sy = cx - x, cy - y
                t = ((kx - x) * sx + (ky - y) * sy) / (sx * sx + sy * sy)
                t = min(max(t, 0.0), 1.0)
                px, py = x + t * sx, y + t * sy
                if math.hypot(kx - px, ky - py) < radius:
                    blocked = True
                    break
        out[j] = 0 if blocked else 1
    return out


def brute_proximity(pose, objects, radius, half, n_rays, max_range):
    x, y, h = pose
    out = np.empty(n_rays)
    for k in range(n_rays):
        a = h + 2.0 * math.pi * k / n_rays
        ux, uy = math.cos(a), math.sin(a)
        best = max_range
        for wall_t in (
            (half - x) / ux if ux > 1e-15 else math.inf,
            (-half - x) / ux if ux < -1e-15 else math.inf,
            (half - y) / uy if uy > 1e-15 else math.inf,
            (-half - y) / uy if uy < -1e-15 else math.inf,
        ):
            best = min(best, wall_t)
        for cx, cy in objects:
            # |p + s u - c|^2 = r^2, smallest s > 0
            fx, fy = x - cx, y - cy
            b = fx * ux + fy * uy
            c = fx * fx + fy * fy - radius * radius
            disc = b * b - c
            if disc >= 0.0:
                s = -b - math.sqrt(disc)
                if s > 0.0:
                    best = min(best, s)
        out[k] = best
    return out


# ----------------------------------------------------------------------------- visibility
@pytest.mark.parametrize("occlusion", [True, False])
def test_visibility_matches_brute_force_in_crowded_scenes(occlusion):
    rng = np.random.default_rng(0)
    n_occluded = n_visible = 0
    for _ in range(120):
        # A crowd around the robot so that occlusion and the 5-degree threshold both matter.
        objects = non_overlapping(rng, 25, 0.7, 2 * R + 1e-3, R + 0.05)
        pose = np.array([0.0, 0.0, rng.uniform(-math.pi, math.pi)])
        fast = sensors.visibility(pose, objects, R, THRESHOLD, occlusion)
        slow = brute_visibility(pose, objects, R, THRESHOLD, occlusion)
        np.testing.assert_array_equal(fast, slow)
        assert fast.dtype == np.int8
        n_visible += int(slow.sum())
        if occlusion:
            n_occluded += int((brute_visibility(pose, objects, R, THRESHOLD, False) - slow).sum())
    assert n_visible > 100
    if occlusion:
        assert n_occluded > 20  # the scenes really did exercise occlusion


def test_visibility_threshold_distance():
    d_vis = sensors.visibility_distance(R, THRESHOLD)
    assert d_vis == pytest.approx(0.550, abs=1e-3)  # paper §4.3: visible below about 0.550 m for r = 24 mm
    objects = np.array([[d_vis * 0.999, 0.0], [0.0, d_vis * 1.001]])
    np.testing.assert_array_equal(sensors.visibility((0.0, 0.0, 0.0), objects, R, THRESHOLD), [1, 0])


def test_visibility_occluder_in_line_hides_the_far_object_only():
    objects = np.array([[0.2, 0.0], [0.4, 0.0], [0.4, 0.3]])
    vis = sensors.visibility((0.0, 0.0, 1.0), objects, R, THRESHOLD, True)
    np.testing.assert_array_equal(vis, [1, 0, 1])
    # Shift the occluder sideways by just more than r: the far object reappears.
    objects[0, 1] = R * 2.0 * 1.001  # perpendicular distance to the sight line (y = 0) > r
    np.testing.assert_array_equal(sensors.visibility((0.0, 0.0, 1.0), objects, R, THRESHOLD), [1, 1, 1])
    # Behind the robot, an object never occludes.
    objects = np.array([[-0.2, 0.0], [0.4, 0.0]])
    np.testing.assert_array_equal(sensors.visibility((0.0, 0.0, 0.0), objects, R, THRESHOLD), [1, 1])


def test_visibility_at_scale_matches_brute_force():
    rng = np.random.default_rng(1)
    objects = non_overlapping(rng, 500, 3.9, 0.2, 0.0)
    for _ in range(5):
        pose = np.array([*rng.uniform(-3.5, 3.5, 2), 0.0])
        if np.hypot(*(objects - pose[:2]).T).min() < 0.08:
            continue
        np.testing.assert_array_equal(
            sensors.visibility(pose, objects, R, THRESHOLD, True),
            brute_visibility(pose, objects, R, THRESHOLD, True),
        )


# ----------------------------------------------------------------------------- bearing, range
def test_bearing_sign_convention():
    # Heading along +x: an object at +y is to the left -> theta = +pi/2 -> sin > 0.
    b = sensors.bearing((0.0, 0.0, 0.0), [[0.0, 1.0], [0.0, -1.0], [2.0, 0.0], [-1.0, 0.0]])
    np.testing.assert_allclose(b, [[0, 1], [0, -1], [1, 0], [-1, 0]], atol=1e-12)
    # Heading along +y: left is -x.
    b = sensors.bearing((1.0, 1.0, math.pi / 2), [[0.0, 1.0], [2.0, 1.0], [1.0, 3.0]])
    np.testing.assert_allclose(b, [[0, 1], [0, -1], [1, 0]], atol=1e-12)


def test_bearing_matches_atan2():
    rng = np.random.default_rng(2)
    for _ in range(20):
        pose = rng.uniform(-1, 1, 3) * (1, 1, math.pi)
        objects = rng.uniform(-1.2, 1.2, (30, 2))
        got = sensors.bearing(pose, objects)
        theta = np.arctan2(objects[:, 1] - pose[1], objects[:, 0] - pose[0]) - pose[2]
        np.testing.assert_allclose(got, np.c_[np.cos(theta), np.sin(theta)], atol=1e-12)


def test_ranges_and_max_range():
    objects = np.array([[3.0, 4.0], [0.3, 0.0]])
    np.testing.assert_allclose(sensors.ranges((0.0, 0.0, 1.0), objects), [5.0, 0.3])
    np.testing.assert_allclose(sensors.ranges((0.0, 0.0, 1.0), objects, max_range=1.0), [0.0, 0.3])
    with pytest.raises(ValueError, match="max_range"):
        sensors.ranges((0.0, 0.0, 1.0), objects, max_range=-1.0)


# ----------------------------------------------------------------------------- proximity
def test_proximity_matches_brute_force():
    rng = np.random.default_rng(3)
    half = 1.25
    hits = 0
    for _ in range(150):
        objects = non_overlapping(rng, 30, 1.2, 0.1, 0.0)
        pose = np.array([*rng.uniform(-1.2, 1.2, 2), rng.uniform(-math.pi, math.pi)])
        if np.hypot(*(objects - pose[:2]).T).min() < R + 0.05:
            continue
        for n_rays in (16, 7):
            fast = sensors.proximity(pose, objects, R, half, n_rays, 0.5)
            slow = brute_proximity(pose, objects, R, half, n_rays, 0.5)
            np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12)
            hits += int((slow < 0.5).sum())
    assert hits > 200


def test_proximity_ray_zero_points_ahead_and_rays_go_anticlockwise():
    # Wall x = 1.25 is 0.25 ahead of a robot at x = 1.0 facing +x; y = 1.25 is 0.4 to its left.
    prox = sensors.proximity((1.0, 0.85, 0.0), np.zeros((0, 2)), R, 1.25, 4, 1.0)
    np.testing.assert_allclose(prox, [0.25, 0.4, 1.0, 1.0])
    # Facing +y, an object straight ahead reads its distance minus the radius.
    prox = sensors.proximity((0.0, 0.0, math.pi / 2), [[0.0, 0.3]], R, 1.25, 4, 0.5)
    np.testing.assert_allclose(prox, [0.3 - R, 0.5, 0.5, 0.5])


def test_pure_functions_check_their_inputs():
    with pytest.raises(ValueError, match="pose"):
        sensors.bearing((0.0, 0.0), [[1.0, 1.0]])
    with pytest.raises(ValueError, match="objects"):
        sensors.visibility((0.0, 0.0, 0.0), [1.0, 1.0], R, THRESHOLD)
    with pytest.raises(ValueError, match="visual_angle"):
        sensors.visibility((0.0, 0.0, 0.0), [[1.0, 1.0]], R, 4.0)
    with pytest.raises(ValueError, match="n_rays"):
        sensors.ray_directions(0)
