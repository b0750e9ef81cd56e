"""What a demo run and a bag replay both do at the end, without ROS: the metrics of the run against the
ground truth, its figures and metrics.json, the results table they print, and the progress bar of their
loop.

Both hand over a :class:`RunRecord`: the pose series their monitor heard (in the truth's frame), the final
state of the in-process slam node's filter (:func:`slam_snapshot`), the true cylinders and how close each
must come to count as seen (:func:`sensor_range_m`). docs/demo.md describes the metrics, docs/replay.md
what a replay without ground truth still writes.
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from turtlelib import MODES
from turtlelib.mapping.grid_map_file import save_grid_map
from turtlelib.mapping.occupancy_grid import GridMap
from turtlelib.util.validation import in_range, one_of, store

from . import plots
from .metrics import PoseSeries, RunData, RunMetrics, evaluate_run
from .tum import write_tum

# Landmarks closer than this to a true cylinder count as that cylinder (m)
LANDMARK_GATE_M = 0.2
METRICS_FILE = "metrics.json"
# the occupancy grid in map_server's format (GRID_YAML + its .pgm) and its figure
GRID_YAML, GRID_FIGURE = "map.yaml", "grid.png"
GRID_OUTPUTS = (GRID_YAML, "map.pgm", GRID_FIGURE)
# the trajectories in the TUM format (nuturtle_eval.tum): SLAM's, the odometry's and the reference's
ESTIMATE_TUM, ODOMETRY_TUM, REFERENCE_TUM = "estimate.tum", "odometry.tum", "reference.tum"
TUM_OUTPUTS = (ESTIMATE_TUM, ODOMETRY_TUM, REFERENCE_TUM)
# The odometry drift target (>= 0.2 m) is about the demo's world: its wheels slip by up to this fraction
# of each step's travel, over a run of at least this long (s)
DRIFT_SLIP_FRACTION = 0.3
DRIFT_RUN_S = 120.0


@dataclass(frozen=True)
class NotApplicable:
    """A target of the results table that does not apply to the run, and why (shown ``n/a: reason``;
    never a failure)."""

    reason: str


# (label, value text, target text, verdict): verdict True met, False failed (✗), None no target or not
# measured, NotApplicable a target this run is not about
Row = tuple[str, str, str, bool | NotApplicable | None]


@dataclass(frozen=True)
class RunScope:
    """What kind of run the results table is about, which decides the targets that apply to it: slam's
    ``mode`` (mapping | localization: the landmark map was loaded, this run made none), ``grid_loaded``
    (slam's occupancy grid came from the map file, this run mapped no scan), ``slip_fraction`` the
    simulated wheel slip (nusim's ``slip_fraction``; None: not known, e.g. a recording)."""

    mode: str = "mapping"
    grid_loaded: bool = False
    slip_fraction: float | None = None

    def __post_init__(self) -> None:
        store(self, ("mode",), partial(one_of, choices=MODES))
        if self.slip_fraction is not None:
            store(self, ("slip_fraction",), partial(in_range, low=0.0, high=1.0))

    def odometry_drift(self, sim_seconds: float) -> NotApplicable | None:
        """Why the odometry drift target (the demo world's slip over its whole run) does not apply: the
        world slips less than ``DRIFT_SLIP_FRACTION``, or the run (``sim_seconds``, s) is shorter than
        ``DRIFT_RUN_S``."""
        if self.slip_fraction is not None and self.slip_fraction < DRIFT_SLIP_FRACTION:
            return NotApplicable(
                f"set for {100 * DRIFT_SLIP_FRACTION:g} % wheel slip, this world's is "
                f"{100 * self.slip_fraction:g} %"
            )
        # to the second: a recording's span is a fraction of its last period shorter than its run
        if round(sim_seconds) < DRIFT_RUN_S:
            return NotApplicable(f"set for a run of {DRIFT_RUN_S:g} s")
        return None

    def landmark_mapping(self, landmarks_in_range: int) -> NotApplicable | None:
        """Why the landmark mapping target does not apply: localization (the map was loaded) or no true
        cylinder in range (nothing to map)."""
        if self.mode == "localization":
            return NotApplicable("localization: the landmark map was loaded, not made")
        if landmarks_in_range == 0:
            return NotApplicable("no cylinder came in range")
        return None

    def grid_mapping(self) -> NotApplicable | None:
        """Why the grid's targets do not apply: the grid was loaded (localization), not mapped."""
        return NotApplicable("localization: the grid was loaded, not mapped") if self.grid_loaded else None


# the scope of a mapping run of unknown wheel slip (a replay's)
MAPPING_SCOPE = RunScope()

# (metrics.json key, label, format, target text, check, why it may not apply (None: it always does)) of
# the printed table
TARGETS = (
    ("final_position_error_slam_m", "final position error, SLAM (m)", "{:.4f}", "<= 0.02",
     lambda v: v <= 0.02, None),
    ("final_heading_error_slam_rad", "final heading error, SLAM (rad)", "{:.4f}", "<= 0.02",
     lambda v: v <= 0.02, None),
    ("final_position_error_odom_m", "final position error, odometry (m)", "{:.4f}", ">= 0.2",
     lambda v: v >= 0.2, lambda scope, values: scope.odometry_drift(values["sim_seconds"])),
    ("final_heading_error_odom_rad", "final heading error, odometry (rad)", "{:.4f}", "", None, None),
    ("ate_rmse_slam_m", "ATE RMSE, SLAM (m)", "{:.4f}", "", None, None),
    ("ate_rmse_odom_m", "ATE RMSE, odometry (m)", "{:.4f}", "", None, None),
    ("ate_rmse_aligned_slam_m", "ATE RMSE aligned, SLAM (m)", "{:.4f}", "", None, None),
    ("ate_rmse_aligned_odom_m", "ATE RMSE aligned, odometry (m)", "{:.4f}", "", None, None),
    ("rpe_translation_slam_m", "RPE 1-10 m, SLAM (m)", "{:.4f}", "", None, None),
    ("rpe_translation_odom_m", "RPE 1-10 m, odometry (m)", "{:.4f}", "", None, None),
    ("rpe_rotation_slam_deg", "RPE 1-10 m, SLAM (deg)", "{:.3f}", "", None, None),
    ("rpe_rotation_odom_deg", "RPE 1-10 m, odometry (deg)", "{:.3f}", "", None, None),
    ("landmark_rmse_m", "landmark RMSE (m)", "{:.4f}", "", None, None),
    ("nees_pose_mean", "pose NEES, mean (3 dof)", "{:.2f}", "", None, None),
    ("nees_pose_median", "pose NEES, median (3 dof)", "{:.2f}", "", None, None),
    ("nees_pose_within_95_fraction", "pose NEES inside the 95% band", "{:.3f}", ">= 0.9",
     lambda v: v >= 0.9, None),
    ("sim_seconds", "simulated time (s)", "{:.1f}", "", None, None),
    ("wall_seconds", "wall time (s)", "{:.1f}", "<= sim / 2", None, None),
)  # fmt: skip


@dataclass(frozen=True)
class SlamSnapshot:
    """The filter's final state: ``covariance`` (N, N) of ``[x, y, theta, m_0x, m_0y, ...]``,
    ``landmarks_xy`` (n, 2) and their ``landmark_covariances`` (n, 2, 2); slam's occupancy ``grid`` as a
    save writes it (None: no grid, e.g. no scan); the ``loops`` slam closed (L, 2, 2), each as the
    positions of its two keyframes in the map frame (None: no loop closure)."""

    covariance: np.ndarray
    landmarks_xy: np.ndarray
    landmark_covariances: np.ndarray
    grid: GridMap | None = None
    loops: np.ndarray | None = None


def slam_snapshot(slam_node: Any) -> SlamSnapshot:
    """Read the final state straight from the in-process slam node's filter (its ``slam`` attribute) and
    its occupancy grid (its ``grid`` attribute: ``nuslam.grid_mapping.GridMapping``, re-rendered as a save
    would) and the loops its loop closure closed (its ``loop_closing`` attribute, None without:
    ``nuslam.loop_closing.LoopClosing``)."""
    ekf = slam_node.slam
    grid_mapping = slam_node.grid
    loop_closing = slam_node.loop_closing
    return SlamSnapshot(
        covariance=np.array(ekf.covariance),
        landmarks_xy=np.array(ekf.landmarks).reshape(-1, 2),
        landmark_covariances=np.array(ekf.landmark_covariances).reshape(-1, 2, 2),
        grid=grid_mapping.render() if grid_mapping.has_grid else None,
        loops=None if loop_closing is None else loop_closing.loop_segments(),
    )


def slip_counts(slam_node: Any) -> dict[str, int | float | str | None]:
    """The in-process slam node's landmarks removed because the LiDAR saw through them (its ``report``
    attribute) and its slip recovery totals (its ``recovery`` attribute): scans held because they
    contradicted the motion, relocalizations against the map, stalls and the size of the last correction
    (m, rad; None before any); and what its motion gate (its ``motion_gate`` attribute) refused, bridged
    and restarted: motion samples refused, silences bridged and the longest (s), restarts of the motion
    stream, the last reason (None: nothing refused)."""
    status, tally = slam_node.recovery.status, slam_node.motion_gate.tally
    correction = status.last_correction
    return {
        "slam_landmarks_removed": slam_node.report.landmarks_removed,
        "slam_scans_held": status.held,
        "slam_relocalizations": status.relocalized,
        "slam_stalls": status.stalls,
        "slam_last_correction_m": None if correction is None else math.hypot(correction.x, correction.y),
        "slam_last_correction_rad": None if correction is None else correction.theta,
        "slam_motion_samples_refused": tally.refused,
        "slam_motion_silences_bridged": tally.bridged,
        "slam_motion_longest_bridge_s": tally.longest_bridge_s,
        "slam_motion_restarts": tally.restarts,
        "slam_motion_last_refusal": tally.last_reason or None,
    }


def loop_counts(slam_node: Any) -> dict[str, Any]:
    """The in-process slam node's loop closure totals (its ``loop_closing`` attribute:
    ``nuslam.loop_closing.LoopClosing.counts``: keyframes, loops closed, candidates refused by reason, the
    last correction, CPU time); {} without loop closure."""
    loop_closing = slam_node.loop_closing
    return {} if loop_closing is None else loop_closing.counts()


def grid_counts(slam_node: Any) -> dict[str, int]:
    """The in-process slam node's live occupancy grid (its ``grid`` attribute:
    ``nuslam.grid_mapping.GridMapping``) at the end: its cells and bytes, the most bytes it may hold
    (``grid.max_size_m``) and the scans that reached past that bound."""
    grid_mapping = slam_node.grid
    memory = grid_mapping.memory()
    return {
        "slam_grid_cells": memory["cells"],
        "slam_grid_bytes": memory["bytes"],
        "slam_grid_max_bytes": memory["max_bytes"],
        "slam_grid_scans_past_bound": grid_mapping.scans_past_bound,
    }


def sensor_range_m(
    association: str,
    fake_sensor_range_m: float,
    slam_range_m: float,
    radii_m: NDArray[np.float64],
    min_points: int,
    angle_increment: float | None,
    lidar_range_m: float | None,
) -> float | NDArray[np.float64]:
    """How close each cylinder (radii (M,)) must come to count as seen (m): the fake sensor's range (known
    association), or (unknown) the farthest distance at which the LiDAR puts the detector's ``min_points``
    beams on it, within SLAM's and the LiDAR's range. A cylinder of radius r at distance d spans about
    2 r / d rad, so it is hit by about 2 r / (d angle_increment) beams::

        d_max = min(lidar_range_m, slam_range_m, 2 r / (min_points angle_increment))

    Without a scan to take the LiDAR's ``angle_increment`` and ``lidar_range_m`` from (None), or without
    cylinders: SLAM's range."""
    if association == "known":
        return fake_sensor_range_m
    radii_m = np.asarray(radii_m, dtype=np.float64).reshape(-1)
    if angle_increment is None or lidar_range_m is None or not radii_m.size:
        return slam_range_m
    detectable_m = 2.0 * radii_m / (min_points * angle_increment)
    return np.minimum(detectable_m, min(slam_range_m, lidar_range_m))


@dataclass(frozen=True)
class RunRecord:
    """What a run or a replay produced, in the truth's frame: the ``truth`` (None without ground truth),
    ``odom`` (None or empty without odometry) and ``slam`` pose series, ``slam_covariances`` (K, 3, 3) of
    the SLAM poses, the filter's final ``snapshot``, the true cylinders ``circles`` (M, 3) of rows
    ``[x, y, r]`` (None: unknown, a recording of another world: the map is counted, not judged),
    ``sensor_range_m`` (:func:`sensor_range_m`) and ``walls`` (K, 4) the arena's wall
    segments ``[x0, y0, x1, y1]``, which the trajectory figure draws (None: no walls, the axes fit the
    data)."""

    truth: PoseSeries | None
    odom: PoseSeries | None
    slam: PoseSeries
    slam_covariances: NDArray[np.float64]
    snapshot: SlamSnapshot
    circles: NDArray[np.float64] | None
    sensor_range_m: float | NDArray[np.float64]
    walls: NDArray[np.float64] | None = None


def evaluate_and_plot(
    out_dir: Path, record: RunRecord, sim_seconds: float, wall_seconds: float
) -> RunMetrics | None:
    """Write the figures of ``record`` into ``out_dir`` and return its metrics: ``trajectory.png`` (once
    SLAM published a pose) and ``covariance.png``; the trajectories in the TUM format (:func:`write_tums`);
    with a grid, ``map.yaml`` + ``map.pgm`` (map_server's
    format) and ``grid.png`` (:func:`write_grid`); with the truth, odometry and SLAM poses also the metrics
    (:func:`metrics.evaluate_run`, landmarks paired within ``LANDMARK_GATE_M``) and ``errors.png``, else
    None. ValueError from evaluate_run (``errors.png`` is then not written)."""
    odom = record.odom if record.odom is not None and len(record.odom) else None
    snapshot = record.snapshot
    circles = np.zeros((0, 3)) if record.circles is None else np.asarray(record.circles).reshape(-1, 3)
    write_tums(out_dir, record.slam, odom, record.truth)
    if len(record.slam):
        plots.plot_trajectory(
            out_dir / "trajectory.png", record.truth, odom, record.slam, circles,
            snapshot.landmarks_xy, snapshot.landmark_covariances, record.walls, snapshot.loops,
        )  # fmt: skip
    plots.plot_covariance(out_dir / "covariance.png", snapshot.covariance)
    if snapshot.grid is not None:
        write_grid(out_dir, snapshot.grid, record.slam.xy, snapshot.landmarks_xy, snapshot.loops)
    if record.truth is None or odom is None or not len(record.slam):
        return None
    data = RunData(
        truth=record.truth,
        odom=odom,
        slam=record.slam,
        slam_covariances=record.slam_covariances,
        mapped_xy=snapshot.landmarks_xy,
        true_xy=None if record.circles is None else circles[:, :2],
        sensor_range_m=record.sensor_range_m,
        gate_m=LANDMARK_GATE_M,
        true_radii_m=circles[:, 2],
    )
    metrics = evaluate_run(data, sim_seconds=sim_seconds, wall_seconds=wall_seconds)
    plots.plot_slam_errors(out_dir / "errors.png", record.slam, record.slam_covariances, record.truth)
    return metrics


def write_tums(
    out_dir: Path, estimate: PoseSeries, odometry: PoseSeries | None, reference: PoseSeries | None
) -> None:
    """``estimate.tum``, ``odometry.tum`` and ``reference.tum`` (:mod:`nuturtle_eval.tum`) in ``out_dir``:
    each series that has a pose (all in the reference's frame, as the metrics compare them)."""
    for name, series in ((ESTIMATE_TUM, estimate), (ODOMETRY_TUM, odometry), (REFERENCE_TUM, reference)):
        if series is not None and len(series):
            write_tum(out_dir / name, series)


def write_grid(
    out_dir: Path,
    grid: GridMap,
    path_xy: NDArray[np.float64],
    landmarks_xy: NDArray[np.float64],
    loops: NDArray[np.float64] | None = None,
) -> None:
    """``map.yaml`` + ``map.pgm`` (:func:`turtlelib.mapping.grid_map_file.save_grid_map`) and ``grid.png``:
    the grid with the SLAM path ``path_xy`` (K, 2), the landmarks (n, 2) and the loops closed (L, 2, 2; None:
    none) over it, all in the map frame."""
    save_grid_map(out_dir / GRID_YAML, grid)
    plots.plot_grid(out_dir / GRID_FIGURE, grid, path_xy, landmarks_xy, loops)


def json_value(value: Any) -> Any:
    """``value`` with every non-finite float (NaN: a figure that could not be measured) as None, in nested
    dicts, lists and tuples: what JSON can hold (``json.dumps(..., allow_nan=False)`` accepts it)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {key: json_value(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_value(item) for item in value]
    return value


def write_metrics(out_dir: Path, values: Mapping[str, Any]) -> Path:
    """``out_dir/metrics.json``: ``values`` as indented, valid JSON (a NaN figure is null); its path."""
    path = out_dir / METRICS_FILE
    path.write_text(json.dumps(json_value(values), indent=2, allow_nan=False) + "\n", encoding="utf-8")
    return path


def target_rows(metrics: RunMetrics, scope: RunScope = MAPPING_SCOPE) -> list[Row]:
    """The rows of the results table: (label, value text, target text, verdict) with verdict None where no
    target applies or the figure could not be measured (NaN, shown ``n/a``), a :class:`NotApplicable`
    where the target is not about a run of this ``scope``. Without the true landmarks the map is only
    counted: no landmark is called unmapped, a duplicate or spurious."""
    values = metrics.as_dict()
    rows: list[Row] = []
    for key, label, fmt, target, check, scoped in TARGETS:
        value = values[key]
        if isinstance(value, float) and math.isnan(value):
            rows.append((label, "n/a", target, None))
            continue
        if key == "wall_seconds":
            ok = value <= 0.5 * values["sim_seconds"]
        else:
            ok = check(value) if check is not None else None
        not_applicable = None if scoped is None else scoped(scope, values)
        rows.append((label, fmt.format(value), target, ok if not_applicable is None else not_applicable))
    if values["landmarks_true"] is None:
        mapped = str(values["landmarks_mapped"])
        rows.append(("landmarks mapped (no true landmarks to judge them by)", mapped, "", None))
        return rows
    mapped_ok = values["landmarks_in_range_unmapped"] == 0 and values["landmarks_duplicate"] == 0
    not_applicable = scope.landmark_mapping(values["landmarks_in_range"])
    rows.append(
        (
            "landmarks: true / came in range / mapped",
            f"{values['landmarks_true']} / {values['landmarks_in_range']} / {values['landmarks_mapped']}",
            "every one in range mapped once",
            mapped_ok if not_applicable is None else not_applicable,
        )
    )
    rows.append(
        (
            "landmarks: in range but unmapped / duplicates / spurious",
            f"{values['landmarks_in_range_unmapped']} / {values['landmarks_duplicate']} / "
            f"{values['landmarks_spurious']}",
            "0 / 0 / 0",
            None,
        )
    )
    return rows


def failed_targets(
    metrics: RunMetrics, more_rows: Sequence[Row] = (), scope: RunScope = MAPPING_SCOPE
) -> list[str]:
    """The labels of the targets the results table (with ``more_rows``, for a run of ``scope``) marks
    failed (✗); a target that does not apply never fails."""
    return [label for label, _, _, ok in [*target_rows(metrics, scope), *more_rows] if ok is False]


def results_table(
    metrics: RunMetrics, targets: bool = True, more_rows: Sequence[Row] = (), scope: RunScope = MAPPING_SCOPE
) -> str:
    """A markdown table of the run's figures and, with ``targets``, the demo's targets (✓/✗ where one
    applies, ``n/a: why`` where it is not about a run of this ``scope``: :class:`RunScope`); without, the
    figures alone (a recording of another world, which those targets are not about). ``more_rows`` follow
    the metrics' own (the grid's score: :mod:`nuturtle_eval.grid_score`)."""
    rows = (
        ["| metric | value | target | |", "|---|---:|---|---|"]
        if targets
        else ["| metric | value |", "|---|---:|"]
    )
    for label, text, target, ok in [*target_rows(metrics, scope), *more_rows]:
        rows.append(f"| {label} | {text} | {target} | {_mark(ok)} |" if targets else f"| {label} | {text} |")
    return "\n".join(rows)


def _mark(verdict: bool | NotApplicable | None) -> str:
    if isinstance(verdict, NotApplicable):
        return f"n/a: {verdict.reason}"
    return "" if verdict is None else ("✓" if verdict else "✗")


class ProgressBar:
    """A progress bar on stderr over ``total_s`` seconds of the run's ``clock`` (``sim``, ``bag``), with the
    pace in times real time since it was made (tqdm, imported here: only a run needs it); hidden unless
    ``enabled``. A context manager: leaving it closes the bar."""

    def __init__(self, total_s: float, clock: str, enabled: bool) -> None:
        from tqdm import tqdm

        self.total_s = round(total_s, 1)
        self._bar = tqdm(
            total=self.total_s, unit=f"{clock} s", file=sys.stderr, disable=not enabled,
            bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} " + clock + " s [{elapsed}<{remaining}{postfix}]",
        )  # fmt: skip
        self._wall_start = time.monotonic()

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, traceback: TracebackType | None
    ) -> None:
        self._bar.close()

    def advance(self, now_s: float) -> None:
        """Show that the run's clock reached ``now_s`` (s since its start, clamped to ``total_s``): redrawn
        every 0.5 s of it and at the end."""
        now_s = min(now_s, self.total_s)
        if now_s - self._bar.n >= 0.5 or (now_s >= self.total_s > self._bar.n):
            wall_s = time.monotonic() - self._wall_start
            self._bar.set_postfix_str(f"{now_s / max(wall_s, 1e-9):.1f}x real time", refresh=False)
            self._bar.update(round(now_s - self._bar.n, 1))
