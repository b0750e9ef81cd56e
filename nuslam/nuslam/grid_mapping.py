"""slam's occupancy grid: LiDAR scans placed at slam's poses, published on `map`, saved beside the
landmark map in map_server's format (a thin owner over `turtlelib.mapping.occupancy_grid`).

Mapping (``mode: mapping``): each `scan` (sensor_msgs/LaserScan, frame ``sensor_id`` or ``body_id``) is
inserted into a `turtlelib.OccupancyGrid` at ``T_map_scan = T_map_body(t_s) T_body_scan``: slam's pose at
the scan's own stamp ``t_s`` from the filter's time base (`turtlelib.SlamTimeline.pose_at`: the filter moved
on by the motion to ``t_s``, one step per motion-sample interval) composed with the LiDAR mount of the
robot model (``T_body_scan``: ``lidar_x``, ``lidar_y``, ``lidar_yaw``; identity for a scan in
``body_id``). A scan newer than the newest motion sample waits (up to ``MAX_WAITING_SCANS``) for the
motion sample that reaches it; one older than the filter's time has no pose and is skipped. Every scan is
also offered to `turtlelib.ScanKeyframes` (one kept per ``grid.keyframe_step_m`` or
``grid.keyframe_turn_rad`` of motion).

Poses at save: an EKF estimates the current pose, not the past ones, so no later scan moves an earlier
pose. What a save can improve is the pose of each keyframe's own scan: the grid is built live at the pose
slam had when the scan arrived (predicted from the motion, before the landmarks seen in that same scan
were fused); the timeline tells the grid (a `turtlelib.PoseListener`) the posterior pose at the stamp of
every measurement it applies, which replaces the keyframe's of that stamp
(:meth:`GridMapping.corrected`), and that the run starts again without its map
(:meth:`GridMapping.cleared`, slam's ``~/reset``). With slam's loop closure (`nuslam.loop_closing`) the
keyframes are placed at its pose graph's poses instead (:attr:`GridMapping.pose_source`), and the live
grid is rendered again from them after a loop closes (:meth:`GridMapping.render_again`). ``~/save_map``
re-renders the keyframes at these poses (`ScanKeyframes.render`) and writes ``<stem>.yaml`` + ``<stem>.pgm``
beside ``map_file`` (`turtlelib.mapping.grid_map_file.save_grid_map`: map_server's trinary format, each
file written atomically).

Continued mapping: when a grid is saved beside ``map_file`` at start-up, and ``map_file`` is there too (a
saved map is both: without the file the grid is not continued, said at INFO), the session continues it (as
slam continues the landmarks of ``map_file``): the grid starts as the saved one
(`turtlelib.OccupancyGrid.from_grid_map`: its extent and origin, saved free and occupied cells at the
clamping bounds, unknown ones unobserved), logged at INFO with its file and size and published at once;
the scans add to it, the keyframes (this session's only) are rendered over it after a loop closure and by
``~/save_map``, which writes the continued grid over the saved one; ``~/reset`` goes back to it. A
malformed grid file, or one this grid cannot continue (another ``grid.resolution_m``, larger than
``grid.max_size_m``), stops the node at start-up with the reason. Loop closure's pose graph is not saved:
a continued session's loop closure starts a new graph, whose poses move this session's keyframes only.

Localization (``mode: localization``): the grid saved beside ``map_file`` is loaded at start-up, if there,
and published once; no scan is mapped. A malformed grid file stops the node at start-up with the reason.
Without a grid file beside ``map_file`` (only the ``.json`` copied) the scans are mapped into a fresh grid,
as in mapping, after one WARN at start-up naming the ``<stem>.yaml`` looked for.

Publishes (reliable + transient local, depth 1, REP 2003: a late RViz, nav2 or Foxglove gets the last)
    `map` (nav_msgs/OccupancyGrid, frame ``map_id``): -1 unknown, 0..100 per cent occupied, at most once
        per ``grid.publish_period_s`` of scan time and only when scans were added, stamped with the newest
        inserted scan's stamp.
    `map_metadata` (nav_msgs/MapMetaData): its ``info``.

Bad input (a scan in another frame, one `nuturtle_ros_common.conversions.range_scan_from_message` refuses:
a layout that contradicts itself, intensities neither empty nor one per range, what `turtlelib.RangeScan`
refuses; one older than the filter's time) is skipped with a throttled warning and counted; the grid is
unchanged.

The bound: the grid grows up to ``grid.max_size_m`` a side (its memory bound, ``max_cells`` cells); a scan
reaching past it is mapped all the same: the grid moves toward it, forgetting its far side, and clips what
still lies outside (`turtlelib.mapping.occupancy_grid`, "The bound"). Such scans are counted and warned
about at most once per ``BOUND_WARN_S`` (with the count since the last warning).

`/diagnostics` gets `slam: occupancy grid` (:meth:`GridMapping.status`): scans mapped, skipped and past
the bound, keyframes, the grid's size and memory (cells and bytes now, and at most); WARN when scans were
skipped since the last report.
"""

from __future__ import annotations

import time
from array import array
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import MapMetaData
from nav_msgs.msg import OccupancyGrid as OccupancyGridMsg
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan

from nuturtle_ros_common.conversions import (
    mounted_range_scan,
    pose_from_transform,
    stamp_from_nanoseconds,
)
from nuturtle_ros_common.diagnostics import OK, WARN, status
from nuturtle_ros_common.ros_params import declare_dataclass
from nuturtle_ros_common.throttle import SourceWarnings
from turtlelib import (
    GridConfig,
    KeyframeConfig,
    OccupancyGrid,
    RangeScan,
    ScanKeyframes,
    SlamTimeline,
    Transform2D,
)
from turtlelib.mapping.grid_map_file import load_grid_map, save_grid_map
from turtlelib.mapping.occupancy_grid import GridMap
from turtlelib.util.timebase import NS_PER_S
from turtlelib.util.validation import positive, store

# scans waiting for the motion sample that reaches their stamp (1 s of an LDS-01's 5 Hz)
MAX_WAITING_SCANS = 5
# the shortest time between two warnings of scans past the grid's bound (s, steady clock)
BOUND_WARN_S = 10.0
PREFIX = "grid."
# the map files' suffixes: the landmark map must be neither, or a save would write over it
GRID_SUFFIXES = (".yaml", ".pgm")


@dataclass(frozen=True)
class GridTopicConfig:
    """The grid's own node parameters (prefixed ``grid.``; ValueError for invalid values):

    * ``enabled``: build, publish and save the occupancy grid (false: slam neither subscribes to `scan`
      nor publishes `map`);
    * ``publish_period_s`` (s of scan time, > 0): the shortest time between two publications of `map`.
    """

    enabled: bool = True
    publish_period_s: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise ValueError(f"enabled must be a bool, got {self.enabled!r}")
        store(self, ("publish_period_s",), positive)


def grid_yaml_path(map_file: str) -> Path:
    """``<stem>.yaml`` beside the landmark map ``map_file`` (its image is ``<stem>.pgm``); ValueError for
    a ``map_file`` that is itself a ``.yaml`` or ``.pgm`` (a save would write over it)."""
    path = Path(map_file)
    if path.suffix in GRID_SUFFIXES:
        raise ValueError(
            f"map_file {map_file!r}: the occupancy grid is saved beside it as {path.stem}.yaml + "
            f"{path.stem}.pgm, so the landmark map must not end in .yaml or .pgm (use .json)"
        )
    return path.with_suffix(".yaml")


def grid_message(grid_map: GridMap, frame_id: str, stamp_ns: int) -> OccupancyGridMsg:
    """``nav_msgs/OccupancyGrid`` of ``grid_map`` (data row-major, row 0 at ``info.origin``), no Python
    loop over the cells."""
    msg = OccupancyGridMsg()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp_from_nanoseconds(stamp_ns)
    msg.info.map_load_time = msg.header.stamp
    msg.info.resolution = float(grid_map.resolution_m)
    msg.info.width, msg.info.height = grid_map.width, grid_map.height
    msg.info.origin = pose_from_transform(grid_map.origin)
    msg.data = array("b", grid_map.occupancy.tobytes())
    return msg


class GridMapping:
    """slam's occupancy grid (module docstring): declares the ``grid.*`` parameters on ``node``, owns the
    grid, the keyframes and the `map` publishers.

    ``T_body_scan`` is the LiDAR mount; ``frames`` the node's ``(map_id, body_id, sensor_id)``;
    ``map_file`` slam's landmark map (empty: none), ``localization``: load the grid beside it instead of
    mapping (else a grid saved beside it is continued, when the map file itself is there). ValueError
    for invalid parameters, a ``map_file`` ending in ``.yaml`` or ``.pgm``, or a malformed grid file beside
    it (or, in mapping, one that cannot be continued). The topics come with :meth:`connect`, once the node
    has checked everything else (a node that fails at start-up must not hold subscriptions: their
    callbacks keep it alive).
    """

    def __init__(
        self,
        node: Node,
        T_body_scan: Transform2D,
        frames: tuple[str, str, str],
        warnings: SourceWarnings,
        map_file: str,
        localization: bool,
    ) -> None:
        self.topic_config = declare_dataclass(node, GridTopicConfig, prefix=PREFIX)
        self.config = declare_dataclass(node, GridConfig, prefix=PREFIX)
        self.keyframe_config = declare_dataclass(node, KeyframeConfig, prefix=PREFIX)
        enabled = self.topic_config.enabled
        self.yaml_path = grid_yaml_path(map_file) if enabled and map_file else None
        loaded = saved = None
        grid_saved = self.yaml_path is not None and self.yaml_path.exists()
        if grid_saved and not localization and not Path(map_file).exists():
            # a saved map is its landmark file and its grid: without the file, mapping starts afresh
            node.get_logger().info(f"no map file {map_file}: the grid {self.yaml_path} is not continued")
        elif grid_saved:
            saved = load_grid_map(self.yaml_path)
            verb = "loaded" if localization else "continuing"
            node.get_logger().info(f"{verb} the {saved.width} x {saved.height} cell grid {self.yaml_path}")
            if localization:
                loaded, saved = saved, None
        # localization found no saved grid beside map_file: connect warns once and the scans are mapped
        self._grid_missing = localization and loaded is None and self.yaml_path is not None
        self._map_id, body_id, sensor_id = frames
        self._T_body_from = {sensor_id: T_body_scan, body_id: Transform2D()}
        self._T_body_scan = T_body_scan
        self._warnings = warnings
        # the node's own logger: a child logger of a node name used again in one process (tests) can lose
        # its /rosout link when the older one is collected
        self._bound_logger = node.get_logger()
        self._bound_warned_s: float | None = None
        self._period_ns = round(self.topic_config.publish_period_s * NS_PER_S)
        # the saved grid this mapping session continues (None: a fresh one)
        self.base = saved
        self.grid = self._start_grid()
        self.keyframes = ScanKeyframes(self.keyframe_config)
        # the pose each keyframe's scan is rendered at by a save: T_map_body by stamp (ns)
        self._keyframe_poses: dict[int, Transform2D] = {}
        # a better pose of a keyframe's scan by its stamp, before the kept one (None where it has none):
        # slam's loop closure, the graph's poses (nuslam.loop_closing)
        self.pose_source: Callable[[int], Transform2D | None] | None = None
        # slam's timeline: the poses scans are placed at (set by connect)
        self._timeline: SlamTimeline | None = None
        self._waiting: deque[tuple[int, RangeScan, Transform2D]] = deque()
        self._newest_ns: int | None = None
        self._published_ns: int | None = None
        self.scans_inserted = self.scans_skipped = self._skipped_reported = 0
        self.scans_past_bound = self._past_bound_warned = 0
        self.loaded = loaded

    def connect(self, node: Node, map_qos: QoSProfile, timeline: SlamTimeline) -> None:
        """Create `map`, `map_metadata` (``map_qos``) and, when mapping, the `scan` subscription placed at
        ``timeline``'s poses (whose corrections and resets it listens to); publish the loaded or continued
        grid; WARN once for a localization without a saved grid (a fresh one is mapped). Nothing when the
        grid is off."""
        if not self.topic_config.enabled:
            return
        self._timeline = timeline
        timeline.listen(self)
        self._grid_publisher = node.create_publisher(OccupancyGridMsg, "map", map_qos)
        self._metadata_publisher = node.create_publisher(MapMetaData, "map_metadata", map_qos)
        if self.loaded is not None:
            self._publish(self.loaded, node.get_clock().now().nanoseconds)
        else:
            if self._grid_missing:
                node.get_logger().warning(
                    f"localization without a saved occupancy grid: no {self.yaml_path} beside map_file, so "
                    f"the scans are mapped into a fresh grid (copy the saved map's .yaml and .pgm with its "
                    f".json to localize in the saved grid)"
                )
            if self.base is not None:
                self._publish(self.grid.grid_map(), node.get_clock().now().nanoseconds)
            node.create_subscription(LaserScan, "scan", self.on_scan, qos_profile_sensor_data)

    @property
    def mapping(self) -> bool:
        """True when scans are mapped (enabled, no grid loaded for localization)."""
        return self.topic_config.enabled and self.loaded is None

    def on_scan(self, msg: LaserScan) -> None:
        """Queue the scan for slam's pose at its stamp (inserted now if slam's poses already reach it)."""
        try:
            t_ns, scan, T_body_scan = mounted_range_scan(msg, self._T_body_from)
        except ValueError as error:
            self._skip(f"scan skipped by the occupancy grid: {error}")
            return
        self._waiting.append((t_ns, scan, T_body_scan))
        if len(self._waiting) > MAX_WAITING_SCANS:
            dropped_ns, _, _ = self._waiting.popleft()
            self._skip(
                f"scan at {dropped_ns} ns skipped by the occupancy grid: no slam pose reached its stamp "
                f"while {MAX_WAITING_SCANS} newer scans came (are joint_states / odom arriving?)",
            )
        self.insert_reached()

    def status(self) -> DiagnosticStatus | None:
        """`slam: occupancy grid` for /diagnostics (None when the grid is off): WARN when scans were
        skipped since the last report."""
        if not self.topic_config.enabled:
            return None
        if self.loaded is not None:
            grid_map = self.loaded
            message = f"localization: the {grid_map.width} x {grid_map.height} cell grid {self.yaml_path}"
            return status("slam: occupancy grid", "slam", OK, message, {"loaded": str(self.yaml_path)})
        skipped = self.scans_skipped - self._skipped_reported
        self._skipped_reported = self.scans_skipped
        grid = self.grid
        height, width = grid.log_odds.shape
        message = (
            f"{self.scans_inserted} scans mapped into {width} x {height} cells "
            f"({grid.nbytes / 1e6:.1f} of at most {grid.max_nbytes / 1e6:.1f} MB)"
        )
        if self.scans_past_bound:
            message += f"; {self.scans_past_bound} reached past grid.max_size_m (the grid moved or clipped)"
        if self.base is not None:
            message += f", continuing {self.yaml_path}"
        if skipped:
            message += f"; {skipped} skipped since the last report"
        values = {
            "scans_mapped": self.scans_inserted,
            "scans_skipped": self.scans_skipped,
            "scans_past_bound": self.scans_past_bound,
            "keyframes": len(self.keyframes),
            "width": width,
            "height": height,
            **self.memory(),
        }
        return status("slam: occupancy grid", "slam", WARN if skipped else OK, message, values)

    def memory(self) -> dict[str, int]:
        """The live grid's memory: ``cells`` and ``bytes`` now, ``max_cells`` and ``max_bytes`` at most
        (``grid.max_size_m``)."""
        grid = self.grid
        return {
            "cells": grid.cells,
            "bytes": grid.nbytes,
            "max_cells": grid.max_cells,
            "max_bytes": grid.max_nbytes,
        }

    def corrected(self, t_ns: int, T_map_body: Transform2D) -> None:
        """slam's posterior pose at ``t_ns`` (after fusing a measurement stamped ``t_ns``): the pose a save
        renders the keyframe of that stamp at, if there is one."""
        if t_ns in self._keyframe_poses:
            self._keyframe_poses[t_ns] = T_map_body

    def cleared(self) -> None:
        """The run starts again without its map (slam's ~/reset): when mapping, forget every scan."""
        if self.mapping:
            self.reset()

    @property
    def has_grid(self) -> bool:
        """True when there is a grid to save: enabled, and loaded, continued or made of at least one
        keyframe."""
        saved = self.loaded is not None or self.base is not None
        return self.topic_config.enabled and (saved or len(self.keyframes) > 0)

    def render(self, pose_at: Callable[[int], Transform2D | None] | None = None) -> GridMap:
        """The grid of the keyframes at their poses (module docstring), or at ``pose_at(stamp_ns)`` where
        that gives one (a smoothed run's poses), else at :attr:`pose_source`'s; the loaded one in
        localization."""
        if self.loaded is not None:
            return self.loaded
        return self._rendered(pose_at).grid_map()

    def render_again(self) -> None:
        """Replace the live grid by its keyframes rendered at :attr:`pose_source`'s poses (slam's loop
        closure corrected them) and publish it; nothing unless mapping."""
        if not self.mapping:
            return
        self.grid = self._rendered(None)
        if self._newest_ns is not None:
            self._publish(self.grid.grid_map(), self._newest_ns)

    def _rendered(self, pose_at: Callable[[int], Transform2D | None] | None) -> OccupancyGrid:
        sources = [source for source in (pose_at, self.pose_source) if source is not None]

        def keyframe_pose(t_ns: int) -> Transform2D | None:
            for source in sources:
                T_map_body = source(t_ns)
                if T_map_body is not None:
                    return T_map_body
            return self._keyframe_poses.get(t_ns)

        return self.keyframes.render(keyframe_pose, self._T_body_scan, self.config, self.base)

    def save(self, pose_at: Callable[[int], Transform2D | None] | None = None) -> str:
        """Write :meth:`render` (with ``pose_at``) beside ``map_file`` (``<stem>.yaml`` + ``<stem>.pgm``,
        atomically); a one-line account of it ('' when the grid is off). OSError or ValueError when it
        cannot be written."""
        if self.yaml_path is None:
            return ""
        grid_map = self.render(pose_at)
        save_grid_map(self.yaml_path, grid_map)
        source = "loaded" if self.loaded is not None else f"of {len(self.keyframes)} keyframes"
        if self.base is not None:
            source += " over the continued one"
        return f"the {grid_map.width} x {grid_map.height} cell grid {source} to {self.yaml_path}"

    def reset(self) -> None:
        """Forget every scan (slam's ~/reset): the grid at start-up (empty or the continued one), no
        keyframes."""
        self.grid = self._start_grid()
        self.keyframes.clear()
        self._keyframe_poses.clear()
        self._waiting.clear()
        self._newest_ns = self._published_ns = None

    # --- helpers -----------------------------------------------------------------------------------------

    def _start_grid(self) -> OccupancyGrid:
        """A fresh grid, or the saved one this session continues (ValueError naming its file when it
        cannot be continued)."""
        if self.base is None:
            return OccupancyGrid(self.config)
        try:
            return OccupancyGrid.from_grid_map(self.base, self.config)
        except ValueError as error:
            raise ValueError(f"{self.yaml_path}: cannot continue mapping it: {error}") from None

    def insert_reached(self) -> None:
        """Insert, oldest first, the waiting scans the motion samples reach, at slam's pose at their stamps;
        skip those older than the filter's time."""
        timeline = self._timeline
        if timeline is None or not self.mapping:
            return
        latest = timeline.latest_time_ns
        while self._waiting and latest is not None and self._waiting[0][0] <= latest:
            t_ns, scan, T_body_scan = self._waiting.popleft()
            T_map_body = timeline.pose_at(t_ns)
            if T_map_body is None:
                self._skip(f"scan at {t_ns} ns skipped by the occupancy grid: older than slam's filter time")
                continue
            if self.grid.insert_scan(scan, T_map_body @ T_body_scan):
                self._past_bound()
            self.scans_inserted += 1
            if self.keyframes.offer(t_ns, T_map_body, scan):
                self._keyframe_poses[t_ns] = T_map_body
                if len(self._keyframe_poses) > len(self.keyframes):
                    kept = set(self.keyframes.stamps_ns)
                    self._keyframe_poses = {t: T for t, T in self._keyframe_poses.items() if t in kept}
            self._newest_ns = t_ns
        if self._newest_ns is not None and (
            self._published_ns is None
            or self._newest_ns < self._published_ns
            or self._newest_ns - self._published_ns >= self._period_ns
        ):
            self._publish(self.grid.grid_map(), self._newest_ns)

    def _past_bound(self) -> None:
        """Count a scan that reached past the grid's bound; warn (at most once per ``BOUND_WARN_S``) with
        the count since the last warning."""
        self.scans_past_bound += 1
        count = self.scans_past_bound - self._past_bound_warned
        res = self.config.resolution_m
        (x0, y0), (height, width) = self.grid.origin_m, self.grid.log_odds.shape
        x1, y1 = x0 + width * res, y0 + height * res
        # this grid's own throttle: rclpy's throttles per call site, so one node's warning would silence
        # another's in the same process
        now_s = time.monotonic()
        if self._bound_warned_s is not None and now_s - self._bound_warned_s < BOUND_WARN_S:
            return
        self._bound_logger.warning(
            f"scans reaching past grid.max_size_m = {self.config.max_size_m} m: {count} since the last "
            f"warning; the occupancy grid (now x {x0:.1f}..{x1:.1f} m, y {y0:.1f}..{y1:.1f} m) moved "
            "toward them, forgetting its far side, and clipped what lay outside"
        )
        self._bound_warned_s, self._past_bound_warned = now_s, self.scans_past_bound

    def _skip(self, text: str) -> None:
        self.scans_skipped += 1
        self._warnings.warn("scan", text)

    def _publish(self, grid_map: GridMap, stamp_ns: int) -> None:
        msg = grid_message(grid_map, self._map_id, stamp_ns)
        self._grid_publisher.publish(msg)
        self._metadata_publisher.publish(msg.info)
        self._published_ns = stamp_ns
