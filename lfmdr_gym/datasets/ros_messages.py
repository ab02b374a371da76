"""The AprilTag detection messages lfmdr reads from ROS bags, defined inside the project.

A bag recorded by ROS normally embeds the definitions of the messages it holds, but ROS 2 bags in
the sqlite3 storage written before Iron (and bags re-written by some tools) do not; the ``rosbags``
library then needs a *typestore* that knows the types. The three AprilTag detector messages below are
not part of any ROS distribution, so they are registered here from their ``.msg`` text, copied from
the packages that publish them:

* ``apriltag_ros/msg/AprilTagDetectionArray`` — ROS 1 ``apriltag_ros`` (AprilRobotics,
  https://github.com/AprilRobotics/apriltag_ros): per tag ``id[]`` and ``size[]`` (one entry for a
  standalone tag, several for a tag bundle) and the tag's pose in the camera's optical frame.
* ``apriltag_msgs/msg/AprilTagDetectionArray`` — ROS 2 ``apriltag_msgs`` 2.x (C. Rauch,
  https://github.com/christianrauch/apriltag_msgs), published by ``apriltag_ros`` for ROS 2: the tag's
  family, id, decoding quality, pixel centre, corners and homography; no pose.
* ``isaac_ros_apriltag_interfaces/msg/AprilTagDetectionArray`` — NVIDIA Isaac ROS
  (https://github.com/NVIDIA-ISAAC-ROS/isaac_ros_apriltag, before 0.10 moved the interfaces to
  ``isaac_ros_common``): family, id, pixel centre and corners, and the tag's pose in the camera frame.

``rosbags`` is an optional dependency (the ``[ros]`` extra); it is imported only when a typestore is
asked for, and its absence is reported with the command that installs it.
"""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = [
    "APRILTAG_MSGS", "APRILTAG_ROS", "CAMERA_INFO", "DETECTION_ARRAY_TYPES", "ISAAC_ROS",
    "MESSAGE_DEFINITIONS", "POSE_TYPES", "detection_typestore", "require_rosbags", "shared_typestore",
]

APRILTAG_ROS = "apriltag_ros/msg/AprilTagDetectionArray"
"""ROS 1 apriltag_ros: each detection carries its tag's pose in the camera frame (ray and range)."""
APRILTAG_MSGS = "apriltag_msgs/msg/AprilTagDetectionArray"
"""ROS 2 apriltag_msgs: each detection carries its tag's pixel centre only (a ray, given intrinsics)."""
ISAAC_ROS = "isaac_ros_apriltag_interfaces/msg/AprilTagDetectionArray"
"""NVIDIA Isaac ROS: each detection carries its tag's pose in the camera frame (ray and range)."""
DETECTION_ARRAY_TYPES = (APRILTAG_ROS, APRILTAG_MSGS, ISAAC_ROS)
"""The detection-array message types :func:`lfmdr_gym.datasets.rosbag.read_rosbag` reads."""
POSE_TYPES = (APRILTAG_ROS, ISAAC_ROS)
"""The types whose detections carry a pose (so a range); the others need the camera's intrinsics."""
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
"""The standard message of a camera's intrinsics (K, distortion), read for pixel detections."""

ROS_EXTRA_HINT = "pip install 'lfmdr[ros]'"

MESSAGE_DEFINITIONS: dict[str, str] = {
    "apriltag_ros/msg/AprilTagDetection": (
        "int32[] id\n"
        "float64[] size\n"
        "geometry_msgs/PoseWithCovarianceStamped pose\n"
    ),
    APRILTAG_ROS: (
        "std_msgs/Header header\n"
        "AprilTagDetection[] detections\n"
    ),
    "apriltag_msgs/msg/Point": (
        "float64 x\n"
        "float64 y\n"
    ),
    "apriltag_msgs/msg/AprilTagDetection": (
        "string family\n"
        "int32 id\n"
        "int32 hamming\n"
        "float32 goodness\n"
        "float32 decision_margin\n"
        "Point centre\n"
        "Point[4] corners\n"
        "float64[9] homography\n"
    ),
    APRILTAG_MSGS: (
        "std_msgs/Header header\n"
        "AprilTagDetection[] detections\n"
    ),
    "isaac_ros_apriltag_interfaces/msg/AprilTagDetection": (
        "string family\n"
        "int32 id\n"
        "geometry_msgs/Point center\n"
        "geometry_msgs/Point[4] corners\n"
        "geometry_msgs/PoseWithCovarianceStamped pose\n"
    ),
    ISAAC_ROS: (
        "std_msgs/Header header\n"
        "AprilTagDetection[] detections\n"
    ),
}
"""The ``.msg`` text of every detection message (comments dropped), keyed by full type name."""


def require_rosbags() -> Any:
    """Import and return the ``rosbags`` package, or raise ImportError saying how to install it."""
    try:
        import rosbags
        import rosbags.highlevel  # noqa: F401  (the submodules the readers and writers use)
        import rosbags.typesys  # noqa: F401
    except ImportError as err:
        raise ImportError(
            f"reading or writing ROS bags needs the rosbags library: {ROS_EXTRA_HINT} "
            f"(no ROS install needed); import failed: {err}"
        ) from err
    return rosbags


def detection_typestore(ros_version: int) -> Typestore:
    """A ``rosbags`` typestore of a ROS distribution plus the three AprilTag detection messages.

    Args:
        ros_version: 1 for ROS 1 Noetic's standard messages (``std_msgs/Header`` has ``seq``,
            ``CameraInfo`` has ``D``/``K``/``R``/``P``), 2 for ROS 2 Humble's (no ``seq``;
            ``d``/``k``/``r``/``p``).
    """
    if ros_version not in (1, 2):
        raise ValueError(f"ros_version must be 1 or 2, got {ros_version!r}")
    require_rosbags()
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros_version == 1 else Stores.ROS2_HUMBLE)
    types: dict = {}
    for name, text in MESSAGE_DEFINITIONS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


@lru_cache(maxsize=2)
def shared_typestore(ros_version: int) -> Typestore:
    """One :func:`detection_typestore` per ROS version, shared by the bag readers and writers.

    ``rosbags`` compiles a (de)serialiser per message type on first use (~0.2 s each); sharing
    the store keeps that to once per process. Do not register further types into it: take a
    fresh :func:`detection_typestore` for that.
    """
    return detection_typestore(ros_version)
