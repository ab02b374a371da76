"""What a pitched camera on the planar robot sees of tags in 3-D: rays, ranges, view and occlusion.

The geometry of ``LFMDR-Camera3D-v0`` (:mod:`lfmdr_gym.camera3d_env`), as pure functions of a
robot pose ``(x, y, heading)`` and the tags' 3-D positions, so that they serve logged poses as
well as the simulator.

**The camera.** It sits on the robot's centre at ``height`` above the floor, looks along the
heading, tilted up by ``pitch`` (radians; negative looks down), with no roll. Its frame is the
usual computer-vision one: ``z`` forward (the optical axis), ``x`` to the right in the image,
``y`` down in the image. A tag's reading is the unit ray from the camera's centre to the tag in
that frame, and its range the 3-D distance.

**The view.** A pinhole camera with a rectangular image: a tag is in view iff it lies in front
(``z > 0``), ``|x / z| <= tan(hfov / 2)`` and ``|y / z| <= tan(vfov / 2)``, and (with a range
limit) no farther than ``max_range``.

**Occlusion.** The cylinders (posts) of the arena are taken to be taller than every tag and the
camera (the tags' band is 0-2 m), so a straight 3-D line of sight meets a post iff its
projection on the floor meets the post's disc: a tag is hidden iff the horizontal segment from the
camera's centre to the tag's foot passes within ``radius`` of another post's axis with the foot of
that perpendicular on the segment (the visibility test of :func:`lfmdr_gym.sim.sensors.visibility`,
in the floor plane). The post a tag is mounted on never hides it: a tag on a post is a band
around it, seen from every side, and its position is the point on the post's axis at its height
(like the MRCLAM runs' barcoded cylinders). Tags on the walls face into the arena, so the camera,
always inside, is in front of them; no angle of incidence limits their reading. The robot's own
body hides nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from lfmdr_gym.checks import check_real

__all__ = ["CameraModel", "camera_frame", "hidden_by_posts", "in_view", "rays_and_ranges", "view"]


@dataclass(frozen=True)
class CameraModel:
    """The camera of ``LFMDR-Camera3D-v0``: mount and optics (see the module docstring).

    Attributes:
        height: the optical centre's height above the floor [m], > 0.
        pitch_deg: tilt of the optical axis above the horizontal [deg], in (-90, 90).
        hfov_deg: horizontal field of view [deg], in (0, 180).
        vfov_deg: vertical field of view [deg], in (0, 180).
        max_range: largest 3-D distance [m] at which a tag is read, or None (no limit).
        occlusion: whether posts hide the tags behind them.
    """

    height: float = 0.3
    pitch_deg: float = 20.0
    hfov_deg: float = 90.0
    vfov_deg: float = 70.0
    max_range: float | None = 3.0
    occlusion: bool = True

    def __post_init__(self) -> None:
        check_real("camera_height", self.height, low=0.0, low_open=True)
        check_real("pitch_deg", self.pitch_deg, low=-90.0, low_open=True, high=90.0, high_open=True)
        for name in ("hfov_deg", "vfov_deg"):
            check_real(name, getattr(self, name), low=0.0, low_open=True, high=180.0, high_open=True)
        if self.max_range is not None:
            check_real("max_range", self.max_range, low=0.0, low_open=True)
        if not isinstance(self.occlusion, bool | np.bool_):
            raise ValueError(f"occlusion must be True or False, got {self.occlusion!r}")

    @property
    def tan_half_fov(self) -> tuple[float, float]:
        """``(tan(hfov / 2), tan(vfov / 2))``: the image's half-width and half-height at z = 1."""
        return (math.tan(math.radians(self.hfov_deg) / 2.0),
                math.tan(math.radians(self.vfov_deg) / 2.0))


def camera_frame(pose: ArrayLike, height: float, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """The camera's centre (3,) in the world and the rotation (3, 3) whose rows are its axes
    ``x`` (right), ``y`` (down), ``z`` (forward) in world coordinates, so that
    ``R @ (p - centre)`` is a world point ``p`` in the camera frame.

    ``pose`` is the robot's ``(x, y, heading)``; ``pitch`` [rad] tilts the optical axis up.
    """
    p = np.asarray(pose, dtype=np.float64)
    if p.shape != (3,) or not np.isfinite(p).all():
        raise ValueError(f"pose must be 3 finite numbers (x, y, heading), got {pose!r}")
    ch, sh = math.cos(p[2]), math.sin(p[2])
    cp, sp = math.cos(pitch), math.sin(pitch)
    forward = np.array((cp * ch, cp * sh, sp))
    right = np.array((sh, -ch, 0.0))
    down = np.cross(forward, right)  # z x x = y: a right-handed frame
    return np.array((p[0], p[1], float(height))), np.stack((right, down, forward))


def rays_and_ranges(centre: np.ndarray, rotation: np.ndarray,
                    tags: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Unit rays (M, 3) in the camera frame and 3-D distances (M,) from the camera's centre to
    each tag (M, 3). A tag at the centre itself has no direction: ray (0, 0, 0), range 0."""
    rel = (np.asarray(tags, dtype=np.float64) - centre) @ rotation.T
    dist = np.sqrt(np.einsum("ij,ij->i", rel, rel))
    safe = np.where(dist > 0.0, dist, np.inf)
    return rel / safe[:, None], dist


def in_view(rays: np.ndarray, dist: np.ndarray, camera: CameraModel) -> np.ndarray:
    """(M,) bool: the tags inside the image (in front, within both fields of view) and within
    the range limit, from their rays and ranges (:func:`rays_and_ranges`)."""
    th, tv = camera.tan_half_fov
    z = rays[:, 2]
    seen = (z > 0.0) & (np.abs(rays[:, 0]) <= th * z) & (np.abs(rays[:, 1]) <= tv * z)
    if camera.max_range is not None:
        seen &= dist <= camera.max_range
    return seen


def hidden_by_posts(camera_xy: ArrayLike, tags: ArrayLike, hosts: ArrayLike, posts: ArrayLike,
                    radius: float) -> np.ndarray:
    """(M,) bool: the tags whose line of sight from ``camera_xy`` meets a post (see the module
    docstring). ``tags`` (M, 2 or 3; only x, y are read), ``hosts`` (M,) the post each tag is
    mounted on (-1: none, e.g. a wall), ``posts`` (K, 2) the posts' axes, ``radius`` theirs.

    Post k hides tag j when the foot of the perpendicular from k's axis onto the floor segment
    camera -> tag lies on the segment and that perpendicular is shorter than ``radius``.
    """
    xy = np.asarray(camera_xy, dtype=np.float64)[:2]
    seg = np.asarray(tags, dtype=np.float64)[:, :2] - xy          # (M, 2) camera -> tag
    rel = np.asarray(posts, dtype=np.float64) - xy                # (K, 2) camera -> post
    hosts = np.asarray(hosts, dtype=np.int64)
    if rel.shape[0] == 0:
        return np.zeros(seg.shape[0], dtype=bool)
    len2 = np.einsum("ij,ij->i", seg, seg)                        # (M,)
    dot = seg @ rel.T                                             # (M, K): projection * |seg|
    # foot on the segment: 0 <= dot <= len2; squared perpendicular: |rel|^2 - dot^2 / len2
    rel2 = np.einsum("ij,ij->i", rel, rel)
    with np.errstate(divide="ignore", invalid="ignore"):
        perp2 = rel2[None, :] - dot * dot / len2[:, None]
    blocks = (dot >= 0.0) & (dot <= len2[:, None]) & (perp2 < radius * radius)
    blocks[hosts >= 0, hosts[hosts >= 0]] = False                  # a tag's own post
    blocks[len2 == 0.0] = False                                   # a tag above the camera
    return blocks.any(axis=1)


def view(pose: ArrayLike, tags: ArrayLike, hosts: ArrayLike, posts: ArrayLike, radius: float,
         camera: CameraModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the camera on a robot at ``pose`` reads of every tag, before noise and dropouts:
    ``(rays (M, 3), ranges (M,), seen (M,) bool)`` with ``seen`` the tags in view, in range and
    (with ``camera.occlusion``) not hidden by a post; the rays and ranges of every tag, seen or
    not (the caller zeroes the unseen)."""
    tags = np.asarray(tags, dtype=np.float64)
    if tags.ndim != 2 or tags.shape[1] != 3:
        raise ValueError(f"tags must have shape (M, 3), got {tags.shape}")
    centre, rotation = camera_frame(pose, camera.height, math.radians(camera.pitch_deg))
    rays, dist = rays_and_ranges(centre, rotation, tags)
    seen = in_view(rays, dist, camera)
    if camera.occlusion:
        seen &= ~hidden_by_posts(centre, tags, hosts, posts, radius)
    return rays, dist, seen
