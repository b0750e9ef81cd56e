"""nuturtle_demo.lockstep with real rclpy: one wait per cycle, a message published in a callback is handled
in the next cycle (one hop per physics step), the stepped node's step comes before its own callbacks, and
the pace holds cycles apart in wall time."""

import time

import pytest
from std_msgs.msg import Float64

from nuturtle_demo.lockstep import Pace, run_cycle


@pytest.mark.ros
def test_one_hop_per_cycle_and_the_step_before_the_stepped_node_s_callbacks(ros):
    events: list[str] = []
    stepped = ros.node("stepped")
    relay = ros.node("relay")
    sink = ros.node("sink")
    step_out = stepped.create_publisher(Float64, "step_out", 10)
    relay_out = relay.create_publisher(Float64, "relay_out", 10)
    to_stepped = sink.create_publisher(Float64, "to_stepped", 10)

    def on_step_out(msg: Float64) -> None:
        events.append(f"relay {msg.data:g}")
        relay_out.publish(msg)

    relay.create_subscription(Float64, "step_out", on_step_out, 10)
    sink.create_subscription(Float64, "relay_out", lambda msg: events.append(f"sink {msg.data:g}"), 10)
    stepped.create_subscription(Float64, "to_stepped", lambda msg: events.append("stepped callback"), 10)
    assert ros.spin_until(
        lambda: step_out.get_subscription_count() and relay_out.get_subscription_count()
        and to_stepped.get_subscription_count()
    )  # fmt: skip
    ros.spin_for(0.1)
    steps = [0]

    def step() -> None:
        steps[0] += 1
        events.append(f"step {steps[0]}")
        step_out.publish(Float64(data=float(steps[0])))

    def cycle() -> list[str]:
        events.clear()
        run_cycle(ros.executor, stepped, step, stepped.get_logger())
        return list(events)

    to_stepped.publish(Float64(data=0.0))
    # the stepped node's ready callback runs after its step; step 1's message waits for the next cycle
    assert cycle() == ["step 1", "stepped callback"]
    # one hop per cycle (the nodes' order within a cycle is the executor's, a set's)
    assert sorted(cycle()) == ["relay 1", "step 2"]
    assert sorted(cycle()) == ["relay 2", "sink 1", "step 3"]
    assert sorted(cycle()) == ["relay 3", "sink 2", "step 4"]


def test_the_pace_holds_cycles_apart_and_does_not_make_up_lost_time():
    pace = Pace(0.02)
    start = time.monotonic()
    for _ in range(5):
        pace.wait()
    assert time.monotonic() - start >= 4 * 0.02 - 1e-3
    time.sleep(0.1)  # a slow stretch: the next waits do not hurry to catch up
    pace.wait()
    after = time.monotonic()
    pace.wait()
    assert time.monotonic() - after >= 0.02 - 1e-3
    with pytest.raises(ValueError):
        Pace(0.0)
