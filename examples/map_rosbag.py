"""A ROS bag of AprilTag detections, mapped: simulate an episode, write its detections as a bag,
read the bag back into an observation table, map the table and score the map.

    python examples/map_rosbag.py [--steps 1500] [--container rosbag1|sqlite3|mcap]
                                  [--msgtype apriltag_ros|apriltag_msgs|isaac_ros] [--out DIR]

The robot of ``LFMDR-Visibility-v0`` walks the paper's random walk; a forward-looking camera on it
(90 degree field of view, 1.5 m range, noise 0.01 rad in bearing and 0.02 m in range) "detects" every object in view as
an AprilTag, and the detections are written as a ROS bag of the chosen container and message type
(``lfmdr_gym.datasets.rosbag_write``; ``apriltag_msgs`` as pixel centres with a ``CameraInfo``).
From there on only the bag is used: ``read_rosbag`` gives one row per sighting (a ray, and a range
where the detector gives the tag's pose), ``observations_to_history`` makes each image a step of a
masked history (each ray a bearing in the camera's horizontal plane), and ``build_map`` maps it from
the four anchors. The robot's true poses and the objects'
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
from lfmdr_gym import collect
from lfmdr_gym.datasets.ros_intrinsics import CameraIntrinsics
from lfmdr_gym.datasets.ros_messages import APRILTAG_MSGS, APRILTAG_ROS, ISAAC_ROS
from lfmdr_gym.datasets.rosbag import read_rosbag
from lfmdr_gym.datasets.rosbag_write import CONTAINERS, camera_detections, write_detection_bag
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.histories.observations import observations_to_history

MSGTYPES = {"apriltag_ros": APRILTAG_ROS, "apriltag_msgs": APRILTAG_MSGS, "isaac_ros": ISAAC_ROS}
CAMERA = CameraIntrinsics(np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]]),
                          "plumb_bob", (-0.1, 0.01, 0.0, 0.0, 0.0))
STEP_SECONDS = 0.1  # the simulated camera's frame period
BEARING_NOISE = 0.01  # [rad]
RANGE_NOISE = 0.02  # [m]


def noisy(detections: pd.DataFrame, rng: np.random.Generator) -> pd.DataFrame:
    """The detections with each tag's position turned about the camera's vertical axis by a
    Gaussian angle (bearing noise, :data:`BEARING_NOISE`) and moved along its ray by a Gaussian
    distance (range noise, :data:`RANGE_NOISE`), as a detector's pixel and pose errors give."""
    a = rng.normal(0.0, BEARING_NOISE, len(detections))
    xyz = detections[["x", "y", "z"]].to_numpy()
    x, z = np.cos(a) * xyz[:, 0] + np.sin(a) * xyz[:, 2], -np.sin(a) * xyz[:, 0] + np.cos(a) * xyz[:, 2]
    scale = 1.0 + rng.normal(0.0, RANGE_NOISE, len(xyz)) / np.linalg.norm(xyz, axis=1)
    return detections.assign(x=x * scale, y=xyz[:, 1] * scale, z=z * scale)


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
    detections = noisy(detections, np.random.default_rng(args.seed))

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.out) if args.out else Path(tmp)
        name = "episode.bag" if args.container == "rosbag1" else f"episode_{args.container}"
        bag = write_detection_bag(folder / name, detections, container=args.container,
                                  msgtype=MSGTYPES[args.msgtype], camera=CAMERA)
        table = read_rosbag(bag, "/tag_detections", camera_info_topic="/camera_info")
    print(f"bag: {args.container}, {MSGTYPES[args.msgtype]}, {table.attrs['messages']} messages")
    print(f"table: {len(table)} sightings of {table['landmark'].nunique()} tags; columns "
          f"{', '.join(table.columns)}")

    # The table becomes a history (one step per image; a bearing from each ray, and a range where
    # the detector gave a pose); the anchors' positions are all the mapper is told of the world.
    ids = np.arange(episode.n_objects)  # the tags carry the objects' indices as ids
    anchors = pd.DataFrame({"landmark": ids[episode.anchor_ids],
                            "x": episode.anchor_positions[:, 0], "y": episode.anchor_positions[:, 1]})
    truth = pd.DataFrame({"landmark": ids, "x": episode.object_positions[:, 0],
                          "y": episode.object_positions[:, 1]})  # for scoring only
    history = observations_to_history(table, anchors, truth=truth)
    result = mappers.build_map(history, history.anchor_ids, history.anchor_positions)
    mpe = mappers.mean_position_error(result.positions, history.object_positions,
                                      exclude=history.anchor_ids)
    print(f"{history.sensor} history of {history.n_objects} tags, {history.n_steps} steps; "
          f"{result.method}: MPE {mpe:.3f} m over the non-anchor tags "
          f"(noise: bearing {BEARING_NOISE} rad, range {RANGE_NOISE} m)")
    for w in result.warnings:  # what the mapper repaired or doubts (Map.warnings)
        print(f"  warning: {w}")
    return result


if __name__ == "__main__":
    main()
