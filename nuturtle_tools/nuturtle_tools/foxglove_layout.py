"""The Foxglove layout for watching SLAM live or in a recorded bag, built with ``foxglove.layouts``.

What it shows
    * a 3D panel in ``map`` (display and fixed frame, the camera follows nothing), seen from above:
      ``/map`` (slam's occupancy grid, nav_msgs/OccupancyGrid, drawn behind the rest in map colours),
      ``/scan`` (LaserScan, frame ``base_scan``), ``/landmarks`` (the LiDAR's cylinder detections),
      ``/slam/map`` (SLAM's landmarks and their 2-sigma ellipses), the paths ``/slam/path`` (green),
      ``/odometry/path`` (blue) and ``/nusim/path`` (red, the simulator's ground truth), ``/slam/odom`` (the
      pose with its covariance), the simulator's ``/nusim/obstacles`` and ``/nusim/walls`` (in
      ``nusim/world``) and ``/fake_sensor`` (hidden: tick it in the panel's settings). Frames come from
      ``/tf`` and ``/tf_static``, which the 3D panel reads by itself.
    * two plots over receive time of ``/demo_monitor/slam_error`` (std_msgs/Float64MultiArray, ``data`` =
      ``[position_error_m, heading_error_rad, nees_pose]``, published where ground truth exists): the
      position error (m, left axis) and heading error (rad, right axis), and the pose NEES (3 dof) with its
      95 % band of one sample in the title (the Plot panel has no reference lines).
    * tabs for ``/diagnostics`` (Diagnostics summary) and ``/slam/odom`` (Raw Messages).

How to open it
    In Foxglove, *Open connection* > *Foxglove WebSocket* ``ws://127.0.0.1:8765`` (served by the demo's or
    the replay's ``--foxglove``, or ``ros2 run nuturtle_tools foxglove_relay``: docs/live.md), or open a
    bag, then *Layouts* > *Import from file* and pick ``nuturtle_tools/config/foxglove_layout.json``
    (installed as ``share/nuturtle_tools/config/foxglove_layout.json``).

One robot of several (``namespace``, e.g. ``tb3_1``; docs/robot.md "Several robots")
    The same layout on that robot's topics (``/tb3_1/scan``, ``/tb3_1/slam/odom``,
    ``/tb3_1/demo_monitor/slam_error``, ...; ``/diagnostics``, ``/nusim/obstacles`` and ``/nusim/walls``
    stay global) with its map frame as the fixed frame (``tb3_1/map``, or ``map_frame``:
    :func:`nuturtle_ros_common.launch_parameters.robot_frames`): ``python -P -m
    nuturtle_tools.foxglove_layout --namespace tb3_1 --out tb3_1.json``.

The committed JSON is this module's output for no namespace: ``python -P -m nuturtle_tools.foxglove_layout``
rewrites it, ``--check`` exits 1 when it differs from :func:`build_layout`.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import foxglove.layouts as fl

from nuturtle_eval.metrics import POSE_DOF, nees_band
from nuturtle_ros_common.launch_parameters import RobotFrames, robot_frames
from nuturtle_ros_common.ros_files import share_file

# the robot's topics (under its namespace), and the topics every robot shares
SLAM_ERROR_TOPIC = "demo_monitor/slam_error"
SLAM_ODOM_TOPIC = "slam/odom"
DIAGNOSTICS_TOPIC = "/diagnostics"
WORLD_TOPICS = ("/nusim/obstacles", "/nusim/walls")
# the colours of the demo's figures (matplotlib's tab:green, tab:blue, tab:red)
SLAM_COLOR = "#2ca02c"
ODOM_COLOR = "#1f77b4"
TRUTH_COLOR = "#d62728"
SCAN_COLOR = "#ffffff"
PATH_LINE_WIDTH = 0.03  # m
GRID_ALPHA = 0.7  # the occupancy grid under the paths and markers
CAMERA_DISTANCE = 8.0  # m, from above: a basic world of a few metres fills the panel
HEADING_AXIS = "heading"


def _path(color: str) -> fl.BaseRendererPosesTopicSettings:
    return fl.BaseRendererPosesTopicSettings(
        visible=True, type="line", line_width=PATH_LINE_WIDTH, gradient=(color, color)
    )


def _markers(visible: bool = True) -> fl.BaseRendererRosMarkerTopicSettings:
    return fl.BaseRendererRosMarkerTopicSettings(visible=visible)


def robot_topic(frames: RobotFrames, name: str) -> str:
    """The robot's topic ``name`` (``scan``) in full: ``/scan``, ``/tb3_1/scan`` under ``tb3_1``."""
    return f"/{frames.prefix}{name}"


def _scene_topics(frames: RobotFrames) -> dict[str, fl.BaseRendererTopicSettings]:
    """The 3D panel's topics and how each is drawn."""
    robot = {
        "map": fl.BaseRendererRosOccupancyGridTopicSettings(
            visible=True, color_mode="map", draw_behind=True, alpha=GRID_ALPHA
        ),
        "scan": fl.BaseRendererLaserScanTopicSettings(
            visible=True, point_size=3, color_mode="flat", flat_color=SCAN_COLOR
        ),
        "landmarks": _markers(),
        "slam/map": _markers(),
        "slam/path": _path(SLAM_COLOR),
        "odometry/path": _path(ODOM_COLOR),
        "nusim/path": _path(TRUTH_COLOR),
        SLAM_ODOM_TOPIC: fl.BaseRendererPoseTopicSettings(
            visible=True, type="arrow", color=SLAM_COLOR, show_covariance=True, covariance_color=SLAM_COLOR
        ),
    }
    world = {topic: _markers() for topic in WORLD_TOPICS}
    return {
        **{robot_topic(frames, name): settings for name, settings in robot.items()},
        **world,
        robot_topic(frames, "fake_sensor"): _markers(visible=False),
    }


def _scene(frames: RobotFrames) -> fl.ThreeDeePanel:
    fixed_frame = frames.map_id
    return fl.ThreeDeePanel(
        title=f"SLAM in {fixed_frame}",
        config=fl.ThreeDeeConfig(
            follow_tf=fixed_frame,
            fixed_frame=fixed_frame,
            follow_mode="follow-none",
            camera_state=fl.ThreeDeeCameraState(perspective=False, distance=CAMERA_DISTANCE),
            layers={"grid": fl.BaseRendererGridLayerSettings(visible=True, frame_id=fixed_frame, size=10)},
            topics=_scene_topics(frames),
        ),
    )


def _error_series(
    error_topic: str, index: int, label: str, color: str, y_axis_id: str | None = None
) -> fl.PlotSeries:
    return fl.PlotSeries(
        value=f"{error_topic}.data[{index}]",
        label=label,
        color=color,
        timestamp_method="receiveTime",
        y_axis_id=y_axis_id,
    )


def _plot(
    title: str,
    y_axis_label: str,
    series: list[fl.PlotSeries],
    secondary_axes: list[fl.PlotSecondaryAxis] | None = None,
    min_y_value: float | None = None,
) -> fl.PlotPanel:
    return fl.PlotPanel(
        title=title,
        config=fl.PlotConfig(
            paths=series,
            x_axis_val="timestamp",
            y_axis_label=y_axis_label,
            min_y_value=min_y_value,
            secondary_axes=secondary_axes,
            show_legend=True,
            legend_display="floating",
        ),
    )


def _error_plot(error_topic: str) -> fl.PlotPanel:
    return _plot(
        "SLAM error against ground truth",
        "position error (m)",
        [
            _error_series(error_topic, 0, "position error (m)", SLAM_COLOR),
            _error_series(error_topic, 1, "heading error (rad)", TRUTH_COLOR, y_axis_id=HEADING_AXIS),
        ],
        secondary_axes=[fl.PlotSecondaryAxis(id=HEADING_AXIS, label="heading error (rad)")],
    )


def _nees_plot(error_topic: str) -> fl.PlotPanel:
    low, high = nees_band()
    return _plot(
        f"pose NEES ({POSE_DOF} dof; 95 % of samples in [{low:.3f}, {high:.2f}] if consistent)",
        "NEES",
        [_error_series(error_topic, 2, "pose NEES", SLAM_COLOR)],
        min_y_value=0.0,
    )


def build_layout(namespace: str = "", map_frame: str = "") -> fl.Layout:
    """The layout: the 3D scene on the left; the error and NEES plots and the diagnostics / raw
    ``/slam/odom`` tabs stacked on the right; of the robot in ``namespace`` (``""``: none) with slam's map
    frame ``map_frame`` (``""``: the robot's own; module docstring). ValueError for a namespace that is no
    ROS name."""
    frames = robot_frames(namespace, map_frame)
    slam_odom, error_topic = (robot_topic(frames, name) for name in (SLAM_ODOM_TOPIC, SLAM_ERROR_TOPIC))
    tabs = fl.TabContainer(
        tabs=[
            fl.TabItem(
                title="Diagnostics",
                content=fl.DiagnosticsSummaryPanel(
                    config=fl.DiagnosticsSummaryConfig(topic_to_render=DIAGNOSTICS_TOPIC, sort_by_level=True)
                ),
            ),
            fl.TabItem(
                title=slam_odom,
                content=fl.RawMessagesPanel(config=fl.RawMessagesConfig(topic_path=slam_odom)),
            ),
        ]
    )
    side = fl.SplitContainer(
        direction="column",
        items=[
            fl.SplitItem(content=_error_plot(error_topic)),
            fl.SplitItem(content=_nees_plot(error_topic)),
            fl.SplitItem(content=tabs),
        ],
    )
    return fl.Layout(
        content=fl.SplitContainer(
            direction="row",
            items=[
                fl.SplitItem(proportion=2, content=_scene(frames)),
                fl.SplitItem(proportion=1, content=side),
            ],
        )
    )


def layout_json(layout: fl.Layout) -> str:
    """``layout`` as the committed file holds it: indented JSON in the layout's own key order, newline at
    the end (the same text for the same layout)."""
    return json.dumps(json.loads(layout.to_json()), indent=2) + "\n"


def committed_layout_path() -> Path:
    """``share/nuturtle_tools/config/foxglove_layout.json`` (the source folder in a pip install)."""
    return share_file("nuturtle_tools", "config", "foxglove_layout.json")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m nuturtle_tools.foxglove_layout",
        description="Write the demo's Foxglove layout (or check the file against build_layout()).",
    )
    parser.add_argument("--out", type=Path, default=None, help="the file (default: the committed layout)")
    parser.add_argument(
        "--check", action="store_true", help="write nothing; exit 1 when the file differs from build_layout()"
    )
    parser.add_argument("--namespace", default="", metavar="NS",
                        help="the layout of the robot under NS (e.g. tb3_1): its topics, its map frame; "
                        "needs --out (default: none, the committed layout)")  # fmt: skip
    parser.add_argument(
        "--map-frame",
        default="",
        metavar="FRAME",
        help="the fixed frame: slam's map frame (default: NS/map, map without --namespace)",
    )
    args = parser.parse_args(argv)
    if (args.namespace or args.map_frame) and args.out is None:
        parser.error("--namespace and --map-frame write another layout than the committed one: give --out")
    try:
        text = layout_json(build_layout(args.namespace, args.map_frame))
    except ValueError as error:
        parser.error(str(error))
    path = args.out or committed_layout_path()
    if args.check:
        current = path.read_text(encoding="utf-8") if path.is_file() else None
        if current != text:
            state = "is missing" if current is None else "differs from build_layout()"
            print(
                f"{path} {state}: regenerate it with `python -P -m nuturtle_tools.foxglove_layout`",
                file=sys.stderr,
            )
            return 1
        print(f"{path} is up to date")
        return 0
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
