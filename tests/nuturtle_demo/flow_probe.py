"""An independent subscriber process for tests/nuturtle_demo/test_demo_processes.py.

Usage: python flow_probe.py TIMEOUT_S MIN_MESSAGES
Subscribes to scan (sensor-data QoS), joint_states, odom and slam/odom like any ROS 2 tool would, waits
until each has delivered MIN_MESSAGES messages (or TIMEOUT_S wall seconds pass), and prints one JSON
object: per topic the message count, the advertised types, and the frame ids / joint names seen.
"""

import json
import sys
import time

import rclpy
from nav_msgs.msg import Odometry
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState, LaserScan


def main() -> None:
    timeout_s, min_messages = float(sys.argv[1]), int(sys.argv[2])
    rclpy.init()
    node = rclpy.create_node("flow_probe")
    seen = {
        topic: {"count": 0, "frames": set()} for topic in ("/scan", "/joint_states", "/odom", "/slam/odom")
    }

    def on(topic, describe):
        def callback(msg):
            seen[topic]["count"] += 1
            seen[topic]["frames"].add(describe(msg))

        return callback

    node.create_subscription(
        LaserScan, "scan", on("/scan", lambda m: m.header.frame_id), qos_profile_sensor_data
    )
    node.create_subscription(JointState, "joint_states", on("/joint_states", lambda m: ",".join(m.name)), 10)
    for topic in ("/odom", "/slam/odom"):
        node.create_subscription(
            Odometry, topic, on(topic, lambda m: f"{m.header.frame_id}->{m.child_frame_id}"), 10
        )
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and min(s["count"] for s in seen.values()) < min_messages:
        rclpy.spin_once(node, timeout_sec=0.1)
    types = dict(node.get_topic_names_and_types())
    print(json.dumps({
        topic: {"count": s["count"], "frames": sorted(s["frames"]), "types": types.get(topic, [])}
        for topic, s in seen.items()
    }))  # fmt: skip
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
