"""declare_dataclass / replace_from_parameters: frozen config dataclasses <-> ROS parameters (real rclpy)."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
from rclpy.parameter import Parameter

from nuturtle_description.robot_params import RobotParams, burger_params
from nuturtle_ros_common.ros_params import declare_dataclass, replace_from_parameters


@dataclass(frozen=True)
class Example:
    """Every supported field type; `gain` must be > 0."""

    gain: float = 1.5
    count: int = 3
    label: str = "x"
    enabled: bool = False
    weights: tuple[float, ...] = (1.0, 2.0)
    names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.gain > 0:
            raise ValueError(f"gain must be > 0, got {self.gain!r}")


def test_declare_dataclass_declares_every_field_with_its_default(ros):
    node = ros.node("declare_defaults")
    config = declare_dataclass(node, Example)
    assert config == Example()
    assert node.get_parameter("gain").value == 1.5
    assert list(node.get_parameter("weights").value) == [1.0, 2.0]


def test_declare_dataclass_takes_overrides_and_parameter_values(ros):
    node = ros.node(
        "declare_overrides",
        parameter_overrides=[
            Parameter("robot.wheel_radius", value=0.05),
            Parameter("robot.track_width", value=1),  # int where a float is expected
        ],
    )
    params = declare_dataclass(node, RobotParams, prefix="robot.", overrides=vars(burger_params()))
    assert params.wheel_radius == 0.05
    assert params.track_width == 1.0 and isinstance(params.track_width, float)
    assert params.motor_cmd_max == 265 and params.collision_radius == 0.11  # from the YAML overrides
    assert node.has_parameter("robot.encoder_ticks_per_rad")


def test_declare_dataclass_converts_every_field_type(ros):
    node = ros.node(
        "declare_types",
        parameter_overrides=[
            Parameter("gain", value=2),
            Parameter("count", value=7),
            Parameter("label", value="y"),
            Parameter("enabled", value=True),
            Parameter("weights", value=[3, 4, 5]),
            Parameter("names", value=["tb3_0", "tb3_1"]),
        ],
    )
    config = declare_dataclass(node, Example)
    assert config == Example(
        gain=2.0, count=7, label="y", enabled=True, weights=(3.0, 4.0, 5.0), names=("tb3_0", "tb3_1")
    )
    assert isinstance(config.gain, float) and all(isinstance(w, float) for w in config.weights)


def test_an_empty_yaml_list_is_an_empty_tuple(tmp_path):
    """rcl reads ``weights: []`` from a params file as a parameter without a type (value None)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node

    params = tmp_path / "params.yaml"
    params.write_text("declare_empty:\n  ros__parameters:\n    weights: []\n")
    context = Context()
    rclpy.init(context=context, args=["--ros-args", "--params-file", str(params)])
    try:
        node = Node("declare_empty", context=context)
        assert declare_dataclass(node, Example).weights == ()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


@pytest.mark.parametrize(
    "parameter",
    [
        Parameter("gain", value="big"),
        Parameter("gain", value=True),
        Parameter("count", value=2.5),
        Parameter("label", value=1),
        Parameter("enabled", value=1),
        Parameter("weights", value=["a", "b"]),
        Parameter("names", value=[1.0, 2.0]),
        Parameter("gain", value=-1.0),  # the right type, refused by the dataclass
    ],
    ids=lambda p: f"{p.name}={p.value!r}",
)
def test_declare_dataclass_rejects_wrong_types_and_invalid_values(ros, parameter):
    node = ros.node("declare_invalid", parameter_overrides=[parameter])
    with pytest.raises(ValueError, match=parameter.name):
        declare_dataclass(node, Example)


def test_replace_from_parameters_coerces_validates_and_ignores_other_names():
    config = Example()
    changed = replace_from_parameters(
        config, [Parameter("gain", value=4), Parameter("use_sim_time", value=True)]
    )
    assert changed == Example(gain=4.0) and config == Example()
    parameters = [Parameter("a.count", value=9), Parameter("count", value=1)]
    prefixed = replace_from_parameters(config, parameters, prefix="a.")
    assert prefixed == Example(count=9)
    with pytest.raises(ValueError, match="gain"):
        replace_from_parameters(config, [Parameter("gain", value=0.0)])
    with pytest.raises(ValueError, match="label"):
        replace_from_parameters(config, [Parameter("label", value=2.0)])
