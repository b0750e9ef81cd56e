"""The `model` parameter, declared first, decides the defaults of a node's robot constants: real rclpy nodes
with their arguments parsed by rcl (``--ros-args``), and with the parameter files a launch file's list
becomes (launch_ros writes each dict as a ``/**`` parameter file, in the list's order)."""

from __future__ import annotations

from pathlib import Path

import pytest

from nuslam.launch_nodes import slam_parameters
from nuslam.slam_node import SlamNode
from nuturtle_control.launch_nodes import odometry_parameters, robot_state_publisher_parameters
from nuturtle_control.odometry import OdometryNode
from nuturtle_description.robot_params import MODEL_ENV
from nuturtle_ros_common.launch_parameters import ros_arguments
from turtlelib import Transform2D

ROOT = Path(__file__).resolve().parents[2]


def test_turtlebot3_model_gives_slam_the_waffle_s_track_and_lidar_mount(ros, monkeypatch):
    monkeypatch.setenv(MODEL_ENV, "waffle")
    node = ros.add(SlamNode(context=ros.context))
    assert node.get_parameter("model").value == "waffle"
    assert node.get_parameter("track_width").value == 0.287
    assert node.get_parameter("lidar_x").value == -0.064
    # the filter observes from the Waffle's LiDAR and moves with its wheels
    assert node.slam.measurement.T_body_sensor == Transform2D(-0.064, 0.0, 0.0)
    assert node.odometry.drive.track_width == 0.287


def test_the_model_parameter_beats_the_environment_and_a_set_constant_beats_the_model(ros, monkeypatch):
    monkeypatch.setenv(MODEL_ENV, "burger")
    arguments = ["--ros-args", "-p", "model:=waffle_pi", "-p", "lidar_y:=0.01"]
    node = ros.add(OdometryNode(context=ros.context, cli_args=arguments))
    values = {name: node.get_parameter(name).value for name in ("model", "track_width", "lidar_x", "lidar_y")}
    assert values == {"model": "waffle_pi", "track_width": 0.287, "lidar_x": -0.064, "lidar_y": 0.01}
    assert node.odometry.drive.track_width == 0.287


def test_an_unknown_model_stops_the_node_naming_the_choices(ros, monkeypatch):
    monkeypatch.setenv(MODEL_ENV, "waffle")
    with pytest.raises(
        ValueError, match=r"model must be one of \('burger', 'waffle', 'waffle_pi'\), got 'wafle'"
    ):
        OdometryNode(context=ros.context, cli_args=["--ros-args", "-p", "model:=wafle"])
    monkeypatch.setenv(MODEL_ENV, "burger_pi")
    with pytest.raises(ValueError, match=r"got 'burger_pi' \(the model parameter, else \$TURTLEBOT3_MODEL"):
        OdometryNode(context=ros.context)


def test_the_launch_lists_give_the_model_and_keep_an_explicit_constant(ros, tmp_path, monkeypatch):
    """slam.launch.py's list for model:=waffle: slam.yaml, then the arguments; a params file of the user's,
    keyed by the node's name, still sets a constant."""
    monkeypatch.setenv(MODEL_ENV, "burger")
    own = tmp_path / "own.yaml"
    own.write_text("slam:\n  ros__parameters:\n    track_width: 0.29\n")
    parameters = [*slam_parameters("known", False, "waffle", mode="mapping"), str(own)]
    slam = ros.add(SlamNode(context=ros.context, cli_args=ros_arguments(parameters, tmp_path)))
    values = {
        name: slam.get_parameter(name).value for name in ("model", "track_width", "lidar_x", "wheel_noise")
    }
    assert values == {"model": "waffle", "track_width": 0.29, "lidar_x": -0.064, "wheel_noise": 0.05}
    assert slam.get_parameter("association").value == "known"
    # odometry's list, and the URDF robot_state_publisher publishes: the same Waffle
    odometry = ros.add(
        OdometryNode(
            context=ros.context, cli_args=ros_arguments(odometry_parameters(False, "waffle"), tmp_path)
        )
    )
    assert odometry.get_parameter("track_width").value == 0.287
    (rsp,) = robot_state_publisher_parameters(False, "waffle")
    assert '<robot name="turtlebot3_waffle_purple">' in rsp["robot_description"]
    assert 'xyz="-0.064 0 0.122"' in rsp["robot_description"]  # base_link -> base_scan


@pytest.mark.parametrize(
    "launch_file",
    [
        "nuturtle_description/launch/load_urdf.launch.py",
        "nusim/launch/nusim.launch.py",
        "nuturtle_control/launch/start_robot.launch.py",
        "nuslam/launch/slam.launch.py",
        "nuslam/launch/turtlebot3.launch.py",
        "nuturtle_demo/launch/nusim_slam.launch.py",
    ],
)
def test_every_launch_file_declares_the_model_argument_and_passes_it_on(launch_file):
    text = (ROOT / launch_file).read_text()
    assert "model_argument()," in text
    # to the lists it builds, or to the launch files it includes
    assert 'LaunchConfiguration("model")' in text
