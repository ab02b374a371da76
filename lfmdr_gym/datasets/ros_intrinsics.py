"""A pinhole camera's intrinsics from a ROS ``sensor_msgs/CameraInfo``, and pixel <-> ray maths.

The model is ROS's (and OpenCV's), documented with ``sensor_msgs/CameraInfo``
(https://docs.ros.org/en/api/sensor_msgs/html/msg/CameraInfo.html) and in the camera-calibration
chapter of the OpenCV docs: a point ``(X, Y, Z)`` in the camera's optical frame (z forward, x right,
y down) has normalised coordinates ``x = X/Z, y = Y/Z``; the lens moves them to

    r2 = x^2 + y^2
    s  = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
    xd = x s + 2 p1 x y + p2 (r2 + 2 x^2)
    yd = y s + p1 (r2 + 2 y^2) + 2 p2 x y

(``plumb_bob``: ``D = (k1, k2, p1, p2, k3)``, Brown–Conrady; ``rational_polynomial``: ``D = (k1, k2,
p1, p2, k3, k4, k5, k6)``). The fisheye model ``equidistant`` (``D = (k1, k2, k3, k4)``, OpenCV's
``cv::fisheye``, Kannala & Brandt 2006) bends the angle ``theta = atan(r)`` off the axis instead:
``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)`` and ``(xd, yd) =
(theta_d / r) (x, y)``. Either way the pixel is ``u = fx xd + cx, v = fy yd + cy`` with ``K = [[fx, 0,
cx], [0, fy, cy], [0, 0, 1]]`` (a skew ``K[0, 1]`` is honoured too).

Undistortion (pixel -> ray) has no closed form. It is solved here by Newton's method (for the
fisheye on the one equation in ``theta``; else on the two equations above), with their analytic Jacobian, started at the distorted point — vectorised over all
pixels, to 1e-12 in normalised coordinates. It is written by hand because OpenCV
(``cv2.undistortPoints``, a fixed-point iteration of a fixed count that does not report whether it
converged) is not a dependency; here a pixel that does not converge, or lands where the lens model
folds over (Jacobian determinant <= 0, or the radial map ``r -> r s(r)`` not increasing all the way
from the centre: a spurious second preimage beyond the calibrated field), raises an error naming it rather
than giving a wrong ray.

A detector that ran on the *rectified* image (``image_rect``) gives pixels of the ideal camera
``P``: use :meth:`CameraIntrinsics.from_camera_info` with ``rectified=True`` (``P``'s left 3x3, no
distortion).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["CameraIntrinsics", "IntrinsicsError", "pixels_to_rays", "rays_to_pixels"]

MODELS = {"plumb_bob": 5, "rational_polynomial": 8, "equidistant": 4}
"""Distortion models handled, with their coefficient counts."""

_TOL = 1e-12  # Newton stops when the distortion residual (normalised coordinates) is below this
_MAX_ITER = 50


class IntrinsicsError(ValueError):
    """A camera's intrinsics are unusable, or a pixel cannot be turned into a ray."""


@dataclass(frozen=True)
class CameraIntrinsics:
    """A pinhole camera with lens distortion, in ROS's ``CameraInfo`` convention.

    Attributes:
        K: (3, 3) camera matrix [pixels].
        distortion_model: ``"plumb_bob"``, ``"rational_polynomial"`` or ``""`` (none).
        D: The distortion coefficients (see the module docstring); all zero or empty means none.
    """

    K: np.ndarray
    distortion_model: str = ""
    D: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        K = np.asarray(self.K, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise IntrinsicsError(f"K must be a finite 3x3 matrix, got {self.K!r}")
        if K[0, 0] <= 0 or K[1, 1] <= 0 or K[1, 0] != 0 or np.any(K[2] != (0.0, 0.0, 1.0)):
            raise IntrinsicsError(
                "K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0 "
                f"(an all-zero K means the camera was not calibrated), got {K.tolist()}"
            )
        D = tuple(float(d) for d in self.D)
        if not all(np.isfinite(D)):
            raise IntrinsicsError(f"distortion coefficients must be finite, got {D}")
        if any(D):
            if self.distortion_model not in MODELS:
                raise IntrinsicsError(
                    f"distortion model {self.distortion_model!r} is not handled (handled: "
                    f"{', '.join(MODELS)}); give rectified=True if the detector ran on the "
                    "rectified image"
                )
            if len(D) != MODELS[self.distortion_model]:
                raise IntrinsicsError(
                    f"{self.distortion_model} needs {MODELS[self.distortion_model]} distortion "
                    f"coefficients, got {len(D)}: {D}"
                )
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "D", D)

    @property
    def distorted(self) -> bool:
        """Whether any distortion coefficient is non-zero."""
        return any(self.D)

    def coefficients(self) -> np.ndarray:
        """``(k1, k2, k3, k4)`` of the fisheye, else ``(k1, k2, p1, p2, k3, k4, k5, k6)``, zeros
        where the model has none."""
        out = np.zeros(4 if self.distortion_model == "equidistant" else 8)
        out[: len(self.D)] = self.D
        return out

    @classmethod
    def from_camera_info(cls, msg: Any, *, rectified: bool = False) -> CameraIntrinsics:
        """The intrinsics of a ``sensor_msgs/CameraInfo`` message (ROS 1 or ROS 2 field names).

        With ``rectified=True`` the pixels are taken as the rectified image's: ``K`` is the left
        3x3 of the projection matrix ``P`` and there is no distortion.
        """
        def field(name: str) -> Any:  # ROS 1 spells the matrices in capitals, ROS 2 in lower case
            return getattr(msg, name) if hasattr(msg, name) else getattr(msg, name.lower())

        if rectified:
            P = np.asarray(field("P"), dtype=float).reshape(3, 4)
            return cls(P[:, :3])
        model = str(msg.distortion_model)
        return cls(np.asarray(field("K"), dtype=float).reshape(3, 3), model,
                   tuple(np.asarray(field("D"), dtype=float)))


def _distort(xy: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distorted normalised points and the (n, 2, 2) Jacobian d(distorted)/d(undistorted)."""
    k1, k2, p1, p2, k3, k4, k5, k6 = c
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    s = num / den
    ds = ((k1 + r2 * (2 * k2 + 3 * k3 * r2)) * den - num * (k4 + r2 * (2 * k5 + 3 * k6 * r2))) / den**2
    xd = x * s + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * s + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    J = np.empty((len(x), 2, 2))
    J[:, 0, 0] = s + 2 * x * x * ds + 2 * p1 * y + 6 * p2 * x
    J[:, 0, 1] = 2 * x * y * ds + 2 * p1 * x + 2 * p2 * y
    J[:, 1, 0] = 2 * x * y * ds + 2 * p1 * x + 2 * p2 * y
    J[:, 1, 1] = s + 2 * y * y * ds + 6 * p1 * y + 2 * p2 * x
    return np.stack([xd, yd], axis=1), J


def _radial_monotone(xy: np.ndarray, c: np.ndarray, samples: int = 32) -> np.ndarray:
    """Whether the radial map ``r -> r s(r)`` increases all the way from the centre to each point.

    Beyond the first radius where it stops increasing the lens model folds over (a second,
    spurious preimage of a pixel lies there), so an undistorted point must lie inside.
    """
    k1, k2, _, _, k3, k4, k5, k6 = c
    r2 = (xy * xy).sum(axis=1)[:, None] * np.linspace(0.0, 1.0, samples + 1)[None, 1:] ** 2
    num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    ds = ((k1 + r2 * (2 * k2 + 3 * k3 * r2)) * den - num * (k4 + r2 * (2 * k5 + 3 * k6 * r2))) / den**2
    return np.all((num / den + 2 * r2 * ds > 0) & (den > 0), axis=1)


def _fisheye_theta_d(theta: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fisheye's distorted angle and its derivative d(theta_d)/d(theta)."""
    t2 = theta * theta
    poly = 1 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3])))
    dpoly = 1 + t2 * (3 * k[0] + t2 * (5 * k[1] + t2 * (7 * k[2] + t2 * 9 * k[3])))
    return theta * poly, dpoly


def _fisheye_undistort(target: np.ndarray, k: np.ndarray,
                       samples: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Undistorted normalised points of the fisheye and which of them are valid.

    Valid: Newton converged, ``theta < pi/2`` (in front of the camera) and ``theta_d`` increases
    all the way from the axis (no fold of the model before the point).
    """
    theta_d = np.hypot(target[:, 0], target[:, 1])
    theta = theta_d.copy()
    for _ in range(_MAX_ITER):
        f, df = _fisheye_theta_d(theta, k)
        if np.max(np.abs(f - theta_d)) < _TOL:
            break
        theta = theta - (f - theta_d) / df
    f, _ = _fisheye_theta_d(theta, k)
    _, df = _fisheye_theta_d(theta[:, None] * np.linspace(0.0, 1.0, samples + 1)[None, :], k)
    ok = (np.abs(f - theta_d) < _TOL * 10) & (np.abs(theta) < np.pi / 2) & np.all(df > 0, axis=1)
    scale = np.ones_like(theta)
    nz = theta_d > 0
    scale[nz & ok] = np.tan(theta[nz & ok]) / theta_d[nz & ok]
    return target * scale[:, None], ok


def _pixels_array(pixels: np.ndarray | Sequence) -> np.ndarray:
    uv = np.asarray(pixels, dtype=float)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise IntrinsicsError(f"pixels must be an (n, 2) array of (u, v), got shape {uv.shape}")
    bad = ~np.isfinite(uv).all(axis=1)
    if bad.any():
        raise IntrinsicsError(f"pixel {int(np.argmax(bad))} is not finite: {uv[bad][0].tolist()}")
    return uv


def pixels_to_rays(pixels: np.ndarray | Sequence, camera: CameraIntrinsics) -> np.ndarray:
    """Rays ``(x, y, 1)`` in the camera's optical frame through pixels ``(u, v)`` (an (n, 2) array).

    The lens distortion is undone by Newton's method (module docstring); raises
    :class:`IntrinsicsError` naming the first pixel that does not converge or falls where the
    model folds over.
    """
    uv = _pixels_array(pixels)
    K = camera.K
    y = (uv[:, 1] - K[1, 2]) / K[1, 1]
    x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    target = np.stack([x, y], axis=1)
    xy = target.copy()
    if camera.distorted and len(xy) and camera.distortion_model == "equidistant":
        xy, ok = _fisheye_undistort(target, camera.coefficients())
        if not ok.all():
            i = int(np.argmin(ok))
            raise IntrinsicsError(
                f"pixel {i} {uv[i].tolist()} cannot be undistorted with equidistant "
                f"D={list(camera.D)}: Newton's method did not converge, the model folds over "
                "there, or the direction is 90 degrees or more off the axis"
            )
    elif camera.distorted and len(xy):
        c = camera.coefficients()
        for _ in range(_MAX_ITER):
            d, J = _distort(xy, c)
            res = d - target
            if np.max(np.abs(res)) < _TOL:
                break
            xy = xy - np.linalg.solve(J, res[:, :, None])[:, :, 0]
        d, J = _distort(xy, c)
        res = np.abs(d - target).max(axis=1)
        bad = ~(res < _TOL * 10) | ~(np.linalg.det(J) > 0) | ~_radial_monotone(xy, c)
        if bad.any():
            i = int(np.argmax(bad))
            raise IntrinsicsError(
                f"pixel {i} {uv[i].tolist()} cannot be undistorted with {camera.distortion_model} "
                f"D={list(camera.D)}: Newton's method did not converge or the lens model folds "
                "over there (outside the calibrated field of view)"
            )
    return np.column_stack([xy, np.ones(len(xy))])


def rays_to_pixels(rays: np.ndarray | Sequence, camera: CameraIntrinsics) -> np.ndarray:
    """Pixels ``(u, v)`` of directions ``(x, y, z)`` in the optical frame, distortion applied.

    Every ray must point in front of the camera (``z > 0``); raises :class:`IntrinsicsError`
    naming the first that does not.
    """
    r = np.asarray(rays, dtype=float)
    if r.ndim != 2 or r.shape[1] != 3:
        raise IntrinsicsError(f"rays must be an (n, 3) array, got shape {r.shape}")
    behind = ~(r[:, 2] > 0)
    if behind.any():
        i = int(np.argmax(behind))
        raise IntrinsicsError(f"ray {i} {r[i].tolist()} is not in front of the camera (z <= 0)")
    xy = r[:, :2] / r[:, 2:3]
    if camera.distorted and camera.distortion_model == "equidistant":
        rr = np.hypot(xy[:, 0], xy[:, 1])
        theta_d, _ = _fisheye_theta_d(np.arctan(rr), camera.coefficients())
        nz = rr > 0
        xy[nz] *= (theta_d[nz] / rr[nz])[:, None]
    elif camera.distorted:
        xy, _ = _distort(xy, camera.coefficients())
    K = camera.K
    u = K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2]
    v = K[1, 1] * xy[:, 1] + K[1, 2]
    return np.column_stack([u, v])
