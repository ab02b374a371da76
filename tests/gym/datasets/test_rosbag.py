"""ROS bags in (issue 33): simulated detections written with rosbags' writers in every container and
message type, read back into the observation table (lfmdr_gym/datasets/rosbag.py, rosbag_write.py,
ros_messages.py), and every error a user can meet."""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("rosbags", reason="rosbags not installed (pip install 'lfmdr[ros]')")

from lfmdr_gym.datasets.ros_intrinsics import CameraIntrinsics, rays_to_pixels  # noqa: E402
from lfmdr_gym.datasets.ros_messages import (  # noqa: E402
    APRILTAG_MSGS,
    APRILTAG_ROS,
    CAMERA_INFO,
    DETECTION_ARRAY_TYPES,
    ISAAC_ROS,
    POSE_TYPES,
    require_rosbags,
    shared_typestore,
)
from lfmdr_gym.datasets.rosbag import RosbagError, add_arguments, read_rosbag, run  # noqa: E402
from lfmdr_gym.datasets.rosbag_write import (  # noqa: E402
    CONTAINERS,
    camera_detections,
    write_detection_bag,
)

pytestmark = pytest.mark.xdist_group("rosbag")  # one worker builds the module's bags once

TOPIC = "/tag_detections"
CAMERA = CameraIntrinsics(np.array([[600.0, 0.0, 320.0], [0.0, 610.0, 240.0], [0.0, 0.0, 1.0]]),
                          "plumb_bob", (-0.12, 0.02, 0.001, -0.002, 0.003))
T0 = 1_700_000_000.0  # an epoch time, as real header stamps are


def _episode():
    rng = np.random.default_rng(7)
    steps = 12
    poses = np.column_stack([rng.uniform(-1, 1, (steps, 2)), rng.uniform(-np.pi, np.pi, steps)])
    landmarks = rng.uniform(-1.5, 1.5, (8, 2))
    times = T0 + 0.25 * np.arange(steps)
    det = camera_detections(times, poses, landmarks, ids=np.arange(8) * 3 + 1,
                            fov=math.radians(100), camera_height=0.3, landmark_height=0.1)
    return poses, landmarks, det


POSES, LANDMARKS, DETECTIONS = _episode()


def _name(container, msgtype):
    return f"{container}-{msgtype.split('/')[0]}" + (".bag" if container == "rosbag1" else "")


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    root = tmp_path_factory.mktemp("bags")
    return {(c, m): write_detection_bag(root / _name(c, m), DETECTIONS, container=c, msgtype=m,
                                        topic=TOPIC, camera=CAMERA)
            for c in CONTAINERS for m in DETECTION_ARRAY_TYPES}


def _unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_the_episode_sees_enough_to_test_with():
    assert len(DETECTIONS) > 20 and DETECTIONS["frame"].nunique() > 6


@pytest.mark.parametrize("msgtype", DETECTION_ARRAY_TYPES)
@pytest.mark.parametrize("container", CONTAINERS)
def test_detections_written_to_a_bag_read_back_as_the_table(bags, container, msgtype):
    table = read_rosbag(bags[container, msgtype], TOPIC, camera_info_topic="/camera_info")
    assert len(table) == len(DETECTIONS)
    np.testing.assert_array_equal(table["landmark"], DETECTIONS["landmark"])
    assert table["landmark"].dtype == np.int64
    np.testing.assert_allclose(table["time"], DETECTIONS["time"], rtol=0, atol=1e-6)
    # frames are message indices: one per pose with a detection, in order
    np.testing.assert_array_equal(table["frame"], pd.factorize(DETECTIONS["frame"])[0])
    xyz = DETECTIONS[["x", "y", "z"]].to_numpy()
    rays = table[["ray_x", "ray_y", "ray_z"]].to_numpy()
    np.testing.assert_allclose(_unit(rays), _unit(xyz), atol=1e-9)
    if msgtype in POSE_TYPES:
        np.testing.assert_allclose(table["range"], np.linalg.norm(xyz, axis=1), rtol=1e-12)
    else:
        assert "range" not in table.columns
    assert table.attrs["msgtype"] == msgtype and table.attrs["topic"] == TOPIC
    assert table.attrs["source"] == "rosbag" and table.attrs["time_source"] == "header"
    assert table.attrs["families"] == ([] if msgtype == APRILTAG_ROS else ["36h11"])


def test_the_rays_give_the_true_bearings_in_the_horizontal_plane(bags):
    table = read_rosbag(bags["mcap", APRILTAG_MSGS], TOPIC, camera_info_topic="/camera_info")
    bearing = np.arctan2(-table["ray_x"], table["ray_z"])
    step = DETECTIONS["frame"].to_numpy()
    k = (DETECTIONS["landmark"].to_numpy() - 1) // 3
    d = LANDMARKS[k] - POSES[step, :2]
    truth = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - POSES[step, 2])))
    np.testing.assert_allclose(bearing, truth, atol=1e-9)


@pytest.mark.parametrize("msgtype", [APRILTAG_ROS, APRILTAG_MSGS])
def test_the_table_keeps_the_contract_and_becomes_a_history(bags, tmp_path, msgtype):
    from lfmdr_gym.histories.observation_table import (
        check_observations,
        read_observations,
        write_observations,
    )
    from lfmdr_gym.histories.observations import landmark_ids, observations_to_history

    table = read_rosbag(bags["sqlite3", msgtype], TOPIC, camera_info_topic="/camera_info",
                        robot=1)
    check_observations(table)
    back = read_observations(write_observations(table, tmp_path / "obs.csv"))
    pd.testing.assert_frame_equal(back, table, check_exact=False, rtol=1e-15)
    assert back.attrs == table.attrs
    ids = np.arange(8) * 3 + 1
    anchors = pd.DataFrame({"landmark": ids[:4], "x": LANDMARKS[:4, 0], "y": LANDMARKS[:4, 1]})
    history = observations_to_history(table, anchors)
    assert history.sensor == ("range-bearing" if msgtype == APRILTAG_ROS else "bearing")
    assert history.n_steps == table["frame"].nunique()
    bearing = history.matrix["bearing"] if history.fused else history.matrix
    mask = history.mask["bearing"] if history.fused else history.mask
    # every sighting is one observed cell holding the true bearing's cosine and sine
    rows = np.searchsorted(landmark_ids(history), table["landmark"].to_numpy())
    step = table["frame"].to_numpy()  # frames are 0.. in order, so steps are frames
    truth = np.arctan2(-DETECTIONS["x"].to_numpy(), DETECTIONS["z"].to_numpy())
    np.testing.assert_allclose(bearing[rows, 2 * step], np.cos(truth), atol=1e-9)
    np.testing.assert_allclose(bearing[rows, 2 * step + 1], np.sin(truth), atol=1e-9)
    assert mask.sum() == 2 * len(table)


def test_robot_column_and_bag_times(bags):
    table = read_rosbag(bags["rosbag1", APRILTAG_ROS], TOPIC, robot="r2", time_source="bag")
    assert list(table.columns[:4]) == ["time", "landmark", "robot", "frame"]
    assert (table["robot"] == "r2").all()
    np.testing.assert_allclose(table["time"], DETECTIONS["time"], atol=1e-6)  # written as stamps
    assert read_rosbag(bags["rosbag1", APRILTAG_ROS], TOPIC, robot=3)["robot"].dtype == np.int64


def test_the_cli_options_read_the_same_table(bags):
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    path = bags["sqlite3", APRILTAG_MSGS]
    args = parser.parse_args([str(path), "--topic", TOPIC, "--camera-info", "/camera_info",
                              "--robot", "4"])
    expected = read_rosbag(path, TOPIC, camera_info_topic="/camera_info", robot=4)
    pd.testing.assert_frame_equal(run(args), expected)


def test_a_split_ros1_recording_reads_as_one(bags, tmp_path):
    late = DETECTIONS["time"] >= T0 + 1.4
    parts = [write_detection_bag(tmp_path / f"part{i}.bag", DETECTIONS[sel], container="rosbag1")
             for i, sel in enumerate((late, ~late))]  # in any order: messages come in time order
    whole = read_rosbag(bags["rosbag1", APRILTAG_ROS], TOPIC)
    split = read_rosbag(parts, TOPIC)
    pd.testing.assert_frame_equal(split, whole)
    assert split.attrs["path"] == [str(p) for p in parts]
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    pd.testing.assert_frame_equal(run(parser.parse_args([*map(str, parts), "--topic", TOPIC])),
                                  whole)
    with pytest.raises(RosbagError, match="only as the .bag files of one split ROS 1 recording"):
        read_rosbag([parts[0], bags["mcap", ISAAC_ROS]], TOPIC)


def test_mixed_tag_families_become_string_landmarks(tmp_path):
    det = DETECTIONS.assign(family=np.where(DETECTIONS["landmark"] < 10, "36h11", "25h9"))
    path = write_detection_bag(tmp_path / "fam", det, container="mcap", msgtype=ISAAC_ROS)
    table = read_rosbag(path, TOPIC)
    expected = [f"{f}:{i}" for f, i in zip(det["family"], det["landmark"], strict=True)]
    assert table["landmark"].tolist() == expected
    assert table.attrs["families"] == ["25h9", "36h11"]


def test_changing_intrinsics_are_taken_per_image(tmp_path):
    first, later = DETECTIONS[DETECTIONS["time"] < T0 + 1.4], DETECTIONS[DETECTIONS["time"] >= T0 + 1.4]
    wide = CameraIntrinsics(np.array([[300.0, 0, 320], [0, 300, 240], [0, 0, 1]]))
    # two bags of one camera that changed zoom, merged: each part read with its own CameraInfo
    a = write_detection_bag(tmp_path / "a", first, container="mcap", msgtype=APRILTAG_MSGS,
                            camera=CAMERA)
    b = write_detection_bag(tmp_path / "b", later, container="mcap", msgtype=APRILTAG_MSGS,
                            camera=wide)
    merged = _merge_bags([a, b], tmp_path / "merged")
    table = read_rosbag(merged, TOPIC, camera_info_topic="/camera_info")
    xyz = pd.concat([first, later])[["x", "y", "z"]].to_numpy()
    np.testing.assert_allclose(_unit(table[["ray_x", "ray_y", "ray_z"]].to_numpy()), _unit(xyz),
                               atol=1e-9)


def _merge_bags(paths, out):
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = shared_typestore(2)
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {}
        for path in paths:
            with AnyReader([path]) as reader:
                for conn, t, raw in reader.messages():
                    if conn.topic not in conns:
                        conns[conn.topic] = writer.add_connection(conn.topic, conn.msgtype,
                                                                  typestore=store)
                    writer.write(conns[conn.topic], t, raw)
    return out


# ---- errors ------------------------------------------------------------------------------------

def test_a_topic_not_in_the_bag_lists_the_topics_and_types(bags):
    with pytest.raises(RosbagError, match=r"'/tags' is not in .*topics in the bag: /camera_info "
                       r"\(sensor_msgs/msg/CameraInfo, \d+ messages\); /tag_detections "
                       r"\(apriltag_msgs/msg/AprilTagDetectionArray"):
        read_rosbag(bags["rosbag1", APRILTAG_MSGS], "/tags")


def test_an_unknown_message_type_lists_the_handled(bags):
    with pytest.raises(RosbagError, match=f"holds {CAMERA_INFO}, which lfmdr does not read; "
                       f"handled types: {APRILTAG_ROS}"):
        read_rosbag(bags["mcap", APRILTAG_MSGS], "/camera_info")


def test_pixel_detections_without_camera_info_are_refused(bags):
    path = bags["sqlite3", APRILTAG_MSGS]
    with pytest.raises(RosbagError, match=r"pixel centres only\): give the camera's "
                       "sensor_msgs/msg/CameraInfo topic .*--camera-info.*topics in the bag"):
        read_rosbag(path, TOPIC)
    with pytest.raises(RosbagError, match="'/cam/info' is not in the bag; topics in the bag"):
        read_rosbag(path, TOPIC, camera_info_topic="/cam/info")
    with pytest.raises(RosbagError, match="holds apriltag_msgs/msg/AprilTagDetectionArray, "
                       "not sensor_msgs/msg/CameraInfo"):
        read_rosbag(path, TOPIC, camera_info_topic=TOPIC)


def test_an_empty_topic_and_a_topic_without_detections_are_refused(tmp_path):
    from rosbags.rosbag1 import Writer

    store = shared_typestore(1)
    path = tmp_path / "empty.bag"
    with Writer(path) as writer:
        writer.add_connection("/empty", APRILTAG_ROS, typestore=store)
        conn = writer.add_connection(TOPIC, APRILTAG_ROS, typestore=store)
        header = store.types["std_msgs/msg/Header"](
            seq=0, stamp=store.types["builtin_interfaces/msg/Time"](sec=5, nanosec=0), frame_id="c")
        msg = store.types[APRILTAG_ROS](header=header, detections=[])
        writer.write(conn, 5 * 10**9, store.serialize_ros1(msg, APRILTAG_ROS))
    with pytest.raises(RosbagError, match="'/empty' in .* has no messages"):
        read_rosbag(path, "/empty")
    with pytest.raises(RosbagError, match="has 1 messages but no detections"):
        read_rosbag(path, TOPIC)


@pytest.mark.parametrize("make", ["missing", "garbage", "folder"])
def test_an_unreadable_bag_says_what_a_bag_looks_like(tmp_path, make):
    path = tmp_path / ("x.bag" if make != "folder" else "x")
    if make == "garbage":
        path.write_bytes(b"#ROSBAG V1.0\nthis is not a bag")
    elif make == "folder":
        path.mkdir()
    with pytest.raises(RosbagError, match="a ROS 2 bag is a folder holding metadata.yaml"):
        read_rosbag(path, TOPIC)


def _bag_of(path, detections, stamp_sec=5):
    """A ROS 1 bag with one hand-made apriltag_ros message of the given (ids, xyz) detections."""
    from rosbags.rosbag1 import Writer

    store = shared_typestore(1)
    T = store.types
    header = T["std_msgs/msg/Header"](
        seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=stamp_sec, nanosec=0), frame_id="cam")
    items = []
    for ids, xyz in detections:
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=xyz[0], y=xyz[1], z=xyz[2]),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
        stamped = T["geometry_msgs/msg/PoseWithCovarianceStamped"](
            header=header, pose=T["geometry_msgs/msg/PoseWithCovariance"](
                pose=pose, covariance=np.zeros(36)))
        items.append(T["apriltag_ros/msg/AprilTagDetection"](
            id=np.array(ids, dtype=np.int32), size=np.full(len(ids), 0.1), pose=stamped))
    with Writer(path) as writer:
        conn = writer.add_connection(TOPIC, APRILTAG_ROS, typestore=store)
        msg = T[APRILTAG_ROS](header=header, detections=items)
        writer.write(conn, 7 * 10**9, store.serialize_ros1(msg, APRILTAG_ROS))
    return path


def test_tag_bundles_are_refused_or_skipped_when_asked(tmp_path):
    path = _bag_of(tmp_path / "b.bag", [([4], (0.1, 0.0, 1.0)), ([1, 2, 3], (0.0, 0.1, 2.0))])
    with pytest.raises(RosbagError, match=r"tag bundle \(ids \[1, 2, 3\]\).*bundles='skip'"):
        read_rosbag(path, TOPIC)
    table = read_rosbag(path, TOPIC, bundles="skip")
    assert table["landmark"].tolist() == [4] and table.attrs["skipped_bundles"] == 1


def test_zero_stamps_and_bad_positions_are_refused(tmp_path):
    zero = _bag_of(tmp_path / "zero.bag", [([4], (0.1, 0.0, 1.0))], stamp_sec=0)
    with pytest.raises(RosbagError, match="zero header stamp.*time_source='bag'"):
        read_rosbag(zero, TOPIC)
    assert read_rosbag(zero, TOPIC, time_source="bag")["time"].tolist() == [7.0]
    bad = _bag_of(tmp_path / "bad.bag", [([4], (0.1, 0.0, 1.0)), ([5], (0.0, 0.0, 0.0))])
    with pytest.raises(RosbagError, match="tag 5's position .* not a finite, non-zero vector"):
        read_rosbag(bad, TOPIC)


def test_bad_options_are_refused(bags):
    with pytest.raises(ValueError, match="time_source must be one of"):
        read_rosbag(bags["mcap", ISAAC_ROS], TOPIC, time_source="receive")
    with pytest.raises(ValueError, match="bundles must be one of"):
        read_rosbag(bags["mcap", ISAAC_ROS], TOPIC, bundles="merge")


def test_without_rosbags_the_error_says_how_to_install_it(monkeypatch, bags, tmp_path):
    for name in [m for m in sys.modules if m == "rosbags" or m.startswith("rosbags.")]:
        monkeypatch.setitem(sys.modules, name, None)  # as if not installed
    with pytest.raises(ImportError, match=r"pip install 'lfmdr\[ros\]'"):
        require_rosbags()
    with pytest.raises(ImportError, match=r"pip install 'lfmdr\[ros\]'"):
        read_rosbag(bags["mcap", ISAAC_ROS], TOPIC)
    with pytest.raises(ImportError, match=r"pip install 'lfmdr\[ros\]'"):
        write_detection_bag(tmp_path / "x", DETECTIONS, container="mcap")
    assert list(tmp_path.iterdir()) == []


# ---- writer ------------------------------------------------------------------------------------

def test_the_writer_refuses_bad_requests(tmp_path):
    with pytest.raises(ValueError, match="container must be one of"):
        write_detection_bag(tmp_path / "a", DETECTIONS, container="zip")
    with pytest.raises(ValueError, match="ends in .bag"):
        write_detection_bag(tmp_path / "a", DETECTIONS, container="rosbag1")
    with pytest.raises(ValueError, match="give the camera's intrinsics"):
        write_detection_bag(tmp_path / "a", DETECTIONS, container="mcap", msgtype=APRILTAG_MSGS)
    with pytest.raises(ValueError, match=r"lack columns \['z'\]"):
        write_detection_bag(tmp_path / "a", DETECTIONS.drop(columns="z"), container="mcap")
    (tmp_path / "there").mkdir()
    with pytest.raises(FileExistsError, match="exists already"):
        write_detection_bag(tmp_path / "there", DETECTIONS, container="mcap")


def test_the_writer_refuses_tag_ids_a_message_cannot_hold(tmp_path):
    with pytest.raises(ValueError, match=r"tag id 10995116277\d\d does not fit the messages' int32"):
        write_detection_bag(tmp_path / "a", DETECTIONS.assign(landmark=DETECTIONS["landmark"] + 2**40),
                            container="mcap")
    with pytest.raises(ValueError, match="landmark must be integer tag ids"):
        write_detection_bag(tmp_path / "a", DETECTIONS.assign(landmark="x"), container="mcap")


@pytest.mark.parametrize("container", CONTAINERS)
def test_a_failed_write_leaves_nothing_behind(tmp_path, monkeypatch, container):
    from lfmdr_gym.datasets import rosbag_write

    calls = []

    def failing(*args, **kwargs):  # the third message fails, after two were written
        calls.append(1)
        if len(calls) == 3:
            raise RuntimeError("disk full")
        return header(*args, **kwargs)

    header = rosbag_write._header
    monkeypatch.setattr(rosbag_write, "_header", failing)
    with pytest.raises(RuntimeError, match="disk full"):
        write_detection_bag(tmp_path / _name(container, ISAAC_ROS), DETECTIONS, container=container,
                            msgtype=ISAAC_ROS)
    assert list(tmp_path.iterdir()) == []


# ---- older message layouts, as a bag embeds them ------------------------------------------------

LEGACY = {
    APRILTAG_MSGS: ("apriltag_msgs/msg/AprilTagDetection",  # apriltag_msgs 1.x: arrays, no Point
                    "string family\nint32 id\nint32 hamming\nfloat32 goodness\n"
                    "float32 decision_margin\nfloat64[2] centre\nfloat64[8] corners\n"
                    "float64[9] homography\n"),
    ISAAC_ROS: ("isaac_ros_apriltag_interfaces/msg/AprilTagDetection",  # a pose without stamp
                "string family\nint32 id\ngeometry_msgs/Point center\n"
                "geometry_msgs/Point[4] corners\ngeometry_msgs/PoseWithCovariance pose\n"),
}


@pytest.mark.parametrize("msgtype", LEGACY)
def test_older_layouts_embedded_in_a_bag_are_read(tmp_path, msgtype):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from lfmdr_gym.datasets.rosbag_write import _camera_info, _header

    store = get_typestore(Stores.ROS2_HUMBLE)
    name, text = LEGACY[msgtype]
    types = get_types_from_msg(text, name)
    types.update(get_types_from_msg("std_msgs/Header header\nAprilTagDetection[] detections\n",
                                    msgtype))
    store.register(types)
    T = store.types
    xyz = np.array([0.2, -0.1, 1.5])
    uv = rays_to_pixels(xyz[None], CAMERA)[0]
    header = _header(store, T0, "cam", 0)
    if msgtype == APRILTAG_MSGS:
        det = T[name](family="36h11", id=9, hamming=0, goodness=0.0, decision_margin=0.0,
                      centre=uv, corners=np.zeros(8), homography=np.zeros(9))
    else:
        point = T["geometry_msgs/msg/Point"]
        pose = T["geometry_msgs/msg/Pose"](
            position=point(x=xyz[0], y=xyz[1], z=xyz[2]),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
        det = T[name](family="36h11", id=9, center=point(x=0.0, y=0.0, z=0.0),
                      corners=[point(x=0.0, y=0.0, z=0.0)] * 4,
                      pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose,
                                                                      covariance=np.zeros(36)))
    path = tmp_path / "legacy"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection(TOPIC, msgtype, typestore=store)
        info = writer.add_connection("/camera_info", CAMERA_INFO, typestore=store)
        writer.write(info, int(T0 * 1e9), store.serialize_cdr(_camera_info(store, header, CAMERA, 2),
                                                              CAMERA_INFO))
        writer.write(conn, int(T0 * 1e9), store.serialize_cdr(T[msgtype](header=header,
                                                                         detections=[det]), msgtype))
    table = read_rosbag(path, TOPIC, camera_info_topic="/camera_info")
    assert table["landmark"].tolist() == [9]
    ray = table[["ray_x", "ray_y", "ray_z"]].to_numpy()
    np.testing.assert_allclose(_unit(ray), _unit(xyz[None]), atol=1e-9)
