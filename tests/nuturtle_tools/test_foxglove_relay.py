"""The Foxglove relay, seen from an independent client (foxglove_client.py: websockets + rosbags): the server
on its own, the `foxglove_relay` node over DDS, and a running demo."""

from __future__ import annotations

import math
import socket
import subprocess
import sys

import numpy as np
import pytest
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import LaserScan
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from foxglove_client import FoxgloveClient
from nuturtle_tools.foxglove_relay import FoxgloveRelay, FoxgloveRelayNode, StaticTransform
from nuturtle_tools.relay_config import DEFAULT_HOST, DEFAULT_PORT, RelayConfig, parse_endpoint
from turtlelib import Transform2D

JAZZY = get_typestore(Stores.ROS2_JAZZY)
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
STRING = "std_msgs/msg/String"


def cdr(message, type_name: str) -> bytes:
    return bytes(JAZZY.serialize_cdr(message, type_name))


def string_cdr(text: str) -> bytes:
    return cdr(JAZZY.types[STRING](data=text), STRING)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("127.0.0.1:8765", ("127.0.0.1", 8765)),
        ("0.0.0.0:9000", ("0.0.0.0", 9000)),
        ("localhost", ("localhost", DEFAULT_PORT)),
        (":0", (DEFAULT_HOST, 0)),
        ("[::1]:8766", ("::1", 8766)),
        ("[::1]", ("::1", DEFAULT_PORT)),
    ],
)
def test_endpoints_parse_with_the_defaults_for_what_is_left_out(text, expected):
    assert parse_endpoint(text) == expected


@pytest.mark.parametrize("text", ["127.0.0.1:port", "127.0.0.1:70000", "127.0.0.1:-1", "a b:1"])
def test_bad_endpoints_are_refused(text):
    with pytest.raises(ValueError, match="port|HOST:PORT|host"):
        parse_endpoint(text)


def test_the_default_binds_this_machine_only():
    assert (RelayConfig().host, RelayConfig().port) == ("127.0.0.1", 8765)


def test_a_port_in_use_is_refused_with_the_address_and_the_reason():
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        with pytest.raises(OSError, match=rf"127\.0\.0\.1:{port}: .*in use"):
            FoxgloveRelay(port=port)


def test_channels_carry_the_recording_schema_and_raw_cdr_with_log_times():
    with FoxgloveRelay(port=0) as relay:
        relay.add_topic("/chatter", STRING, [QoSProfile(depth=10)])
        client = FoxgloveClient(relay.url)
        assert client.wait_for(lambda: "/chatter" in client.channels)
        channel = client.channels["/chatter"]
        definition, _ = JAZZY.generate_msgdef(STRING, ros_version=2)
        assert (channel["schemaName"], channel["schemaEncoding"], channel["encoding"]) == (
            STRING, "ros2msg", "cdr",
        )  # fmt: skip
        assert channel["schema"] == definition
        assert client.server_info["capabilities"] == ["time"]
        client.subscribe(["/chatter"])
        # the subscription reaches the server asynchronously: send until one arrives
        assert client.send_until_received(
            lambda k: relay.write("/chatter", string_cdr(f"m{k}"), 10**9 + k), "/chatter"
        )
        received = client.messages["/chatter"][0]
        assert client.decode(received).data == f"m{received.log_time_ns - 10**9}"
        assert relay.message_counts["/chatter"] >= 1
        assert client.times and client.times[0] == 10**9  # the clock, broadcast
        client.close()


def test_a_latched_topic_gives_its_last_message_to_a_client_that_subscribes_later():
    with FoxgloveRelay(port=0) as relay:
        relay.add_topic("/map", STRING, [LATCHED])
        relay.add_topic("/chatter", STRING, [QoSProfile(depth=10)])
        relay.write("/map", string_cdr("old"), 1)
        relay.write("/map", string_cdr("newest"), 2)
        relay.write("/chatter", string_cdr("gone"), 3)
        client = FoxgloveClient(relay.url)
        assert client.wait_for(lambda: {"/map", "/chatter"} <= set(client.channels))
        client.subscribe(["/map", "/chatter"])
        assert client.wait_for(lambda: client.messages["/map"], timeout_s=5.0)
        client.receive(0.3)
        assert [client.decode(m).data for m in client.messages["/map"]] == ["newest"]
        assert client.messages["/map"][0].log_time_ns == 2
        assert client.messages["/chatter"] == []  # volatile: nothing kept
        client.close()


def static_tf_cdr(*transforms: tuple[str, str, float]) -> bytes:
    """A /tf_static TFMessage of (parent, child, x) transforms."""
    t = JAZZY.types
    stamped = [
        t["geometry_msgs/msg/TransformStamped"](
            header=t["std_msgs/msg/Header"](
                stamp=t["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=parent
            ),
            child_frame_id=child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=0.0),
                rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
        )
        for parent, child, x in transforms
    ]
    return cdr(t["tf2_msgs/msg/TFMessage"](transforms=stamped), "tf2_msgs/msg/TFMessage")


def test_a_late_client_gets_every_publishers_static_transforms_as_tf2_holds_them():
    """Two publishers of /tf_static (the robot's mount, the world's map frame), one of them updating its
    transform: a client subscribing afterwards gets the union by child frame, newest per child."""
    with FoxgloveRelay(port=0) as relay:
        relay.add_topic("/tf_static", "tf2_msgs/msg/TFMessage", [LATCHED])
        relay.write("/tf_static", static_tf_cdr(("base_footprint", "base_scan", -0.03)), 1)
        relay.write("/tf_static", static_tf_cdr(("nusim/world", "map", 0.5)), 2)
        relay.write("/tf_static", static_tf_cdr(("base_footprint", "base_scan", -0.032)), 3)
        client = FoxgloveClient(relay.url)
        assert client.wait_for(lambda: "/tf_static" in client.channels)
        client.subscribe(["/tf_static"])
        assert client.wait_for(lambda: client.messages["/tf_static"], timeout_s=5.0)
        client.receive(0.3)
        (received,) = client.messages["/tf_static"]
        transforms = client.decode(received).transforms
        assert {(t.header.frame_id, t.child_frame_id, t.transform.translation.x) for t in transforms} == {
            ("base_footprint", "base_scan", -0.032),
            ("nusim/world", "map", 0.5),
        }
        assert received.log_time_ns == 3
        client.close()


def test_a_topic_twice_or_of_an_unknown_type_is_refused():
    with FoxgloveRelay(port=0) as relay:
        relay.add_topic("/a", STRING)
        with pytest.raises(ValueError, match="already relayed"):
            relay.add_topic("/a", STRING)
        with pytest.raises(LookupError, match="does not know"):
            relay.add_topic("/b", "no_such_msgs/msg/Nothing")
        with pytest.raises(LookupError, match="is not the typestore's"):
            relay.add_topic("/c", STRING, type_hashes=["RIHS01_" + "00" * 32])


def odometry_cdr(frame: str, child: str, x: float, y: float, theta: float, sec: int) -> bytes:
    t = JAZZY.types
    zeros = np.zeros(36)
    pose = t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
        orientation=t["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2)
        ),
    )
    vector = t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    message = t["nav_msgs/msg/Odometry"](
        header=t["std_msgs/msg/Header"](
            stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=0), frame_id=frame
        ),
        child_frame_id=child,
        pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=zeros),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](linear=vector, angular=vector), covariance=zeros
        ),
    )
    return cdr(message, "nav_msgs/msg/Odometry")


def test_without_tf_the_relay_serves_odometry_and_static_transforms_on_tf():
    mount = StaticTransform("base_footprint", "base_scan", Transform2D(-0.032, 0.0, math.pi / 2))
    with FoxgloveRelay(port=0, tf_from_odometry=["slam/odom"], static_transforms=[mount]) as relay:
        relay.add_topic("/slam/odom", "nav_msgs/msg/Odometry")
        client = FoxgloveClient(relay.url)
        assert client.wait_for(lambda: {"/tf", "/tf_static", "/slam/odom"} <= set(client.channels))
        assert client.channels["/tf"]["schemaName"] == "tf2_msgs/msg/TFMessage"
        client.subscribe(["/tf", "/tf_static"])
        assert client.wait_for(lambda: client.messages["/tf_static"], timeout_s=5.0)
        (static,) = client.decode(client.messages["/tf_static"][0]).transforms
        assert (static.header.frame_id, static.child_frame_id) == ("base_footprint", "base_scan")
        assert static.transform.translation.x == pytest.approx(-0.032, abs=1e-15)
        assert static.transform.rotation.z == pytest.approx(math.sqrt(0.5), abs=1e-15)
        assert client.send_until_received(
            lambda k: relay.write("/slam/odom", odometry_cdr("map", "base_footprint", 1.5, -2.0, 0.3, k), k),
            "/tf",
        )
        (moving,) = client.decode(client.messages["/tf"][0]).transforms
        assert (moving.header.frame_id, moving.child_frame_id) == ("map", "base_footprint")
        assert (moving.transform.translation.x, moving.transform.translation.y) == (1.5, -2.0)
        assert moving.transform.rotation.z == pytest.approx(math.sin(0.15), abs=1e-15)
        client.close()


@pytest.mark.ros
def test_the_node_relays_topics_that_appear_later_with_their_publishers_qos(ros):
    source = ros.node("late_source")
    map_publisher = source.create_publisher(MarkerArray, "slam/map", LATCHED)
    # published before the relay exists: only a transient-local subscription receives it
    map_publisher.publish(MarkerArray(markers=[Marker(id=7)]))
    relay = ros.add(FoxgloveRelayNode(context=ros.context, parameter_overrides=[Parameter("port", value=0)]))
    assert relay.get_parameter("host").value == "127.0.0.1"
    client = FoxgloveClient(relay.relay.url)
    assert ros.spin_until(lambda: "/slam/map" in relay.tap.topics)
    assert client.wait_for(lambda: "/slam/map" in client.channels)
    client.subscribe(["/slam/map"])
    assert ros.spin_until(lambda: client.receive(0.05) or bool(client.messages["/slam/map"]))
    assert client.decode(client.messages["/slam/map"][0]).markers[0].id == 7

    # a best-effort sensor topic that appears after the relay started
    scans = source.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
    assert ros.spin_until(lambda: "/scan" in relay.tap.topics)
    assert client.wait_for(lambda: "/scan" in client.channels)
    client.subscribe(["/scan"])
    ranges = [0.5, 1.25, 3.5]

    def received() -> bool:
        scans.publish(LaserScan(ranges=ranges, range_max=3.5))
        ros.spin_for(0.05)
        client.receive(0.05)
        return bool(client.messages["/scan"])

    assert ros.spin_until(received)
    decoded = client.decode(client.messages["/scan"][0])
    assert decoded.ranges.tolist() == ranges and decoded.range_max == 3.5
    assert client.messages["/scan"][0].log_time_ns > 0
    client.close()


@pytest.mark.ros
def test_the_node_leaves_out_what_it_is_told_to(ros):
    source = ros.node("excluded_source")
    source.create_publisher(String, "secret", 10)
    source.create_publisher(String, "public", 10)
    relay = ros.add(
        FoxgloveRelayNode(
            exclude=["/secret"], context=ros.context, parameter_overrides=[Parameter("port", value=0)]
        )
    )
    assert ros.spin_until(lambda: "/public" in relay.tap.topics)
    assert "/secret" not in relay.relay.topics
    relay.destroy_node()
    ros.remove(relay)


@pytest.mark.ros
def test_the_node_stops_at_start_up_when_its_port_is_in_use(tmp_path):
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        result = subprocess.run(
            [sys.executable, "-m", "nuturtle_tools.foxglove_relay", "--ros-args", "-p", f"port:={port}"],
            capture_output=True, text=True, timeout=60, cwd=tmp_path,
        )  # fmt: skip
    assert result.returncode == 1, result.stderr
    assert f"cannot start: cannot serve the Foxglove WebSocket on 127.0.0.1:{port}" in result.stderr
    assert "in use" in result.stderr and "Traceback" not in result.stderr


@pytest.mark.ros
def test_the_demo_cli_refuses_a_port_in_use(tmp_path, capsys):
    from nuturtle_demo.cli import main

    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        code = main(
            ["--foxglove", f"127.0.0.1:{port}", "--duration", "1", "--out", str(tmp_path), "--no-progress"]
        )
    assert code == 2
    assert f"127.0.0.1:{port}" in capsys.readouterr().err
    assert not (tmp_path / "metrics.json").exists()


def test_a_tee_sends_each_topic_to_the_sinks_that_take_it(tmp_path):
    from bag_reading import read_bag
    from nuturtle_tools.recorder import BagWriter, TeeSink

    with FoxgloveRelay(port=0, tf_from_odometry=["slam/odom"]) as relay, BagWriter(tmp_path / "bag") as bag:
        tee = TeeSink(bag, relay)
        tee.add_topic("/chatter", STRING)
        tee.add_topic("/tf", "tf2_msgs/msg/TFMessage")  # the relay serves its own /tf: the bag alone
        with pytest.raises(LookupError, match="does not know"):
            tee.add_topic("/custom", "no_such_msgs/msg/Nothing")
        tee.write("/chatter", string_cdr("both"), 5)
        tee.write(
            "/tf", cdr(JAZZY.types["tf2_msgs/msg/TFMessage"](transforms=[]), "tf2_msgs/msg/TFMessage"), 6
        )
        assert relay.message_counts == {"/tf": 0, "/chatter": 1}
    assert {topic: len(read_bag(tmp_path / "bag").topic_records(topic)) for topic in ("/chatter", "/tf")} == {
        "/chatter": 1,
        "/tf": 1,
    }
