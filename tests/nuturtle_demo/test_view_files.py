"""The committed view files: the Foxglove layout (the output of nuturtle_tools.foxglove_layout), RViz2's
nuslam/rviz/slam.rviz, and the `rviz` launch argument that opens it (text and AST checks: `launch` is not
installable here)."""

from __future__ import annotations

import ast
import json
import tempfile
from functools import cache
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from nuslam.launch_nodes import rviz_arguments
from nuturtle_demo.run import REQUIRED_TOPICS
from nuturtle_tools.foxglove_layout import build_layout, committed_layout_path, layout_json, main

ROOT = Path(__file__).resolve().parents[2]
LAYOUT_FILE = ROOT / "nuturtle_tools" / "config" / "foxglove_layout.json"
RVIZ_FILE = ROOT / "nuslam" / "rviz" / "slam.rviz"
LAYOUT_TEXT = layout_json(build_layout())
# the topics of a demo run's bag, the demo monitor's SLAM error and the transforms
DEMO_TOPICS = frozenset({
    "/clock", "/fake_sensor", "/joint_states", "/nusim/ground_truth", "/nusim/obstacles", "/nusim/path",
    "/nusim/walls", "/parameter_events", "/rosout", "/scan", "/cmd_vel", "/diagnostics", "/landmarks",
    "/landmarks/clusters", "/odom", "/odometry/path", "/slam/map", "/slam/odom", "/slam/path", "/wheel_cmd",
    "/tf", "/tf_static", "/demo_monitor/slam_error", "/map", "/map_metadata",
})  # fmt: skip
SCENE_TOPICS = {
    "/map", "/scan", "/landmarks", "/slam/map", "/slam/path", "/odometry/path", "/nusim/path", "/slam/odom",
    "/nusim/obstacles", "/nusim/walls", "/fake_sensor",
}  # fmt: skip
LAUNCH_FILES_STARTING_RVIZ = ("nuslam/launch/slam.launch.py", "nuslam/launch/turtlebot3.launch.py")
NUSIM_SLAM_LAUNCH = "nuturtle_demo/launch/nusim_slam.launch.py"


def panels(content: dict) -> list[dict]:
    """Every panel in a layout's content (splits and tabs opened)."""
    if content["type"] == "split":
        return [panel for item in content["items"] for panel in panels(item["content"])]
    if content["type"] == "tabs":
        return [panel for tab in content["tabs"] for panel in panels(tab["content"])]
    return [content]


def referenced_topics(panel: dict) -> set[str]:
    """The topics a panel reads: 3D topics, plot series (``/topic.field``), diagnostics, raw messages."""
    config = panel["config"]
    topics = set(config.get("topics", {}))
    topics.update(series["value"].split(".")[0] for series in config.get("paths", []))
    topics.update(config[key] for key in ("topicToRender", "topicPath") if key in config)
    return topics


@cache
def the_layout() -> dict:
    return json.loads(LAYOUT_FILE.read_text(encoding="utf-8"))


def by_type(panel_type: str) -> list[dict]:
    return [panel for panel in panels(the_layout()["content"]) if panel["panelType"] == panel_type]


def test_the_committed_layout_is_build_layout_s_output():
    assert committed_layout_path() == LAYOUT_FILE
    assert LAYOUT_FILE.read_text(encoding="utf-8") == LAYOUT_TEXT
    assert main(["--check"]) == 0


def test_main_writes_the_layout_that_check_then_accepts(tmp_path, capsys):
    out = tmp_path / "views" / "layout.json"
    assert main(["--check", "--out", str(out)]) == 1
    assert "is missing" in capsys.readouterr().err
    assert main(["--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == LAYOUT_FILE.read_text(encoding="utf-8")
    assert main(["--check", "--out", str(out)]) == 0


@settings(max_examples=10, deadline=None)
@given(st.integers(0, len(LAYOUT_TEXT)), st.characters(codec="utf-8"))
def test_check_refuses_the_layout_with_one_character_more(position, character):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "layout.json"
        path.write_text(LAYOUT_TEXT[:position] + character + LAYOUT_TEXT[position:], encoding="utf-8")
        assert main(["--check", "--out", str(path)]) == 1


def test_every_topic_of_the_layout_is_one_the_demo_records():
    # the demo itself checks its bag holds these: the list above is a demo run's
    assert set(REQUIRED_TOPICS) <= DEMO_TOPICS
    referenced = set().union(*(referenced_topics(panel) for panel in panels(the_layout()["content"])))
    assert referenced and referenced <= DEMO_TOPICS, sorted(referenced - DEMO_TOPICS)


def test_the_3d_panel_shows_slam_in_map_with_the_fake_sensor_hidden():
    (scene,) = by_type("ThreeDee")
    config = scene["config"]
    assert (config["followTf"], config["fixedFrame"], config["followMode"]) == ("map", "map", "follow-none")
    topics = config["topics"]
    assert set(topics) == SCENE_TOPICS
    assert [name for name, settings_ in topics.items() if not settings_["visible"]] == ["/fake_sensor"]
    assert topics["/slam/odom"]["showCovariance"] is True
    assert {topics[name]["type"] for name in ("/slam/path", "/odometry/path", "/nusim/path")} == {"line"}


def test_the_plots_show_the_slam_error_and_nees_over_receive_time():
    plots = {panel["title"]: panel["config"] for panel in by_type("Plot")}
    values = {
        series["value"]: series["timestampMethod"] for config in plots.values() for series in config["paths"]
    }
    assert values == {f"/demo_monitor/slam_error.data[{i}]": "receiveTime" for i in range(3)}
    assert all(config["xAxisVal"] == "timestamp" for config in plots.values())
    (nees_title,) = [title for title in plots if "NEES" in title]
    assert "3 dof" in nees_title and "[0.216, 9.35]" in nees_title
    (diagnostics,) = by_type("DiagnosticsSummary")
    assert diagnostics["config"]["topicToRender"] == "/diagnostics"
    (raw,) = by_type("RawMessages")
    assert raw["config"]["topicPath"] == "/slam/odom"


@pytest.mark.parametrize(("map_frame", "fixed_frame"), [("", "tb3_1/map"), ("map", "map")])
def test_a_robot_s_layout_shows_its_topics_in_its_map_frame(map_frame, fixed_frame):
    layout = json.loads(layout_json(build_layout("tb3_1", map_frame)))
    referenced = set().union(*(referenced_topics(panel) for panel in panels(layout["content"])))
    # the one robot's topics, each under /tb3_1 (the world's and the diagnostics stay global)
    shared = {"/diagnostics", "/nusim/obstacles", "/nusim/walls"}
    own = referenced - shared
    assert all(topic.startswith("/tb3_1/") for topic in own), sorted(own)
    assert {topic.removeprefix("/tb3_1") for topic in own} | shared == set().union(
        *(referenced_topics(panel) for panel in panels(the_layout()["content"]))
    )
    (scene,) = [panel for panel in panels(layout["content"]) if panel["panelType"] == "ThreeDee"]
    config = scene["config"]
    assert (config["followTf"], config["fixedFrame"]) == (fixed_frame, fixed_frame)
    assert config["layers"]["grid"]["frameId"] == fixed_frame


def test_a_robot_s_layout_is_written_to_a_file_of_its_own(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--namespace", "tb3_1"])  # never over the committed layout
    assert stop.value.code == 2 and "give --out" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--namespace", "tb3 1", "--out", str(tmp_path / "bad.json")])
    assert "namespace 'tb3 1'" in capsys.readouterr().err
    out = tmp_path / "tb3_1.json"
    assert main(["--namespace", "tb3_1", "--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == layout_json(build_layout("tb3_1"))


@cache
def rviz_config() -> dict:
    return yaml.load(
        RVIZ_FILE.read_text(encoding="utf-8"), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    )


def test_the_rviz_config_shows_slam_in_map():
    config = rviz_config()
    manager = config["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "map"
    assert {"rviz_common/Displays", "rviz_common/Views"} <= {panel["Class"] for panel in config["Panels"]}
    classes = {display["Class"]: display for display in manager["Displays"]}
    assert {"rviz_default_plugins/Grid", "rviz_default_plugins/TF"} <= classes.keys()
    assert classes["rviz_default_plugins/RobotModel"]["Enabled"] is False
    # the displays that read a topic, by topic
    displays = {display["Topic"]["Value"]: display for display in manager["Displays"] if "Topic" in display}
    expected = {
        "/scan": "LaserScan", "/landmarks": "MarkerArray", "/slam/map": "MarkerArray",
        "/nusim/obstacles": "MarkerArray", "/nusim/walls": "MarkerArray", "/slam/path": "Path",
        "/odometry/path": "Path", "/slam/odom": "Odometry", "/map": "Map",
    }  # fmt: skip
    for topic, display_class in expected.items():
        assert displays[topic]["Class"] == f"rviz_default_plugins/{display_class}", topic
        assert displays[topic]["Enabled"] is True, topic
    assert set(displays) - {"/robot_description"} <= DEMO_TOPICS
    assert displays["/scan"]["Topic"]["Reliability Policy"] == "Best Effort"
    assert displays["/slam/odom"]["Covariance"]["Value"] is True
    # published once or latched (REP 2003): a volatile subscriber would show nothing
    for latched in ("/slam/map", "/map", "/nusim/obstacles", "/nusim/walls"):
        assert displays[latched]["Topic"]["Durability Policy"] == "Transient Local", latched


def test_rviz_arguments_name_the_installed_slam_rviz():
    flag, path = rviz_arguments()
    assert flag == "-d" and Path(path).name == "slam.rviz"
    assert Path(path).read_text(encoding="utf-8") == RVIZ_FILE.read_text(encoding="utf-8")
    assert '"rviz"' in (ROOT / "nuslam" / "setup.py").read_text(encoding="utf-8"), "setup.py installs rviz/"


def calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", None)) == name
    ]


def declares_rviz_false(tree: ast.AST) -> bool:
    """``switch_argument("rviz", False, ...)``: rviz:=true|false, false by default."""
    return any(
        [ast.literal_eval(argument) for argument in call.args[:2]] == ["rviz", False]
        for call in calls(tree, "switch_argument")
    )


def parse(launch_file: str) -> ast.Module:
    return ast.parse((ROOT / launch_file).read_text(encoding="utf-8"))


def test_the_slam_launch_files_start_rviz2_with_slam_rviz_when_asked():
    for launch_file in LAUNCH_FILES_STARTING_RVIZ:
        tree = parse(launch_file)
        assert declares_rviz_false(tree), launch_file
        (rviz,) = [
            call
            for call in calls(tree, "Node")
            if {kw.arg: ast.unparse(kw.value) for kw in call.keywords}.get("package") == "'rviz2'"
        ]
        keywords = {kw.arg: ast.unparse(kw.value) for kw in rviz.keywords}
        assert keywords["executable"] == "'rviz2'", launch_file
        assert keywords["arguments"] == "rviz_arguments(frames)", launch_file  # the robot's frames
        assert keywords["condition"] == "IfCondition(LaunchConfiguration('rviz'))", launch_file


def test_nusim_slam_passes_rviz_on_to_slam_launch():
    tree = parse(NUSIM_SLAM_LAUNCH)
    assert declares_rviz_false(tree)
    (include,) = [
        call for call in calls(tree, "IncludeLaunchDescription") if "slam.launch.py" in ast.unparse(call)
    ]
    assert "'rviz': LaunchConfiguration('rviz')" in ast.unparse(include)
