"""share_clock: the nodes of one process on one /clock subscription (real rclpy over DDS)."""

from __future__ import annotations

import pytest
from builtin_interfaces.msg import Time
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from nuturtle_ros_common.shared_clock import share_clock


def sim_time_node(ros, name: str, use_sim_time: bool = True):
    return ros.add(ros.node(name, parameter_overrides=[Parameter("use_sim_time", value=use_sim_time)]))


def test_the_nodes_of_one_process_follow_one_clock_subscription(ros):
    nodes = [sim_time_node(ros, f"shared_{k}") for k in range(3)]
    recorded: list[Clock] = []
    nodes[1].create_subscription(Clock, "/clock", recorded.append, 10)
    helper = ros.node("clock_feeder")
    clock = helper.create_publisher(Clock, "/clock", 10)
    assert ros.spin_until(lambda: clock.get_subscription_count() == 4, 10.0), "each node's own, and one more"
    share_clock(nodes)
    ros.spin_for(1.0)
    assert clock.get_subscription_count() == 2, "the first node's and the one a node made for itself"
    assert next(iter(nodes[0].subscriptions)).topic_name == "/clock", "the first node's own, still its first"
    fired = []
    for sec in (7, 8):
        clock.publish(Clock(clock=Time(sec=sec, nanosec=0)))
        assert ros.spin_until(
            lambda sec=sec: all(node.get_clock().now().nanoseconds == sec * 10**9 for node in nodes), 5.0
        ), [node.get_clock().now().nanoseconds for node in nodes]
        if sec == 7:
            # started at 7 s of sim time: due when the shared clock passes 7.5 s
            nodes[2].create_timer(0.5, lambda: fired.append(nodes[2].get_clock().now().nanoseconds))
            ros.spin_for(0.2)
            assert not fired, "no sim time passed"
    ros.spin_for(0.2)
    assert fired and fired[0] == 8 * 10**9, "a timer of another node runs on the shared sim time"
    assert [m.clock.sec for m in recorded] == [7, 8], "a node's own /clock subscription is kept"


def test_nodes_on_different_clocks_are_refused(ros):
    nodes = [sim_time_node(ros, "on_sim_time"), sim_time_node(ros, "on_wall_time", use_sim_time=False)]
    with pytest.raises(ValueError, match="must agree on use_sim_time"):
        share_clock(nodes)
    with pytest.raises(ValueError, match="at least one node"):
        share_clock([])
