"""nuturtle_tools.recorder: the rosbag2 bag writer and the live topic recorder.

Every bag is read back independently of rosbags (which writes it), see bag_reading.py: the `mcap` library for
the MCAP layer, rclpy's deserialize_message with the real message classes for the CDR, yaml for metadata.yaml.
"""

import sys
import threading

import numpy as np
import pytest
import yaml
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from rclpy.duration import Duration
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    QoSCompatibility,
    QoSProfile,
    ReliabilityPolicy,
    qos_check_compatible,
    qos_profile_sensor_data,
)
from rclpy.serialization import serialize_message
from rosbags.typesys import Stores, get_typestore
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, LaserScan
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from bag_reading import SEPARATOR, definition_sections, rclpy_definitions, read_bag
from nuturtle_tools.recorder import RECORD_DEPTH, BagWriter, TopicRecorder, recording_qos
from rclpy_harness import RosHarness, matched, record_rosout, warnings_of

SCAN = "sensor_msgs/msg/LaserScan"
JOINTS = "sensor_msgs/msg/JointState"
MARKERS = "visualization_msgs/msg/MarkerArray"
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
T0_NS = 1_700_000_000_000_000_000
SCAN_PERIOD_NS = 200_000_000
JOINT_PERIOD_NS = 50_000_000


def scan_message(rng: np.random.Generator, stamp_s: int) -> LaserScan:
    ranges_m = rng.uniform(0.1, 3.5, 360).tolist()
    scan = LaserScan(angle_increment=np.radians(1.0), range_max=3.5, ranges=ranges_m)
    scan.header.frame_id = "base_scan"
    scan.header.stamp.sec = stamp_s
    return scan


def joints_message(rng: np.random.Generator) -> JointState:
    positions_rad = rng.normal(0.0, 10.0, 2).tolist()
    return JointState(name=["wheel_left_joint", "wheel_right_joint"], position=positions_rad)


def write_demo_bag(path, rng):
    """A bag of 5 scans (sensor data QoS), 20 joint states (default QoS, 1.5 s deadline) and one latched
    marker array, written in time order; returns the writer and, per topic, the (time, message, CDR bytes)
    written (the bytes, as rclpy leaves CDR padding uninitialised, differ between two serialisations)."""
    published = {"/scan": [], "/joint_states": [], "/map": []}

    def write(topic, message, t_ns):
        data = serialize_message(message)
        writer.write(topic, data, t_ns)
        published[topic].append((t_ns, message, data))

    with BagWriter(path) as writer:
        writer.add_topic("/scan", SCAN, [qos_profile_sensor_data])
        writer.add_topic("/joint_states", JOINTS, [QoSProfile(depth=10, deadline=Duration(seconds=1.5))])
        writer.add_topic("/map", MARKERS, [LATCHED])
        markers = MarkerArray(markers=[Marker(id=4, points=[Point(x=1.0, y=2.0)])])
        write("/map", markers, T0_NS)
        for k in range(20):
            t_ns = T0_NS + k * JOINT_PERIOD_NS
            write("/joint_states", joints_message(rng), t_ns)
            if k % 4 == 0:
                write("/scan", scan_message(rng, k), t_ns)
    return writer, published


def test_bag_writer_writes_a_rosbag2_bag_of_mcap_storage(tmp_path):
    rng = np.random.default_rng(7)
    bag_dir = tmp_path / "run"
    writer, published = write_demo_bag(bag_dir, rng)
    counts = {topic: len(messages) for topic, messages in published.items()}
    assert counts == {"/scan": 5, "/joint_states": 20, "/map": 1}
    assert writer.message_counts == counts and writer.message_count == 26
    assert writer.topics == ["/scan", "/joint_states", "/map"]
    assert sorted(p.name for p in bag_dir.iterdir()) == ["metadata.yaml", "run.mcap"]

    bag = read_bag(bag_dir)
    # MCAP layer
    assert bag.profile == "ros2"
    assert set(bag.schemas) == {SCAN, JOINTS, MARKERS}
    for type_name, schema in bag.schemas.items():
        assert schema.encoding == "ros2msg"
        text = schema.data.decode("utf-8")
        expected = rclpy_definitions(type_name)
        assert definition_sections(text) == expected, type_name
        assert text.count(SEPARATOR) == len(expected) - 1, f"{type_name}: a dependency is repeated"
    assert bag.channel_types == {"/scan": SCAN, "/joint_states": JOINTS, "/map": MARKERS}
    assert {channel.message_encoding for channel in bag.channels.values()} == {"cdr"}
    (scan_qos,) = yaml.safe_load(bag.channels["/scan"].metadata["offered_qos_profiles"])
    assert (scan_qos["reliability"], scan_qos["durability"]) == ("best_effort", "volatile")
    assert scan_qos["depth"] == qos_profile_sensor_data.depth
    assert bag.summary_counts == counts
    times_ns = [record.log_time_ns for record in bag.records]
    assert times_ns == sorted(times_ns)
    assert all(record.publish_time_ns == record.log_time_ns for record in bag.records)
    for topic, messages in published.items():
        assert [r.log_time_ns for r in bag.topic_records(topic)] == [t for t, _, _ in messages], topic
        assert [r.data for r in bag.topic_records(topic)] == [data for _, _, data in messages], topic

    # CDR decoded by rclpy: float32 ranges are the published values rounded to float32, nothing else
    for decoded, (_, sent, _) in zip(bag.decoded("/scan"), published["/scan"], strict=True):
        np.testing.assert_array_equal(np.asarray(decoded.ranges), np.asarray(sent.ranges, dtype=np.float32))
        assert decoded.header.frame_id == "base_scan" and decoded.header.stamp.sec == sent.header.stamp.sec
        assert decoded.range_max == 3.5
    for decoded, (_, sent, _) in zip(bag.decoded("/joint_states"), published["/joint_states"], strict=True):
        assert decoded.name == sent.name and list(decoded.position) == list(sent.position)
    ((marker,),) = [m.markers for m in bag.decoded("/map")]
    assert marker.id == 4 and (marker.points[0].x, marker.points[0].y) == (1.0, 2.0)

    # rosbag2 metadata
    info = bag.metadata
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["run.mcap"]
    assert info["message_count"] == 26
    assert info["starting_time"]["nanoseconds_since_epoch"] == T0_NS
    assert info["duration"]["nanoseconds"] == 19 * JOINT_PERIOD_NS
    # rosbag2 reads custom_data as a map of strings
    assert info["custom_data"] and all(isinstance(v, str) for v in info["custom_data"].values())
    topics = bag.topic_metadata()
    assert {topic: entry["message_count"] for topic, entry in topics.items()} == counts
    assert {topic: entry["type"] for topic, entry in topics.items()} == bag.channel_types
    assert {entry["serialization_format"] for entry in topics.values()} == {"cdr"}
    assert all(entry["type_description_hash"].startswith("RIHS01_") for entry in topics.values())
    (joint_qos,) = topics["/joint_states"]["offered_qos_profiles"]
    assert joint_qos["reliability"] == "reliable" and joint_qos["history"] == "keep_last"
    assert joint_qos["deadline"] == {"sec": 1, "nsec": 500_000_000}
    (map_qos,) = topics["/map"]["offered_qos_profiles"]
    assert (map_qos["durability"], map_qos["depth"]) == ("transient_local", 1)
    assert yaml.safe_load(bag.channels["/map"].metadata["offered_qos_profiles"]) == [map_qos]


def test_bag_writer_refuses_what_it_cannot_record(tmp_path):
    path = tmp_path / "run"
    writer = BagWriter(path)
    writer.add_topic("/scan", SCAN)
    with pytest.raises(ValueError, match="already"):
        writer.add_topic("/scan", SCAN)
    with pytest.raises(LookupError, match="does not know"):
        writer.add_topic("/custom", "no_such_msgs/msg/Nothing")
    with pytest.raises(LookupError, match="not the typestore's"):
        writer.add_topic("/other_scan", SCAN, type_hashes=["RIHS01_" + "00" * 32])
    assert writer.topics == ["/scan"]
    with pytest.raises(KeyError):
        writer.write("/nowhere", b"", 0)
    writer.write("/scan", serialize_message(LaserScan()), 5)
    with pytest.raises(FileExistsError):
        BagWriter(path)
    writer.close()
    writer.close()
    writer.write("/scan", serialize_message(LaserScan()), 6)
    assert writer.message_count == 1
    assert read_bag(path).metadata["message_count"] == 1


def test_bag_writer_replaces_only_a_bag(tmp_path):
    path = tmp_path / "run"
    with BagWriter(path) as first:
        first.add_topic("/a", JOINTS)
        for k in range(3):
            first.write("/a", serialize_message(JointState()), k)
    with BagWriter(path, overwrite=True) as second:
        second.add_topic("/b", JOINTS)
        second.write("/b", serialize_message(JointState()), 10)
    bag = read_bag(path)
    assert set(bag.channels) == {"/b"} and bag.metadata["message_count"] == 1

    (path / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="not a rosbag2"):
        BagWriter(path, overwrite=True)
    assert (path / "notes.txt").read_text() == "mine" and (path / "metadata.yaml").is_file()
    a_file = tmp_path / "plain"
    a_file.write_text("x")
    with pytest.raises(FileExistsError):
        BagWriter(a_file, overwrite=True)


def test_bag_writer_is_thread_safe(tmp_path):
    threads_n, messages_n = 4, 300
    start = threading.Barrier(threads_n)

    def produce(writer: BagWriter, i: int) -> None:
        start.wait()
        for k in range(messages_n):
            writer.write(f"/t{i}", serialize_message(JointState(position=[float(i), float(k)])), k)

    switch_interval_s = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads every microsecond, so that unguarded writes interleave
    try:
        with BagWriter(tmp_path / "run") as writer:
            for i in range(threads_n):
                writer.add_topic(f"/t{i}", JOINTS)
            threads = [threading.Thread(target=produce, args=(writer, i)) for i in range(threads_n)]
            for thread in threads:
                thread.start()
            for thread in threads:
                thread.join()
    finally:
        sys.setswitchinterval(switch_interval_s)
    assert writer.message_count == threads_n * messages_n
    bag = read_bag(tmp_path / "run")
    assert bag.metadata["message_count"] == threads_n * messages_n
    for i in range(threads_n):
        positions = [tuple(m.position) for m in bag.decoded(f"/t{i}")]
        assert positions == [(float(i), float(k)) for k in range(messages_n)]


BEST_EFFORT = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)


@pytest.mark.parametrize(
    ("offered", "reliability", "durability"),
    [
        ([QoSProfile(depth=10)], ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE),
        ([qos_profile_sensor_data], ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE),
        ([LATCHED, LATCHED], ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL),
        ([LATCHED, QoSProfile(depth=10)], ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE),
        ([LATCHED, BEST_EFFORT], ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE),
    ],
)
def test_recording_qos_is_compatible_with_every_publisher(offered, reliability, durability):
    qos = recording_qos(offered)
    assert (qos.reliability, qos.durability, qos.depth) == (reliability, durability, RECORD_DEPTH)
    for publisher in offered:
        # WARNING only says that system-default liveliness cannot be checked before matching
        compatibility, reason = qos_check_compatible(publisher, qos)
        assert compatibility != QoSCompatibility.ERROR, reason


def test_a_transient_local_subscription_would_miss_a_volatile_publisher():
    """Why recording_qos asks for transient local only when every publisher offers it."""
    compatibility, _ = qos_check_compatible(QoSProfile(depth=10), LATCHED)
    assert compatibility == QoSCompatibility.ERROR


def without_string_type():
    """The Jazzy typestore minus std_msgs/msg/String."""
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    store = get_typestore(Stores.EMPTY)
    store.register({name: defs for name, defs in jazzy.fielddefs.items() if name != "std_msgs/msg/String"})
    return store


@pytest.fixture
def other_participant():
    """A node in a context (DDS participant) of its own: it may publish a topic name with another type."""
    harness = RosHarness()
    yield harness.node("other_source")
    harness.shutdown()


@pytest.mark.ros
def test_topic_recorder_hears_every_publisher_qos_in_simulation_time(ros, other_participant, tmp_path):
    sim_s = 1234
    source = ros.node("source")
    logs = record_rosout(source)
    clock = source.create_publisher(Clock, "/clock", 10)
    source.create_timer(0.05, lambda: clock.publish(Clock(clock=Time(sec=sim_s))))
    latched = source.create_publisher(MarkerArray, "obstacles", LATCHED)
    # published before the recorder exists: only a transient-local subscription receives it
    latched.publish(MarkerArray(markers=[Marker(id=7)]))
    scans = source.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
    joints = source.create_publisher(JointState, "joint_states", 10)
    mixed = [source.create_publisher(Point, "mixed", qos) for qos in (LATCHED, QoSProfile(depth=10))]
    source.create_publisher(String, "ignored", 10)
    source.create_publisher(String, "chatter", 10)  # a type the recorder's typestore does not know
    source.create_publisher(String, "clash", 10)
    other_participant.create_publisher(Point, "clash", 10)  # two types on one topic
    assert ros.spin_until(lambda: len(dict(source.get_topic_names_and_types()).get("/clash", [])) == 2)

    writer = BagWriter(tmp_path / "run", typestore=without_string_type())
    sim_time = [Parameter("use_sim_time", value=True)]
    recorder = ros.add(
        TopicRecorder(writer, exclude=["/ignored"], context=ros.context, parameter_overrides=sim_time)
    )
    wanted = {"/obstacles", "/scan", "/joint_states", "/mixed", "/clock"}
    assert ros.spin_until(lambda: wanted <= set(recorder.recorded_topics), timeout_s=10.0)
    assert ros.spin_until(lambda: recorder.get_clock().now().nanoseconds == sim_s * 10**9, timeout_s=10.0)
    assert ros.spin_until(lambda: matched(scans, joints, *mixed), timeout_s=10.0)
    for k in range(5):
        scans.publish(LaserScan(ranges=[float(k)]))
        joints.publish(JointState(name=["wheel_left_joint"], position=[0.1 * k]))
    for k, publisher in enumerate(mixed):
        publisher.publish(Point(x=float(k)))
    expected = {"/scan": 5, "/joint_states": 5, "/mixed": 2, "/obstacles": 1}

    def all_arrived() -> bool:
        counts = writer.message_counts
        return all(counts.get(topic, 0) >= n for topic, n in expected.items())

    assert ros.spin_until(all_arrived, timeout_s=10.0)
    ros.spin_for(0.5)  # several more discovery rounds: still one warning per left-out topic
    scan_hash = str(source.get_publishers_info_by_topic("/scan")[0].topic_type_hash)
    writer.close()

    warnings = warnings_of(logs, "recorder")
    for topic, reason in (("/chatter", "does not know std_msgs/msg/String"), ("/clash", "several types")):
        assert len([w for w in warnings if w.startswith(f"not recording {topic}:")]) == 1, warnings
        assert any(reason in w for w in warnings if topic in w), warnings
    bag = read_bag(tmp_path / "run")
    assert not {"/ignored", "/chatter", "/clash"} & set(bag.channels)
    assert {topic: bag.summary_counts[topic] for topic in expected} == expected
    assert [list(m.ranges) for m in bag.decoded("/scan")] == [[float(k)] for k in range(5)]
    assert [list(m.position) for m in bag.decoded("/joint_states")] == [[0.1 * k] for k in range(5)]
    assert sorted(m.x for m in bag.decoded("/mixed")) == [0.0, 1.0]
    assert [m.markers[0].id for m in bag.decoded("/obstacles")] == [7]
    # stamped with the recorder's clock at reception: simulation time
    for topic in ("/scan", "/joint_states", "/mixed"):
        assert {r.log_time_ns for r in bag.topic_records(topic)} == {sim_s * 10**9}, topic
    # the publishers' QoS as rosbag2 stores it, and the middleware's type hash
    topics = bag.topic_metadata()
    assert [q["reliability"] for q in topics["/scan"]["offered_qos_profiles"]] == ["best_effort"]
    assert [q["durability"] for q in topics["/obstacles"]["offered_qos_profiles"]] == ["transient_local"]
    assert sorted(q["durability"] for q in topics["/mixed"]["offered_qos_profiles"]) == [
        "transient_local",
        "volatile",
    ]
    assert topics["/scan"]["type_description_hash"] == scan_hash
