"""Damaged ROS bags, fuzzed (issue 35): truncated and bit-flipped bags of every container (ROS 1
``.bag``; ROS 2 sqlite3 and MCAP storage, the storage file damaged) give :class:`RosbagError`
within seconds, or read as a table (a bag has no checksum over its messages: a flipped bit in
a number is another number); never a hang, a crash of the interpreter or another exception
(rosbags' own errors, sqlite3's, assertions: each now said as the bag's fault). Read in a child
process (``tests/fuzzing.py``); ``-m slow`` damages many more copies.
"""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest

pytest.importorskip("rosbags", reason="rosbags not installed (pip install 'lfmdr[ros]')")

from fuzzing import BAG_TOPIC, bit_flipped, read_all, truncated  # noqa: E402

from lfmdr_gym.datasets.ros_intrinsics import CameraIntrinsics  # noqa: E402
from lfmdr_gym.datasets.ros_messages import APRILTAG_MSGS  # noqa: E402
from lfmdr_gym.datasets.rosbag_write import (  # noqa: E402
    CONTAINERS,
    camera_detections,
    write_detection_bag,
)

ERRORS = ["lfmdr_gym.datasets.rosbag.RosbagError"]
READER = "fuzzing:rosbag_summary"
CAMERA = CameraIntrinsics(np.array([[600.0, 0.0, 320.0], [0.0, 610.0, 240.0], [0.0, 0.0, 1.0]]),
                          "plumb_bob", (-0.12, 0.02, 0.001, -0.002, 0.003))


def _good_bag(root, container):
    """A small bag of apriltag_msgs detections (pixels, so the CameraInfo topic is read too)."""
    rng = np.random.default_rng(7)
    steps = 6
    poses = np.column_stack([rng.uniform(-1, 1, (steps, 2)), rng.uniform(-np.pi, np.pi, steps)])
    landmarks = rng.uniform(-1.5, 1.5, (5, 2))
    det = camera_detections(1.7e9 + 0.25 * np.arange(steps), poses, landmarks,
                            ids=np.arange(5) + 1, fov=math.radians(100), camera_height=0.3,
                            landmark_height=0.1)
    name = f"good-{container}" + (".bag" if container == "rosbag1" else "")
    return write_detection_bag(root / name, det, container=container, msgtype=APRILTAG_MSGS,
                               topic=BAG_TOPIC, camera=CAMERA)


def _storage(bag):
    """The file holding a bag's messages: the .bag itself, or a ROS 2 folder's .db3 / .mcap."""
    return bag if bag.is_file() else next(p for p in bag.iterdir()
                                          if p.suffix in (".db3", ".mcap"))


@pytest.mark.parametrize("slow", [False, pytest.param(True, marks=pytest.mark.slow)],
                         ids=["default", "many"])
def test_truncated_and_bit_flipped_bags(tmp_path, slow):
    rng = np.random.default_rng(35)
    paths = []
    for container in CONTAINERS:
        good_bag = _good_bag(tmp_path, container)
        good = _storage(good_bag).read_bytes()
        cuts = np.linspace(0, len(good) - 1, 200 if slow else 8).astype(int)
        copies = [(f"cut{k}", truncated(good, k)) for k in cuts]
        copies += [(f"flip{k}", bit_flipped(good, rng.integers(0, 8 * len(good),
                                                               rng.integers(1, 4))))
                   for k in range(500 if slow else 14)]
        for label, data in copies:
            bag = tmp_path / (f"{container}-{label}" + good_bag.suffix)
            if good_bag.is_dir():  # a ROS 2 bag: its folder, the storage file damaged
                shutil.copytree(good_bag, bag)
                _storage(bag).write_bytes(data)
            else:
                bag.write_bytes(data)
            paths.append(bag)
    outcomes = read_all(paths, READER, ERRORS, time_limit=1800.0 if slow else 300.0)
    unexpected = {p: o for p, o in outcomes.items() if "unexpected" in o}
    assert not unexpected, f"{len(unexpected)} bag(s) raised another error, e.g. " \
                           f"{next(iter(unexpected.items()))}"
    for container in CONTAINERS:  # the damage is real: many are refused
        mine = [o for p, o in outcomes.items() if f"/{container}-" in p]
        assert sum("error" in o for o in mine) > 0.3 * len(mine), container
    cut_short = outcomes[str(tmp_path / ("rosbag1-cut0.bag"))]
    assert "error" in cut_short and "cannot read ROS bag" in cut_short["message"]
