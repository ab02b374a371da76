"""Write simulated AprilTag detections as a ROS bag (ROS 1 ``.bag``, ROS 2 sqlite3 or MCAP).

For tests, the example and a user who wants a sample bag to try ``lfmdr convert rosbag`` on:
:func:`camera_detections` turns robot poses and true landmark positions (a simulated episode) into
what a camera on the robot would detect, and :func:`write_detection_bag` writes them as messages of
one of the three detection types of :mod:`lfmdr_gym.datasets.ros_messages`, through ``rosbags``'
writers (``pip install 'lfmdr[ros]'``). What the messages hold beyond what
:func:`lfmdr_gym.datasets.rosbag.read_rosbag` reads is not simulated and is written as neutral
values: the tag's orientation is the identity, covariances, corners (the centre, repeated) and the
homography are zero, decoding quality is perfect; Isaac ROS's pixel centre is the projected position
when ``camera`` is given, else zero.

The bag is written atomically: into a temporary folder beside ``path``, moved into place when
complete; an existing ``path`` is refused (as ``rosbags`` does), never overwritten.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from lfmdr_gym.datasets.ros_intrinsics import CameraIntrinsics, rays_to_pixels
from lfmdr_gym.datasets.ros_messages import (
    APRILTAG_MSGS,
    APRILTAG_ROS,
    CAMERA_INFO,
    DETECTION_ARRAY_TYPES,
    require_rosbags,
    shared_typestore,
)

__all__ = ["CONTAINERS", "camera_detections", "write_detection_bag"]

CONTAINERS = ("rosbag1", "sqlite3", "mcap")
"""Bag containers: ROS 1 ``.bag`` file, ROS 2 folder with sqlite3 storage, ROS 2 folder with MCAP."""

_COLUMNS = ("time", "landmark", "x", "y", "z")


def camera_detections(
    times: Sequence[float] | np.ndarray,
    poses: np.ndarray,
    landmarks: np.ndarray,
    *,
    ids: Sequence[int] | None = None,
    fov: float = math.radians(90.0),
    max_range: float = math.inf,
    camera_height: float = 0.0,
    landmark_height: float = 0.0,
) -> pd.DataFrame:
    """What a forward-looking camera on a planar robot detects: tag positions in its optical frame.

    Args:
        times: (T,) time of each pose [s].
        poses: (T, 3) robot poses ``x, y, heading`` [m, m, rad]; the camera looks along the heading.
        landmarks: (L, 2) true landmark positions [m].
        ids: The landmarks' tag ids (default 0..L-1).
        fov: Horizontal field of view [rad]: a tag is seen when its bearing is within ``fov/2``.
        max_range: Tags farther [m] (in the plane) are not seen.
        camera_height, landmark_height: Heights [m] of the camera and of the tags (the tags' ``y``,
            pointing down, is ``camera_height - landmark_height``).

    Returns:
        ``time, frame, landmark, x, y, z``: one row per detection, ``frame`` the pose index, the
        position in the optical frame (z forward, x right, y down), so the planar bearing is
        ``atan2(-x, z)``. Only tags in front of the camera are kept, so ``z > 0``.
    """
    t = np.asarray(times, dtype=float)
    P = np.asarray(poses, dtype=float)
    L = np.asarray(landmarks, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or t.shape != (len(P),):
        raise ValueError(f"poses must be (T, 3) and times (T,), got {P.shape} and {t.shape}")
    if L.ndim != 2 or L.shape[1] != 2:
        raise ValueError(f"landmarks must be an (L, 2) array, got shape {L.shape}")
    tag = np.arange(len(L)) if ids is None else np.asarray(ids)
    if tag.shape != (len(L),):
        raise ValueError(f"ids must give one id per landmark ({len(L)}), got {len(tag)}")
    if not 0 < fov < math.pi:
        raise ValueError(f"fov must be in (0, pi) rad for a pinhole camera, got {fov}")
    d = L[None, :, :] - P[:, None, :2]
    c, s = np.cos(P[:, 2])[:, None], np.sin(P[:, 2])[:, None]
    forward = c * d[..., 0] + s * d[..., 1]
    left = -s * d[..., 0] + c * d[..., 1]
    seen = (np.abs(np.arctan2(left, forward)) <= fov / 2) & (forward > 0)
    seen &= np.hypot(forward, left) <= max_range
    frame, k = np.nonzero(seen)
    return pd.DataFrame({
        "time": t[frame], "frame": frame.astype(np.int64), "landmark": tag[k],
        "x": -left[frame, k], "y": np.full(len(k), camera_height - landmark_height),
        "z": forward[frame, k],
    })


def _check_detections(detections: pd.DataFrame) -> pd.DataFrame:
    missing = [c for c in _COLUMNS if c not in detections.columns]
    if missing:
        raise ValueError(f"detections lack columns {missing}; found {list(detections.columns)}")
    xyz = detections[["time", "x", "y", "z"]].to_numpy(dtype=float)
    bad = ~np.isfinite(xyz).all(axis=1)
    if bad.any():
        raise ValueError(f"detections row {int(np.argmax(bad))} has a non-finite time or position")
    if (detections["time"] <= 0).any():
        raise ValueError("detection times must be > 0 s (a zero ROS stamp means 'not set')")
    tags = detections["landmark"]
    if not pd.api.types.is_integer_dtype(tags):
        raise ValueError(f"detections' landmark must be integer tag ids, got dtype {tags.dtype}")
    info = np.iinfo(np.int32)
    out = (tags < info.min) | (tags > info.max)
    if out.any():
        raise ValueError(f"tag id {tags[out].iloc[0]} does not fit the messages' int32 id")
    return detections


def _stamp(store: Any, seconds: float) -> Any:
    ns = round(seconds * 1e9)
    return store.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def _header(store: Any, seconds: float, frame_id: str, seq: int) -> Any:
    cls = store.types["std_msgs/msg/Header"]
    kw = {"seq": seq} if "seq" in cls.__dataclass_fields__ else {}
    return cls(**kw, stamp=_stamp(store, seconds), frame_id=frame_id)


def _pose(store: Any, header: Any, xyz: list[float]) -> Any:
    T = store.types
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=xyz[0], y=xyz[1], z=xyz[2]),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )
    cov = T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36))
    return T["geometry_msgs/msg/PoseWithCovarianceStamped"](header=header, pose=cov)


def _detection(store: Any, msgtype: str, header: Any, tag: int, family: str, xyz: list[float],
               uv: list[float] | None, tag_size: float) -> Any:
    T = store.types
    if msgtype == APRILTAG_ROS:
        return T["apriltag_ros/msg/AprilTagDetection"](
            id=np.array([tag], dtype=np.int32), size=np.array([tag_size]),
            pose=_pose(store, header, xyz))
    if msgtype == APRILTAG_MSGS:
        centre = T["apriltag_msgs/msg/Point"](x=uv[0], y=uv[1])
        return T["apriltag_msgs/msg/AprilTagDetection"](
            family=family, id=tag, hamming=0, goodness=0.0, decision_margin=0.0,
            centre=centre, corners=[centre] * 4, homography=np.zeros(9))
    u, v = (0.0, 0.0) if uv is None else uv
    centre = T["geometry_msgs/msg/Point"](x=u, y=v, z=0.0)
    return T["isaac_ros_apriltag_interfaces/msg/AprilTagDetection"](
        family=family, id=tag, center=centre, corners=[centre] * 4,
        pose=_pose(store, header, xyz))


def _camera_info(store: Any, header: Any, camera: CameraIntrinsics, ros_version: int) -> Any:
    """A ``CameraInfo`` of ``camera``: ``P = [K | 0]``, ``R = I`` (a monocular camera), and an
    image size twice the principal point's coordinates (the simulated camera has no other; the
    reader does not use it)."""
    cls = store.types[CAMERA_INFO]
    P = np.zeros((3, 4))
    P[:, :3] = camera.K
    mats = {"D": np.asarray(camera.D, dtype=float), "K": camera.K.ravel(),
            "R": np.eye(3).ravel(), "P": P.ravel()}
    if ros_version == 2:
        mats = {k.lower(): v for k, v in mats.items()}
    roi = store.types["sensor_msgs/msg/RegionOfInterest"](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return cls(header=header, height=int(2 * camera.K[1, 2]), width=int(2 * camera.K[0, 2]),
               distortion_model=camera.distortion_model, **mats, binning_x=0, binning_y=0, roi=roi)


def _open_writer(tmp: Path, container: str) -> Any:
    if container == "rosbag1":
        from rosbags.rosbag1 import Writer as Writer1
        return Writer1(tmp)
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    plugin = StoragePlugin.MCAP if container == "mcap" else StoragePlugin.SQLITE3
    return Writer2(tmp, version=9, storage_plugin=plugin)


def write_detection_bag(
    path: str | os.PathLike,
    detections: pd.DataFrame,
    *,
    container: str = "rosbag1",
    msgtype: str = APRILTAG_ROS,
    topic: str = "/tag_detections",
    camera: CameraIntrinsics | None = None,
    camera_info_topic: str = "/camera_info",
    camera_frame: str = "camera",
    tag_size: float = 0.16,
) -> Path:
    """Write detections as a bag of AprilTag detection-array messages, one message per frame.

    Args:
        path: The bag to create: a ``.bag`` file for ``"rosbag1"``, a folder otherwise; must not
            exist.
        detections: ``time`` [s, > 0], ``landmark`` (int tag id), ``x, y, z`` (the tag's position in
            the camera's optical frame [m]), optionally ``frame`` (rows of one frame form one
            message; default: rows of one time) and ``family`` (default ``"36h11"``) — e.g. from
            :func:`camera_detections`.
        container: One of :data:`CONTAINERS`.
        msgtype: One of :data:`~lfmdr_gym.datasets.ros_messages.DETECTION_ARRAY_TYPES`.
        topic: The detection topic.
        camera: The camera's intrinsics; required for ``apriltag_msgs`` (the tag's pixel centre is
            its position projected, distortion applied), whose bag then also holds one
            ``sensor_msgs/CameraInfo`` per frame on ``camera_info_topic``, stamped as the frame.
        camera_frame: ``header.frame_id`` of every message.
        tag_size: The tags' side [m] (``apriltag_ros``'s ``size``).

    Returns:
        ``path``.
    """
    if container not in CONTAINERS:
        raise ValueError(f"container must be one of {CONTAINERS}, got {container!r}")
    if msgtype not in DETECTION_ARRAY_TYPES:
        raise ValueError(f"msgtype must be one of {DETECTION_ARRAY_TYPES}, got {msgtype!r}")
    path = Path(path)
    if (container == "rosbag1") != (path.suffix == ".bag"):
        raise ValueError(f"{path}: a ROS 1 bag's name ends in .bag, a ROS 2 bag folder's does not "
                         "(readers tell them apart by it)")
    if path.exists():
        raise FileExistsError(f"{path} exists already; remove it or choose another path")
    if msgtype == APRILTAG_MSGS and camera is None:
        raise ValueError(f"{APRILTAG_MSGS} holds pixels: give the camera's intrinsics (camera=)")
    det = _check_detections(detections)
    require_rosbags()
    ros_version = 1 if container == "rosbag1" else 2
    store = shared_typestore(ros_version)
    serialize = store.serialize_ros1 if ros_version == 1 else store.serialize_cdr
    xyz = det[["x", "y", "z"]].to_numpy(dtype=float)
    uv = rays_to_pixels(xyz, camera).tolist() if camera else [None] * len(det)
    xyz, times, tags = xyz.tolist(), det["time"].tolist(), det["landmark"].tolist()
    families = (det["family"].astype(str).tolist() if "family" in det.columns
                else ["36h11"] * len(det))
    # rows of one frame (or time) form one message, in the key's order; plain lists, not a
    # pandas groupby, because per-row pandas access was 80 % of the writing time
    key = (det["frame"] if "frame" in det.columns else det["time"]).to_numpy()
    order = np.argsort(key, kind="stable")
    starts = np.flatnonzero(np.r_[True, key[order][1:] != key[order][:-1]])
    groups = np.split(order, starts[1:])
    path.parent.mkdir(parents=True, exist_ok=True)
    tmpdir = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=path.parent))
    try:
        tmp = tmpdir / path.name
        with _open_writer(tmp, container) as writer:
            conn = writer.add_connection(topic, msgtype, typestore=store)
            info = (writer.add_connection(camera_info_topic, CAMERA_INFO, typestore=store)
                    if msgtype == APRILTAG_MSGS else None)
            for seq, rows in enumerate(groups):
                t = times[rows[0]]
                header = _header(store, t, camera_frame, seq)
                items = [_detection(store, msgtype, header, tags[i], families[i], xyz[i], uv[i],
                                    tag_size) for i in rows.tolist()]
                array = store.types[msgtype](header=header, detections=items)
                ns = round(t * 1e9)
                if info is not None:
                    writer.write(info, ns, serialize(
                        _camera_info(store, header, camera, ros_version), CAMERA_INFO))
                writer.write(conn, ns, serialize(array, msgtype))
        os.replace(tmp, path)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    return path
