"""nuturtle_ros_common.dds_domain: the DDS world of a demo or replay run. The choice of a private domain
(real flock locks, a real bound UDP port read back from /proc), then a private context in real rclpy over
Fast DDS: its nodes talk to each other, while ROS programs that join its very domain id hear nothing of it
and are not heard. The two-demos-at-once test is tests/nuturtle_demo/test_demo_domains.py."""

import os
import socket
import time

import pytest

from nuturtle_ros_common.dds_domain import (
    bound_udp_ports,
    domain_choice,
    domain_ports,
    lease_domain,
    run_context,
)


@pytest.mark.parametrize(
    ("value", "expected"), [("private", "private"), ("env", "env"), (0, 0), ("232", 232), (" 7 ", 7)]
)
def test_a_domain_choice_is_private_env_or_an_id_up_to_232(value, expected):
    assert domain_choice("domain_id", value) == expected


@pytest.mark.parametrize("value", [-1, 233, "300", "x", "", True, 1.5, None])
def test_any_other_domain_choice_is_refused(value):
    with pytest.raises(ValueError, match="domain_id"):
        domain_choice("domain_id", value)


def test_the_replay_is_private_unless_it_only_plays_for_the_users_nodes(tmp_path):
    from nuturtle_tools.replay_run import ReplayOptions

    assert ReplayOptions(bag=tmp_path).domain == "private"
    assert ReplayOptions(bag=tmp_path, play_only=True).domain == "env"
    assert ReplayOptions(bag=tmp_path, play_only=True, domain_id="private").domain == "private"
    assert ReplayOptions(bag=tmp_path, domain_id="12").domain == 12


def test_runs_lease_distinct_free_domains_until_released(tmp_path):
    shell = int(os.environ["ROS_DOMAIN_ID"])
    # four domains below the ephemeral ports with no UDP port bound in their blocks right now
    bound = bound_udp_ports()
    idle = [d for d in range(100, 1, -1) if d != shell and bound.isdisjoint(domain_ports(d))]
    taken, *free = candidates = idle[:4]
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", domain_ports(taken)[11]))  # as a DDS participant's unicast port
    try:
        # the shell's own domain and a domain with a bound port are skipped; each lease locks another id
        first = lease_domain([shell, *candidates], tmp_path)
        second = lease_domain([shell, *candidates], tmp_path)
        third = lease_domain([shell, *candidates], tmp_path)
        assert [first.domain_id, second.domain_id, third.domain_id] == free
        with pytest.raises(OSError, match="no free DDS domain"):
            lease_domain(candidates, tmp_path)
        second.release()
        again = lease_domain(candidates, tmp_path)
        assert again.domain_id == free[1]
        for lease in (first, third, again):
            lease.release()
    finally:
        udp.close()
    last = lease_domain(candidates, tmp_path)
    assert last.domain_id == taken
    last.release()


def test_a_private_run_hears_its_own_nodes_only_even_beside_programs_on_its_domain_id():
    """A private context's two nodes exchange messages; two plain contexts (as a user's ROS programs, the
    suite's LOCALHOST discovery) in the same domain id find each other, but neither them and the private
    context. The environment is the same afterwards."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import String

    environment = dict(os.environ)
    private = run_context("private")
    domain_id = private.get_domain_id()
    assert dict(os.environ) == environment
    outside = []
    for _ in range(2):
        context = Context()
        rclpy.init(context=context, domain_id=domain_id)
        outside.append(context)
    heard = {"private": [], "outsider": []}
    executors, nodes = [], []
    try:
        for context, name in ((private, "private"), (outside[0], "outsider")):
            node = Node(f"{name}_listener", context=context)
            node.create_subscription(
                String, "probe", lambda msg, name=name: heard[name].append(msg.data), 100
            )
            nodes.append(node)
        talkers = {}
        for context, name in ((private, "private"), (outside[1], "outsider")):
            node = Node(f"{name}_talker", context=context)
            talkers[name] = node.create_publisher(String, "probe", 100)
            nodes.append(node)
        for context in (private, *outside):
            executor = SingleThreadedExecutor(context=context)
            for node in nodes:
                if node.context is context:
                    executor.add_node(node)
            executors.append(executor)

        deadline = time.monotonic() + 10.0
        # until the outsiders have heard each other (their discovery works), then a little longer
        while time.monotonic() < deadline and "outsider" not in heard["outsider"]:
            for name, publisher in talkers.items():
                publisher.publish(String(data=name))
            for executor in executors:
                executor.spin_once(timeout_sec=0.01)
        assert "outsider" in heard["outsider"], "the plain contexts did not discover each other"
        for _ in range(20):
            for name, publisher in talkers.items():
                publisher.publish(String(data=name))
            for executor in executors:
                executor.spin_once(timeout_sec=0.01)
        assert set(heard["private"]) == {"private"}
        assert set(heard["outsider"]) == {"outsider"}
        assert nodes[0].count_publishers("probe") == 1 and nodes[1].count_publishers("probe") == 1
        assert "private_talker" not in nodes[1].get_node_names()
    finally:
        for executor in executors:
            executor.shutdown()
        for node in nodes:
            node.destroy_node()
        for context in (private, *outside):
            rclpy.try_shutdown(context=context)
    assert dict(os.environ) == environment
