"""AprilTag detections in a ROS bag -> an observation table (one row per sighting).

:func:`read_rosbag` reads ROS 1 ``.bag`` files and ROS 2 bags (a folder with ``metadata.yaml`` and
sqlite3 ``.db3`` or ``.mcap`` files) through ``rosbags.highlevel.AnyReader`` — the pure-Python
``rosbags`` library (``pip install 'lfmdr[ros]'``), no ROS install — and returns the table of issue 33
(``time, landmark[, robot], frame, ray_x, ray_y, ray_z[, range]``). The detection messages it
reads are those of :mod:`lfmdr_gym.datasets.ros_messages` (as a bag embeds them, so also
``apriltag_msgs`` 1.x, whose centre is a ``float64[2]``, and Isaac ROS releases whose pose has no
stamp):

* ``apriltag_ros/AprilTagDetectionArray`` (ROS 1) and ``isaac_ros_apriltag_interfaces/
  AprilTagDetectionArray`` carry each tag's pose in the camera's optical frame (z forward, x right,
  y down): the ray is the tag's position and ``range`` its length.
* ``apriltag_msgs/AprilTagDetectionArray`` (ROS 2) carries each tag's pixel centre only: the ray
  comes from the intrinsics of a ``sensor_msgs/CameraInfo`` topic (``camera_info_topic``), with the
  lens distortion undone (:mod:`lfmdr_gym.datasets.ros_intrinsics`); there is no range.

Choices, each documented in the table's ``attrs``:

* ``time`` is the array message's header stamp [s since the epoch]: the capture time of the image
  the tags were found in, which the detectors copy from the image. The bag's own receive time is
  later by the detector's latency and jitters with the load; ``time_source="bag"`` takes it
  instead, for publishers that leave the stamp at zero (then refused with ``"header"``).
* ``frame`` numbers the topic's messages 0, 1, ... in bag order: one message is one image, so its
  tags were seen from one pose. A message with no detection gives no row (a row is a sighting).
* ``landmark`` is the tag id (an integer). When the topic holds several tag families, ids would
  collide, so every landmark becomes the string ``"<family>:<id>"`` (the ROS 2 detector's tf name).
  A tag bundle (``apriltag_ros`` with several ids in one detection) is one pose for several tags
  and has no single landmark: it is refused unless ``bundles="skip"`` (counted in ``attrs``).
* A topic whose messages name several camera frames (``header.frame_id``) is refused: the table
  has no camera column, and rays of different cameras are not comparable.

:func:`add_arguments` and :func:`run` are the ``lfmdr convert rosbag`` sub-command's options and
body, kept here so the command line and the Python API cannot drift apart.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from lfmdr_gym.datasets.ros_intrinsics import CameraIntrinsics, IntrinsicsError, pixels_to_rays
from lfmdr_gym.datasets.ros_messages import (
    APRILTAG_MSGS,
    APRILTAG_ROS,
    CAMERA_INFO,
    DETECTION_ARRAY_TYPES,
    require_rosbags,
    shared_typestore,
)

__all__ = ["RosbagError", "add_arguments", "read_rosbag", "run"]

TIME_SOURCES = ("header", "bag")
BUNDLE_CHOICES = ("error", "skip")
_LAYOUT = ("a ROS 1 bag is a .bag file; a ROS 2 bag is a folder holding metadata.yaml and its "
           ".db3 (sqlite3) or .mcap files")


class RosbagError(ValueError):
    """A ROS bag cannot be read into an observation table; the message says why and what to do."""


class _Detections:
    """What the messages of a detection topic hold, gathered message by message."""

    def __init__(self) -> None:
        self.time: list[float] = []
        self.frame: list[int] = []
        self.family: list[str] = []
        self.tag: list[int] = []
        self.xyz: list[tuple[float, float, float]] = []
        self.pixel: list[tuple[float, float]] = []
        self.camera_frames: set[str] = set()
        self.messages = 0
        self.bundles = 0


def _stamp(header: Any) -> float:
    return float(header.stamp.sec) + 1e-9 * float(header.stamp.nanosec)


def _topics_listing(topics: dict[str, Any]) -> str:
    if not topics:
        return "the bag has no topics"
    return "topics in the bag: " + "; ".join(
        f"{name} ({info.msgtype}, {info.msgcount} messages)" for name, info in sorted(topics.items())
    )


def _paths(path: str | os.PathLike | Sequence[str | os.PathLike]) -> list[Path]:
    """The bag's path(s): one bag, or the .bag files of a split ROS 1 recording."""
    paths = [Path(path)] if isinstance(path, str | os.PathLike) else [Path(p) for p in path]
    if not paths:
        raise RosbagError(f"no ROS bag given ({_LAYOUT})")
    if len(paths) > 1 and any(p.suffix != ".bag" for p in paths):
        raise RosbagError("several paths are read together only as the .bag files of one split "
                          f"ROS 1 recording; got {[str(p) for p in paths]} ({_LAYOUT})")
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        raise RosbagError(f"ROS bag {', '.join(missing)} does not exist ({_LAYOUT})")
    return paths


def _open(paths: list[Path]) -> Any:
    """An open ``AnyReader`` on ``paths``, or RosbagError saying why they cannot be read."""
    require_rosbags()
    from rosbags.highlevel import AnyReader

    path = paths[0] if len(paths) == 1 else [str(p) for p in paths]
    store = shared_typestore(1 if paths[0].suffix == ".bag" else 2)
    try:
        reader = AnyReader(paths, default_typestore=store)
        reader.open()
    except Exception as err:  # rosbags raises its own errors, sqlite3's, OSError, ... per container
        raise RosbagError(f"cannot read ROS bag {path}: {err} ({_LAYOUT})") from err
    return reader


def _message_time(msg: Any, bag_ns: int, time_source: str, topic: str, index: int) -> float:
    if time_source == "bag":
        return bag_ns * 1e-9
    t = _stamp(msg.header)
    if t == 0.0:
        raise RosbagError(
            f"message {index} on {topic} has a zero header stamp (its publisher does not set "
            "it); read with time_source='bag' (--time bag) to use the bag's receive time"
        )
    return t


def _centre(det: Any) -> tuple[float, float]:
    """A detection's pixel centre: a ``Point`` (apriltag_msgs 2.x) or ``float64[2]`` (1.x)."""
    c = det.centre
    if isinstance(c, np.ndarray):
        return float(c[0]), float(c[1])
    return float(c.x), float(c.y)


def _position(det: Any) -> tuple[float, float, float]:
    """A detection's position, under a ``PoseWithCovarianceStamped`` or (Isaac ROS releases that
    dropped the stamp) a ``PoseWithCovariance``."""
    pose = det.pose
    while not hasattr(pose, "position"):
        pose = pose.pose
    p = pose.position
    return float(p.x), float(p.y), float(p.z)


def _gather(reader: Any, topic: str, msgtype: str, time_source: str, bundles: str) -> _Detections:
    """Walk the topic's messages once, keeping each detection's id, family and position or pixel."""
    out = _Detections()
    connections = [c for c in reader.connections if c.topic == topic]
    for index, (conn, bag_ns, raw) in enumerate(reader.messages(connections=connections)):
        msg = reader.deserialize(raw, conn.msgtype)
        out.messages += 1
        t = _message_time(msg, bag_ns, time_source, topic, index)
        if msg.detections:
            out.camera_frames.add(str(msg.header.frame_id))
        for det in msg.detections:
            if msgtype == APRILTAG_ROS:
                ids = np.asarray(det.id).ravel()
                if ids.size != 1:
                    if bundles == "skip":
                        out.bundles += 1
                        continue
                    raise RosbagError(
                        f"message {index} on {topic} holds a tag bundle (ids {ids.tolist()}): one "
                        "pose for several tags, so no single landmark; read with "
                        "bundles='skip' (--bundles skip) to leave bundles out"
                    )
                tag, family = int(ids[0]), ""
            else:
                tag, family = int(det.id), str(det.family)
            if msgtype == APRILTAG_MSGS:
                out.pixel.append(_centre(det))
            else:
                out.xyz.append(_position(det))
            out.time.append(t)
            out.frame.append(index)
            out.tag.append(tag)
            out.family.append(family)
    return out


def _camera_infos(reader: Any, topic: str, time_source: str,
                  rectified: bool) -> tuple[np.ndarray, list[CameraIntrinsics]]:
    """Times and intrinsics of every message of a CameraInfo topic."""
    connections = [c for c in reader.connections if c.topic == topic]
    times, cams = [], []
    for index, (conn, bag_ns, raw) in enumerate(reader.messages(connections=connections)):
        msg = reader.deserialize(raw, conn.msgtype)
        times.append(_message_time(msg, bag_ns, time_source, topic, index))
        try:
            cams.append(CameraIntrinsics.from_camera_info(msg, rectified=rectified))
        except IntrinsicsError as err:
            raise RosbagError(f"CameraInfo message {index} on {topic}: {err}") from err
    return np.asarray(times, dtype=float), cams


def _same(a: CameraIntrinsics, b: CameraIntrinsics) -> bool:
    return np.array_equal(a.K, b.K) and a.distortion_model == b.distortion_model and a.D == b.D


def _pixel_rays(reader: Any, found: _Detections, topics: dict[str, Any], topic: str,
                camera_info_topic: str | None, time_source: str, rectified: bool) -> np.ndarray:
    """Rays through the detections' pixel centres, from the CameraInfo in effect at each."""
    if camera_info_topic is None:
        raise RosbagError(
            f"{topic} holds {APRILTAG_MSGS} (pixel centres only): give the camera's "
            f"{CAMERA_INFO} topic as camera_info_topic (--camera-info); {_topics_listing(topics)}"
        )
    if camera_info_topic not in topics:
        raise RosbagError(f"camera info topic {camera_info_topic!r} is not in the bag; "
                          f"{_topics_listing(topics)}")
    if topics[camera_info_topic].msgtype != CAMERA_INFO:
        raise RosbagError(f"camera info topic {camera_info_topic!r} holds "
                          f"{topics[camera_info_topic].msgtype}, not {CAMERA_INFO}")
    times, cams = _camera_infos(reader, camera_info_topic, time_source, rectified)
    if not cams:
        raise RosbagError(f"camera info topic {camera_info_topic!r} has no messages")
    pixels = np.asarray(found.pixel, dtype=float)
    t = np.asarray(found.time)
    if all(_same(c, cams[0]) for c in cams[1:]):
        which = np.zeros(len(t), dtype=int)
    else:  # the intrinsics changed (a zoom, a re-calibration): each image takes the latest before it
        order = np.argsort(times, kind="stable")
        times, cams = times[order], [cams[i] for i in order]
        which = np.searchsorted(times, t, side="right") - 1
        if (which < 0).any():
            i = int(np.argmax(which < 0))
            raise RosbagError(
                f"the CameraInfo on {camera_info_topic} changes during the bag, and the detection "
                f"at t={t[i]:.9f} s precedes the first one ({times[0]:.9f} s): its intrinsics "
                "are unknown"
            )
    rays = np.empty((len(t), 3))
    for k in np.unique(which):
        sel = which == k
        try:
            rays[sel] = pixels_to_rays(pixels[sel], cams[k])
        except IntrinsicsError as err:
            raise RosbagError(f"{topic}: {err}") from err
    return rays


def _landmarks(found: _Detections) -> tuple[pd.Series, list[str]]:
    families = sorted(set(found.family) - {""})  # apriltag_ros names no family
    if len(families) > 1:
        ids = [f"{f}:{i}" for f, i in zip(found.family, found.tag, strict=True)]
        return pd.Series(ids, dtype=object), families
    return pd.Series(found.tag, dtype="int64"), families


def _check_positions(xyz: np.ndarray, found: _Detections, topic: str) -> None:
    bad = ~np.isfinite(xyz).all(axis=1) | ~(np.linalg.norm(xyz, axis=1) > 0)
    if bad.any():
        i = int(np.argmax(bad))
        raise RosbagError(
            f"message {found.frame[i]} on {topic}: tag {found.tag[i]}'s position {xyz[i].tolist()} "
            "is not a finite, non-zero vector, so it gives no ray"
        )


def read_rosbag(
    path: str | os.PathLike | Sequence[str | os.PathLike],
    topic: str,
    *,
    camera_info_topic: str | None = None,
    robot: int | str | None = None,
    time_source: str = "header",
    rectified: bool = False,
    bundles: str = "error",
) -> pd.DataFrame:
    """Read a topic of AprilTag detections from a ROS bag into an observation table.

    Args:
        path: A ROS 1 ``.bag`` file, or a ROS 2 bag folder (sqlite3 or MCAP storage); or a list of
            the ``.bag`` files of a split ROS 1 recording, read as one (messages in time order).
        topic: The detection topic; its type must be one of
            :data:`~lfmdr_gym.datasets.ros_messages.DETECTION_ARRAY_TYPES`.
        camera_info_topic: The ``sensor_msgs/CameraInfo`` topic of the camera, needed (only) for
            ``apriltag_msgs/AprilTagDetectionArray``, whose detections are pixels. If its intrinsics
            change during the bag, each image takes the latest CameraInfo at or before its time.
        robot: If given, a ``robot`` column with this id (several robots: read each bag,
            concatenate).
        time_source: ``"header"`` (default): the messages' header stamps (the images' capture
            times); ``"bag"``: the times the bag recorded them.
        rectified: The detector ran on the rectified image: pixels are mapped with
            ``CameraInfo.P``'s left 3x3 and no distortion, instead of ``K`` and ``D``.
        bundles: ``"error"`` (default) refuses ``apriltag_ros`` tag bundles; ``"skip"`` leaves them
            out and counts them in ``attrs["skipped_bundles"]``.

    Returns:
        One row per detection: ``time`` [s], ``landmark`` (int, or ``"family:id"`` strings when
        families mix), ``robot`` (if given), ``frame`` (message index), ``ray_x, ray_y, ray_z``
        (optical frame) and, for pose-carrying types, ``range`` [m]. ``attrs`` records the
        source, topic, message type, time source, camera frame and tag families.

    Raises:
        RosbagError: A missing or unreadable bag (the expected layout is said), a topic not in the
            bag (the bag's topics and types are listed), a message type not handled (the handled are
            listed), an empty topic, a missing or unusable CameraInfo, zero stamps, bundles, mixed
            camera frames or a detection that gives no ray.
        ImportError: ``rosbags`` is not installed (the message says ``pip install 'lfmdr[ros]'``).
    """
    if time_source not in TIME_SOURCES:
        raise ValueError(f"time_source must be one of {TIME_SOURCES}, got {time_source!r}")
    if bundles not in BUNDLE_CHOICES:
        raise ValueError(f"bundles must be one of {BUNDLE_CHOICES}, got {bundles!r}")
    paths = _paths(path)
    path = paths[0] if len(paths) == 1 else [str(p) for p in paths]
    reader = _open(paths)
    try:
        topics = reader.topics
        if topic not in topics:
            raise RosbagError(f"topic {topic!r} is not in {path}; {_topics_listing(topics)}")
        msgtype = topics[topic].msgtype
        if msgtype is None:  # rosbags' summary of a topic recorded with several types
            types = sorted({c.msgtype for c in topics[topic].connections})
            raise RosbagError(f"topic {topic!r} carries several message types {types}; "
                              "lfmdr reads a topic of one detection type")
        if msgtype not in DETECTION_ARRAY_TYPES:
            raise RosbagError(f"topic {topic!r} holds {msgtype}, which lfmdr does not read; "
                              f"handled types: {', '.join(DETECTION_ARRAY_TYPES)}")
        found = _gather(reader, topic, msgtype, time_source, bundles)
        if found.messages == 0:
            raise RosbagError(f"topic {topic!r} in {path} has no messages")
        if not found.tag:
            raise RosbagError(f"topic {topic!r} in {path} has {found.messages} messages but no "
                              "detections" + (f" ({found.bundles} bundles skipped)" if found.bundles else ""))
        if len(found.camera_frames) > 1:
            raise RosbagError(f"topic {topic!r} mixes camera frames {sorted(found.camera_frames)}; "
                              "read one camera per table")
        if msgtype == APRILTAG_MSGS:
            rays = _pixel_rays(reader, found, topics, topic, camera_info_topic, time_source,
                               rectified)
        else:
            rays = np.asarray(found.xyz, dtype=float)
            _check_positions(rays, found, topic)
    except RosbagError:
        raise
    except Exception as err:
        # a damaged bag fails inside rosbags as it reads or decodes a message: its own errors,
        # sqlite3's, an AssertionError, a KeyError of a connection type... (found by fuzzing,
        # tests/gym/datasets/test_fuzz_bags.py); each is the bag's fault, said as such
        raise RosbagError(f"cannot read ROS bag {path}: damaged or not as written "
                          f"({type(err).__name__}: {err})") from err
    finally:
        reader.close()
    landmark, families = _landmarks(found)
    columns: dict[str, Any] = {"time": np.asarray(found.time, dtype=float), "landmark": landmark}
    if robot is not None:
        columns["robot"] = pd.Series([robot] * len(landmark),
                                     dtype="int64" if isinstance(robot, int | np.integer) else object)
    columns["frame"] = np.asarray(found.frame, dtype=np.int64)
    columns.update(ray_x=rays[:, 0], ray_y=rays[:, 1], ray_z=rays[:, 2])
    if msgtype != APRILTAG_MSGS:
        columns["range"] = np.linalg.norm(rays, axis=1)
    table = pd.DataFrame(columns)
    table.attrs.update(
        source="rosbag", path=path if isinstance(path, list) else str(path), topic=topic, msgtype=msgtype,
        time_source=time_source, camera_frame=next(iter(found.camera_frames)),
        families=families, messages=found.messages, skipped_bundles=found.bundles,
    )
    if camera_info_topic is not None and msgtype == APRILTAG_MSGS:
        table.attrs.update(camera_info_topic=camera_info_topic, rectified=rectified)
    return table


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``lfmdr convert rosbag``'s arguments (the bag and :func:`read_rosbag`'s options)."""
    parser.add_argument("src", metavar="BAG", nargs="+",
                        help="a ROS 1 .bag file (or the .bag files of a split recording) or a ROS 2 "
                             "bag folder (sqlite3 or MCAP)")
    parser.add_argument("--topic", required=True,
                        help=f"the detection topic (types: {', '.join(DETECTION_ARRAY_TYPES)})")
    parser.add_argument("--camera-info", default=None, metavar="TOPIC",
                        help="the sensor_msgs/CameraInfo topic (needed for apriltag_msgs pixels)")
    parser.add_argument("--robot", default=None,
                        help="add a robot column with this id (digits make an integer id)")
    parser.add_argument("--time", choices=TIME_SOURCES, default="header",
                        help="time = the messages' header stamps (default) or the bag's times")
    parser.add_argument("--rectified", action="store_true",
                        help="the detector ran on the rectified image (use CameraInfo.P, no distortion)")
    parser.add_argument("--bundles", choices=BUNDLE_CHOICES, default="error",
                        help="apriltag_ros tag bundles: refuse (default) or skip them")


def run(args: argparse.Namespace) -> pd.DataFrame:
    """The observation table ``lfmdr convert rosbag`` writes, from :func:`add_arguments`' options."""
    robot = args.robot
    if robot is not None and str(robot).isdigit():
        robot = int(robot)
    src = args.src[0] if len(args.src) == 1 else args.src
    return read_rosbag(src, args.topic, camera_info_topic=args.camera_info, robot=robot,
                       time_source=args.time, rectified=args.rectified, bundles=args.bundles)
