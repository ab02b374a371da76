"""A ROS bag of AprilTag detections, mapped: simulate an episode, write its detections as a bag,
read the bag back into an observation table, map the table and score the map.

    python examples/map_rosbag.py [--steps 1500] [--container rosbag1|sqlite3|mcap]
                                  [--msgtype apriltag_ros|apriltag_msgs|isaac_ros] [--out DIR]

The robot of ``LFMDR-Visibility-v0`` walks the paper's random walk; a forward-looking camera on it
(90 degree field of view, 1.5 m range, bearing noise 0.01 rad) "detects" every object in view as
an AprilTag, and the detections are written as a ROS bag of the chosen container and message type
(``lfmdr_gym.datasets.rosbag_write``; ``apriltag_msgs`` as pixel centres with a ``CameraInfo``).
From there on only the bag is used: ``read_rosbag`` gives one row per sighting, each row's ray is
a bearing in the camera's horizontal plane, each message (image) one step of a masked bearing
history, and ``build_map`` maps it from the four anchors. The robot's true poses and the objects'
true positions are used only to simulate the detections and to score the map. Needs
``pip install 'lfmdr[ros]'``.
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pandas as pd

import lfmdr_gym  # noqa: F401  (registers the LFMDR env ids)
import mappers
from lfmdr_gym import History, collect
from lfmdr_gym.datasets.ros_intrinsics import CameraIntrinsics
from lfmdr_gym.datasets.ros_messages import APRILTAG_MSGS, APRILTAG_ROS, ISAAC_ROS
from lfmdr_gym.datasets.rosbag import read_rosbag
from lfmdr_gym.datasets.rosbag_write import CONTAINERS, camera_detections, write_detection_bag
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy

MSGTYPES = {"apriltag_ros": APRILTAG_ROS, "apriltag_msgs": APRILTAG_MSGS, "isaac_ros": ISAAC_ROS}
CAMERA = CameraIntrinsics(np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]]),
                          "plumb_bob", (-0.1, 0.01, 0.0, 0.0, 0.0))
STEP_SECONDS = 0.1  # the simulated camera's frame period
BEARING_NOISE = 0.01  # [rad]


def noisy(detections: pd.DataFrame, sd: float, rng: np.random.Generator) -> pd.DataFrame:
    """The detections with each tag's position turned about the camera's vertical axis by a
    Gaussian angle of ``sd`` rad: bearing noise, as a detector's pixel error gives."""
    a = rng.normal(0.0, sd, len(detections))
    x, z = detections["x"].to_numpy(), detections["z"].to_numpy()
    return detections.assign(x=np.cos(a) * x + np.sin(a) * z, z=-np.sin(a) * x + np.cos(a) * z)


def bearing_history(table: pd.DataFrame, truth: History) -> History:
    """The table as a masked bearing history: one step per frame, one row per landmark.

    The bearing of a ray in the camera's horizontal plane is ``atan2(-ray_x, ray_z)``; a step
    holds its cosine and sine (``mappers.core.sensors``' bearing layout), observed where the
    frame saw the landmark. ``truth`` gives the objects and anchors the history is scored on.
    """
    frames, step = np.unique(table["frame"].to_numpy(), return_inverse=True)
    obj = table["landmark"].to_numpy()
    bearing = np.arctan2(-table["ray_x"].to_numpy(), table["ray_z"].to_numpy())
    matrix = np.zeros((truth.n_objects, 2 * len(frames)))
    mask = np.zeros(matrix.shape, dtype=bool)
    matrix[obj, 2 * step], matrix[obj, 2 * step + 1] = np.cos(bearing), np.sin(bearing)
    mask[obj, 2 * step] = mask[obj, 2 * step + 1] = True
    return History("bearing", matrix, truth.object_positions, truth.anchor_ids,
                   truth.anchor_positions, mask=mask, meta=dict(table.attrs))


def main(argv: list[str] | None = None) -> mappers.Map:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--container", choices=CONTAINERS, default="rosbag1")
    parser.add_argument("--msgtype", choices=MSGTYPES, default="apriltag_ros")
    parser.add_argument("--out", default=None, help="folder for the bag (default: a temporary one)")
    args = parser.parse_args(argv)

    env = gym.make("LFMDR-Visibility-v0")
    episode = collect(env, RandomWalkPolicy.for_env(env), args.steps, seed=args.seed)
    env.close()
    times = 1.0 + STEP_SECONDS * np.arange(episode.n_steps)  # ROS stamps must be > 0
    detections = camera_detections(times, episode.robot_poses, episode.object_positions,
                                   fov=math.radians(90), max_range=1.5)
    detections = noisy(detections, BEARING_NOISE, np.random.default_rng(args.seed))

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.out) if args.out else Path(tmp)
        name = "episode.bag" if args.container == "rosbag1" else f"episode_{args.container}"
        bag = write_detection_bag(folder / name, detections, container=args.container,
                                  msgtype=MSGTYPES[args.msgtype], camera=CAMERA)
        table = read_rosbag(bag, "/tag_detections", camera_info_topic="/camera_info")
    print(f"bag: {args.container}, {MSGTYPES[args.msgtype]}, {table.attrs['messages']} messages")
    print(f"table: {len(table)} sightings of {table['landmark'].nunique()} tags; columns "
          f"{', '.join(table.columns)}")

    history = bearing_history(table, episode)
    result = mappers.build_map(history, episode.anchor_ids, episode.anchor_positions)
    mpe = mappers.mean_position_error(result.positions, episode.object_positions,
                                      exclude=episode.anchor_ids)
    print(f"{result.method}: MPE {mpe:.3f} m over the non-anchor objects "
          f"({history.n_steps} steps, bearing noise {BEARING_NOISE} rad)")
    for w in result.warnings:  # what the mapper repaired or doubts (Map.warnings)
        print(f"  warning: {w}")
    return result


if __name__ == "__main__":
    main()
