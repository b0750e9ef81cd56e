"""What the launch files give their nodes, without `ros2 launch` (not installable here): the parameter
lists come from plain functions, turned into the command line launch_ros builds from them (each dict a
``/**`` parameter file, in the list's order) and parsed by rcl itself into a real node's parameters, so a
launch argument must beat the node's YAML file under rcl's own merge rule."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from nuslam.launch_nodes import SLAM_ARGUMENTS, landmarks_parameters, slam_parameters
from nuturtle_control.launch_nodes import circle_parameters, odometry_parameters, turtle_control_parameters
from nuturtle_ros_common.launch_parameters import with_arguments
from nuturtle_ros_common.ros_files import share_file
from rclpy_harness import launch_ros_arguments, rcl_parameters

ROOT = Path(__file__).resolve().parents[2]


def resolved(ros, tmp_path, parameters: list, node_name: str) -> dict:
    """What rcl gives ``node_name`` for the launch list ``parameters``."""
    return rcl_parameters(ros.context, node_name, launch_ros_arguments(parameters, tmp_path))


@pytest.mark.parametrize("association", ["known", "unknown"])
def test_the_association_argument_reaches_slam_over_its_yaml(ros, tmp_path, association):
    values = resolved(ros, tmp_path, slam_parameters(association, True, "waffle"), "slam")
    assert values["association"] == association
    assert values["use_sim_time"] is True and values["model"] == "waffle"
    # the rest from slam.yaml; the robot's constants are the model's defaults, in no file
    assert values["wheel_noise"] == 0.05 and "wheel_radius" not in values


def test_the_map_and_motion_arguments_reach_slam_over_its_yaml(ros, tmp_path):
    map_file = str(tmp_path / "lab.json")
    parameters = slam_parameters(
        "unknown", False, "burger", motion_source="odom", mode="localization", map_file=map_file
    )
    values = resolved(ros, tmp_path, parameters, "slam")
    assert (values["motion_source"], values["mode"], values["map_file"]) == ("odom", "localization", map_file)
    defaults = resolved(ros, tmp_path, slam_parameters("unknown", False, "burger"), "slam")
    assert [defaults[name] for name in SLAM_ARGUMENTS] == [default for default, _ in SLAM_ARGUMENTS.values()]


def test_a_dict_before_the_yaml_loses_to_it(ros, tmp_path):
    # what went wrong: slam.yaml (association: unknown) after the argument wins
    slam_yaml = share_file("nuslam", "config", "slam.yaml")
    assert resolved(ros, tmp_path, [{"association": "known"}, slam_yaml], "slam")["association"] == "unknown"
    arguments_last = with_arguments([slam_yaml], {"association": "known"})
    assert resolved(ros, tmp_path, arguments_last, "slam")["association"] == "known"


@pytest.mark.parametrize(
    ("parameters", "node", "expected"),
    [
        (landmarks_parameters(True), "landmarks", {"use_sim_time": True}),
        (
            turtle_control_parameters(False, "waffle"),
            "turtle_control",
            {"use_sim_time": False, "cmd_timeout": 0.5, "model": "waffle"},
        ),
        (odometry_parameters(True, "burger"), "odometry", {"use_sim_time": True, "odom_id": "odom"}),
        (circle_parameters(True), "circle", {"use_sim_time": True, "radius": 0.5}),
    ],
)
def test_every_node_list_is_files_then_arguments(ros, tmp_path, parameters, node, expected):
    assert isinstance(parameters[-1], dict), "the launch arguments come last"
    assert all(Path(entry).is_file() for entry in parameters[:-1])
    values = resolved(ros, tmp_path, parameters, node)
    assert {name: values[name] for name in expected} == expected


@pytest.mark.parametrize(
    ("launch_file", "functions"),
    [
        ("nuslam/launch/slam.launch.py", ["slam_parameters(", "landmarks_parameters("]),
        ("nuslam/launch/turtlebot3.launch.py", ["slam_parameters(", "landmarks_parameters("]),
        (
            "nuturtle_control/launch/start_robot.launch.py",
            ["turtle_control_parameters(", "odometry_parameters(", "circle_parameters("],
        ),
    ],
)
def test_the_launch_files_build_their_lists_with_these_functions(launch_file, functions):
    text = (ROOT / launch_file).read_text()
    for function in functions:
        assert f"parameters={function}" in text, function


def test_the_stock_turtlebot3_launch_drives_nothing_and_duplicates_no_odometry():
    # the robot's turtlebot3_node owns cmd_vel, odom and odom -> base_footprint
    text = (ROOT / "nuslam/launch/turtlebot3.launch.py").read_text()
    for executable in ("turtle_control", "odometry", "circle", "teleop"):
        assert f'executable="{executable}"' not in text
    # and no launch starts the robot moving unless asked
    for launch_file in ("nuslam/launch/slam.launch.py", "nuturtle_control/launch/start_robot.launch.py"):
        assert re.search(r'"cmd_src",\s*default_value="none"', (ROOT / launch_file).read_text()), launch_file


def test_world_to_map_is_the_world_file_s_start_pose(tmp_path):
    from nuturtle_demo.launch_nodes import world_to_map_arguments

    basic = world_to_map_arguments(ROOT / "nusim" / "config" / "basic_world.yaml")
    assert basic == [
        "--x",
        "0.0",
        "--y",
        "0.0",
        "--yaw",
        "0.0",
        "--frame-id",
        "nusim/world",
        "--child-frame-id",
        "map",
    ]
    world = tmp_path / "world.yaml"
    world.write_text("nusim:\n  ros__parameters:\n    x0: 1.5\n    y0: -2.0\n    theta0: 0.5\n")
    assert world_to_map_arguments(world)[:6] == ["--x", "1.5", "--y", "-2.0", "--yaw", "0.5"]
    assert (
        "arguments=world_to_map_arguments("
        in (ROOT / "nuturtle_demo/launch/nusim_slam.launch.py").read_text()
    )


def test_robot_state_publisher_gets_the_urdf_with_the_lidar_mount_slam_uses():
    from nuturtle_control.launch_nodes import robot_state_publisher_parameters
    from nuturtle_description.robot_params import model_params

    (parameters,) = robot_state_publisher_parameters(True, "waffle")
    assert parameters["use_sim_time"] is True
    urdf = parameters["robot_description"]
    robot = model_params("waffle")
    # the fixed scan joint base_link -> base_scan at the mount's x, y and yaw (base_link is planar with
    # base_footprint), so /tf_static's base_footprint -> base_scan is slam's T_body_scan
    scan_joint = urdf[urdf.index('<joint name="scan_joint"') :]
    scan_joint = scan_joint[: scan_joint.index("</joint>")]
    assert '<child link="base_scan"/>' in scan_joint
    assert f'xyz="{robot.lidar_x:.12g} {robot.lidar_y:.12g} ' in scan_joint
    assert f'rpy="0 0 {robot.lidar_yaw:.12g}"' in scan_joint
    text = (ROOT / "nuturtle_control/launch/start_robot.launch.py").read_text()
    assert "parameters=robot_state_publisher_parameters(" in text
