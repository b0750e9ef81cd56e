"""One SLAM run over a recorded dataset: the filter fed exactly as the slam node feeds it.

An :class:`Experiment` holds what any recording reduces to: a motion model with its signal and stamped
samples, stamped scans of range-bearing observations (with ids for known association), the start pose, and
the filter's configuration. :func:`run_experiment` feeds the samples and scans to a
:class:`turtlelib.SlamTimeline` in time order (a scan after the motion samples of its own time, so each
is applied at its stamp with the motion held or interpolated up to it) and keeps the pose estimate after
every scan, the filter's track, the final map and the timing. Offline nothing arrives late, so the
timeline holds the motion until each scan and predicts the samples between two scans as one batch
(:meth:`turtlelib.EkfSlam.predict_along`): the node's sample-by-sample result, to rounding.

Times are integer ns; the estimates are kept at the scan stamps.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from turtlelib import (
    EkfSlam,
    MotionModel,
    MotionSignal,
    SlamConfig,
    SlamTimeline,
    TimelineConfig,
    Transform2D,
)
from turtlelib.estimation.run_history import RunHistory
from turtlelib.estimation.slam_timeline import ScanResult
from turtlelib.util.timebase import NS_PER_S

# data association: landmark ids given with the observations (known) or found by the filter (unknown)
ASSOCIATIONS = ("known", "unknown")


@dataclass(frozen=True)
class Scans:
    """Stamped observations grouped by scan: ``t_ns`` (S,) increasing scan stamps; scan ``i`` holds rows
    ``start[i]:start[i + 1]`` of ``z`` (K, 2) [range_m, bearing_rad] (sensor frame) and, for known
    association, of ``ids`` (K,) (None for unknown association)."""

    t_ns: NDArray[np.int64]
    start: NDArray[np.int64]
    z: NDArray[np.float64]
    ids: NDArray[np.int64] | None

    @classmethod
    def from_rows(
        cls, t_ns: NDArray[np.int64], z: NDArray[np.float64], ids: NDArray[np.int64] | None = None
    ) -> Scans:
        """Rows stamped ``t_ns`` (K,) (non-decreasing) grouped into scans of equal stamp."""
        t_ns = np.asarray(t_ns, dtype=np.int64)
        if np.any(np.diff(t_ns) < 0):
            raise ValueError("observation stamps must be non-decreasing")
        first = np.flatnonzero(np.r_[True, np.diff(t_ns) > 0]) if len(t_ns) else np.zeros(0, dtype=np.int64)
        start = np.r_[first, len(t_ns)].astype(np.int64)
        return cls(t_ns[first], start, np.asarray(z, dtype=np.float64).reshape(-1, 2), ids)

    def __len__(self) -> int:
        return len(self.t_ns)

    def until(self, t_ns: int) -> Scans:
        """The scans stamped at or before ``t_ns``."""
        n = int(np.searchsorted(self.t_ns, t_ns, side="right"))
        rows = int(self.start[n])
        return Scans(
            self.t_ns[:n], self.start[: n + 1], self.z[:rows], None if self.ids is None else self.ids[:rows]
        )

    def scan(self, i: int) -> tuple[NDArray[np.float64], NDArray[np.int64] | None]:
        rows = slice(self.start[i], self.start[i + 1])
        return self.z[rows], None if self.ids is None else self.ids[rows]


@dataclass(frozen=True)
class Experiment:
    """A recording ready for the filter (module docstring): ``motion`` and ``signal``, motion samples
    ``motion_t_ns`` (M,) increasing with values ``motion_samples`` (M, k), ``scans``, the start pose
    ``T_map_body0`` at ``motion_t_ns[0]`` and ``config`` (its ``initial_*_std`` give the start
    covariance)."""

    name: str
    motion: MotionModel
    signal: MotionSignal
    motion_t_ns: NDArray[np.int64]
    motion_samples: NDArray[np.float64]
    scans: Scans
    T_map_body0: Transform2D
    config: SlamConfig


@dataclass(frozen=True)
class ExperimentResult:
    """The estimates after every applied scan: ``t_ns`` (S,), ``poses`` (S, 3) ``T_map_body``,
    ``covariances`` (S, 3, 3); the filter's pose at the start and after every prediction up to the last scan
    (at every motion sample and scan stamp), ``track`` (T, 3) at ``track_t_ns`` (T,); the final map
    (``landmark_ids`` (n,), ``landmarks`` (n, 2), ``landmark_covariances`` (n, 2, 2)); per observation
    status counts; CPU seconds of the whole run and the wall time (ms) of every timeline call that applied
    a scan (its prediction up to the stamp and its update); the run's ``history`` for a smoother (the
    motion samples, each applied scan's observations, associations and pose)."""

    t_ns: NDArray[np.int64]
    poses: NDArray[np.float64]
    covariances: NDArray[np.float64]
    track_t_ns: NDArray[np.int64]
    track: NDArray[np.float64]
    landmark_ids: NDArray[np.int64]
    landmarks: NDArray[np.float64]
    landmark_covariances: NDArray[np.float64]
    status_counts: dict[str, int]
    cpu_seconds: float
    update_ms: NDArray[np.float64]
    history: RunHistory


def run_experiment(experiment: Experiment, progress: Callable[[int], None] | None = None) -> ExperimentResult:
    """Run the filter over the whole recording; ``progress(n)`` is called with the number of motion
    samples done since its last call."""
    slam = EkfSlam(experiment.config, experiment.motion, experiment.T_map_body0)
    t_motion = experiment.motion_t_ns
    samples = experiment.motion_samples
    # offline every observation is fed right after the motion samples of its time, so none is ever late
    # and the filter may hold all motion until the next scan: the samples between two scans are then
    # predicted as one batch (SlamTimeline, EkfSlam.predict_along)
    hold = TimelineConfig(max_observation_delay=(int(t_motion[-1]) - int(t_motion[0])) / NS_PER_S)
    # recorded data: a refused sample ends the run, so the timeline need not check samples ahead
    timeline = SlamTimeline(
        slam, experiment.signal, hold, keep_track=True, check_motion=False, keep_history=True
    )
    scans = experiment.scans
    # scans before the first motion sample cannot be placed in time; the others go after the motion
    # samples of their stamp
    first_scan = int(np.searchsorted(scans.t_ns, t_motion[0], side="left"))
    scan_after = np.searchsorted(t_motion, scans.t_ns, side="right")
    t_est, poses, covariances, update_ms = [], [], [], []
    counts = {"matched": 0, "new": 0, "rejected": 0}

    def keep(applied: list[ScanResult], elapsed_ms: float) -> None:
        for result in applied:
            t_est.append(result.t_ns)
            poses.append(slam.pose.as_array())
            covariances.append(slam.pose_covariance)
            tally = result.association.counts
            for status in counts:
                counts[status] += tally[status]
        if applied:
            update_ms.append(elapsed_ms)

    cpu_start = time.process_time()
    i_scan = first_scan
    chunk = max(1, len(t_motion) // 200)
    for k in range(len(t_motion)):
        start = time.perf_counter()
        applied = timeline.add_motion(int(t_motion[k]), samples[k])
        keep(applied, 1e3 * (time.perf_counter() - start))
        # the scans whose stamp lies before the next motion sample
        while i_scan < len(scans) and scan_after[i_scan] == k + 1:
            z, ids = scans.scan(i_scan)
            start = time.perf_counter()
            applied = timeline.add_observations(int(scans.t_ns[i_scan]), z, ids=ids)
            keep(applied, 1e3 * (time.perf_counter() - start))
            i_scan += 1
        if progress is not None and (k + 1) % chunk == 0:
            progress(chunk)
    cpu_seconds = time.process_time() - cpu_start
    if progress is not None:
        progress(len(t_motion) % chunk)
    track_t_ns, track = timeline.take_track()
    return ExperimentResult(
        t_ns=np.array(t_est, dtype=np.int64),
        poses=np.array(poses).reshape(-1, 3),
        covariances=np.array(covariances).reshape(-1, 3, 3),
        track_t_ns=np.r_[t_motion[:1], track_t_ns],
        track=np.vstack([experiment.T_map_body0.as_array(), track]),
        landmark_ids=slam.landmark_ids,
        landmarks=slam.landmarks,
        landmark_covariances=slam.landmark_covariances,
        status_counts=counts,
        cpu_seconds=cpu_seconds,
        update_ms=np.array(update_ms),
        history=timeline.history,
    )
