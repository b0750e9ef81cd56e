"""circle in process with real rclpy: the twist it publishes, ~/reverse, ~/stop, run-time parameters."""

from __future__ import annotations

import math

import pytest
from geometry_msgs.msg import Twist
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from std_srvs.srv import Empty

from nuturtle_control.circle import CircleConfig, CircleNode
from rclpy_harness import matched

pytestmark = pytest.mark.ros

TOL = 1e-12


def test_circle_config_body_twist_is_velocity_over_radius():
    config = CircleConfig(frequency=10.0, radius=0.25, velocity=0.2)
    twist = config.body_twist(1.0)
    assert (twist.omega, twist.vx, twist.vy) == pytest.approx((0.8, 0.2, 0.0), abs=TOL)
    twist = config.body_twist(-1.0)
    assert (twist.omega, twist.vx, twist.vy) == pytest.approx((-0.8, -0.2, 0.0), abs=TOL)


@pytest.mark.parametrize(
    "fields",
    [
        dict(radius=0.0),
        dict(radius=-1.0),
        dict(radius=math.inf),
        dict(frequency=0.0),
        dict(frequency=math.nan),
        dict(velocity=math.nan),
        dict(velocity=-math.inf),
        dict(velocity=1e300, radius=1e-300),
    ],
)
def test_circle_config_rejects_invalid_values(fields):
    with pytest.raises(ValueError, match=next(iter(fields))):
        CircleConfig(**fields)


class Rig:
    """circle plus a helper node recording cmd_vel, calling its services and setting its parameters."""

    def __init__(self, ros, **node_kwargs) -> None:
        self.ros = ros
        self.node = ros.add(CircleNode(context=ros.context, **node_kwargs))
        helper = ros.node("circle_test_helper")
        self.twists: list[Twist] = []
        cmd_vel = helper.create_subscription(Twist, "cmd_vel", self.twists.append, 100)
        self.reverse = helper.create_client(Empty, "circle/reverse")
        self.stop = helper.create_client(Empty, "circle/stop")
        self.parameters = AsyncParameterClient(helper, "circle")
        assert ros.spin_until(
            lambda: (
                matched(cmd_vel)
                and self.reverse.service_is_ready()
                and self.stop.service_is_ready()
                and self.parameters.services_are_ready()
            ),
            10.0,
        )

    def call(self, client) -> None:
        future = client.call_async(Empty.Request())
        assert self.ros.spin_until(future.done, 5.0)

    def set(self, **values):
        """Set parameters through the node's parameter service; the SetParametersResult of each."""
        future = self.parameters.set_parameters([Parameter(k, value=v) for k, v in values.items()])
        assert self.ros.spin_until(future.done, 5.0)
        return future.result().results

    def next_twists(self, count: int = 3) -> list[Twist]:
        """The next `count` published twists."""
        start = len(self.twists)
        assert self.ros.spin_until(lambda: len(self.twists) >= start + count, 5.0), "circle is silent"
        return self.twists[start : start + count]


def components(twist: Twist) -> tuple[float, float, float, float, float, float]:
    linear, angular = twist.linear, twist.angular
    return (linear.x, linear.y, linear.z, angular.x, angular.y, angular.z)


def test_publishes_the_circle_twist_with_default_parameters(ros):
    rig = Rig(ros)
    for twist in rig.next_twists():
        # velocity 0.1 m/s on radius 0.5 m: omega = 0.2 rad/s
        assert components(twist) == pytest.approx((0.1, 0.0, 0.0, 0.0, 0.0, 0.2), abs=TOL)


def test_reverse_flips_the_direction_of_travel_and_back(ros):
    overrides = [Parameter("radius", value=0.25), Parameter("velocity", value=0.2)]
    rig = Rig(ros, parameter_overrides=overrides)
    assert components(rig.next_twists()[-1]) == pytest.approx((0.2, 0, 0, 0, 0, 0.8), abs=TOL)
    rig.call(rig.reverse)
    assert components(rig.next_twists()[-1]) == pytest.approx((-0.2, 0, 0, 0, 0, -0.8), abs=TOL)
    rig.call(rig.reverse)
    assert components(rig.next_twists()[-1]) == pytest.approx((0.2, 0, 0, 0, 0, 0.8), abs=TOL)


def test_stop_publishes_one_zero_twist_then_nothing_until_reverse_resumes(ros):
    rig = Rig(ros)
    rig.next_twists()
    rig.call(rig.stop)
    rig.ros.spin_for(0.1)
    assert components(rig.twists[-1]) == (0.0,) * 6
    count = len(rig.twists)
    rig.ros.spin_for(0.3)  # 30 periods at 100 Hz
    assert len(rig.twists) == count
    rig.call(rig.reverse)
    assert components(rig.next_twists()[-1]) == pytest.approx((-0.1, 0, 0, 0, 0, -0.2), abs=TOL)


def test_parameter_changes_apply_at_run_time_and_resume_after_stop(ros):
    rig = Rig(ros)
    rig.next_twists()
    rig.call(rig.stop)
    rig.ros.spin_for(0.1)
    count = len(rig.twists)
    results = rig.set(radius=2, velocity=0.3)  # an int where a float is expected
    assert all(result.successful for result in results)
    assert rig.node.config == CircleConfig(frequency=20.0, radius=2.0, velocity=0.3)
    twists = rig.next_twists()
    assert len(rig.twists) > count
    assert components(twists[-1]) == pytest.approx((0.3, 0, 0, 0, 0, 0.15), abs=TOL)


@pytest.mark.parametrize(
    "values, reason",
    [
        (dict(radius=-0.5), "radius must be finite and > 0"),
        (dict(radius=math.inf), "radius must be a finite number"),
        (dict(velocity=math.nan), "velocity must be a finite number"),
        (dict(frequency=0.0), "frequency must be finite and > 0"),
        (dict(radius="big"), "radius must be of type float"),
    ],
)
def test_invalid_parameter_changes_are_rejected_with_the_reason(ros, values, reason):
    rig = Rig(ros)
    (result,) = rig.set(**values)
    assert not result.successful and reason in result.reason
    assert rig.node.config == CircleConfig()
    name = next(iter(values))
    assert rig.node.get_parameter(name).value == getattr(CircleConfig(), name)
    assert components(rig.next_twists()[-1]) == pytest.approx((0.1, 0, 0, 0, 0, 0.2), abs=TOL)


def test_frequency_change_at_run_time_slows_publishing(ros):
    rig = Rig(ros)
    rig.next_twists()
    (result,) = rig.set(frequency=2.0)
    assert result.successful
    rig.ros.spin_for(0.05)
    count = len(rig.twists)
    rig.ros.spin_for(1.2)
    # at 2 Hz at most 3 periods fit in 1.2 s (at 100 Hz it would be about 120 messages)
    assert len(rig.twists) - count <= 3


@pytest.mark.parametrize(
    "parameter", [Parameter("radius", value=0.0), Parameter("frequency", value=-1.0)], ids=str
)
def test_invalid_start_parameters_refuse_to_construct(ros, parameter):
    with pytest.raises(ValueError, match=parameter.name):
        CircleNode(context=ros.context, parameter_overrides=[parameter])
