"""What the launch files give their nodes, without `ros2 launch` (not installable here): the parameter
lists come from plain functions, turned into the command line launch_ros builds from them (each dict a
``/**`` parameter file, in the list's order); the real node is started with it, rcl parses it, and the
values are read back through the node's parameter services, so a launch argument must beat the node's
YAML file under rcl's own merge rule."""

from __future__ import annotations

from pathlib import Path

import pytest

from nuslam.launch_nodes import (
    SLAM_ARGUMENTS,
    landmarks_parameters,
    robot_side_parameters,
    slam_parameters,
    slam_side_parameters,
)
from nuturtle_control.launch_nodes import circle_parameters, odometry_parameters, turtle_control_parameters
from nuturtle_ros_common.launch_parameters import (
    LaunchArgument,
    RobotFrames,
    robot_frames,
    ros_arguments,
    with_arguments,
)
from nuturtle_ros_common.ros_files import share_file
from rclpy_harness import rcl_parameters, served_parameters

ROOT = Path(__file__).resolve().parents[2]


def node_class(node_name: str) -> type:
    from nuslam.landmarks_node import LandmarksNode
    from nuslam.slam_node import SlamNode
    from nuturtle_control.circle import CircleNode
    from nuturtle_control.odometry import OdometryNode
    from nuturtle_control.turtle_control import TurtleControlNode

    return {
        "slam": SlamNode,
        "landmarks": LandmarksNode,
        "turtle_control": TurtleControlNode,
        "odometry": OdometryNode,
        "circle": CircleNode,
    }[node_name]


def resolved(ros, tmp_path, parameters: list, node_name: str, names: list[str]) -> dict:
    """``names`` as the real node ``node_name``, started with the command line launch_ros builds from
    ``parameters``, serves them."""
    node = ros.add(node_class(node_name)(context=ros.context, cli_args=ros_arguments(parameters, tmp_path)))
    try:
        return served_parameters(ros, node, names)
    finally:
        ros.remove(node)


@pytest.mark.parametrize("association", ["known", "unknown"])
def test_the_association_argument_reaches_slam_over_its_yaml(ros, tmp_path, association):
    names = ["association", "use_sim_time", "model", "wheel_noise", "track_width"]
    values = resolved(ros, tmp_path, slam_parameters(association, True, "waffle"), "slam", names)
    assert values["association"] == association
    assert values["use_sim_time"] is True and values["model"] == "waffle"
    # the rest from slam.yaml; the robot's constants are the model's defaults, in no file
    assert values["wheel_noise"] == 0.05 and values["track_width"] == pytest.approx(0.287)


def test_the_map_and_motion_arguments_reach_slam_over_its_yaml(ros, tmp_path):
    import numpy as np

    from turtlelib.mapping.landmark_map import LandmarkMap, save_map

    map_file = str(tmp_path / "lab.json")
    save_map(map_file, LandmarkMap("map", 0, np.array([3]), np.array([[1.0, 2.0]]), 1e-4 * np.eye(2)))
    parameters = slam_parameters(
        "unknown", False, "burger", motion_source="odom", mode="localization", map_file=map_file
    )
    names = list(SLAM_ARGUMENTS)
    values = resolved(ros, tmp_path, parameters, "slam", names)
    assert values == {"motion_source": "odom", "mode": "localization", "map_file": map_file}
    defaults = resolved(ros, tmp_path, slam_parameters("unknown", False, "burger"), "slam", names)
    assert list(defaults.values()) == [argument.default for argument in SLAM_ARGUMENTS.values()]


@pytest.mark.parametrize(
    ("one_process", "names"),
    [
        (robot_side_parameters, ["turtle_control", "odometry", "slam", "landmarks"]),
        (slam_side_parameters, ["slam", "landmarks"]),
    ],
)
def test_the_one_process_list_gives_each_node_what_its_own_list_gives_it(ros, tmp_path, one_process, names):
    """robot_side's (slam_side's) one command line, parsed by rcl for each node name: the values of the
    node's own launch list, and beyond them only slam's arguments, which the other nodes do not declare."""
    arguments = {"motion_source": "odom", "mode": "mapping", "map_file": "/tmp/m.json"}
    one = ros_arguments(one_process("unknown", True, "waffle_pi", **arguments), tmp_path / "one")
    own_lists = {
        "turtle_control": turtle_control_parameters(True, "waffle_pi"),
        "odometry": odometry_parameters(True, "waffle_pi"),
        "slam": slam_parameters("unknown", True, "waffle_pi", **arguments),
        "landmarks": landmarks_parameters(True),
    }
    assert rcl_parameters(ros.context, "turtle_control", one).get("cmd_timeout") == (
        0.5 if "turtle_control" in names else None
    ), "a node's file only in the list of the process that runs it"
    for name in names:
        own_list = own_lists[name]
        own = rcl_parameters(ros.context, name, ros_arguments(own_list, tmp_path / name))
        shared = rcl_parameters(ros.context, name, one)
        assert {key: shared[key] for key in own} == own, name
        extra = set(shared) - set(own)
        assert extra <= {"association", "model", *SLAM_ARGUMENTS}, (name, extra)
        if extra:
            node = ros.add(node_class(name)(context=ros.context, cli_args=one))
            assert not any(node.has_parameter(key) for key in extra), (name, extra)
            ros.remove(node)


def test_a_dict_before_the_yaml_loses_to_it(ros, tmp_path):
    # what went wrong: slam.yaml (association: unknown) after the argument wins
    # rcl's own rule, shown on a bare node that takes whatever rcl gives it
    slam_yaml = share_file("nuslam", "config", "slam.yaml")

    def association(parameters: list) -> str:
        return rcl_parameters(ros.context, "slam", ros_arguments(parameters, tmp_path))["association"]

    assert association([{"association": "known"}, slam_yaml]) == "unknown"
    assert association(with_arguments([slam_yaml], {"association": "known"})) == "known"


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
    assert resolved(ros, tmp_path, parameters, node, list(expected)) == expected


@pytest.mark.parametrize(
    ("launch_file", "functions"),
    [
        (
            "nuslam/launch/slam.launch.py",
            ["slam_parameters(", "landmarks_parameters(", "robot_side_parameters("],
        ),
        (
            "nuslam/launch/turtlebot3.launch.py",
            ["slam_parameters(", "landmarks_parameters(", "slam_side_parameters("],
        ),
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


def test_managed_picks_the_lifecycle_variants_installed_by_nuslam():
    from nuslam.launch_nodes import node_executable

    assert [node_executable(node, False) for node in ("slam", "landmarks")] == ["slam", "landmarks"]
    managed = [node_executable(node, True) for node in ("slam", "landmarks")]
    assert managed == ["slam_managed", "landmarks_managed"]
    setup = (ROOT / "nuslam" / "setup.py").read_text()
    for executable in managed:
        assert f'"{executable} = nuslam.managed_nodes:' in setup, executable
    with pytest.raises(ValueError, match="only slam and landmarks"):
        node_executable("odometry", True)


@pytest.mark.parametrize(
    "launch_file", ["nuslam/launch/slam.launch.py", "nuslam/launch/turtlebot3.launch.py"]
)
def test_the_slam_launch_files_start_managed_nodes_only_when_asked(launch_file):
    import ast

    tree = ast.parse((ROOT / launch_file).read_text())
    calls = [node for node in ast.walk(tree) if isinstance(node, ast.Call)]
    # managed:=false|true, false by default
    assert any(
        ast.unparse(call) == "switch_argument('managed', False, MANAGED_DESCRIPTION)" for call in calls
    )
    executables = {
        ast.unparse(keyword.value)
        for call in calls
        if getattr(call.func, "id", None) == "Node"
        for keyword in call.keywords
        if keyword.arg == "executable"
    }
    # slam and landmarks by the switch; the one-process executable refused with it (it runs plain nodes)
    assert {"node_executable('slam', managed)", "node_executable('landmarks', managed)"} <= executables
    assert not {"'slam'", "'landmarks'", "'slam_managed'", "'landmarks_managed'"} & executables
    (one_process,) = [
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and "one_process" in ast.unparse(node.test)
    ]
    refusal = one_process.body[0]
    assert ast.unparse(refusal) == "if managed:\n    raise ValueError(MANAGED_ONE_PROCESS)"


def test_the_stock_turtlebot3_launch_drives_nothing_and_duplicates_no_odometry():
    # the robot's turtlebot3_node owns cmd_vel, odom and odom -> base_footprint
    text = (ROOT / "nuslam/launch/turtlebot3.launch.py").read_text()
    for executable in ("turtle_control", "odometry", "circle", "teleop"):
        assert f'executable="{executable}"' not in text
    # and no launch starts the robot moving unless asked
    from nuturtle_control.launch_nodes import CMD_SRC

    assert CMD_SRC.default == "none"
    for launch_file in (
        "nuslam/launch/slam.launch.py",
        "nuturtle_control/launch/start_robot.launch.py",
        "nuturtle_demo/launch/nusim_slam.launch.py",
    ):
        assert 'declare_argument("cmd_src", CMD_SRC)' in (ROOT / launch_file).read_text(), launch_file


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


@pytest.mark.parametrize(
    ("fields", "message"),
    [(("x", ("a", "b"), "an argument"), "not one of"), (("a", None, " "), "needs a description")],
)
def test_a_launch_argument_record_refuses_a_default_outside_its_choices_or_no_description(fields, message):
    with pytest.raises(ValueError, match=message):
        LaunchArgument(*fields)


@pytest.mark.parametrize(
    ("node", "parameters"),
    [
        ("slam", slam_parameters("unknown", False, "burger")),
        ("landmarks", landmarks_parameters(False)),
        ("turtle_control", turtle_control_parameters(False, "burger")),
        ("odometry", odometry_parameters(False, "burger")),
        ("circle", circle_parameters(False)),
    ],
)
def test_a_node_s_own_yaml_reaches_it_in_any_namespace(ros, tmp_path, node, parameters):
    # what rcl gives a node under /tb3_0 from the list launch builds is what it gives it without one (a
    # file keyed by the bare node name would reach /slam only: the /tb3_0/slam of `namespace:=tb3_0`
    # would run on its code's defaults)
    arguments = ros_arguments(parameters, tmp_path)
    bare = rcl_parameters(ros.context, node, arguments)
    assert len(bare) > 3, "the node's file reached it"
    assert rcl_parameters(ros.context, node, arguments, namespace="tb3_0") == bare
    assert rcl_parameters(ros.context, node, arguments, namespace="fleet/tb3_1") == bare


def test_a_namespaced_robot_s_frames_reach_slam_and_odometry(ros, tmp_path):
    frames = robot_frames("tb3_0")
    names = ["map_id", "odom_id", "body_id", "sensor_id", "association"]
    slam = ros.add(
        node_class("slam")(
            context=ros.context,
            namespace="tb3_0",
            cli_args=ros_arguments(slam_parameters("unknown", False, "burger", **frames.slam()), tmp_path),
        )
    )
    assert slam.get_fully_qualified_name() == "/tb3_0/slam"
    assert served_parameters(ros, slam, names) == {
        "map_id": "tb3_0/map",
        "odom_id": "tb3_0/odom",
        "body_id": "tb3_0/base_footprint",
        "sensor_id": "tb3_0/base_scan",
        "association": "unknown",
    }
    ros.remove(slam)
    parameters = odometry_parameters(False, "burger", **frames.odometry())
    values = rcl_parameters(ros.context, "odometry", ros_arguments(parameters, tmp_path), namespace="tb3_0")
    assert (values["odom_id"], values["body_id"]) == ("tb3_0/odom", "tb3_0/base_footprint")


@pytest.mark.parametrize(
    ("namespace", "map_frame", "expected"),
    [
        ("", "", ("", "map", "odom", "base_footprint", "base_scan")),
        ("tb3_0", "", ("tb3_0/", "tb3_0/map", "tb3_0/odom", "tb3_0/base_footprint", "tb3_0/base_scan")),
        ("/tb3_1/", "map", ("tb3_1/", "map", "tb3_1/odom", "tb3_1/base_footprint", "tb3_1/base_scan")),
        (
            "fleet/r2",
            "",
            ("fleet/r2/", "fleet/r2/map", "fleet/r2/odom", "fleet/r2/base_footprint", "fleet/r2/base_scan"),
        ),
    ],
)
def test_robot_frames_prefix_every_frame_with_the_namespace(namespace, map_frame, expected):
    frames = robot_frames(namespace, map_frame)
    assert (frames.prefix, frames.map_id, frames.odom_id, frames.body_id, frames.sensor_id) == expected


def test_without_a_namespace_the_nodes_keep_their_own_frame_parameters():
    # no frame id in the launch list: a frame set in a node's yaml file stays as today
    assert robot_frames("").slam() == {} and robot_frames("").odometry() == {}
    assert robot_frames("", "world").slam() == {"map_id": "world"}
    assert robot_frames("tb3_0", "map").slam()["map_id"] == "map"
    assert robot_frames("tb3_0").odometry() == {"odom_id": "tb3_0/odom", "body_id": "tb3_0/base_footprint"}


@pytest.mark.parametrize(
    ("namespace", "map_frame", "message"),
    [
        ("tb3-0", "", "namespace"),
        ("0tb3", "", "namespace"),
        ("a//b", "", "namespace"),
        ("tb3_0", "/map", "map frame"),
    ],
)
def test_robot_frames_refuse_a_namespace_that_is_no_ros_name(namespace, map_frame, message):
    with pytest.raises(ValueError, match=message):
        robot_frames(namespace, map_frame)


def test_the_namespaced_rviz_config_shows_that_robot():
    import yaml

    from nuslam.launch_nodes import namespaced_rviz_config, rviz_arguments

    installed = share_file("nuslam", "rviz", "slam.rviz")
    config = yaml.safe_load(installed.read_text())
    shown = namespaced_rviz_config(config, robot_frames("tb3_0"))
    displays = {display["Name"]: display for display in shown["Visualization Manager"]["Displays"]}
    assert displays["Occupancy grid (SLAM)"]["Topic"]["Value"] == "/tb3_0/map"
    assert displays["Occupancy grid (SLAM)"]["Update Topic"]["Value"] == "/tb3_0/map_updates"
    assert displays["RobotModel"]["Description Topic"]["Value"] == "/tb3_0/robot_description"
    assert displays["RobotModel"]["TF Prefix"] == "tb3_0"
    assert shown["Visualization Manager"]["Global Options"]["Fixed Frame"] == "tb3_0/map"
    tools = {tool["Class"]: tool for tool in shown["Visualization Manager"]["Tools"]}
    assert tools["rviz_default_plugins/SetInitialPose"]["Topic"]["Value"] == "/tb3_0/initialpose"

    def topics(value) -> list[str]:
        if isinstance(value, dict):
            own = [value["Value"]] if "Value" in value and "Depth" in value else []
            return own + [t for item in value.values() for t in topics(item)]
        return [t for item in value for t in topics(item)] if isinstance(value, list) else []

    before, after = topics(config), topics(shown)
    assert len(before) >= 12 and after == [f"/tb3_0{topic}" for topic in before]
    # the config read is left as it was, and a shared map frame keeps the topics and sets the frame
    assert config == yaml.safe_load(installed.read_text())
    shared = namespaced_rviz_config(config, robot_frames("tb3_1", "map"))
    assert shared["Visualization Manager"]["Global Options"]["Fixed Frame"] == "map"
    assert topics(shared)[0].startswith("/tb3_1/")
    # the launch files' arguments: the installed file without a namespace, else the rewritten copy
    assert rviz_arguments() == ["-d", str(installed)] == rviz_arguments(RobotFrames(""))
    flag, path = rviz_arguments(robot_frames("tb3_0"))
    assert flag == "-d" and yaml.safe_load(Path(path).read_text()) == shown
    Path(path).unlink()
