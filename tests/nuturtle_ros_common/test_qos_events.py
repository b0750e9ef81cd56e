"""drop_qos_event_handlers: fewer waitables, the same messages (real rclpy over DDS)."""

from __future__ import annotations

from std_msgs.msg import String

from nuturtle_ros_common.qos_events import drop_qos_event_handlers
from rclpy_harness import matched


def test_a_node_without_its_qos_event_handlers_still_talks_and_is_destroyed_cleanly(ros):
    node = ros.node("talker_listener")
    heard: list[str] = []
    publisher = node.create_publisher(String, "chatter", 10)
    subscription = node.create_subscription(String, "chatter", lambda m: heard.append(m.data), 10)
    # ours and rclpy's own (its /parameter_events publisher)
    handlers = sum(len(endpoint.event_handlers) for endpoint in [*node.publishers, *node.subscriptions])
    waitables = len(list(node.waitables))
    assert len(publisher.event_handlers) > 0 and len(subscription.event_handlers) > 0, "rclpy's defaults"
    assert drop_qos_event_handlers(node) == handlers
    assert len(list(node.waitables)) == waitables - handlers
    assert publisher.event_handlers == [] and subscription.event_handlers == []
    assert ros.spin_until(lambda: matched(publisher, subscription), 10.0)
    publisher.publish(String(data="hello"))
    assert ros.spin_until(lambda: heard == ["hello"], 5.0)
    assert node.destroy_publisher(publisher) and node.destroy_subscription(subscription)
    assert drop_qos_event_handlers(node) == 0
