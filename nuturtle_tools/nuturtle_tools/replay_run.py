"""One replay: a rosbag2 recording played into the real `landmarks` and `slam` nodes, in one process on one
SingleThreadedExecutor, then metrics and figures (the command line is replay.py; docs/replay.md).

The system::

    bag --BagSource--> bag_player --/clock, scan, joint_states, odom, nusim/ground_truth-->
        landmarks --landmarks--> slam --slam/odom, slam/path, slam/map-->
        recorder (every topic but the played ones -> slam/ bag), demo_monitor (truth, odom, slam/odom)
        with ``foxglove``, a Foxglove WebSocket: the played messages from the player, the rest from the
        recorder's subscriptions (with ``play_only``, a tap on the player node)

Every node but the player runs on simulation time from the played /clock (each message's log time, sent
just before the message). The messages are played a log-time step at a time: /clock, then the messages of
that log time (at most one per topic; a second one of a topic starts a new step), then the executor runs
until no callback is ready (``player.run_until_idle``), so a scan's landmarks reach slam before the next
step goes out: as fast as the nodes go (default) or paced at ``rate`` x real time, and no message is
dropped either way (no queue ever holds more than one played message). Within a step each node hears /clock
first (its time source subscribed first), and slam hears the step's joint_states before the landmarks the
step's scan gives, as in the live run. The four share one /clock subscription (landmarks', the first of them
the executor spins) and have no QoS event handlers (``nuturtle_ros_common.qos_events``).

Motion: slam's ``motion_source`` (the option, else the params file's, else the node's default) decides
which motion topic the bag must have and which is played: ``joint_states`` (the wheels; the bag's odom is
played too, for slam's ``map -> odom`` and the odometry metrics) or ``odom`` (no joint_states played: slam
does not subscribe to them then).

Ground truth (``truth_topic``, nav_msgs/Odometry, default ``/nusim/ground_truth``) is played on
``nusim/ground_truth``, which only the monitor hears. One bag topic may have several roles: a Gazebo
``/odom`` (the model's true pose) given as ``truth_topic`` is played as both ``odom`` and the truth. When
the bag has a truth, SLAM starts at the truth's pose at the first motion sample's stamp (so ``map`` = the
truth's frame; a truth that starts later, as a reference made at the scans, is moved back to it by the bag's
odometry: :func:`truth_pose_at`), odometry is placed in that frame by its first sample
(``T_world_odom = T_world_body(t0) T_odom_body(t0)^-1``), and the demo's accuracy metrics are computed;
the true cylinders come from the params file's ``nusim`` section (``obstacles.x/y/r``, e.g. a nusim world
file) or else the bag's ``/nusim/obstacles`` markers (neither: the map is counted, never judged, so no
landmark is called spurious). With the truth and scans, slam's grid is also scored
against the scans placed at the truth's poses (:mod:`nuturtle_eval.grid_agreement`). Without it SLAM starts
at the params' ``x0, y0, theta0``. The demo's pass/fail targets apply to nusim recordings only (the bag has
``/nusim/ground_truth``).

``max_range_m`` cuts the played scans to a shorter-ranged LiDAR's (an LDS-01's 3.5 m on a recording of a
SICK's 40 m): ``range_max`` lowered to it and every reading beyond it made +inf (REP 117's "no return").

A robot of several (``namespace``, e.g. ``tb3_1``: a recording of a namespaced robot, or one robot of the
demo's ``--robots N`` bag): each role's default bag topic is that robot's (``/tb3_1/scan``, ...,
``/tb3_1/nusim/ground_truth``; a topic given explicitly is taken as given), every node of the replay lives
in the namespace (the topics above under ``/tb3_1``; /clock stays global) and slam gets the robot's frame
ids (``tb3_1/odom``, ``tb3_1/base_footprint``, ``tb3_1/base_scan`` and ``tb3_1/map``, or ``map_frame``:
:func:`nuturtle_ros_common.launch_parameters.robot_frames`), over the params file's, as a launch argument
wins; the params file's sections for the nodes are those rcl gives nodes of that namespace
(``tb3_1/slam``, as the demo's config.yaml has them). The outputs are those of any replay.
"""

from __future__ import annotations

import math
import re
import sys
import time
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
import yaml
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.signals import SignalHandlerOptions

from nuturtle_description.robot_params import resolve_model
from nuturtle_eval.grid_agreement import scan_grid_agreement
from nuturtle_eval.metrics import PoseSeries, odom_in_world
from nuturtle_eval.run_evaluation import (
    GRID_OUTPUTS,
    TUM_OUTPUTS,
    ProgressBar,
    RunRecord,
    SlamSnapshot,
    evaluate_and_plot,
    grid_counts,
    loop_counts,
    sensor_range_m,
    slam_snapshot,
    slip_counts,
    write_metrics,
)
from nuturtle_eval.run_folder import RunFolder, say_previous_result
from nuturtle_ros_common.conversions import stamp_nanoseconds, transform_from_pose
from nuturtle_ros_common.dds_domain import ENVIRONMENT, PRIVATE, DomainChoice, domain_choice, run_context
from nuturtle_ros_common.launch_parameters import RobotFrames, robot_frames
from nuturtle_ros_common.qos_events import drop_qos_event_handlers
from nuturtle_ros_common.ros_files import flatten
from nuturtle_ros_common.shared_clock import share_clock
from nuturtle_ros_common.stop_signals import StopSignals
from turtlelib import Transform2D
from turtlelib.mapping.landmark_map import save_map
from turtlelib.sensing.range_scan import RangeScan
from turtlelib.util.timebase import NS_PER_S
from turtlelib.util.validation import store

from .bag_source import BagError, BagMessage, BagSource, BagTopic
from .foxglove_relay import FoxgloveRelay, slam_view_transforms
from .monitor import RunMonitor
from .params import params_file, to_parameters
from .player import (
    BagPlayer,
    Pacer,
    PlayedTopic,
    played_qos,
    run_until_idle,
    spin_until,
    wait_for_acks,
    wait_until,
)
from .recorder import BagWriter, TeeSink, TopicRecorder, TopicTap, absolute, message_class
from .relay_config import RelayConfig, check_port_free
from .staged_run import run_staged

# The SLAM outputs: a rosbag2 bag directory in the output folder (slam/metadata.yaml + slam/slam.mcap)
BAG_NAME = "slam"
# With --smooth: the smoothed run's outputs, in a folder of their own beside the filter's
SMOOTHED_DIR = "smoothed"
# Everything a replay writes into its output folder (nuturtle_eval.run_folder)
OUTPUTS = (
    "metrics.json", "trajectory.png", "errors.png", "covariance.png", "map.json", *GRID_OUTPUTS,
    *TUM_OUTPUTS, "config.yaml", BAG_NAME, SMOOTHED_DIR,
)  # fmt: skip
TRUTH_PLAYED_AS = "nusim/ground_truth"
# a recording of nusim (the demo's): its pass/fail targets apply
NUSIM_TRUTH_TOPIC = "/nusim/ground_truth"
OBSTACLES_TOPIC = "/nusim/obstacles"
# Wall time to wait for every subscription to match the player and the recorder to subscribe (s)
DISCOVERY_TIMEOUT_S = 10.0
# Wall time a reliable publication may wait for acknowledgements in --play-only mode (s)
ACK_TIMEOUT_S = 5.0
# (role, played name, expected type); the sensor role mirrors the recorded QoS
ROLES = {
    "scan": ("scan", "sensor_msgs/msg/LaserScan"),
    "joint_states": ("joint_states", "sensor_msgs/msg/JointState"),
    "odom": ("odom", "nav_msgs/msg/Odometry"),
    "truth": (TRUTH_PLAYED_AS, "nav_msgs/msg/Odometry"),
    "fake_sensor": ("fake_sensor", "visualization_msgs/msg/MarkerArray"),
}
SENSOR_ROLES = ("scan",)


def default_topics(namespace: str = "") -> dict[str, str]:
    """The bag topic of each role in a recording of the robot in ``namespace`` (``""``: none): ``/scan``,
    ``/joint_states``, ``/odom``, ``/nusim/ground_truth``, ``/fake_sensor``, under ``/<namespace>``."""
    prefix = f"/{namespace}" if namespace else ""
    return {role: prefix + absolute(name) for role, (name, _) in ROLES.items()}


@dataclass(frozen=True)
class ReplayOptions:
    """What to replay (docs/replay.md): the recording ``bag`` (a bag directory or a single .mcap/.db3);
    ``out_dir``; ``params`` a ROS params file whose ``slam`` and ``landmarks`` sections (and ``/**``) go to
    those nodes; ``association`` / ``motion_source`` override it (None: the file's, or the node's default);
    ``model`` slam's robot model (None: the file's, else TURTLEBOT3_MODEL, else burger; robot constants set in
    the file still win over the model's, as any explicit parameter does); ``topics`` the bag topic of each
    role (``scan``, ``joint_states``, ``odom``, ``truth``, ``fake_sensor``; None: :func:`default_topics` of
    ``namespace``); ``rate`` > 0 paces at that many times real time, 0 plays as fast as the nodes go (None: 0,
    or 1.0 with ``play_only``); ``play_only`` runs only the player, which first waits up to
    ``wait_for_subscribers_s`` (wall) for a subscriber on every played topic; ``progress`` a bar on stderr;
    ``foxglove`` (host, port) serves every topic live on a Foxglove WebSocket there (docs/live.md; with
    ``rate`` 1 it plays at robot speed); ``domain_id`` the run's DDS world: ``"private"`` (no other ROS
    program hears it), ``"env"`` (the shell's ROS_DOMAIN_ID) or a domain id 0-232
    (:mod:`nuturtle_ros_common.dds_domain`; None: private, or env with ``play_only``, whose listeners are the
    user's nodes); ``smooth`` also smooths slam's whole run at the end (its ``smooth_saved_map``) and writes
    it beside the filter's outputs, in ``smoothed/``; ``max_range_m`` (> 0) cuts the played scans' ranges to
    it (module docstring; None: as recorded); ``namespace`` the recorded robot's (``""``: none) and
    ``map_frame`` its slam's map frame (``""``: ``<namespace>/map``; module docstring). ValueError for a
    namespace that is not a ROS name."""

    bag: Path
    out_dir: Path = Path("out/replay")
    params: Path | None = None
    association: str | None = None
    motion_source: str | None = None
    model: str | None = None
    topics: Mapping[str, str] | None = None
    rate: float | None = None
    play_only: bool = False
    wait_for_subscribers_s: float = 5.0
    progress: bool = True
    foxglove: tuple[str, int] | None = None
    domain_id: DomainChoice | None = None
    smooth: bool = False
    max_range_m: float | None = None
    namespace: str = ""
    map_frame: str = ""

    def __post_init__(self) -> None:
        frames = robot_frames(self.namespace, self.map_frame)
        object.__setattr__(self, "namespace", frames.namespace)
        if self.topics is None:
            object.__setattr__(self, "topics", default_topics(self.namespace))
        if self.max_range_m is not None and not (math.isfinite(self.max_range_m) and self.max_range_m > 0.0):
            raise ValueError(f"max_range_m must be > 0, got {self.max_range_m!r}")
        if self.smooth and self.play_only:
            raise ValueError("smoothing needs the slam node, which --play-only does not run")
        if self.domain_id is not None:
            store(self, ("domain_id",), domain_choice)
        if self.foxglove is not None:
            host, port = self.foxglove
            endpoint = RelayConfig(host=host, port=port)
            object.__setattr__(self, "foxglove", (endpoint.host, endpoint.port))
        if self.association not in (None, "known", "unknown"):
            raise ValueError(f"association must be known or unknown, got {self.association!r}")
        if self.motion_source not in (None, "joint_states", "odom"):
            raise ValueError(f"motion_source must be joint_states or odom, got {self.motion_source!r}")
        if self.model is not None:
            resolve_model(self.model)
        if self.rate is not None and not (math.isfinite(self.rate) and self.rate >= 0.0):
            raise ValueError(f"rate must be >= 0 (0: as fast as possible), got {self.rate!r}")
        if self.params is not None and not Path(self.params).is_file():
            raise ValueError(f"params file {self.params} does not exist")
        unknown = sorted(set(self.topics) - set(ROLES))
        if unknown:
            raise ValueError(f"unknown topic roles {unknown}; known: {sorted(ROLES)}")

    @property
    def pace(self) -> float:
        """The rate in use: > 0 paced, 0 as fast as possible."""
        if self.rate is not None:
            return float(self.rate)
        return 1.0 if self.play_only else 0.0

    @property
    def domain(self) -> DomainChoice:
        """The DDS world in use (``domain_id``, else private, or env with ``play_only``)."""
        if self.domain_id is not None:
            return self.domain_id
        return ENVIRONMENT if self.play_only else PRIVATE

    @property
    def frames(self) -> RobotFrames:
        """The recorded robot's frames (:func:`~nuturtle_ros_common.launch_parameters.robot_frames`)."""
        return robot_frames(self.namespace, self.map_frame)

    def bag_topic(self, role: str) -> str:
        return absolute(self.topics.get(role, ""))

    def topic(self, name: str) -> str:
        """The replay's topic ``name`` (relative, as its nodes name it) in full, under ``namespace``."""
        return absolute(f"{self.namespace}/{name}" if self.namespace else name)


@dataclass(frozen=True)
class ReplayResult:
    """``metrics`` (metrics.json), ``out_dir`` where the outputs are (``OUT``, or ``OUT.incomplete`` for a
    replay stopped early), ``accuracy`` whether the accuracy metrics are in it, ``interrupted`` the name of
    the signal that stopped it early (``SIGTERM``), None when the whole bag was played."""

    metrics: dict[str, Any]
    out_dir: Path
    accuracy: bool
    interrupted: str | None


def node_name_matches(key: str, fully_qualified: str) -> bool:
    """Whether a params file's node entry ``key`` names the node ``fully_qualified`` (``/ns/node``), as rcl
    matches them: a key without a leading ``/`` is absolute all the same, ``*`` stands for one name token
    and ``**`` for any number of them (``/**`` every node, ``/**/slam`` a slam in any namespace)."""
    tokens = key.strip("/").split("/")
    pattern = "".join(
        "(/[^/]+)*" if t == "**" else "/[^/]+" if t == "*" else "/" + re.escape(t) for t in tokens
    )
    return re.fullmatch(pattern, fully_qualified) is not None


def node_parameters_from_file(path: Path | None, node: str, namespace: str = "") -> dict[str, Any]:
    """The parameters of ``node`` (in ``namespace``, ``""``: none) in a ROS params file by their dotted
    names: every entry whose key names it (:func:`node_name_matches`: ``/**``, ``/**/slam``, ``slam``,
    ``tb3_0/slam`` ...), in the file's order, later ones winning; {} without a file. ValueError for a file
    that is no params file."""
    if path is None:
        return {}
    try:
        document = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    except (OSError, yaml.YAMLError) as error:
        raise ValueError(f"cannot read params file {path}: {error}") from error
    if not isinstance(document, dict):
        raise ValueError(f"{path} is not a ROS params file (a mapping of node names)")
    values: dict[str, Any] = {}
    fully_qualified = f"/{namespace}/{node}" if namespace else f"/{node}"
    for key, entry in document.items():
        if not (isinstance(key, str) and node_name_matches(key, fully_qualified)):
            continue
        if isinstance(entry, dict) and isinstance(entry.get("ros__parameters"), dict):
            values.update(flatten(entry["ros__parameters"]))
    return values


# --- reading what the replay needs before it starts --------------------------------------------------------


@dataclass
class BagFacts:
    """Read from the bag before playing: ``truth`` (None without ground truth), the first motion sample's
    stamp (ns), the true cylinders ``[x, y, r]`` of /nusim/obstacles (or None), the first scan's
    ``angle_increment`` and ``range_max``; with the truth, every scan ``(stamp (s), scan)`` as played, and the
    odometry (the bag's odom) up to the first sample at or past the truth's first stamp (None without
    them)."""

    truth: PoseSeries | None = None
    first_motion_ns: int | None = None
    obstacles: np.ndarray | None = None
    angle_increment: float | None = None
    range_max: float | None = None
    scans: list[tuple[float, RangeScan]] = field(default_factory=list)
    odom_lead: PoseSeries | None = None


def cut_scan(msg: Any, max_range_m: float | None) -> Any:
    """The LaserScan ``msg`` cut to ``max_range_m`` (module docstring; None: unchanged), in place."""
    if max_range_m is not None and max_range_m < msg.range_max:
        msg.range_max = float(max_range_m)
        ranges = np.asarray(msg.ranges, dtype=np.float32)
        msg.ranges = np.where(ranges > max_range_m, np.float32(np.inf), ranges).tolist()
    return msg


def _range_scan(msg: Any) -> RangeScan:
    return RangeScan(
        np.asarray(msg.ranges, dtype=np.float64),
        float(msg.angle_min),
        float(msg.angle_increment),
        float(msg.range_min),
        float(msg.range_max),
    )


def _odometry_row(msg: Any) -> list[float]:
    T = transform_from_pose(msg.pose.pose)
    return [stamp_nanoseconds(msg.header.stamp) * 1e-9, T.x, T.y, T.theta]


def pose_series(rows: list[list[float]]) -> PoseSeries:
    """Rows ``[t, x, y, theta]`` as a series; a row not later than the previous one replaces it (as the
    monitor does)."""
    kept: list[list[float]] = []
    for row in rows:
        if kept and row[0] <= kept[-1][0]:
            kept[-1] = row
        else:
            kept.append(row)
    table = np.asarray(kept, dtype=np.float64).reshape(-1, 4)
    return PoseSeries(table[:, 0], table[:, 1:])


def read_facts(
    source: BagSource, topics: dict[str, BagTopic], motion_role: str, max_range_m: float | None = None
) -> BagFacts:
    """One pass over the ground truth, the first motion sample (of ``motion_role``), the scans (all of
    them, cut to ``max_range_m``, with a truth; else the first) and the obstacles."""
    facts = BagFacts()
    wanted: dict[str, set[str]] = {}
    for role in ("truth", motion_role, "scan", "odom"):
        if role in topics:
            wanted.setdefault(topics[role].name, set()).add(role)
    if OBSTACLES_TOPIC in source.topics:
        wanted.setdefault(OBSTACLES_TOPIC, set()).add("obstacles")
    truth_rows: list[list[float]] = []
    odom_rows: list[list[float]] = []
    for message in source.messages(wanted):
        roles = wanted[message.topic]
        if "truth" in roles:
            truth_rows.append(
                _odometry_row(deserialize_message(message.data, message_class(message.type_name)))
            )
        if (
            "odom" in roles
            and "truth" in topics
            and not (truth_rows and odom_rows and odom_rows[-1][0] >= truth_rows[0][0])
        ):
            odom_rows.append(
                _odometry_row(deserialize_message(message.data, message_class(message.type_name)))
            )
        if motion_role in roles and facts.first_motion_ns is None:
            msg = deserialize_message(message.data, message_class(message.type_name))
            facts.first_motion_ns = stamp_nanoseconds(msg.header.stamp)
        if "scan" in roles and (facts.angle_increment is None or "truth" in topics):
            msg = cut_scan(deserialize_message(message.data, message_class(message.type_name)), max_range_m)
            if facts.angle_increment is None:
                facts.angle_increment, facts.range_max = float(msg.angle_increment), float(msg.range_max)
            if "truth" in topics:
                facts.scans.append((stamp_nanoseconds(msg.header.stamp) / NS_PER_S, _range_scan(msg)))
        if "obstacles" in roles and facts.obstacles is None:
            msg = deserialize_message(message.data, message_class(message.type_name))
            cylinders = [
                [m.pose.position.x, m.pose.position.y, 0.5 * m.scale.x]
                for m in msg.markers
                if m.type == m.CYLINDER and m.action == m.ADD
            ]
            facts.obstacles = np.asarray(cylinders, dtype=np.float64).reshape(-1, 3)
    if truth_rows:
        facts.truth = pose_series(truth_rows)
    if odom_rows:
        facts.odom_lead = pose_series(odom_rows)
    return facts


def truth_pose_at(truth: PoseSeries, t_ns: int | None, odom: PoseSeries | None = None) -> Transform2D:
    """The truth at ``t_ns`` (its first pose without a time). Before the truth's first stamp ``t_1`` (a
    reference that starts with the first scan, after the robot has moved), the truth's first pose moved
    back by the odometry's motion from ``t_ns`` to ``t_1`` where ``odom`` covers both::

        T_world_body(t) = T_truth(t_1) T_odom_body(t_1)^-1 T_odom_body(t)

    else clamped to the truth's span."""
    t_1 = truth.t_s[0]
    if (
        t_ns is not None
        and odom is not None
        and len(odom)
        and odom.t_s[0] <= t_ns * 1e-9 < t_1 <= odom.t_s[-1]
    ):
        T_odom_t, T_odom_1 = (Transform2D(*pose) for pose in odom.interpolate(np.array([t_ns * 1e-9, t_1])))
        return Transform2D(*truth.poses[0]) @ T_odom_1.inverse() @ T_odom_t
    t_s = t_1 if t_ns is None else float(np.clip(t_ns * 1e-9, t_1, truth.t_s[-1]))
    return Transform2D(*truth.interpolate(np.array([t_s]))[0])


def odom_in_frame(odom: PoseSeries, T_world_body0: Transform2D) -> PoseSeries:
    """Odometry placed in the world by its first sample: :func:`metrics.odom_in_world` with
    ``T_world_odom = T_world_body0 T_odom_body(0)^-1``."""
    if len(odom) == 0:
        return odom
    return odom_in_world(odom, T_world_body0 @ Transform2D(*odom.poses[0]).inverse())


# --- the run -----------------------------------------------------------------------------------------------


def default_motion_source() -> str:
    """The slam node's default ``motion_source``."""
    from nuslam.slam_node import SlamNodeConfig

    return SlamNodeConfig.motion_source


def resolve_topics(
    source: BagSource, options: ReplayOptions, association: str, motion_source: str
) -> dict[str, BagTopic]:
    """The bag topic of each role that is played: the motion (``motion_source``: joint_states or odom) and
    the observations (the scan, or the fake sensor with known association) are needed, the odometry (with
    joint_states motion), the truth and the scan are played when the bag has them. BagError when a needed
    one is missing or a topic is of another type than its role's."""
    needed = {motion_source, "scan" if association == "unknown" else "fake_sensor"}
    optional = {"odom", "truth", "scan"} - needed
    resolved: dict[str, BagTopic] = {}
    for role in sorted(needed | optional):
        name = options.bag_topic(role)
        topic = source.topics.get(name)
        if topic is None:
            if role in needed:
                option = "--" + role.replace("_", "-") + "-topic"
                other = "odom" if role == "joint_states" else "joint_states"
                switch = (
                    f", or --motion-source {other} for its {options.bag_topic(other)}"
                    if role == motion_source and options.bag_topic(other) in source.topics
                    else ""
                )
                robots = namespaces_with(source.topics, name) if options.namespace == "" else []
                if robots:
                    switch += (
                        f"; the bag has it under the namespaces {', '.join(robots)}: replay one robot with "
                        f"--namespace {robots[0]}"
                    )
                raise BagError(
                    f"{source.path} has no topic {name} for {role} "
                    f"(topics: {', '.join(sorted(source.topics))}; choose another with {option}{switch})"
                )
            continue
        expected = ROLES[role][1]
        if topic.type_name != expected:
            raise BagError(f"{source.path}: {name} is {topic.type_name}, but {role} must be {expected}")
        resolved[role] = topic
    return resolved


def namespaces_with(topics: Collection[str], name: str) -> list[str]:
    """The namespaces under which ``topics`` has the topic ``name`` (``/scan``: ``tb3_0`` for
    ``/tb3_0/scan``), sorted: the robots of a multi-robot recording."""
    found = []
    for topic in topics:
        namespace = topic[: -len(name)].strip("/") if topic.endswith(name) and topic != name else ""
        try:
            if namespace and robot_frames(namespace).namespace == namespace:
                found.append(namespace)
        except ValueError:
            continue
    return sorted(found)


def played_topics(topics: dict[str, BagTopic]) -> list[PlayedTopic]:
    return [
        PlayedTopic(topic.name, ROLES[role][0], topic.type_name, played_qos(topic, role in SENSOR_ROLES))
        for role, topic in topics.items()
    ]


class Replay:
    """The nodes and state of one replay (module docstring)."""

    def __init__(self, options: ReplayOptions, source: BagSource) -> None:
        self.options = options
        self.source = source
        namespace = options.namespace
        slam_file = node_parameters_from_file(options.params, "slam", namespace)
        self.association = options.association or str(slam_file.get("association", "unknown"))
        self.motion_source = options.motion_source or str(
            slam_file.get("motion_source", default_motion_source())
        )
        self.topics = resolve_topics(source, options, self.association, self.motion_source)
        self.facts = (
            read_facts(source, self.topics, self.motion_source, options.max_range_m)
            if not options.play_only
            else BagFacts()
        )
        # a nusim recording (the demo's): its pass/fail targets apply
        self.nusim_recording = options.topic(TRUTH_PLAYED_AS) in source.topics
        self.notes: list[str] = [] if source.recovery is None else [source.recovery.note()]
        truth, motion = self.topics.get("truth"), self.topics.get(self.motion_source)
        if truth is not None and motion is not None and truth.name == motion.name:
            self.notes.append(
                f"the truth topic {truth.name} is also slam's motion ({self.motion_source}): the accuracy "
                "compares slam with its own input"
            )
        # the robot's frames win over the file's, as a launch argument does (none without a namespace)
        self.slam_values = {**slam_file, **options.frames.slam()}
        self.slam_values["association"] = self.association
        self.slam_values["motion_source"] = self.motion_source
        if options.smooth:
            self.slam_values["smooth_saved_map"] = True
        if options.model is not None:
            self.slam_values["model"] = options.model
        self.landmarks_values = node_parameters_from_file(options.params, "landmarks", namespace)
        if self.facts.truth is not None:
            T0 = truth_pose_at(self.facts.truth, self.facts.first_motion_ns, self.facts.odom_lead)
            self.slam_values.update(x0=T0.x, y0=T0.y, theta0=T0.theta)
        self.nusim_values = node_parameters_from_file(options.params, "nusim")
        for values in (self.slam_values, self.landmarks_values):
            values["use_sim_time"] = True

    def run(self) -> ReplayResult:
        """Play the bag and write the outputs into a staging folder beside ``out_dir`` that replaces it
        only when the whole bag was played (:class:`nuturtle_eval.run_folder.RunFolder`); a replay
        stopped early by SIGINT, SIGTERM or SIGHUP, or failing once it plays (a full disk: OSError),
        leaves its outputs in ``OUT.incomplete``. ValueError/OSError before anything is written for a
        ``out_dir`` that holds the bag or other files or that another run is writing, or a Foxglove port in
        use."""
        out_dir = Path(self.options.out_dir)
        if out_dir.resolve() in Path(self.options.bag).resolve().parents:
            raise ValueError(
                f"the bag {self.options.bag} is inside the output folder {out_dir}: choose another --out"
            )
        if self.options.foxglove is not None:
            check_port_free(*self.options.foxglove)
        folder = RunFolder(out_dir, OUTPUTS)
        self.started = False

        def stopped_reason(result: ReplayResult) -> str | None:
            if result.interrupted is None:
                return None
            return f"interrupted by {result.interrupted}: the outputs cover the bag up to where it stopped"

        result, where = run_staged(folder, self._run, lambda: self.started, stopped_reason, "the replay")
        return replace(result, out_dir=where)

    def _run(self, out_dir: Path, stop: StopSignals) -> ReplayResult:
        context = run_context(self.options.domain, signal_handler_options=SignalHandlerOptions.NO)
        executor = SingleThreadedExecutor(context=context)
        nodes: list[Any] = []
        writer = None
        try:
            self.player = BagPlayer(played_topics(self.topics), context=context, **self._namespace)
            nodes.append(self.player)
            self.relay = None
            if not self.options.play_only:
                writer = BagWriter(out_dir / BAG_NAME)
                nodes.extend(self._build_nodes(context, writer))
            elif self.options.foxglove is not None:
                self.relay = self._relay()
                # what the user's nodes publish: every topic but the played ones
                self._relay_tap = TopicTap(
                    self.player, self.relay, exclude=self._played_names(), purpose="relaying"
                )
            if self.relay is not None:
                self.player.relay_to(self.relay)
            for node in nodes:
                executor.add_node(node)
            self.logger = self.player.get_logger()
            if self.options.play_only:
                self._wait_for_subscribers(executor)
            else:
                self._wait_for_matching(executor)
            self.started = True
            say_previous_result(self.options.out_dir)
            wall_start = time.monotonic()
            self._play(executor, stop, writer)
            wall_seconds = time.monotonic() - wall_start
            run_until_idle(executor, self.logger)
            if writer is not None:
                writer.close()
            return self._finish(out_dir, wall_seconds, stop.received)
        finally:
            try:
                if writer is not None:
                    writer.close()
            finally:
                if self.relay is not None:
                    self.relay.close()
                for node in nodes:
                    node.destroy_node()
                executor.shutdown()
                rclpy.try_shutdown(context=context)

    def _build_nodes(self, context: Context, writer: BagWriter) -> list[Any]:
        from nuslam.landmarks_node import LandmarksNode
        from nuslam.slam_node import SlamNode

        sim_time = [Parameter("use_sim_time", value=True)]
        self.writer = writer
        namespace = self._namespace
        self.landmarks = LandmarksNode(
            context=context, parameter_overrides=to_parameters(self.landmarks_values), **namespace
        )
        self.slam = SlamNode(
            context=context, parameter_overrides=to_parameters(self.slam_values), **namespace
        )
        self.relay = None if self.options.foxglove is None else self._relay()
        # one subscription per topic for the bag and the relay
        sink = writer if self.relay is None else TeeSink(writer, self.relay)
        self.recorder = TopicRecorder(
            sink, exclude=self._played_names(), context=context, parameter_overrides=sim_time
        )
        self.monitor = RunMonitor(context=context, parameter_overrides=sim_time, **namespace)
        nodes = [self.landmarks, self.slam, self.recorder, self.monitor]
        # all of them ours, in one process: no QoS event handlers, one /clock subscription (qos_events,
        # shared_clock; the player's handlers go too)
        for node in [self.player, *nodes]:
            drop_qos_event_handlers(node)
        share_clock(nodes)
        return nodes

    @property
    def _namespace(self) -> dict[str, str]:
        """The ``namespace`` keyword of the replay's nodes (none without one: the nodes at the root)."""
        return {"namespace": self.options.namespace} if self.options.namespace else {}

    def _played_names(self) -> list[str]:
        return [self.options.topic(ROLES[role][0]) for role in self.topics] + ["/clock"]

    def _relay(self) -> FoxgloveRelay:
        """The Foxglove relay; without /tf it is given slam's pose and sensor mount (none with
        ``play_only``: no slam here); under a namespace, how to write that robot's layout is printed.
        OSError when it cannot bind."""
        host, port = self.options.foxglove
        transforms = {} if self.options.play_only else slam_view_transforms(self.slam)
        relay = FoxgloveRelay(host, port, name="nuturtle_tools.replay", **transforms)
        print(f"Foxglove WebSocket on {relay.url} (Foxglove: Open connection)", file=sys.stderr)
        frames = self.options.frames
        if frames.namespace:
            choice = f" --map-frame {frames.map_frame}" if frames.map_frame else ""
            print(
                f"the layout of {frames.namespace}: python -P -m nuturtle_tools.foxglove_layout --namespace "
                f"{frames.namespace}{choice} --out {frames.namespace}.json (docs/live.md)",
                file=sys.stderr,
            )
        return relay

    def _wait_for_matching(self, executor: SingleThreadedExecutor) -> None:
        """Until every played topic has its in-process subscribers and the recorder hears slam's outputs."""
        # the in-process subscribers of each played topic: landmarks (scan), slam (its motion source and,
        # with joint_states motion, odom for map -> odom; the observations), the monitor (odom, truth)
        expected = {self.motion_source: 1, "odom": 2, TRUTH_PLAYED_AS: 1, "/clock": 1}
        expected["fake_sensor" if self.association == "known" else "scan"] = 1
        outputs = ["slam/odom", "slam/path", "slam/map"] + (
            ["landmarks"] if self.association == "unknown" else []
        )
        required = {self.options.topic(name) for name in outputs}

        def ready() -> bool:
            counts = self.player.subscription_counts()
            matched = all(counts.get(name, n) >= n for name, n in expected.items())
            observers = (
                self.association == "known"
                or self.player.count_subscribers(self.options.topic("landmarks")) >= 2
            )
            return matched and observers and required <= set(self.recorder.recorded_topics)

        if not spin_until(executor, self.logger, ready, DISCOVERY_TIMEOUT_S):
            raise RuntimeError(
                f"the replay's nodes did not match within {DISCOVERY_TIMEOUT_S} s: player "
                f"{self.player.subscription_counts()}, recorder {sorted(self.recorder.recorded_topics)}"
            )

    def _wait_for_subscribers(self, executor: SingleThreadedExecutor) -> None:
        """--play-only: until every played topic has a subscriber or ``wait_for_subscribers_s`` passed
        (messages published before a subscriber matches are lost to it)."""

        def matched() -> bool:
            return all(
                count > 0 for name, count in self.player.subscription_counts().items() if name != "/clock"
            )

        if not spin_until(executor, self.logger, matched, self.options.wait_for_subscribers_s):
            unmatched = sorted(n for n, c in self.player.subscription_counts().items() if c == 0)
            self.logger.info(f"playing although nothing subscribes to {unmatched} yet")

    def _play(self, executor: SingleThreadedExecutor, stop: StopSignals, writer: BagWriter | None) -> None:
        """Every played message in log-time order, until ``stop`` receives a signal; OSError once
        ``writer`` failed to write."""
        pace = self.options.pace
        pacer = Pacer(pace) if pace > 0.0 else None
        in_process = not self.options.play_only
        start_ns = self.source.start_ns
        total_s = (self.source.end_ns - start_ns) * 1e-9
        with ProgressBar(total_s, "bag", self.options.progress) as progress:
            # the topics published since the executor last ran until idle, all of one log time
            step: set[str] = set()
            for message in self.source.messages(self.player.topics):
                if stop.received is not None:
                    return
                if step and (message.log_time_ns != self.player.clock_ns or message.topic in step):
                    run_until_idle(executor, self.logger)
                    step.clear()
                    if writer is not None:
                        writer.check()
                if pacer is not None:
                    wait_until(executor, self.logger, pacer.deadline_s(message.log_time_ns))
                self.player.publish_clock(message.log_time_ns)
                self.player.publish_message(self._cut(message))
                if in_process:
                    step.add(message.topic)
                elif pacer is None:
                    wait_for_acks(self.player.reliable_publishers(message.topic), ACK_TIMEOUT_S)
                progress.advance((message.log_time_ns - start_ns) * 1e-9)
            if in_process:
                run_until_idle(executor, self.logger)
            progress.advance(total_s)
        if self.options.play_only:
            wait_for_acks(self.player.reliable_publishers(), ACK_TIMEOUT_S)

    def _cut(self, message: BagMessage) -> BagMessage:
        """``message``, a scan cut to ``max_range_m`` (:func:`cut_scan`) when that is set."""
        scan = self.topics.get("scan")
        if self.options.max_range_m is None or scan is None or message.topic != scan.name:
            return message
        msg = deserialize_message(message.data, message_class(message.type_name))
        return message._replace(data=serialize_message(cut_scan(msg, self.options.max_range_m)))

    # --- outputs -----------------------------------------------------------------------------------------

    def _counts(self) -> dict[str, Any]:
        played = dict(self.player.played)
        scan = self.topics.get("scan")
        values: dict[str, Any] = {
            "bag": str(self.source.path),
            "storage": self.source.storage,
            "association": self.association,
            "motion_source": self.motion_source,
            "nusim_recording": self.nusim_recording,
            "notes": list(self.notes),
            "messages_played": played,
            "scans_played": played.get(scan.name, 0) if scan is not None else 0,
            "bag_seconds": (self.source.end_ns - self.source.start_ns) / NS_PER_S,
        }
        if not self.options.play_only:
            observations = self.slam.observation_counts
            values.update(
                {
                    "observation_topic": "landmarks" if self.association == "unknown" else "fake_sensor",
                    "observation_arrays_received": observations["received"],
                    "observation_arrays_applied": observations["applied"],
                    "observation_arrays_skipped": observations["skipped"],
                    "observation_arrays_pending": observations["pending"],
                    "slam_mode": self.slam.config.mode,
                    "map_landmarks": len(self.slam.slam.landmark_ids),
                    "slam_outputs_recorded": self.writer.message_counts,
                    **slip_counts(self.slam),
                    **grid_counts(self.slam),
                    **loop_counts(self.slam),
                }
            )
            if self.association == "unknown":
                scans = self.landmarks.scan_counts
                values["scans_received_by_landmarks"] = scans["received"]
                values["scans_refused_by_landmarks"] = scans["refused"]
                values["last_scan_refusal"] = self.landmarks.last_refusal
        return values

    def _finish(self, out_dir: Path, wall_seconds: float, interrupted: str | None) -> ReplayResult:
        values = self._counts()
        values["replay_wall_seconds"] = wall_seconds
        values["complete"] = interrupted is None
        values["stopped_by"] = interrupted
        accuracy = False
        if not self.options.play_only:
            (out_dir / "config.yaml").write_text(params_file([self.landmarks, self.slam]), encoding="utf-8")
            self._write_map(out_dir)
            bag_seconds = (self.source.end_ns - self.source.start_ns) / NS_PER_S
            record = self._run_record()
            try:
                metrics = evaluate_and_plot(
                    out_dir, record, sim_seconds=bag_seconds, wall_seconds=wall_seconds
                )
            except ValueError as error:
                self.logger.warning(f"no accuracy metrics: {error}")
                metrics = None
            accuracy = metrics is not None
            values = {
                **(metrics.as_dict() if metrics is not None else {}),
                **self._grid_agreement(record),
                **values,
            }
            if self.options.smooth:
                values["smoothed"] = self._write_smoothed(out_dir / SMOOTHED_DIR, record, bag_seconds)
        write_metrics(out_dir, values)
        return ReplayResult(values, out_dir, accuracy, interrupted)

    def _grid_agreement(self, record: RunRecord) -> dict[str, Any]:
        """slam's grid against the scans at the truth's poses (:mod:`nuturtle_eval.grid_agreement`) as
        metrics.json figures; {} without a truth, scans or grid."""
        grid = record.snapshot.grid
        if record.truth is None or not self.facts.scans or grid is None:
            return {}
        agreement = scan_grid_agreement(self.facts.scans, record.truth, self.slam.config.T_body_sensor, grid)
        return {
            "grid_reference_cells": agreement.reference_cells,
            "grid_occupied_cells": agreement.occupied_cells,
            "grid_found_fraction": agreement.found_fraction,
            "grid_unexplained_fraction": agreement.unexplained_fraction,
        }

    def _true_circles(self) -> np.ndarray | None:
        """The true cylinders ``[x, y, r]`` (M, 3) of the params' ``nusim`` section, else of the bag's
        ``/nusim/obstacles``; None when neither holds them (a recording of another world)."""
        obstacles = {k: self.nusim_values.get(f"obstacles.{k}") for k in ("x", "y", "r")}
        if all(isinstance(v, list) for v in obstacles.values()):
            return np.column_stack([obstacles["x"], obstacles["y"], obstacles["r"]]).astype(np.float64)
        if self.facts.obstacles is not None:
            return self.facts.obstacles
        return None

    def _run_record(self) -> RunRecord:
        """What the replay produced, in the truth's frame (module docstring), for
        :func:`nuturtle_eval.run_evaluation.evaluate_and_plot`."""
        truth = self.facts.truth
        T_start = Transform2D(
            float(self.slam_values.get("x0", 0.0)),
            float(self.slam_values.get("y0", 0.0)),
            float(self.slam_values.get("theta0", 0.0)),
        )
        odom_raw = self.monitor.odom()
        T_world_body0 = T_start
        if truth is not None and len(odom_raw):
            T_world_body0 = truth_pose_at(truth, round(odom_raw.t_s[0] * 1e9), odom_raw)
        circles = self._true_circles() if truth is not None else None
        slam_range_m = float(self.slam.config.max_range)
        return RunRecord(
            truth=truth,
            odom=odom_in_frame(odom_raw, T_world_body0),
            slam=self.monitor.slam(),
            slam_covariances=self.monitor.slam_covariances(),
            snapshot=slam_snapshot(self.slam),
            circles=circles,
            sensor_range_m=sensor_range_m(
                self.association,
                fake_sensor_range_m=float(self.nusim_values.get("max_range", slam_range_m)),
                slam_range_m=slam_range_m,
                radii_m=np.zeros(0) if circles is None else circles[:, 2],
                min_points=self.landmarks.config.min_points,
                angle_increment=self.facts.angle_increment,
                lidar_range_m=self.facts.range_max,
            ),
        )

    def _write_smoothed(self, folder: Path, record: RunRecord, sim_seconds: float) -> dict[str, Any]:
        """``folder``: slam's whole run smoothed (:meth:`nuslam.slam_node.SlamNode.smooth_run`) in place of
        the filter's in its run ``record``, as a replay's outputs: map.json (the smoothed map), trajectory.png
        and covariance.png (of the last pose and the landmarks), the grid of slam's keyframes at the smoothed
        poses (map.yaml, map.pgm, grid.png) and, with ground truth, errors.png; returns its metrics (the
        grid's agreement too, with the scans; the smoothed poses have no covariance: no NEES), what the
        smoother decided and its CPU time."""
        folder.mkdir()
        cpu_start, wall_start = time.process_time(), time.monotonic()
        outcome = self.slam.smooth_run()
        cpu_seconds, wall_seconds = time.process_time() - cpu_start, time.monotonic() - wall_start
        slam, run = self.slam, outcome.run
        save_map(folder / "map.json", slam.map_to_save(outcome))
        record = replace(
            record,
            slam=PoseSeries(outcome.problem.pose_t_ns / NS_PER_S, run.poses),
            slam_covariances=np.full((len(run.poses), 3, 3), np.nan),
            snapshot=SlamSnapshot(
                run.final_covariance,
                run.landmarks,
                run.landmark_covariances,
                slam.grid.render(outcome.pose_at) if slam.grid.has_grid else None,
            ),
        )
        try:
            metrics = evaluate_and_plot(folder, record, sim_seconds=sim_seconds, wall_seconds=wall_seconds)
        except ValueError as error:
            self.logger.warning(f"no accuracy metrics for the smoothed run: {error}")
            metrics = None
        return {
            **(metrics.as_dict() if metrics is not None else {}),
            **self._grid_agreement(record),
            **outcome.decisions(),
            "smoother_cpu_seconds": cpu_seconds,
        }

    def _write_map(self, out_dir: Path) -> None:
        """map.json: the final map in the slam node's own map file format
        (:mod:`turtlelib.mapping.landmark_map`: ids, centres, joint covariance, the node's parameters), so
        slam can load it (``map_file``)."""
        save_map(out_dir / "map.json", self.slam.map_to_save())


def run_replay(options: ReplayOptions) -> ReplayResult:
    """Replay ``options.bag`` (module docstring) and write every output into ``options.out_dir``.
    BagError for an unreadable bag or a missing topic, ValueError for a bad params file."""
    with BagSource(options.bag) as source:
        return Replay(options, source).run()
