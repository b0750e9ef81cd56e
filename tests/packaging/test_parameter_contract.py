"""Parameters as a contract, through the rclpy parameter services over DDS (what `ros2 param` uses): every
parameter of every node is described; a change to a parameter the node does not apply is refused with the
reason and changes nothing; circle's live parameters are applied; each node logs its effective
parameters at start-up."""

from __future__ import annotations

import re

import pytest
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient

from nusim.nusim_node import NusimNode
from nuslam.landmarks_node import LandmarksNode
from nuslam.slam_node import SlamNode
from nuturtle_control.circle import CircleNode
from nuturtle_control.odometry import OdometryNode
from nuturtle_control.turtle_control import TurtleControlNode
from nuturtle_demo.driver import FigureEightDriver
from nuturtle_ros_common.node_main import effective_parameters
from nuturtle_tools.foxglove_relay import FoxgloveRelayNode

# parameters rclpy declares on every node
ROS_OWN = {"use_sim_time", "start_type_description_service"}
# node class, and a parameter with a value of its type that the node could be asked to take
NODES = {
    "nusim": (NusimNode, Parameter("arena_x_length", value=9.0)),
    "turtle_control": (TurtleControlNode, Parameter("wheel_radius", value=0.05)),
    "odometry": (OdometryNode, Parameter("body_id", value="base_link")),
    "landmarks": (LandmarksNode, Parameter("min_points", value=5)),
    "slam": (SlamNode, Parameter("wheel_noise", value=0.2)),
}


def client_for(ros, name: str) -> AsyncParameterClient:
    client = AsyncParameterClient(ros.node(f"{name}_parameter_client"), name)
    assert ros.spin_until(client.services_are_ready, 10.0)
    return client


def wait(ros, future):
    assert ros.spin_until(future.done, 5.0)
    return future.result()


# every node with parameters, and what it needs to start here
DESCRIBED = {
    **{name: (cls, []) for name, (cls, _) in NODES.items()},
    "circle": (CircleNode, []),
    "driver": (FigureEightDriver, []),
    "foxglove_relay": (FoxgloveRelayNode, [Parameter("port", value=0)]),
}


def names_parameter(description: str, parameter: str) -> bool:
    """Whether a backticked span of ``description`` holds ``parameter`` as a word, or its field name
    after a prefix (``lidar.noise``: ``noise``; ``odom_forward_m2_per_m``: ``forward_m2_per_m``) when the
    description opens with the parameter's full name."""
    fields = [parameter]
    if description.startswith(f"{parameter}: "):
        fields += [parameter[i + 1 :] for i, char in enumerate(parameter) if char in "._"]
    spans = re.findall(r"`+([^`]+)`+", description)
    return any(re.search(rf"(?<![\w.]){re.escape(f)}\b", span) for f in fields for span in spans)


@pytest.mark.parametrize("name", list(DESCRIBED))
def test_every_parameter_is_described_by_a_whole_sentence_of_its_own(ros, name):
    cls, overrides = DESCRIBED[name]
    node = ros.add(cls(context=ros.context, parameter_overrides=overrides))
    client = client_for(ros, name)
    names = sorted(set(node.get_parameters_by_prefix("")) - ROS_OWN)
    descriptors = wait(ros, client.describe_parameters(names)).descriptors
    assert len(descriptors) == len(names)
    described = dict(zip(names, (d.description for d in descriptors), strict=True))
    for parameter, description in described.items():
        # the description names the parameter (the docstring clause it comes from) and says more
        assert names_parameter(description, parameter), (parameter, description)
        assert len(description) > len(parameter) + 10, parameter
        # a whole sentence: not cut inside a parenthesis or a quote, and ended
        assert description.endswith("."), (parameter, description)
        opened = sum(map(description.count, "([")) - sum(map(description.count, ")]"))
        assert opened == 0, (parameter, description)  # intervals such as [0, 1) count as one pair
        assert description.count("`") % 2 == 0, (parameter, description)
    # a description shared by several parameters names each of them (one clause of them all)
    for parameter, description in described.items():
        for other, same in described.items():
            if other != parameter and same == description:
                assert names_parameter(description, other), (parameter, other, description)


@pytest.mark.parametrize("name", list(NODES))
def test_a_change_the_node_does_not_apply_is_refused_with_the_reason(ros, name):
    cls, change = NODES[name]
    node = ros.add(cls(context=ros.context))
    before = node.get_parameter(change.name).value
    client = client_for(ros, name)
    (result,) = wait(ros, client.set_parameters([change])).results
    assert not result.successful
    assert "read-only" in result.reason
    assert node.get_parameter(change.name).value == before
    # `ros2 param get` still answers, with the value the node runs with
    (value,) = wait(ros, client.get_parameters([change.name])).values
    assert parameter_value_to_python(value) == before


def test_circle_applies_its_live_parameters(ros):
    node = ros.add(CircleNode(context=ros.context))
    client = client_for(ros, "circle")
    (result,) = wait(ros, client.set_parameters([Parameter("radius", value=0.8)])).results
    assert result.successful
    assert node.config.radius == 0.8


def test_effective_parameters_list_every_parameter_with_its_value(ros):
    node = ros.add(SlamNode(context=ros.context))
    text = effective_parameters(node)
    assert "association=unknown" in text and "wheel_noise=0.05" in text
    for parameter in set(node.get_parameters_by_prefix("")) - ROS_OWN:
        assert f"{parameter}=" in text
