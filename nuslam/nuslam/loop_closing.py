"""slam's loop closure (``scan_registration`` and ``loop_closure``: a thin owner over
`turtlelib.smoothing.loop_closure.LoopClosure`, docs/loop_closure.md).

Every step of slam's LiDAR odometry (`nuslam.scan_odometry`: a scan registered, or the motion input alone)
goes with its scan's body-frame points to a `LoopClosure`: its keyframe pose graph, revisits matched against
older submaps and verified (score, ambiguity, inliers, degeneracy, chi-square against the graph, two in a
row) before a loop closes. The graph's correction of the odometry ``C = T_map_odom`` (``map_from_odom``, at
the newest keyframe) places the body at ``C T_odom_body``; a loop changes it from ``C_old`` to ``C_new``.

The live filter, at its time ``t_f`` with LiDAR odometry's pose ``T_l = T_odom_body(t_f)`` there, moves by
the change of the graph's pose of the body, applied in the body frame (so that the filter's own frame, its
start pose and what landmarks did to it stay as they are)::

    D = (C_old T_l)^-1 (C_new T_l),   T_map_body' = T_map_body D,   P' = G P G^T

(`turtlelib.smoothing.loop_closure.relocalized`: the pose covariance carried along, as the motion input
carries it: ``ScanOdometry.moved_on``); `turtlelib.SlamTimeline.relocalize` sets it, as
/initialpose does, and the landmarks stay where they are, independent of the new pose (as after slip
recovery: in a room without posts there are none; with posts the landmarks seen again pull the pose to
their frame).

The occupancy grid is drawn at the graph's poses: each grid keyframe's scan (`nuslam.grid_mapping`) at
``B C_k T_odom_body(t)``, ``C_k`` the correction now at the newest graph keyframe at or before its stamp
``t`` (this session's start correction before its first keyframe) and ``B = T_map_body(t_f) (C T_l)^-1``
the filter's frame over the graph's (the identity unless landmarks or /initialpose moved the filter: the
graph's first step is at slam's start pose). After a loop closes the grid is rendered
again from its keyframes, at most once per ``RERENDER_PERIOD_NS`` of scan time (its CPU grows with the
keyframes: `slam: loop closure` reports it); a save and a run's final grid always use the newest graph.

Across sessions (docs/maps.md, "Continuing over sessions"): ``~/save_map`` also writes the graph beside
``map_file`` as ``<stem>.graph.npz`` (:func:`graph_path`, `turtlelib.smoothing.graph_file`: this session's
keyframes at their map poses ``B T_graph_keyframe``, the loaded ones as loaded, every edge); in mapping,
when ``map_file`` and that file are there at start-up, the graph is loaded and continued
(`turtlelib.smoothing.loop_closure`, "Continuing a saved graph": its keyframes anchored, this session placed
at slam's start pose with its covariance, so a revisit of a place the earlier session saw closes a loop onto
it); a malformed file stops the node at start-up with the reason. Localization neither loads nor saves it
(the map is fixed there: the session's loops are its own).

`/diagnostics` gets `slam: loop closure` (:meth:`LoopClosing.status`): keyframes, loops closed, candidates
refused by reason, the last correction, the time per step and per re-rendering. Each loop closed is logged
at INFO. slam's ~/reset starts the graph again (a `turtlelib.PoseListener` of the timeline).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from numpy.typing import NDArray
from rclpy.node import Node

from nuslam.grid_mapping import GridMapping
from nuturtle_ros_common.diagnostics import OK, DurationMonitor, status
from nuturtle_ros_common.ros_params import declare_dataclass
from nuturtle_ros_common.throttle import SourceWarnings
from turtlelib import RegistrationConfig, SlamTimeline, Transform2D
from turtlelib.estimation.lidar_odometry import OdometryStep
from turtlelib.geometry.pose_buffer import PoseBuffer
from turtlelib.sensing.correlative_matcher import CorrelativeConfig
from turtlelib.smoothing.graph_file import SavedGraph, load_graph, save_graph
from turtlelib.smoothing.loop_closure import LoopClosure, LoopClosureConfig, Verdict, relocalized
from turtlelib.smoothing.pose_graph import PoseGraphConfig
from turtlelib.util.timebase import NS_PER_S

PREFIX = "loops."
# the shortest time between two renderings of the grid at the graph's poses (ns of scan time)
RERENDER_PERIOD_NS = 5 * NS_PER_S
# LiDAR odometry's poses kept to read its pose at the filter's time (a scan or motion sample each)
LIDAR_POSES = 200
# scans' poses kept beyond the grid's keyframes before those of dropped scans are forgotten
SCAN_POSES_SLACK = 1000
# the verdicts that are no refusal
KEPT = (Verdict.ACCEPTED, Verdict.HELD)


def graph_path(map_file: str) -> Path:
    """``<stem>.graph.npz`` beside the landmark map ``map_file``."""
    return Path(map_file).with_suffix(".graph.npz")


def declare_loop_closure(node: Node, registration: RegistrationConfig) -> LoopClosureConfig:
    """`turtlelib.smoothing.loop_closure.LoopClosureConfig`'s own fields as ``loops.*`` parameters; the
    refining registration is slam's (``registration.*``), the matcher and the graph at their defaults."""
    fixed = {"registration": registration, "correlative": CorrelativeConfig(), "graph": PoseGraphConfig()}
    return declare_dataclass(node, LoopClosureConfig, prefix=PREFIX, fixed=fixed)


class LoopClosing:
    """slam's loop closure (module docstring) over its ``timeline`` and ``grid``. Feed it each LiDAR
    odometry step with :meth:`add_step`. ``map_file`` (empty: none) has the graph beside it saved and, in
    mapping (not ``localization``), continued; ValueError for a malformed graph file there."""

    def __init__(
        self,
        config: LoopClosureConfig,
        timeline: SlamTimeline,
        grid: GridMapping,
        node: Node,
        warnings: SourceWarnings,
        map_file: str = "",
        localization: bool = False,
    ) -> None:
        self.config = config
        self._timeline, self._grid, self._warnings = timeline, grid, warnings
        self._logger = node.get_logger()
        self.graph_path = graph_path(map_file) if map_file and not localization else None
        # the graph loaded at start-up (None: none), which ~/reset goes back to
        self._loaded: SavedGraph | None = None
        if self.graph_path is not None and self.graph_path.exists():
            if Path(map_file).exists():
                self._loaded = load_graph(self.graph_path)
                self._logger.info(
                    f"continuing the pose graph {self.graph_path}: {self._loaded.n_keyframes} keyframes, "
                    f"{self._loaded.n_edges} edges ({int(self._loaded.edge_loop.sum())} loops)"
                )
            else:
                # a saved map is its landmark file and what lies beside it: without the file, a new graph
                self._logger.info(
                    f"no map file {map_file}: the pose graph {self.graph_path} is not continued"
                )
        self._step_time, self._render_time = DurationMonitor(), DurationMonitor()
        self.cpu_s = {"steps": 0.0, "renders": 0.0}
        self.renders = 0
        self._start()
        timeline.listen(self)
        if grid.mapping:
            grid.pose_source = self.pose_at

    def _start(self) -> None:
        """A new graph (the loaded one continued), this session's first step at the filter's pose."""
        slam = self._timeline.slam
        self.loops = LoopClosure(self.config, self._loaded, slam.pose, slam.pose_covariance)
        self.closed = 0
        self.last_correction: Transform2D | None = None
        self._lidar_poses = PoseBuffer(LIDAR_POSES)
        # T_odom_body of each scan and the newest graph keyframe at its stamp, by stamp (ns)
        self._scan_poses: dict[int, tuple[int, Transform2D]] = {}
        self._render_due = False
        self._rendered_ns: int | None = None

    # --- the timeline's listener ---------------------------------------------------------------------------

    def corrected(self, t_ns: int, T_map_body: Transform2D) -> None:
        """A measurement's posterior pose: nothing to do (the graph holds LiDAR odometry's poses)."""

    def cleared(self) -> None:
        """slam's ~/reset: the graph starts again."""
        self._start()

    # --- steps ---------------------------------------------------------------------------------------------

    def add_step(self, step: OdometryStep, p_body: NDArray[np.float64]) -> None:
        """One step of LiDAR odometry and its scan's points ``p_body`` (n, 2, body frame; none for the
        motion input alone): into the graph; on a loop closed, the filter relocalized (module docstring);
        the grid rendered again when due."""
        start_cpu, start = time.process_time(), time.perf_counter()
        C_old = self.loops.map_from_odom()
        try:
            accepted = self.loops.add_step(step, p_body)
        except (ValueError, np.linalg.LinAlgError) as error:
            self._warnings.warn(
                "loop closure", f"step at {step.t_ns} ns skipped by the loop closure: {error}"
            )
            accepted = []
        try:
            self._lidar_poses.add(step.t_ns, step.T_odom_body)
        except ValueError:  # the clock went back (a restarted input): the old poses are another time's
            self._lidar_poses.clear()
            self._lidar_poses.add(step.t_ns, step.T_odom_body)
        if len(p_body) and self._grid.mapping:
            self._scan_poses[step.t_ns] = (self.loops.session_keyframe, step.T_odom_body)
            self._forget_dropped_scans()
        if accepted:
            self._closed(accepted, C_old)
        self._step_time.add(1e3 * (time.perf_counter() - start))
        self.cpu_s["steps"] += time.process_time() - start_cpu
        if self._render_due and (
            self._rendered_ns is None or abs(step.t_ns - self._rendered_ns) >= RERENDER_PERIOD_NS
        ):
            self._render(step.t_ns)

    def _closed(self, accepted: list, C_old: Transform2D) -> None:
        """Loops ``accepted`` at this step: the filter moved by the change of correction, logged."""
        self.closed += len(accepted)
        self._render_due = True
        C_new = self.loops.map_from_odom()
        t_f = self._timeline.filter_time_ns
        T_l = None if t_f is None else self._lidar_poses.at(t_f)
        pairs = ", ".join(f"{c.j} on {c.i}" for c in accepted)
        if T_l is None:
            self._warnings.warn(
                "loop closure", f"loop closed (keyframes {pairs}) but the filter was not moved: no LiDAR "
                "odometry pose at its time"
            )  # fmt: skip
            return
        slam = self._timeline.slam
        T_new, P_new, D = relocalized(slam.pose, slam.pose_covariance, T_l, C_old, C_new)
        self._timeline.relocalize(T_new, P_new, explained=True)
        self.last_correction = D
        path_m = self.loops.keyframes[-1].path_m - self.loops.keyframes[accepted[0].i].path_m
        back = (
            "onto the saved graph" if accepted[0].i < self.loops.n_loaded else f"{path_m:.0f} m of path back"
        )
        self._logger.info(
            f"loop closed: keyframe {pairs} ({back}); the pose moved by "
            f"{math.hypot(D.x, D.y):.3f} m, {D.theta:+.3f} rad"
        )

    # --- the grid ------------------------------------------------------------------------------------------

    def pose_at(self, t_ns: int) -> Transform2D | None:
        """``T_map_body`` of the scan stamped ``t_ns`` at the graph's poses in the filter's frame (module
        docstring), or None (not a registered scan's stamp, or no filter pose yet)."""
        scan = self._scan_poses.get(t_ns)
        B = self._filter_from_graph()
        if scan is None or B is None:
            return None
        k, T_odom_body = scan
        return B @ self.loops.map_from_odom(k) @ T_odom_body

    def _filter_from_graph(self) -> Transform2D | None:
        """``B = T_map_body(t_f) (C T_l)^-1``: the filter's frame over the graph's; None before a pose."""
        t_f = self._timeline.filter_time_ns
        T_l = None if t_f is None else self._lidar_poses.at(t_f)
        if T_l is None:
            return None
        return self._timeline.slam.pose @ (self.loops.map_from_odom() @ T_l).inverse()

    def _render(self, t_ns: int) -> None:
        """The grid rendered again at the graph's poses."""
        start_cpu, start = time.process_time(), time.perf_counter()
        self._grid.render_again()
        self._render_time.add(1e3 * (time.perf_counter() - start))
        self.cpu_s["renders"] += time.process_time() - start_cpu
        self.renders += 1
        self._render_due, self._rendered_ns = False, t_ns

    def _forget_dropped_scans(self) -> None:
        """Past ``SCAN_POSES_SLACK`` more scan poses than the grid has keyframes, forget those of the scans
        the grid did not keep (memory bounded whether or not a loop ever closes)."""
        if len(self._scan_poses) > len(self._grid.keyframes) + SCAN_POSES_SLACK:
            kept = set(self._grid.keyframes.stamps_ns)
            newest = max(kept, default=-1)
            self._scan_poses = {t: v for t, v in self._scan_poses.items() if t in kept or t > newest}

    def save(self) -> str:
        """Write the graph to :attr:`graph_path` (module docstring; atomically); a one-line account of it
        ('' in localization or without ``map_file``). OSError or ValueError when it cannot be written."""
        if self.graph_path is None:
            return ""
        graph = self.loops.saved_graph(self._filter_from_graph())
        save_graph(self.graph_path, graph)
        return f"the pose graph ({graph.n_keyframes} keyframes, {graph.n_edges} edges) to {self.graph_path}"

    def loop_segments(self) -> NDArray[np.float64]:
        """(L, 2, 2): each loop closed as its two keyframes' positions ``[[x_i, y_i], [x_j, y_j]]`` (m) at the
        graph's poses in the filter's frame (the figures mark them)."""
        i, j, loop = self.loops.graph.edges()
        B = self._filter_from_graph()
        B = Transform2D() if B is None else B
        xy = self.loops.graph.poses[:, :2]
        return np.stack([B @ xy[i[loop]], B @ xy[j[loop]]], axis=1).reshape(-1, 2, 2)

    # --- reports -------------------------------------------------------------------------------------------

    def refused(self) -> dict[str, int]:
        """Candidates refused so far, by reason (`turtlelib.smoothing.loop_closure.Verdict`)."""
        verdicts = Counter(c.verdict for c in self.loops.candidates if c.verdict not in KEPT)
        return {verdict.value: count for verdict, count in sorted(verdicts.items(), key=lambda v: v[0].value)}

    def counts(self) -> dict[str, object]:
        """The totals a run's metrics.json holds: keyframes, loops closed, candidates refused (by reason),
        the last correction (m, rad; None before any), CPU time of the steps and of the grid's renderings."""
        D = self.last_correction
        return {
            "slam_loop_keyframes": len(self.loops.keyframes),
            "slam_loops_closed": self.closed,
            "slam_loop_candidates_refused": self.refused(),
            "slam_loop_last_correction_m": None if D is None else math.hypot(D.x, D.y),
            "slam_loop_last_correction_rad": None if D is None else D.theta,
            "slam_loop_cpu_seconds": self.cpu_s["steps"],
            "slam_loop_grid_renders": self.renders,
            "slam_loop_grid_render_cpu_seconds": self.cpu_s["renders"],
        }

    def status(self) -> DiagnosticStatus:
        """`slam: loop closure`: loops closed and refused so far, the last correction; OK (a refused
        candidate is the verification doing its work)."""
        refused = self.refused()
        message = (
            f"{self.closed} loops closed over {len(self.loops.keyframes)} keyframes, "
            f"{sum(refused.values())} candidates refused"
        )
        values: dict[str, object] = {
            "keyframes": len(self.loops.keyframes),
            "loops_closed": self.closed,
            **{f"refused_{reason.replace(' ', '_')}": count for reason, count in refused.items()},
            **self._step_time.values("step"),
            "grid_renders": self.renders,
            **self._render_time.values("grid_render"),
        }
        D = self.last_correction
        if D is not None:
            message += f"; the last moved the pose by {math.hypot(D.x, D.y):.3f} m, {D.theta:+.3f} rad"
            values["last_correction_m"] = round(math.hypot(D.x, D.y), 3)
            values["last_correction_rad"] = round(D.theta, 3)
        return status("slam: loop closure", "slam", OK, message, values)
