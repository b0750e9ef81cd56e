"""nuturtle_demo.driver: the figure-eight route (hand-checked geometry) and the driver node on sim time."""

import math

import numpy as np
import pytest
from geometry_msgs.msg import Twist
from hypothesis import given, settings
from hypothesis import strategies as st
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from nuturtle_demo.driver import FigureEight, FigureEightDriver, RouteConfig, track
from nuturtle_description.robot_params import burger_params
from nuturtle_ros_common.conversions import pose_from_transform, stamp_from_seconds
from turtlelib import Transform2D, Twist2D


@pytest.mark.parametrize("field", ["radius", "velocity", "rate"])
@pytest.mark.parametrize("bad", [0.0, -1.0, math.inf, math.nan])
def test_route_config_rejects_bad_values(field, bad):
    with pytest.raises(ValueError, match=field):
        RouteConfig(**{field: bad})


@pytest.mark.parametrize("field", ["start_delay", "k_x", "k_y", "k_theta", "route_start_s"])
@pytest.mark.parametrize("bad", [-1.0, math.inf, math.nan])
def test_route_config_rejects_bad_delay_and_gains(field, bad):
    with pytest.raises(ValueError, match=field):
        RouteConfig(**{field: bad})


def test_reference_hand_computed():
    route = FigureEight.for_robot(RouteConfig(), burger_params())
    T, R = route.loop_period_s, route.left_loop.vx / route.left_loop.omega
    # half way round the first (counter-clockwise) loop: 2R to the left, facing back
    half = route.reference(0.5 * T)
    np.testing.assert_allclose([half.x, half.y, abs(half.theta)], [0.0, 2 * R, math.pi], atol=1e-9)
    # half way round the second (clockwise) loop: 2R to the right
    half = route.reference(1.5 * T)
    np.testing.assert_allclose([half.x, half.y], [0.0, -2 * R], atol=1e-9)
    # a quarter into the first loop: (R, R) facing +y
    quarter = route.reference(0.25 * T)
    np.testing.assert_allclose([quarter.x, quarter.y, quarter.theta], [R, R, math.pi / 2], atol=1e-9)


def test_track_passes_the_reference_through_at_zero_error():
    V_ref = Twist2D(0.2, 0.14, 0.0)
    T = Transform2D(0.3, -0.2, 1.0)
    assert track(T, T, V_ref, RouteConfig()) == pytest.approx(V_ref)


@settings(max_examples=20, deadline=None)
@given(st.floats(-0.15, 0.15), st.floats(-0.15, 0.15), st.floats(-0.4, 0.4))
def test_track_converges_onto_the_figure_eight(dx, dy, dtheta):
    """Integrate a unicycle under the tracking law from an offset start: the error decays."""
    config = RouteConfig()
    route = FigureEight.for_robot(config, burger_params())
    T_map_body = Transform2D(dx, dy, dtheta)
    dt = 0.01
    for k in range(int(1.2 * route.loop_period_s / dt)):
        V = track(T_map_body, route.reference(k * dt), route.body_twist(k * dt), config)
        T_map_body = T_map_body @ Transform2D.exp(V * dt)
    error = T_map_body.inverse() @ route.reference(int(1.2 * route.loop_period_s / dt) * dt)
    assert math.hypot(error.x, error.y) < 2e-3 and abs(error.theta) < 5e-3


def test_figure_eight_uses_motor_speeds_and_closes_each_loop():
    robot = burger_params()
    route = FigureEight.for_robot(RouteConfig(radius=0.75, velocity=0.14), robot)
    step = 1.0 / robot.motor_cmd_per_rad_sec
    for w in route.wheel_speeds_rad_s:
        assert abs(w / step - round(w / step)) < 1e-9
    # the twist is that of the rounded wheel speeds, close to the request
    assert route.left_loop == robot.diff_drive().body_twist(*route.wheel_speeds_rad_s)
    assert route.left_loop.vx == pytest.approx(0.14, abs=0.01)
    assert route.left_loop.vx / route.left_loop.omega == pytest.approx(0.75, abs=0.03)
    # holding the twist for one period is one closed loop: exp(T V) = identity
    T = route.loop_period_s
    loop = Transform2D.exp(route.left_loop * T)
    assert math.hypot(loop.x, loop.y) < 1e-9 and abs(math.sin(loop.theta)) < 1e-9
    # loop k turns one way for even k, the other way for odd k
    assert route.body_twist(0.5 * T).omega > 0 and route.body_twist(1.5 * T).omega < 0
    assert route.body_twist(2.5 * T) == route.left_loop
    assert route.body_twist(1.5 * T).vx == route.left_loop.vx


def test_figure_eight_refuses_what_the_motors_cannot_do():
    with pytest.raises(ValueError, match="wheel speeds above"):
        FigureEight.for_robot(RouteConfig(velocity=0.3), burger_params())
    with pytest.raises(ValueError, match="too large"):
        FigureEight.for_robot(RouteConfig(radius=1e6), burger_params())


@pytest.mark.ros
def test_open_loop_driver_waits_then_follows_sim_time_and_stops(ros):
    driver = ros.add(FigureEightDriver(context=ros.context, parameter_overrides=[
        Parameter("use_sim_time", value=True),
        Parameter("radius", value=0.5),
        Parameter("velocity", value=0.1),
        Parameter("feedback", value=False), Parameter("start_delay", value=2.0),
    ]))  # fmt: skip
    helper = ros.node("helper")
    received = []
    helper.create_subscription(Twist, "cmd_vel", received.append, 10)
    clock = helper.create_publisher(Clock, "/clock", 10)
    period = driver.route.loop_period_s
    t = 1.0

    def advance(to_s):
        nonlocal t
        while t < to_s:
            t += 0.5
            clock.publish(Clock(clock=stamp_from_seconds(t)))
            ros.spin_for(0.01)

    assert ros.spin_until(lambda: helper.count_subscribers("/clock") >= 1, 5.0)
    # standing still for start_delay = 2 s after the first command
    advance(2.0)
    assert ros.spin_until(lambda: len(received) > 0, 5.0)
    assert all(m.linear.x == 0.0 and m.angular.z == 0.0 for m in received)
    advance(3.0 + 0.5 * period)
    assert ros.spin_until(lambda: len(received) > 0, 5.0)
    assert received[-1].angular.z == pytest.approx(driver.route.left_loop.omega)
    assert received[-1].linear.x == pytest.approx(driver.route.left_loop.vx)
    advance(3.0 + 1.5 * period)
    ros.spin_for(0.2)
    assert received[-1].angular.z == pytest.approx(-driver.route.left_loop.omega)
    driver.stop()
    assert ros.spin_until(lambda: received[-1].linear.x == 0.0 and received[-1].angular.z == 0.0, 5.0)
    count = len(received)
    advance(t + 2.0)
    ros.spin_for(0.2)
    assert len(received) == count


def feedback_rig(ros):
    """A helper node around a driver: the cmd_vel it receives, and publishers of /clock and slam/odom,
    once the driver listens to both."""
    helper = ros.node("helper")
    received = []
    helper.create_subscription(Twist, "cmd_vel", received.append, 10)
    clock = helper.create_publisher(Clock, "/clock", 10)
    poses = helper.create_publisher(Odometry, "slam/odom", 10)
    assert ros.spin_until(
        lambda: helper.count_subscribers("/clock") >= 1 and helper.count_subscribers("slam/odom") >= 1, 5.0
    )
    return received, clock, poses


def pose_message(T_map_body: Transform2D) -> Odometry:
    msg = Odometry()
    msg.pose.pose = pose_from_transform(T_map_body)
    return msg


@pytest.mark.ros
def test_closed_loop_driver_steers_back_onto_the_route(ros):
    driver = ros.add(FigureEightDriver(context=ros.context, parameter_overrides=[
        Parameter("use_sim_time", value=True), Parameter("start_delay", value=0.0),
    ]))  # fmt: skip
    received, clock, poses = feedback_rig(ros)

    # the first pose fixes the route's start; then the robot is 10 cm left of its reference
    poses.publish(pose_message(Transform2D(0.0, 0.0, 0.0)))
    assert ros.spin_until(lambda: driver.T_map_route is not None, 5.0)
    poses.publish(pose_message(Transform2D(0.0, 0.1, 0.0)))
    assert ros.spin_until(lambda: driver.T_map_body is not None and driver.T_map_body.y == 0.1, 5.0)
    clock.publish(Clock(clock=stamp_from_seconds(1.0)))
    ros.spin_for(0.1)
    clock.publish(Clock(clock=stamp_from_seconds(1.2)))
    assert ros.spin_until(lambda: len(received) > 0, 5.0)
    # turning right of the feed-forward: w = w_ref + v k_y e_y with e_y = -0.1 m (k_x e_x is small)
    V_ref = driver.route.left_loop
    assert received[-1].angular.z < V_ref.omega - 0.5 * V_ref.vx * driver.config.k_y * 0.1


@pytest.mark.ros
def test_driver_continues_a_route_from_where_it_stopped(ros):
    """route_start_s 1.25 loops in: the route's start is the first pose composed back along the route
    driven, and the first command is the second (clockwise) loop's."""
    period = FigureEight.for_robot(RouteConfig(), burger_params()).loop_period_s
    driver = ros.add(FigureEightDriver(context=ros.context, parameter_overrides=[
        Parameter("use_sim_time", value=True), Parameter("start_delay", value=0.0),
        Parameter("route_start_s", value=1.25 * period), Parameter("model", value="burger"),
    ]))  # fmt: skip
    received, clock, poses = feedback_rig(ros)
    T_map_route = Transform2D(0.3, -0.2, 0.4)
    # where the route is 1.25 loops in: a quarter into the clockwise loop
    T_map_first = T_map_route @ driver.route.reference(1.25 * period)
    poses.publish(pose_message(T_map_first))
    assert ros.spin_until(lambda: driver.T_map_route is not None, 5.0)
    start = driver.T_map_route
    assert (start.x, start.y, start.theta) == pytest.approx((0.3, -0.2, 0.4), abs=1e-9)
    clock.publish(Clock(clock=stamp_from_seconds(1.0)))
    assert ros.spin_until(lambda: len(received) > 0, 5.0)
    # on the route: the clockwise loop's feed-forward, nothing to correct
    assert received[-1].angular.z == pytest.approx(-driver.route.left_loop.omega, abs=1e-6)
    assert received[-1].linear.x == pytest.approx(driver.route.left_loop.vx, abs=1e-6)
    assert driver.route_time_s == pytest.approx(1.25 * period)
