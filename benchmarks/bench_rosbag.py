"""ROS bags in (issue 33): how fast AprilTag detection bags are read into observation tables.

A simulated episode (a robot at ``--messages`` random poses among ``--landmarks`` tags, a 90 degree
camera seeing about 8 tags an image) is written as a bag in every container (ROS 1, ROS 2 sqlite3,
ROS 2 MCAP) and every detection type, then read with ``read_rosbag``; the medians over
``--repeats`` reads are printed as seconds and microseconds per message. Reading is the
``rosbags`` library's deserialisation plus a Python step per detection (a bag holds one message
per image), so it scales with messages and detections; writing is printed for reference.

    python benchmarks/bench_rosbag.py                       # 5000 messages
    python benchmarks/bench_rosbag.py --messages 20000 --repeats 3
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from lfmdr_gym.datasets.ros_intrinsics import CameraIntrinsics
from lfmdr_gym.datasets.ros_messages import DETECTION_ARRAY_TYPES
from lfmdr_gym.datasets.rosbag import read_rosbag
from lfmdr_gym.datasets.rosbag_write import CONTAINERS, camera_detections, write_detection_bag

CAMERA = CameraIntrinsics(np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]]),
                          "plumb_bob", (-0.1, 0.01, 0.0, 0.0, 0.0))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=5000)
    parser.add_argument("--landmarks", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)

    rng = np.random.default_rng(0)
    poses = np.column_stack([rng.uniform(-1, 1, (args.messages, 2)),
                             rng.uniform(-np.pi, np.pi, args.messages)])
    landmarks = rng.uniform(-1.5, 1.5, (args.landmarks, 2))
    times = 1.0 + 0.1 * np.arange(args.messages)
    det = camera_detections(times, poses, landmarks, fov=math.radians(90))
    n_msgs = det["frame"].nunique()
    print(f"{n_msgs} messages, {len(det)} detections ({len(det) / n_msgs:.1f} per message); "
          f"medians of {args.repeats} reads")
    print(f"{'container':9s} {'message type':58s} {'write [s]':>9s} {'read [s]':>8s} "
          f"{'us/message':>10s}")
    with tempfile.TemporaryDirectory() as tmp:
        for container in CONTAINERS:
            for msgtype in DETECTION_ARRAY_TYPES:
                path = Path(tmp) / (f"{container}-{msgtype.split('/')[0]}"
                                    + (".bag" if container == "rosbag1" else ""))
                start = time.perf_counter()
                write_detection_bag(path, det, container=container, msgtype=msgtype, camera=CAMERA)
                write = time.perf_counter() - start
                reads = []
                for _ in range(args.repeats):
                    start = time.perf_counter()
                    table = read_rosbag(path, "/tag_detections", camera_info_topic="/camera_info")
                    reads.append(time.perf_counter() - start)
                    assert len(table) == len(det)
                read = statistics.median(reads)
                print(f"{container:9s} {msgtype:58s} {write:9.2f} {read:8.2f} "
                      f"{read / n_msgs * 1e6:10.0f}")


if __name__ == "__main__":
    main()
