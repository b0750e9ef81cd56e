"""nuturtle_demo.recorder: rosbag2-style message definitions, the MCAP writer, and the live topic recorder;
every file is read back with the independent `rosbags` library."""

import math

import pytest
from geometry_msgs.msg import Point
from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
from rclpy.serialization import serialize_message
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from sensor_msgs.msg import JointState, LaserScan
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from nuturtle_demo.recorder import (
    SEPARATOR,
    MessageDefinitions,
    Ros2McapWriter,
    TopicRecorder,
    field_types,
    qos_profiles_yaml,
    split_type_name,
)

DEMO_TYPES = [
    "sensor_msgs/msg/LaserScan",
    "sensor_msgs/msg/JointState",
    "nav_msgs/msg/Odometry",
    "nav_msgs/msg/Path",
    "visualization_msgs/msg/MarkerArray",
    "geometry_msgs/msg/Twist",
    "rosgraph_msgs/msg/Clock",
    "rcl_interfaces/msg/Log",
]


def read_bag(path):
    """{topic: [(log_time_ns, message)]} and {topic: connection}, decoded with the bag's own definitions."""
    messages, connections = {}, {}
    with AnyReader([path], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        for connection in reader.connections:
            connections[connection.topic] = connection
        for connection, timestamp, rawdata in reader.messages():
            messages.setdefault(connection.topic, []).append((timestamp, reader.deserialize(rawdata, connection.msgtype)))
    return messages, connections


def test_split_type_name():
    assert split_type_name("sensor_msgs/msg/LaserScan") == ("sensor_msgs", "LaserScan")
    assert split_type_name("std_msgs/Header") == ("std_msgs", "Header")
    for bad in ("LaserScan", "sensor_msgs/srv/SetBool", "a/msg/", "a/b/c/d"):
        with pytest.raises(ValueError):
            split_type_name(bad)


def test_field_types_skips_primitives_comments_and_constants():
    text = """# a comment with pkg/Type words
uint8 ADD=0  # constant
string NAME = "x"
std_msgs/Header header
float32[] ranges
Point[<=3] points   # same package
string<=10 label
builtin_interfaces/Duration[2] lifetimes
int32 count 5
"""
    assert field_types(text, "geometry_msgs") == [
        "std_msgs/Header",
        "geometry_msgs/Point",
        "builtin_interfaces/Duration",
    ]
    with pytest.raises(ValueError, match="cannot parse"):
        field_types("float32{} x", "p")


def test_full_definition_layout_matches_rosbag2():
    definitions = MessageDefinitions()
    text = definitions.full_definition("sensor_msgs/msg/LaserScan")
    assert text.startswith(definitions.msg_text("sensor_msgs/LaserScan"))
    sections = text.split(f"\n{SEPARATOR}\n")
    assert [s.splitlines()[0] for s in sections[1:]] == ["MSG: std_msgs/Header", "MSG: builtin_interfaces/Time"]
    # MarkerArray pulls in Marker, and each dependency once however often it is used
    markers = definitions.full_definition("visualization_msgs/msg/MarkerArray")
    for dependency in ("visualization_msgs/Marker", "geometry_msgs/Pose", "std_msgs/ColorRGBA", "builtin_interfaces/Duration"):
        assert markers.count(f"MSG: {dependency}\n") == 1
    with pytest.raises(LookupError):
        definitions.msg_text("no_such_msgs/msg/Nothing")


@pytest.mark.parametrize("type_name", DEMO_TYPES)
def test_full_definition_parses_to_the_reference_jazzy_types(type_name):
    """rosbags' msg parser reads our text into exactly the types rosbags ships for Jazzy."""
    parsed = get_types_from_msg(MessageDefinitions().full_definition(type_name), type_name)
    reference = get_typestore(Stores.ROS2_JAZZY).fielddefs
    assert type_name in parsed
    for name, (constants, fields) in parsed.items():
        ref_constants, ref_fields = reference[name]
        assert [f[0] for f in fields] == [f[0] for f in ref_fields], name
        assert fields == ref_fields, name
        assert sorted(c[0] for c in constants) == sorted(c[0] for c in ref_constants), name


def test_writer_round_trip(tmp_path):
    path = tmp_path / "run.mcap"
    scan = LaserScan(angle_min=0.0, angle_increment=math.radians(1.0), range_max=3.5, ranges=[1.0, 0.0, 2.5])
    scan.header.frame_id = "base_scan"
    scan.header.stamp.sec = 3
    markers = MarkerArray(markers=[Marker(id=4, points=[Point(x=1.0, y=2.0)])])
    with Ros2McapWriter(path) as writer:
        writer.add_topic("/scan", "sensor_msgs/msg/LaserScan", qos_profiles_yaml([QoSProfile(depth=5)]))
        writer.add_topic("/slam/map", "visualization_msgs/msg/MarkerArray", type_hash="RIHS01_00")
        with pytest.raises(ValueError, match="already"):
            writer.add_topic("/scan", "sensor_msgs/msg/LaserScan")
        for k in range(3):
            writer.write("/scan", serialize_message(scan), 1_000 + k)
        writer.write("/slam/map", serialize_message(markers), 2_000)
        with pytest.raises(KeyError):
            writer.write("/nowhere", b"", 0)
    assert writer.message_count == 4
    messages, connections = read_bag(path)
    assert [t for t, _ in messages["/scan"]] == [1_000, 1_001, 1_002]
    decoded = messages["/scan"][0][1]
    assert decoded.header.frame_id == "base_scan" and decoded.header.stamp.sec == 3
    assert decoded.ranges.tolist() == [1.0, 0.0, 2.5] and decoded.range_max == pytest.approx(3.5)
    (marker,) = messages["/slam/map"][0][1].markers
    assert marker.id == 4 and (marker.points[0].x, marker.points[0].y) == (1.0, 2.0)
    assert connections["/scan"].msgtype == "sensor_msgs/msg/LaserScan"
    assert connections["/scan"].ext.offered_qos_profiles[0].depth == 5


@pytest.mark.ros
def test_topic_recorder_hears_every_publisher_qos(ros, tmp_path):
    source = ros.node("source")
    latched = source.create_publisher(
        MarkerArray, "obstacles", QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    )
    # published before the recorder exists: only a transient-local subscription receives it
    latched.publish(MarkerArray(markers=[Marker(id=7)]))
    scans = source.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
    joints = source.create_publisher(JointState, "joint_states", 10)
    chatter = source.create_publisher(String, "ignored", 10)
    path = tmp_path / "run.mcap"
    writer = Ros2McapWriter(path)
    recorder = ros.add(TopicRecorder(writer, exclude=["/ignored"], context=ros.context))
    wanted = {"/obstacles", "/scan", "/joint_states"}
    assert ros.spin_until(lambda: wanted <= set(recorder.recorded_topics), timeout_s=10.0)
    # let the new subscriptions match their publishers before publishing
    ros.spin_for(0.5)
    for k in range(5):
        scans.publish(LaserScan(ranges=[float(k)]))
        joints.publish(JointState(name=["wheel_left_joint"], position=[0.1 * k]))
        chatter.publish(String(data="not recorded"))
    assert ros.spin_until(lambda: writer.message_count >= 11, timeout_s=10.0)
    writer.close()
    messages, connections = read_bag(path)
    assert "/ignored" not in messages
    assert [m.ranges.tolist() for _, m in messages["/scan"]] == [[float(k)] for k in range(5)]
    assert [m.position.tolist() for _, m in messages["/joint_states"]] == [[0.1 * k] for k in range(5)]
    assert [m.markers[0].id for _, m in messages["/obstacles"]] == [7]
    # the publishers' QoS is in the channel metadata, as rosbag2 stores it
    assert connections["/scan"].ext.offered_qos_profiles[0].reliability.name == "BEST_EFFORT"
    assert connections["/obstacles"].ext.offered_qos_profiles[0].durability.name == "TRANSIENT_LOCAL"
