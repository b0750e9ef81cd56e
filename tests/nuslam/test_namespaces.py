"""Two robots in one DDS domain (real rclpy, one process): odometry, landmarks and slam of `tb3_0` and of
`tb3_1`, each started with its namespace and its prefixed frame ids as the launch files give them
(`robot_frames`), each fed its own joint_states and scans.

Each stack's topics and services exist under its namespace only (besides the global /rosout,
/parameter_events, /diagnostics, /tf), no node subscribes to the other robot's topics, every frame id
each one writes (odom, slam/odom, slam/map, slam/path, the grid, the landmarks, map -> odom and
odom -> base_footprint) carries its robot's prefix, their statuses on the shared /diagnostics are named
by robot, and each slam follows its own robot's motion: the two robots drive different arcs in one
world.
"""

from __future__ import annotations

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid as OccupancyGridMsg
from nav_msgs.msg import Odometry, Path
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from ros_test_messages import node_inputs_matched, stamp
from sensor_msgs.msg import JointState, LaserScan
from test_slam_node import WHEELS, Arc, S, TfRecorder, joint_state, pose_of
from visualization_msgs.msg import MarkerArray

from nuslam.landmarks_node import LandmarksNode
from nuslam.slam_node import MAP_QOS, SlamNode
from nuturtle_control.odometry import OdometryNode
from nuturtle_description.robot_params import burger_params
from nuturtle_ros_common.launch_parameters import RobotFrames, robot_frames
from rclpy_harness import matched
from turtlelib import LidarConfig, Transform2D, arena_walls, simulate_scan

pytestmark = pytest.mark.ros

LIDAR = LidarConfig(noise=0.005, resolution=0.01)
T_BODY_SCAN = Transform2D(burger_params().lidar_x, burger_params().lidar_y, burger_params().lidar_yaw)
WALLS = arena_walls(3.0, 2.5)
CIRCLES = np.array([[0.8, 0.5, 0.1], [-0.7, -0.4, 0.1], [0.2, -0.9, 0.1]])
# topics every node has whatever its namespace
GLOBAL = {"/rosout", "/parameter_events", "/diagnostics", "/tf", "/tf_static"}
SCANS = 8


class Robot:
    """One robot's nodes under ``frames.namespace`` and a helper there that feeds and records them; its
    arc starts at ``T_world_start`` in the shared world (slam's map starts at the robot's start)."""

    def __init__(self, ros, frames: RobotFrames, T_world_start: Transform2D, arc: Arc) -> None:
        self.frames, self.T_world_start, self.arc = frames, T_world_start, arc
        ns = frames.namespace
        slam = {
            **frames.slam(),
            "observation_timeout": 100.0,
            "max_sample_gap": 1.0,
            "scan_registration": False,
            "grid.publish_period_s": 0.2,
        }
        self.slam = ros.add(SlamNode(context=ros.context, namespace=ns, parameter_overrides=overrides(slam)))
        self.odometry = ros.add(
            OdometryNode(context=ros.context, namespace=ns, parameter_overrides=overrides(frames.odometry()))
        )
        self.landmarks = ros.add(LandmarksNode(context=ros.context, namespace=ns))
        # /tf needs tf2_msgs (on every ROS install, on no registry): what each node sends is recorded
        self.tf = self.slam._map_to_odom._tf = self.odometry._tf = TfRecorder()
        helper = ros.node("helper", namespace=ns)
        self.received: dict[str, list] = {}
        self.joint_states = helper.create_publisher(JointState, "joint_states", 10)
        self.scans = helper.create_publisher(LaserScan, "scan", qos_profile_sensor_data)
        initial = helper.create_publisher(PoseWithCovarianceStamped, "initialpose", 10)  # RViz's, unused
        outputs = [
            ("odom", Odometry, 100),
            ("slam/odom", Odometry, 100),
            ("slam/map", MarkerArray, 100),
            ("slam/path", Path, 100),
            ("odometry/path", Path, 100),
            ("landmarks", MarkerArray, 100),
            ("map", OccupancyGridMsg, MAP_QOS),
        ]
        endpoints = [self.joint_states, self.scans, initial]
        for topic, message_type, qos in outputs:
            self.received[topic] = []
            endpoints.append(
                helper.create_subscription(message_type, topic, self.received[topic].append, qos)
            )
        nodes = (self.slam, self.odometry, self.landmarks)
        assert ros.spin_until(lambda: matched(*endpoints) and all(map(node_inputs_matched, nodes)), 10.0)

    def drive(self, t_ns: int, rng: np.random.Generator) -> None:
        """joint_states at ``t_ns`` and a scan half-way to the previous sample, from the true poses."""
        self.joint_states.publish(joint_state(t_ns, self.arc.angles(t_ns), WHEELS))
        t_scan = t_ns - S // 10
        T_world_scan = self.T_world_start @ self.arc.pose(t_scan) @ T_BODY_SCAN
        msg = LaserScan(angle_min=LIDAR.angle_min, angle_increment=LIDAR.angle_increment)
        msg.angle_max = LIDAR.angle_min + (LIDAR.samples - 1) * LIDAR.angle_increment
        msg.range_min, msg.range_max = LIDAR.range_min, LIDAR.range_max
        msg.header.stamp, msg.header.frame_id = stamp(t_scan), self.frames.sensor_id
        msg.ranges = simulate_scan(T_world_scan, CIRCLES, WALLS, LIDAR, rng).tolist()
        self.scans.publish(msg)

    def frame_ids(self) -> set[str]:
        """Every frame id in what this robot's nodes published (and sent as transforms)."""
        ids = {frame for t in self.tf.sent for frame in (t.header.frame_id, t.child_frame_id)}
        for messages in self.received.values():
            for msg in messages:
                if isinstance(msg, MarkerArray):
                    ids.update(marker.header.frame_id for marker in msg.markers)
                    continue
                ids.add(msg.header.frame_id)
                if isinstance(msg, Odometry):
                    ids.add(msg.child_frame_id)
                if isinstance(msg, Path):
                    ids.update(pose.header.frame_id for pose in msg.poses)
        return ids


def overrides(values: dict) -> list[Parameter]:
    return [Parameter(name, value=value) for name, value in values.items()]


def graph_names(helper, node) -> set[str]:
    """The topics (published or subscribed) and services of ``node``, as the ROS graph shows them."""
    name, ns = node.get_name(), node.get_namespace()
    topics = [
        *helper.get_publisher_names_and_types_by_node(name, ns),
        *helper.get_subscriber_names_and_types_by_node(name, ns),
        *helper.get_service_names_and_types_by_node(name, ns),
    ]
    return {topic for topic, _ in topics}


def test_two_namespaced_stacks_in_one_domain_keep_to_their_own_topics_frames_and_motion(ros):
    turning, reversing = Arc(Transform2D(), S, vx=0.15, omega=0.8), Arc(Transform2D(), S, vx=-0.1, omega=0.0)
    robots = [
        Robot(ros, robot_frames("tb3_0"), Transform2D(), turning),
        Robot(ros, robot_frames("tb3_1"), Transform2D(0.3, -0.3, 2.0), reversing),
    ]
    rng = np.random.default_rng(11)
    for k in range(SCANS + 1):
        for robot in robots:
            robot.drive(S + k * S // 5, rng)
        # each scan's landmarks out before the next joint_states: a loaded machine must not make them late
        # for slam (max_observation_delay), whatever its pace
        ros.spin_until(lambda k=k: all(len(r.received["landmarks"]) > k for r in robots), 5.0)
    last_ns = S + SCANS * S // 5
    for robot in robots:
        assert ros.spin_until(lambda r=robot: len(r.received["slam/map"]) >= SCANS - 1, 10.0), "scans fused"
        assert ros.spin_until(lambda r=robot: r.received["map"], 5.0), "the grid"

    observer = ros.node("observer")
    arrays: list[DiagnosticArray] = []
    observer.create_subscription(DiagnosticArray, "/diagnostics", arrays.append, 10)
    reported = lambda: {s.hardware_id for array in arrays for s in array.status}  # noqa: E731
    everyone = {f"{ns}/{node}" for ns in ("tb3_0", "tb3_1") for node in ("slam", "landmarks")}
    assert ros.spin_until(lambda: reported() >= everyone, 5.0), reported()
    assert all(s.name.startswith(s.hardware_id + ": ") for array in arrays for s in array.status)
    for robot, other in zip(robots, robots[::-1], strict=True):
        own, foreign = f"/{robot.frames.namespace}/", f"/{other.frames.namespace}/"
        for node in (robot.slam, robot.odometry, robot.landmarks):
            names = graph_names(observer, node)
            assert {f"{own}scan", f"{own}slam/odom", f"{own}odom"} & names, node.get_name()
            strays = {name for name in names if not name.startswith(own) and name not in GLOBAL}
            assert not strays, (node.get_fully_qualified_name(), strays)
            assert not any(name.startswith(foreign) for name in names)
        # every frame it wrote is its own, and the frames are the launch files' ones
        frames = robot.frame_ids()
        assert all(frame.startswith(own[1:]) for frame in frames), frames
        expected = {robot.frames.map_id, robot.frames.odom_id, robot.frames.body_id, robot.frames.sensor_id}
        assert frames == expected
        # its slam followed its own robot: the pose at the last joint_states is its arc's, in its map
        slam_odom = robot.received["slam/odom"][-1]
        x, y, theta = pose_of(slam_odom)
        T_true = robot.arc.pose(last_ns)
        assert np.hypot(x - T_true.x, y - T_true.y) < 0.02 and abs(theta - T_true.theta) < 0.02
        assert robot.received["landmarks"][-1].markers[1:], "it saw the cylinders in its own scans"
