"""One headless simulation + SLAM run: every node in this process on one executor, then metrics, figures
and the recording.

The system (real rclpy nodes talking over DDS, all in one process and one SingleThreadedExecutor)::

    driver --cmd_vel--> turtle_control --wheel_cmd--> nusim --joint_states--> odometry --odom-->
                                                        |   --scan--> landmarks --landmarks--> slam
                                                        |   --fake_sensor-------------------> slam (known)
                                                        +-- /clock, nusim/ground_truth --> demo_monitor
    recorder: every topic -> the rosbag2 bag run/ (metadata.yaml, run.mcap)
    with ``foxglove``, the recorder's subscriptions also feed a Foxglove WebSocket (docs/live.md)

nusim publishes /clock; every other node uses simulation time. The run is in lockstep (lockstep.py): one
executor cycle per physics step (a wait, the callbacks it found ready, nusim's step in its turn), at most
``rate * realtime_factor`` cycles per wall second. So the estimators keep pace with the simulation
whatever ``realtime_factor`` asks, and a seed gives the same run on any machine (a busy one only slows it).

Frames: SLAM is started at the simulator's start pose ``(x0, y0, theta0)``, so ``map`` = ``nusim/world``;
odometry starts at the identity of ``odom`` on that same pose, so ``T_world_odom = T_world_start``.
In ``localization`` mode (docs/maps.md) slam loads a map made by an earlier run (so ``map`` is that run's
``nusim/world``, the same world) and starts at the map origin; the demo then relocalizes it at the true
start pose with a real `initialpose` message before nusim moves the robot.

Several robots (``robots``, ``--robots N``): one nusim simulates them all in the one world
(nusim/README.md, "Several robots"), and each robot ``tb3_k`` has a stack of its own (robot_stack.py:
turtle_control, odometry, landmarks, slam, driver, demo_monitor under the namespace ``tb3_k``, its frames
prefixed ``tb3_k/``, slam's map the shared ``map``), all on the one executor in the one lockstep. They
drive the one fitted figure eight one after the other (route_fit.py, "Several robots"), each starting
where it joins it, and each robot's LiDAR sees the others. Each robot is evaluated as a run of its own
(``OUT/tb3_k/``: its metrics.json, figures, grid and trajectories) and ``OUT/summary.md`` holds one row
per robot; the bag and config.yaml are the run's. A run of one robot is exactly the run without robots.

Order of start-up: every node is built, the recorder subscribes to every topic, (localization) slam takes
the initialpose, and only then is nusim added to the executor, so the recording holds the run from its
first physics step. With ``save_map`` the demo calls slam's `~/save_map` service (std_srvs/Trigger) once
the simulation has stopped, before the nodes go.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
import yaml
from geometry_msgs.msg import PoseWithCovarianceStamped
from numpy.typing import NDArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from std_srvs.srv import Trigger

from nusim.nusim_node import NusimNode
from nuslam.slam_node import MOTION_SOURCES
from nuturtle_description.robot_params import resolve_model
from nuturtle_eval.grid_score import GridScore, WorldOutline, score_grid, seen_points
from nuturtle_eval.metrics import PoseSeries, RunMetrics, odom_in_world
from nuturtle_eval.run_evaluation import (
    GRID_OUTPUTS,
    MAPPING_SCOPE,
    TUM_OUTPUTS,
    ProgressBar,
    RunRecord,
    RunScope,
    evaluate_and_plot,
    grid_counts,
    loop_counts,
    sensor_range_m,
    slam_snapshot,
    slip_counts,
    write_metrics,
)
from nuturtle_eval.run_folder import RunFolder, say_previous_result
from nuturtle_ros_common.conversions import planar_covariance_6x6, pose_from_transform
from nuturtle_ros_common.dds_domain import PRIVATE, DomainChoice, domain_choice, run_context
from nuturtle_ros_common.qos_events import drop_qos_event_handlers
from nuturtle_ros_common.ros_files import load_ros_parameters, share_file
from nuturtle_ros_common.shared_clock import share_clock
from nuturtle_ros_common.stop_signals import StopSignals
from nuturtle_tools.foxglove_relay import FoxgloveRelay, StaticTransform, slam_view_transforms
from nuturtle_tools.params import params_file, to_parameters
from nuturtle_tools.player import spin_until, wait_until
from nuturtle_tools.recorder import BagWriter, TeeSink, TopicRecorder
from nuturtle_tools.relay_config import RelayConfig, check_port_free
from nuturtle_tools.staged_run import run_staged
from turtlelib import MODES, Transform2D, normalize_angle
from turtlelib.mapping.landmark_map import load_map
from turtlelib.util.validation import finite_real, integer, non_negative, one_of, positive, store

from .driver import FigureEight, RouteConfig
from .lockstep import Pace, run_cycle
from .robot_stack import (
    MAX_ROBOTS,
    RobotPlan,
    RobotResult,
    RobotStack,
    robot_names,
    summary_table,
)
from .route_fit import FittedRoute, fit_route, fleet_route

ASSOCIATIONS = ("known", "unknown")
# Wall time for slam to take the initialpose, and for its ~/save_map service to appear and answer (s)
SLAM_SERVICE_TIMEOUT_S = 10.0
# The recording: a rosbag2 bag directory in the output folder
BAG_NAME = "run"
# With several robots: the table of their results, beside a folder per robot (robot_stack.py)
SUMMARY_FILE = "summary.md"
# Everything a run writes into its output folder (nuturtle_eval.run_folder): one robot's outputs, or several
# robots' folders and their summary
OUTPUTS = (
    "metrics.json", "trajectory.png", "errors.png", "covariance.png", *GRID_OUTPUTS, *TUM_OUTPUTS,
    "config.yaml", BAG_NAME, SUMMARY_FILE, *robot_names(MAX_ROBOTS),
)  # fmt: skip
# Wall time to wait for the recorder to subscribe to every topic before the simulation starts (s)
DISCOVERY_TIMEOUT_S = 10.0
# Wall time to let the last messages arrive after the simulation stops (s)
DRAIN_S = 0.3
# Topics the recorder must hold before nusim starts (the rest follow as they appear), each robot's
REQUIRED_TOPICS = (
    "/cmd_vel", "/wheel_cmd", "/odom", "/landmarks", "/slam/odom", "/slam/path", "/slam/map",
)  # fmt: skip


def required_topics(names: tuple[str, ...]) -> set[str]:
    """REQUIRED_TOPICS of every robot named in ``names`` (``""``: no namespace)."""
    return {f"/{name}{topic}" if name else topic for name in names for topic in REQUIRED_TOPICS}


def default_world() -> Path:
    """nuturtle_demo/config/demo_world.yaml: from the ament index (colcon install) or the source tree."""
    return share_file("nuturtle_demo", "config", "demo_world.yaml")


@dataclass(frozen=True)
class DemoOptions:
    """What to run: ``model`` the TurtleBot3 every node runs (burger, waffle, waffle_pi; None: the
    TURTLEBOT3_MODEL environment variable, else burger; the resolved name is stored);
    ``association`` known | unknown; ``world`` a nusim params file; ``seed`` (int >= 0)
    of every noise stream; ``duration_s`` of simulation time (> 0); ``out_dir`` for the outputs;
    ``realtime`` paces the simulation at real time, otherwise it runs up to ``max_realtime_factor`` (> 0)
    times faster; ``progress`` shows a progress bar on stderr.

    Maps (docs/maps.md): ``motion_source`` joint_states | odom of slam (odom: its ``odom_*`` twist noise
    is ``TwistNoise.from_wheel_slip`` of the same matched wheel slip); ``map_file`` slam's map file;
    ``mode`` mapping | localization (needs an existing ``map_file``; slam starts at the map origin and
    is given the true start pose through `initialpose` with standard deviations ``initial_pose_std``
    (m, m, rad, > 0)); ``save_map`` calls slam's ``~/save_map`` at the end (needs ``map_file``);
    ``start`` (x0, y0, theta0) (m, m, rad, finite) replaces the world's true start pose;
    ``route_radius`` (m, > 0) replaces the driver's figure-eight loop radius; ``route_start_s`` (s, >= 0)
    begins the figure eight that far into its route, the robot (nusim's true start, slam's start) at the
    route's pose there: the next session of a run that stopped there (not with ``start``).

    ``robots`` (1 to MAX_ROBOTS): how many robots drive the world, each with its own SLAM (module
    docstring); more than one only in mapping, without map_file, save_map, start or foxglove.

    ``foxglove`` (host, port) serves every topic live on a Foxglove WebSocket there (docs/live.md; with
    ``realtime`` it plays at robot speed). ``domain_id`` the run's DDS world: ``"private"`` (no other ROS
    program hears it), ``"env"`` (the shell's ROS_DOMAIN_ID) or a domain id 0-232
    (:mod:`nuturtle_ros_common.dds_domain`). ValueError for invalid values."""

    association: str = "unknown"
    model: str | None = None
    world: Path = field(default_factory=default_world)
    seed: int = 0
    duration_s: float = 120.0
    out_dir: Path = Path("out/latest")
    realtime: bool = False
    max_realtime_factor: float = 20.0
    progress: bool = True
    motion_source: str = "joint_states"
    map_file: Path | None = None
    mode: str = "mapping"
    save_map: bool = False
    start: tuple[float, float, float] | None = None
    initial_pose_std: tuple[float, float, float] = (0.05, 0.05, 0.05)
    route_radius: float | None = None
    route_start_s: float = 0.0
    foxglove: tuple[str, int] | None = None
    domain_id: DomainChoice = PRIVATE
    robots: int = 1

    def __post_init__(self) -> None:
        one_of("association", self.association, ASSOCIATIONS)
        store(self, ("robots",), partial(integer, minimum=1))
        if self.robots > MAX_ROBOTS:
            raise ValueError(f"robots must be at most {MAX_ROBOTS}, got {self.robots}")
        store(self, ("domain_id",), domain_choice)
        object.__setattr__(self, "model", resolve_model(self.model))
        if self.foxglove is not None:
            host, port = self.foxglove
            endpoint = RelayConfig(host=host, port=port)
            object.__setattr__(self, "foxglove", (endpoint.host, endpoint.port))
        one_of("motion_source", self.motion_source, MOTION_SOURCES)
        one_of("mode", self.mode, MODES)
        store(self, ("seed",), partial(integer, minimum=0))
        store(self, ("duration_s", "max_realtime_factor"), positive)
        if not Path(self.world).is_file():
            raise ValueError(f"world file {self.world} does not exist")
        try:
            load_ros_parameters(Path(self.world))
        except (OSError, yaml.YAMLError, ValueError, AttributeError) as error:
            raise ValueError(f"world file {self.world} is not a ROS params file: {error}") from None
        if self.start is not None:
            object.__setattr__(self, "start", _triple("start", self.start, finite_real))
        object.__setattr__(
            self, "initial_pose_std", _triple("initial_pose_std", self.initial_pose_std, positive)
        )
        if self.route_radius is not None:
            store(self, ("route_radius",), positive)
        store(self, ("route_start_s",), non_negative)
        if self.route_start_s > 0.0 and self.start is not None:
            raise ValueError("route_start_s places the robot on the route: give it or start, not both")
        if self.map_file is not None:
            object.__setattr__(self, "map_file", Path(self.map_file))
        if self.save_map and self.map_file is None:
            raise ValueError("save_map needs a map_file to save the map to")
        if self.mode == "localization" and (self.map_file is None or not self.map_file.is_file()):
            raise ValueError(f"localization needs an existing map_file, got {self.map_file}")
        if self.map_file is not None and self.map_file.exists():
            load_map(self.map_file)  # slam loads it at start-up: ValueError naming the file
        if self.robots > 1:
            alone = {
                "localization": self.mode == "localization",
                "map_file": self.map_file is not None,
                "save_map": self.save_map,
                "start": self.start is not None,
                "foxglove": self.foxglove is not None,
            }
            given = [name for name, used in alone.items() if used]
            if given:
                raise ValueError(f"{', '.join(given)} take one robot, not robots = {self.robots}")

    @property
    def realtime_factor(self) -> float:
        return 1.0 if self.realtime else self.max_realtime_factor


def _triple(name: str, values: Any, check: Callable[[str, object], float]) -> tuple[float, float, float]:
    if isinstance(values, (str, bytes)) or len(values) != 3:
        raise ValueError(f"{name} must be 3 numbers, got {values!r}")
    return tuple(check(f"{name}[{i}]", value) for i, value in enumerate(values))


@dataclass(frozen=True)
class DemoResult:
    """``out_dir`` where the outputs are (``OUT``, or ``OUT.incomplete`` for a run stopped early);
    ``interrupted`` the name of the signal that stopped the run early (``SIGTERM``), None when it ran its
    whole duration; ``saved_map``: slam's ``~/save_map`` answer (success, message) with ``save_map``, else
    None; ``grid_score``: slam's occupancy grid against the world's true walls (:func:`grid_score`), None
    without a grid; ``scope``: what kind of run it was, which decides the targets that apply to it;
    ``route``: the driver's figure eight as fitted to the world and the model (None with a given radius);
    ``route_time_s``: how far into the figure eight's route the driver got (s; ``route_start_s`` of a
    run that continues this one);
    ``robots``: each robot's results (one for a run of one robot: ``metrics``, ``grid_score`` and
    ``scope`` are the first robot's)."""

    metrics: RunMetrics
    out_dir: Path
    recorded_topics: list[str]
    message_count: int
    interrupted: str | None
    saved_map: tuple[bool, str] | None = None
    grid_score: GridScore | None = None
    scope: RunScope = MAPPING_SCOPE
    route: FittedRoute | None = None
    route_time_s: float = 0.0
    robots: tuple[RobotResult, ...] = ()


class DemoSystem:
    """The nodes of one run, built in one context (see the module docstring): ``nusim``, each robot's
    ``stacks`` (robot_stack.py: ``turtle_control``, ``odometry``, ``landmarks``, ``slam``, ``driver``,
    ``monitor``; those of the first robot are also this system's attributes of these names), ``recorder``
    and, with ``options.foxglove``, ``relay``: the Foxglove server the recorder's subscriptions also feed
    (else None; the caller closes it); ``sim_time_s`` the simulation time (s) nusim has reached. OSError
    when the relay cannot bind its port; ValueError when the robots' route does not fit the world."""

    def __init__(self, options: DemoOptions, context: Context, writer: BagWriter) -> None:
        sim_time = [Parameter("use_sim_time", value=True)]
        world = load_ros_parameters(Path(options.world))
        world.update(seed=options.seed, realtime_factor=options.realtime_factor, model=options.model)
        if options.start is not None:
            world.update(zip(("x0", "y0", "theta0"), options.start, strict=True))
        self.nusim = NusimNode(
            stepped_by_owner=True, context=context, parameter_overrides=to_parameters(world)
        )
        # the route's loops fitted to the world and the model unless a radius is given (route_fit.py);
        # placed elsewhere in the world (nusim started there) when none fits at the world's start
        self.route: FittedRoute | None = None
        radius_m = options.route_radius
        config = self.nusim.simulation.config
        fitted = FittedRoute(config.arena.T_world_start, radius_m, moved=False) if radius_m else None
        try:
            if radius_m is None:
                self.route = fitted = fit_route(config, RouteConfig(), place=options.start is None)
                radius_m = fitted.radius_m
            figure = FigureEight.for_robot(RouteConfig(radius=radius_m), config.robot)
            fleet = fleet_route(fitted, figure, options.robots, config.robot, options.route_start_s)
        except ValueError as error:
            self.nusim.destroy_node()
            raise ValueError(f"model {options.model} in world {options.world}: {error}") from None
        names = robot_names(options.robots)
        if options.robots > 1:
            columns = zip(*(T.as_array() for T in fleet.starts), strict=True)
            robots = dict(zip(("robots.x0", "robots.y0", "robots.theta0"), map(list, columns), strict=True))
            world.update({"robots.names": list(names), **robots})
        elif fleet.starts[0] != config.arena.T_world_start:
            # moved by the route's fit, or a continued route (--route-start) placing the robot where it is
            T_start = fleet.starts[0]
            world.update(x0=T_start.x, y0=T_start.y, theta0=T_start.theta)
        if options.robots > 1 or fleet.starts[0] != config.arena.T_world_start:
            self.nusim.destroy_node()
            self.nusim = NusimNode(
                stepped_by_owner=True, context=context, parameter_overrides=to_parameters(world)
            )
        self.stacks = [
            RobotStack(RobotPlan(name, T_start, radius_m, route_start_s), options, self.nusim, context)
            for name, T_start, route_start_s in zip(names, fleet.starts, fleet.route_starts_s, strict=True)
        ]
        first = self.stacks[0]
        self.monitor, self.driver = first.monitor, first.driver
        self.turtle_control, self.odometry = first.turtle_control, first.odometry
        self.landmarks, self.slam = first.landmarks, first.slam
        self.relay = None if options.foxglove is None else _relay(self, options.foxglove)
        # one subscription per topic for both: a second tap node would slow every executor step
        sink = writer if self.relay is None else TeeSink(writer, self.relay)
        self.recorder = TopicRecorder(sink, context=context, parameter_overrides=sim_time)
        # all of them ours, in one process: no QoS event handlers, and one /clock subscription for the
        # nodes on sim time (every one but nusim, which makes the clock) (qos_events, shared_clock)
        for node in self.nodes:
            drop_qos_event_handlers(node)
        share_clock([node for node in self.nodes if node is not self.nusim])

    @property
    def nodes(self) -> list[Node]:
        robots = [
            node
            for stack in self.stacks
            for node in (stack.turtle_control, stack.odometry, stack.landmarks, stack.slam, stack.driver)
        ]
        return [self.nusim, *robots, self.recorder, *(stack.monitor for stack in self.stacks)]

    @property
    def sim_time_s(self) -> float:
        return self.nusim.step_count / self.nusim.timing.rate


def _relay(system: DemoSystem, endpoint: tuple[str, int]) -> FoxgloveRelay:
    """The Foxglove relay on ``endpoint``. Without /tf it is given what the demo knows: ``map`` is
    ``nusim/world`` and ``odom`` starts on the true start pose (module docstring), and nusim's ground truth
    places ``nusim/base_footprint``."""
    slam_frames = system.slam.node_config
    T_world_start = system.nusim.simulation.config.arena.T_world_start
    known = [
        StaticTransform(slam_frames.map_id, "nusim/world", Transform2D()),
        StaticTransform(slam_frames.map_id, slam_frames.odom_id, T_world_start),
    ]
    transforms = slam_view_transforms(system.slam, known)
    if transforms:
        transforms["tf_from_odometry"].append("nusim/ground_truth")
    host, port = endpoint
    relay = FoxgloveRelay(host, port, name="nuturtle_demo", **transforms)
    print(f"Foxglove WebSocket on {relay.url} (Foxglove: Open connection)", file=sys.stderr)
    return relay


def relocalize(executor: SingleThreadedExecutor, system: DemoSystem, options: DemoOptions) -> None:
    """Give slam nusim's true start pose through a real `initialpose` message (frame ``map_id``,
    covariance ``diag(initial_pose_std^2)``) from a publisher node in the run's context; return once
    slam's filter holds it. RuntimeError if slam does not subscribe or take it within
    SLAM_SERVICE_TIMEOUT_S."""
    T_start = system.nusim.simulation.config.arena.T_world_start
    node = Node("demo_initialpose", context=system.nusim.context)
    executor.add_node(node)
    try:
        publisher = node.create_publisher(PoseWithCovarianceStamped, "initialpose", 10)
        topic = publisher.topic_name

        def matched() -> bool:
            # slam is among the subscribers (odometry listens too) and every one of them is matched
            subscribers = node.get_subscriptions_info_by_topic(topic)
            slam_name = system.slam.get_name()
            return any(info.node_name == slam_name for info in subscribers) and (
                publisher.get_subscription_count() >= len(subscribers)
            )

        if not spin_until(executor, node.get_logger(), matched, SLAM_SERVICE_TIMEOUT_S):
            raise RuntimeError(f"slam did not subscribe to {topic} within {SLAM_SERVICE_TIMEOUT_S} s")
        msg = PoseWithCovarianceStamped()
        msg.header.frame_id = system.slam.node_config.map_id
        msg.header.stamp = node.get_clock().now().to_msg()
        msg.pose.pose = pose_from_transform(T_start)
        msg.pose.covariance = planar_covariance_6x6(np.diag(np.square(options.initial_pose_std)))
        publisher.publish(msg)

        def taken() -> bool:
            T = system.slam.slam.pose
            return (
                abs(T.x - T_start.x) < 1e-9
                and abs(T.y - T_start.y) < 1e-9
                and abs(normalize_angle(T.theta - T_start.theta)) < 1e-9
            )

        if not spin_until(executor, node.get_logger(), taken, SLAM_SERVICE_TIMEOUT_S):
            raise RuntimeError(
                f"slam did not take the initialpose {T_start} within {SLAM_SERVICE_TIMEOUT_S} s"
            )
    finally:
        executor.remove_node(node)
        node.destroy_node()


def call_save_map(executor: SingleThreadedExecutor, system: DemoSystem) -> tuple[bool, str]:
    """Call slam's ``~/save_map`` (std_srvs/Trigger) through a service client node in the run's context;
    its answer (success, message). RuntimeError if it does not answer within SLAM_SERVICE_TIMEOUT_S."""
    node = Node("demo_save_map", context=system.nusim.context)
    executor.add_node(node)
    try:
        name = f"{system.slam.get_fully_qualified_name()}/save_map"
        client = node.create_client(Trigger, name)
        if not spin_until(executor, node.get_logger(), client.service_is_ready, SLAM_SERVICE_TIMEOUT_S):
            raise RuntimeError(f"{name} did not appear within {SLAM_SERVICE_TIMEOUT_S} s")
        future = client.call_async(Trigger.Request())
        if not spin_until(executor, node.get_logger(), future.done, SLAM_SERVICE_TIMEOUT_S):
            raise RuntimeError(f"{name} did not answer within {SLAM_SERVICE_TIMEOUT_S} s")
        response = future.result()
        return bool(response.success), str(response.message)
    finally:
        executor.remove_node(node)
        node.destroy_node()


# on_progress(system, sim_time_s) of run_demo
ProgressCallback = Callable[[DemoSystem, float], None]


def run_demo(options: DemoOptions, on_progress: ProgressCallback | None = None) -> DemoResult:
    """Run the system for ``options.duration_s`` of simulation time and write every output (module
    docstring, docs/demo.md) into a staging folder beside ``options.out_dir`` that replaces it only when
    the run completes (:class:`nuturtle_eval.run_folder.RunFolder`). SIGINT (Ctrl-C), SIGTERM or SIGHUP
    end the run early (:mod:`nuturtle_ros_common.stop_signals`): the outputs then cover the time simulated,
    metrics.json says ``"complete": false`` and they are left in ``OUT.incomplete`` beside the untouched
    ``OUT``. An error once the simulation ran (a full disk: OSError) leaves what was written there too;
    an error before (a port in use: OSError, a world nusim refuses or an ``out_dir`` another run is writing:
    ValueError) leaves nothing.

    ``on_progress(system, sim_time_s)``, if given, is called in the executor's thread after each physics
    step and the callbacks it led to, with the running :class:`DemoSystem` and the simulation time
    it has reached (s): a hook to watch the nodes during the run (``bench/soak.py``). It must only read
    them. nusim steps on the same thread, so a slow hook costs wall time, never simulation time.
    """
    if options.foxglove is not None:
        check_port_free(*options.foxglove)
    keep = [] if options.map_file is None else [options.map_file]
    folder = RunFolder(Path(options.out_dir), OUTPUTS, keep)
    run = _DemoRun(options)

    def stopped_reason(result: DemoResult) -> str | None:
        if result.interrupted is None:
            return None
        return (
            f"interrupted by {result.interrupted} after {result.metrics.sim_seconds:.1f} of "
            f"{options.duration_s:.1f} s of simulation"
        )

    result, where = run_staged(
        folder, partial(run.run, on_progress=on_progress), lambda: run.started, stopped_reason, "the run"
    )
    robots = tuple(replace(robot, out_dir=where / robot.name) for robot in result.robots)
    return replace(result, out_dir=where, robots=robots)


class _DemoRun:
    """One run of the system into a (staging) folder; ``started`` once nusim steps."""

    def __init__(self, options: DemoOptions) -> None:
        self.options = options
        self.started = False

    def run(self, out_dir: Path, stop: StopSignals, on_progress: ProgressCallback | None) -> DemoResult:
        options = self.options
        context = run_context(options.domain_id, signal_handler_options=SignalHandlerOptions.NO)
        executor = SingleThreadedExecutor(context=context)
        system: DemoSystem | None = None
        writer: BagWriter | None = None
        try:
            writer = BagWriter(out_dir / BAG_NAME)
            system = DemoSystem(options, context, writer)
            for node in system.nodes:
                if node is not system.nusim:
                    executor.add_node(node)

            required = required_topics(tuple(stack.name for stack in system.stacks))

            def subscribed() -> bool:
                return required <= set(system.recorder.recorded_topics)

            logger = system.nusim.get_logger()
            if not spin_until(executor, logger, subscribed, DISCOVERY_TIMEOUT_S):
                missing = sorted(required - set(system.recorder.recorded_topics))
                raise RuntimeError(f"the recorder did not discover {missing} within {DISCOVERY_TIMEOUT_S} s")
            if options.mode == "localization":
                relocalize(executor, system, options)
            if stop.received is not None:
                raise RuntimeError(f"stopped by {stop.received} before the simulation started")
            executor.add_node(system.nusim)
            self.started = True
            say_previous_result(options.out_dir)
            wall_start = time.monotonic()
            pace = Pace(1.0 / (system.nusim.timing.rate * options.realtime_factor))
            with ProgressBar(options.duration_s, "sim", options.progress) as progress:
                # lockstep (lockstep.py): one executor cycle per physics step
                while system.sim_time_s < options.duration_s and stop.received is None:
                    pace.wait()
                    run_cycle(executor, system.nusim, system.nusim.step, logger)
                    writer.check()
                    if on_progress is not None:
                        on_progress(system, system.sim_time_s)
                    progress.advance(system.sim_time_s)
            wall_seconds = time.monotonic() - wall_start
            sim_seconds = system.sim_time_s
            executor.remove_node(system.nusim)
            for stack in system.stacks:
                stack.driver.stop()
            wait_until(executor, logger, time.monotonic() + DRAIN_S)
            saved_map = call_save_map(executor, system) if options.save_map else None
            writer.close()
            # the pace of this run is not part of the world: reusing the file runs nusim at real time
            config = params_file(system.nodes, replace={"nusim": {"realtime_factor": 1.0}})
            (out_dir / "config.yaml").write_text(config, encoding="utf-8")
            scope = RunScope(
                mode=options.mode,
                grid_loaded=system.slam.grid.loaded is not None,
                slip_fraction=system.nusim.simulation.config.noise.slip_fraction,
            )
            results = []
            for stack in system.stacks:
                robot_dir = out_dir / stack.name if stack.name else out_dir
                robot_dir.mkdir(exist_ok=True)
                seconds = (sim_seconds, wall_seconds)
                results.append(_evaluate_robot(system, stack, options, robot_dir, seconds, scope, stop))
            if len(results) > 1:
                (out_dir / SUMMARY_FILE).write_text(summary_table(results) + "\n", encoding="utf-8")
            first = results[0]
            return DemoResult(
                first.metrics,
                out_dir,
                sorted(system.recorder.recorded_topics),
                writer.message_count,
                stop.received,
                saved_map,
                first.grid_score,
                scope,
                system.route,
                system.driver.route_time_s,
                tuple(results),
            )
        finally:
            try:
                if writer is not None:
                    writer.close()
            finally:
                if system is not None and system.relay is not None:
                    system.relay.close()
                for node in system.nodes if system else []:
                    node.destroy_node()
                executor.shutdown()
                rclpy.try_shutdown(context=context)


def _evaluate_robot(
    system: DemoSystem,
    stack: RobotStack,
    options: DemoOptions,
    out_dir: Path,
    seconds: tuple[float, float],
    scope: RunScope,
    stop: StopSignals,
) -> RobotResult:
    """One robot's figures and metrics.json in ``out_dir`` (its name and start added with several robots)
    for a run of ``seconds`` (simulated, wall); RuntimeError when it published no odometry or SLAM pose to
    evaluate."""
    record = _run_record(system, stack, options)
    sim_seconds, wall_seconds = seconds
    metrics = evaluate_and_plot(out_dir, record, sim_seconds=sim_seconds, wall_seconds=wall_seconds)
    if metrics is None:
        where = f" of {stack.name}" if stack.name else ""
        raise RuntimeError(f"the run published no odometry or SLAM pose{where} to evaluate")
    score = grid_score(system, record)
    robot = (
        {"robot": stack.name, "start": stack.T_world_start.as_array().tolist()}
        if len(system.stacks) > 1
        else {}
    )
    write_metrics(
        out_dir,
        {
            **robot,
            **metrics.as_dict(),
            **slip_counts(stack.slam),
            **grid_counts(stack.slam),
            **loop_counts(stack.slam),
            **(score.as_dict() if score is not None else {}),
            "complete": stop.received is None,
            "stopped_by": stop.received,
        },
    )
    return RobotResult(stack.name, stack.T_world_start, metrics, score, scope, out_dir)


def _run_record(system: DemoSystem, stack: RobotStack, options: DemoOptions) -> RunRecord:
    """What ``stack``'s robot produced, in ``nusim/world`` (module docstring), for
    :func:`nuturtle_eval.run_evaluation.evaluate_and_plot`."""
    simulation = system.nusim.simulation
    lidar = simulation.config.lidar
    monitor = stack.monitor
    return RunRecord(
        truth=monitor.truth(),
        odom=odom_in_world(monitor.odom(), stack.T_world_start),
        slam=monitor.slam(),
        slam_covariances=monitor.slam_covariances(),
        snapshot=slam_snapshot(stack.slam),
        circles=simulation.circles,
        sensor_range_m=sensor_range_m(
            options.association,
            fake_sensor_range_m=simulation.config.noise.max_range,
            slam_range_m=float(stack.slam.config.max_range),
            radii_m=simulation.circles[:, 2],
            min_points=stack.landmarks.config.min_points,
            angle_increment=lidar.angle_increment,
            lidar_range_m=lidar.range_max,
        ),
        walls=simulation.world.segments,
    )


def grid_score(system: DemoSystem, record: RunRecord) -> GridScore | None:
    """slam's final occupancy grid scored against everything solid in nusim's world
    (:mod:`nuturtle_eval.grid_score`), the walls seen being those of :func:`seen_walls`; None without a
    grid or a true pose."""
    grid = record.snapshot.grid
    seen_xy = seen_walls(system, record.truth)
    if grid is None or seen_xy is None:
        return None
    return score_grid(grid, world_outline(system), seen_xy)


def world_outline(system: DemoSystem) -> WorldOutline:
    """Everything solid in nusim's world (:class:`nuturtle_eval.grid_score.WorldOutline`)."""
    world = system.nusim.simulation.world
    return WorldOutline(world.segments, world.circles)


def seen_walls(system: DemoSystem, truth: PoseSeries | None) -> NDArray[np.float64] | None:
    """Where the LiDAR's exact beams (its nominal beams, the robot's mount) end on the world's outline from
    the true poses ``truth`` at the scan rate (:func:`nuturtle_eval.grid_score.seen_points`), (N, 2) (m);
    None without two true poses."""
    if truth is None or len(truth) < 2:
        return None
    simulation = system.nusim.simulation
    lidar = simulation.config.lidar
    t_s = np.arange(truth.t_s[0], truth.t_s[-1], 1.0 / system.nusim.timing.scan_rate)
    T_body_scan = simulation.config.robot.T_body_scan
    # T_world_scan = T_world_body @ T_body_scan
    T_world_scans = [Transform2D(*pose) @ T_body_scan for pose in truth.interpolate(t_s)]
    return seen_points(world_outline(system), T_world_scans, lidar.angles(), lidar.range_max)
