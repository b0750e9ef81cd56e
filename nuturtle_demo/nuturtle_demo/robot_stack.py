"""One robot's nodes in the demo, and the summary of several robots' results.

A robot's stack is ``demo_monitor``, ``driver``, ``turtle_control``, ``odometry``, ``landmarks`` and
``slam`` (built in that order). The one robot of a run has no namespace and the frames ``odom``,
``base_footprint``, ``base_scan``, exactly as before. With ``--robots N`` robot ``k`` is named
``tb3_k``: its nodes live in the namespace ``tb3_k`` (``/tb3_k/scan``, ``/tb3_k/slam/odom``, ...) and its
frames carry the prefix ``tb3_k/`` (odometry's ``odom_id``, ``body_id``; slam's ``odom_id``, ``body_id``,
``sensor_id``: the names nusim gives them). slam's ``map_id`` stays the shared ``map``: every robot's
SLAM starts at its true start pose in ``nusim/world`` (run.py's "Frames"), so each robot's ``map`` is
``nusim/world`` and one ``map`` frame is right for all of them.

To each robot's LiDAR the others are discs of their collision radius ``R``, which the landmark detector
would take for cylinders: seen standing still at the start they are mapped, and when they drive off the
map moves with them and the SLAM with it (three robots in the default world: the first robot's SLAM lost
its pose within 1.5 s). So with several robots the landmarks node's radius window is narrowed to leave
``R`` out (:func:`landmark_radius_window`), as one who knows the size of the posts would set it: the
world's cylinders all smaller than ``R`` keep radii up to halfway to ``R``, all larger from halfway up.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rclpy.context import Context
from rclpy.parameter import Parameter

from nuturtle_control.odometry import OdometryNode
from nuturtle_control.turtle_control import TurtleControlNode
from nuturtle_eval.grid_score import GridScore
from nuturtle_eval.metrics import RunMetrics
from nuturtle_eval.run_evaluation import RunScope, failed_targets
from nuturtle_ros_common.launch_parameters import RobotFrames, robot_frames
from nuturtle_tools.monitor import RunMonitor
from nuturtle_tools.params import to_parameters
from turtlelib import DetectorConfig, Transform2D, TwistNoise

from .driver import FigureEightDriver
from .matched_noise import matched_point_std, matched_wheel_noise

# Robot k's name (its namespace and frame prefix) when a run has several
ROBOT_NAME = "tb3_{}"
# The most robots a run takes
MAX_ROBOTS = 6


def robot_names(n: int) -> tuple[str, ...]:
    """The names of ``n`` robots: ``("",)`` for one (no namespace), else ``tb3_0`` ... ``tb3_{n-1}``."""
    return ("",) if n == 1 else tuple(ROBOT_NAME.format(k) for k in range(n))


@dataclass(frozen=True)
class RobotPlan:
    """Where a robot drives: ``name`` (its namespace, ``""`` for the one robot), its true start pose
    ``T_world_start`` (nusim/world), the figure eight's loop ``radius_m`` (m) and the route time
    ``route_start_s`` (s) where it joins it (driver.py)."""

    name: str
    T_world_start: Transform2D
    radius_m: float
    route_start_s: float = 0.0

    @property
    def frames(self) -> RobotFrames:
        """Its frame ids: ``tb3_k/odom`` ... and the shared ``map`` (module docstring); none of its own (the
        nodes' defaults) for the one robot."""
        return robot_frames(self.name, "map" if self.name else "")

    @property
    def namespace(self) -> dict[str, str]:
        """The ``namespace`` keyword of its nodes (none for the one robot)."""
        return {"namespace": self.name} if self.name else {}


class RobotStack:
    """One robot's nodes (module docstring), built in ``context`` for ``plan`` with the run's ``options``
    (:class:`nuturtle_demo.run.DemoOptions`); ``nusim`` the run's simulator (its world, noise and LiDAR
    set slam's matched noise)."""

    def __init__(self, plan: RobotPlan, options: Any, nusim: Any, context: Context) -> None:
        self.plan = plan
        sim_time = [Parameter("use_sim_time", value=True)]
        robot = sim_time + [Parameter("model", value=options.model)]
        where = plan.namespace
        route = {
            "radius": plan.radius_m,
            **({"route_start_s": plan.route_start_s} if plan.route_start_s else {}),
        }
        self.monitor = RunMonitor(context=context, parameter_overrides=sim_time, **where)
        self.driver = FigureEightDriver(
            context=context, parameter_overrides=robot + to_parameters(route), **where
        )
        self.turtle_control = TurtleControlNode(context=context, parameter_overrides=robot, **where)
        self.odometry = OdometryNode(
            context=context, parameter_overrides=robot + to_parameters(plan.frames.odometry()), **where
        )
        self.landmarks, self.slam = slam_nodes(self, options, nusim, context, sim_time)

    @property
    def name(self) -> str:
        return self.plan.name

    @property
    def T_world_start(self) -> Transform2D:
        return self.plan.T_world_start


def landmark_radius_window(radii_m: Iterable[float], robot_radius_m: float) -> dict[str, float]:
    """The landmarks node's ``min_radius`` / ``max_radius`` that leave out the robots (module docstring):
    with every cylinder radius in ``radii_m`` below ``robot_radius_m`` ``R``, ``max_radius`` halfway from
    the largest to ``R``; with every one above, ``min_radius`` halfway from ``R`` to the smallest (each
    only narrowing DetectorConfig's window, never past its other end); none otherwise (nothing to tell
    them apart by)."""
    default = DetectorConfig()
    radii_m = [float(r) for r in radii_m]
    if radii_m and max(radii_m) < robot_radius_m:
        return {"max_radius": min(default.max_radius, 0.5 * (max(radii_m) + robot_radius_m))}
    if (
        radii_m
        and min(radii_m) > robot_radius_m
        and 0.5 * (min(radii_m) + robot_radius_m) < default.max_radius
    ):
        return {"min_radius": max(default.min_radius, 0.5 * (min(radii_m) + robot_radius_m))}
    return {}


def slam_nodes(stack: RobotStack, options: Any, nusim: Any, context: Context, sim_time: list[Parameter]):
    """The landmarks and slam nodes of ``stack``'s robot, SLAM started at its start pose (localization:
    at the map origin) with matched process noise and LiDAR noise (the scan registration's)."""
    from nuslam.landmarks_node import LandmarksNode
    from nuslam.slam_node import SlamNode

    simulation = nusim.simulation
    T_start = stack.T_world_start
    left_rad_s, right_rad_s = stack.driver.route.wheel_speeds_rad_s
    wheel_noise = matched_wheel_noise(
        simulation.config.noise.slip_fraction,
        0.5 * (abs(left_rad_s) + abs(right_rad_s)),
        nusim.timing.rate,
    )
    T_slam_start = Transform2D() if options.mode == "localization" else T_start
    slam_values = {
        "model": options.model,
        "association": options.association,
        "x0": T_slam_start.x,
        "y0": T_slam_start.y,
        "theta0": T_slam_start.theta,
        "wheel_noise": wheel_noise,
        "motion_source": options.motion_source,
        "mode": options.mode,
        "registration.point_std_m": matched_point_std(
            simulation.config.lidar.noise, simulation.config.lidar.resolution
        ),
        # nusim's ranges are unbiased: its local maps do not drift
        "registration.drift_m2_per_m": 0.0,
        "registration.drift_rad2_per_m": 0.0,
    }
    # the shared map (module docstring), the robot's own odom, body and sensor frames
    slam_values.update(stack.plan.frames.slam())
    if options.map_file is not None:
        slam_values["map_file"] = str(options.map_file)
    if options.motion_source == "odom":
        # the same slip as wheel_noise, as the twist noise of the odometry's pose increments
        noise = TwistNoise.from_wheel_slip(stack.driver.robot.diff_drive(), wheel_noise)
        slam_values.update({f"odom_{name}": value for name, value in vars(noise).items()})
    where = stack.plan.namespace
    window = (
        landmark_radius_window(simulation.circles[:, 2], simulation.config.robot.collision_radius)
        if stack.name
        else {}
    )
    landmarks = LandmarksNode(context=context, parameter_overrides=sim_time + to_parameters(window), **where)
    slam = SlamNode(context=context, parameter_overrides=sim_time + to_parameters(slam_values), **where)
    return landmarks, slam


@dataclass(frozen=True)
class RobotResult:
    """One robot's results: its ``name`` (``""`` for the one robot), true start ``T_world_start``, the
    ``metrics``, the grid's ``grid_score`` (None without a grid), the ``scope`` of its targets and the
    folder ``out_dir`` with its metrics.json and figures."""

    name: str
    T_world_start: Transform2D
    metrics: RunMetrics
    grid_score: GridScore | None
    scope: RunScope
    out_dir: Path

    def grid_rows(self) -> list:
        return [] if self.grid_score is None else self.grid_score.rows(self.scope)

    def failed(self) -> list[str]:
        """The labels of the targets it failed (:func:`nuturtle_eval.run_evaluation.failed_targets`)."""
        return failed_targets(self.metrics, self.grid_rows(), self.scope)


def summary_table(results: list[RobotResult]) -> str:
    """A markdown table with one row per robot: its start, SLAM's and odometry's ATE RMSE, SLAM's final
    position error, the landmark RMSE, the landmarks that came in range and were mapped, the share of pose
    NEES inside its 95 % band, and the targets it failed (✓ for none)."""
    rows = [
        "| robot | start (x, y, theta) | ATE RMSE SLAM (m) | ATE RMSE odometry (m) | final position "
        "error SLAM (m) | landmark RMSE (m) | landmarks in range / mapped | pose NEES in 95% band | "
        "targets |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for result in results:
        m, T = result.metrics, result.T_world_start
        failed = result.failed()
        rows.append(
            f"| {result.name} | ({T.x:.2f}, {T.y:.2f}, {T.theta:.2f}) | {m.ate_rmse_slam_m:.4f} | "
            f"{m.ate_rmse_odom_m:.4f} | {m.final_position_error_slam_m:.4f} | {m.landmark_rmse_m:.4f} | "
            f"{m.landmarks_in_range} / {m.landmarks_mapped} | {m.nees_pose_within_95_fraction:.3f} | "
            f"{'✓' if not failed else '✗ ' + '; '.join(failed)} |"
        )
    return "\n".join(rows)
