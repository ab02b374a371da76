"""Pixel <-> ray maths of a ROS CameraInfo camera (lfmdr_gym/datasets/ros_intrinsics.py)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from lfmdr_gym.datasets.ros_intrinsics import (
    CameraIntrinsics,
    IntrinsicsError,
    pixels_to_rays,
    rays_to_pixels,
)

K = np.array([[600.0, 0.0, 320.0], [0.0, 610.0, 240.0], [0.0, 0.0, 1.0]])
PLUMB_BOB = CameraIntrinsics(K, "plumb_bob", (-0.3, 0.1, 0.001, -0.002, -0.02))
FISHEYE = CameraIntrinsics(K, "equidistant", (-0.02, 0.004, -0.001, 0.0002))
RATIONAL = CameraIntrinsics(K, "rational_polynomial", (0.5, 0.1, 0.001, -0.002, -0.02, 0.4, 0.05, 0.01))


def _rays(n: int = 500, half: float = 0.5) -> np.ndarray:
    rng = np.random.default_rng(3)
    return np.column_stack([rng.uniform(-half, half, (n, 2)), np.ones(n)])


@pytest.mark.parametrize("camera", [CameraIntrinsics(K), PLUMB_BOB, RATIONAL, FISHEYE],
                         ids=["pinhole", "plumb_bob", "rational", "equidistant"])
def test_pixels_of_rays_map_back_to_the_rays(camera):
    rays = _rays()
    back = pixels_to_rays(rays_to_pixels(rays * 2.5, camera), camera)
    np.testing.assert_allclose(back, rays, atol=1e-12)


def test_a_pinhole_camera_projects_by_K_alone():
    uv = rays_to_pixels([[0.1, -0.2, 1.0], [0.0, 0.0, 4.0]], CameraIntrinsics(K))
    np.testing.assert_allclose(uv, [[320 + 60, 240 - 122], [320, 240]], atol=1e-12)


def test_distortion_moves_the_pixel_as_the_model_says():
    k1 = -0.2
    cam = CameraIntrinsics(K, "plumb_bob", (k1, 0.0, 0.0, 0.0, 0.0))
    x = 0.4  # on the image's horizontal axis: xd = x (1 + k1 x^2)
    uv = rays_to_pixels([[x, 0.0, 1.0]], cam)
    assert uv[0, 0] == pytest.approx(320 + 600 * x * (1 + k1 * x * x), abs=1e-9)


def test_the_fisheye_bends_the_angle_off_the_axis():
    k1 = FISHEYE.D[0]
    theta = 0.9  # 52 degrees off the axis, in the image's vertical plane
    uv = rays_to_pixels([[0.0, math.tan(theta), 1.0]], FISHEYE)
    poly = 1 + sum(k * theta ** (2 * i + 2) for i, k in enumerate(FISHEYE.D))
    assert uv[0, 1] == pytest.approx(240 + 610 * theta * poly, abs=1e-9)
    assert uv[0, 0] == pytest.approx(320, abs=1e-12) and k1 != 0
    wide = np.column_stack([np.tan(np.linspace(0, 1.4, 30)), np.zeros(30), np.ones(30)])
    np.testing.assert_allclose(pixels_to_rays(rays_to_pixels(wide, FISHEYE), FISHEYE), wide,
                               rtol=1e-10)


def test_a_fisheye_pixel_past_90_degrees_is_refused():
    # theta_d of 1.75 rad is only reached past theta = pi/2 with these coefficients
    with pytest.raises(IntrinsicsError, match=r"pixel 0 .* 90 degrees or more off the axis"):
        pixels_to_rays([[320.0 + 600 * 1.75, 240.0]], CameraIntrinsics(K, "equidistant",
                                                                        (0.0, 0.0, 0.0, 1e-9)))


def test_a_pixel_beyond_the_fold_of_the_lens_model_is_refused():
    # with this strong barrel distortion r -> r s(r) turns back near r = 1.5; a far pixel
    # has a spurious preimage beyond the fold, which must not be returned as a ray
    with pytest.raises(IntrinsicsError, match=r"pixel 1 \[5000.0, 5000.0\] cannot be undistorted"):
        pixels_to_rays([[320.0, 240.0], [5000.0, 5000.0]], PLUMB_BOB)


def test_from_camera_info_reads_ros1_and_ros2_field_names_and_rectified_P():
    P = np.array([[500.0, 0.0, 300.0, 0.0], [0.0, 505.0, 250.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    D = (-0.1, 0.01, 0.0, 0.0, 0.0)
    ros1 = SimpleNamespace(K=K.ravel(), D=np.array(D), P=P.ravel(), distortion_model="plumb_bob")
    ros2 = SimpleNamespace(k=K.ravel(), d=np.array(D), p=P.ravel(), distortion_model="plumb_bob")
    for msg in (ros1, ros2):
        cam = CameraIntrinsics.from_camera_info(msg)
        np.testing.assert_array_equal(cam.K, K)
        assert cam.D == D and cam.distortion_model == "plumb_bob"
        rect = CameraIntrinsics.from_camera_info(msg, rectified=True)
        np.testing.assert_array_equal(rect.K, P[:, :3])
        assert not rect.distorted


@pytest.mark.parametrize("K_bad, match", [
    (np.zeros((3, 3)), "not calibrated"),
    (np.eye(2), "3x3"),
    (np.array([[600.0, 0, 320], [0, 610, 240], [0, 0, np.nan]]), "finite"),
])
def test_bad_camera_matrices_are_refused(K_bad, match):
    with pytest.raises(IntrinsicsError, match=match):
        CameraIntrinsics(K_bad)


def test_unknown_or_miscounted_distortion_is_refused():
    with pytest.raises(IntrinsicsError, match="'fov' is not handled"):
        CameraIntrinsics(K, "fov", (0.1,))
    with pytest.raises(IntrinsicsError, match="plumb_bob needs 5"):
        CameraIntrinsics(K, "plumb_bob", (0.1, 0.0, 0.0, 0.0))
    # all-zero coefficients are no distortion, whatever the model's name
    assert not CameraIntrinsics(K, "fov", (0.0,)).distorted


def test_rays_behind_the_camera_and_bad_pixels_are_refused():
    with pytest.raises(IntrinsicsError, match=r"ray 1 .* not in front"):
        rays_to_pixels([[0.0, 0.0, 1.0], [0.1, 0.0, -1.0]], PLUMB_BOB)
    with pytest.raises(IntrinsicsError, match="pixel 0 is not finite"):
        pixels_to_rays([[np.nan, 1.0]], PLUMB_BOB)
    with pytest.raises(IntrinsicsError, match=r"\(n, 2\)"):
        pixels_to_rays([1.0, 2.0], PLUMB_BOB)
