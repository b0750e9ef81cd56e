"""The record of a filter's run that a smoother needs, kept by :class:`turtlelib.SlamTimeline`.

Since the run's start (or its last break: a restart of the timeline, a relocalization, a reset): the
filter's pose ``q_0`` and covariance ``P_0`` at the first motion sample, every motion sample, and for every
applied scan its stamp, its observations ``z`` (K, 2) with their noise ``R`` (K, 2, 2), the landmark the
filter associated each with (-1: unused) and the filter's pose after the update. A plain record: the
smoothing problem is built from it on the smoothing side
(:func:`turtlelib.smoothing.history_problem.problem_from_history`).

Memory grows with the run (a few hundred bytes per motion sample and per observation): it is kept only
when asked for.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..motion.motion_signals import Sample


@dataclass
class RunHistory:
    """A filter's run since its start or last break (module docstring): ``start_pose`` (3,) (None before
    :meth:`begin`) and ``start_covariance`` (3, 3); the motion samples ``motion_t_ns``, ``motion_samples``;
    per applied scan ``scan_t_ns``, ``scan_z`` (K, 2), ``scan_R`` (K, 2, 2), ``scan_landmark_ids`` (K,) and
    ``scan_poses`` (3,) (the filter's pose after the update)."""

    start_pose: NDArray[np.float64] | None = None
    start_covariance: NDArray[np.float64] = field(default_factory=lambda: np.zeros((3, 3)))
    motion_t_ns: list[int] = field(default_factory=list)
    motion_samples: list[Sample] = field(default_factory=list)
    scan_t_ns: list[int] = field(default_factory=list)
    scan_z: list[NDArray[np.float64]] = field(default_factory=list)
    scan_R: list[NDArray[np.float64]] = field(default_factory=list)
    scan_landmark_ids: list[NDArray[np.int64]] = field(default_factory=list)
    scan_poses: list[NDArray[np.float64]] = field(default_factory=list)

    @property
    def n_scans(self) -> int:
        return len(self.scan_t_ns)

    def begin(
        self, t_ns: int, sample: Sample, pose: NDArray[np.float64], covariance: NDArray[np.float64]
    ) -> None:
        """Forget everything and start at the motion sample ``(t_ns, sample)`` with the filter's ``pose`` (3,)
        and ``covariance`` (3, 3) there."""
        for records in (self.motion_t_ns, self.motion_samples, self.scan_t_ns, self.scan_z, self.scan_R):
            records.clear()
        self.scan_landmark_ids.clear()
        self.scan_poses.clear()
        self.start_pose, self.start_covariance = np.array(pose, dtype=np.float64), np.array(covariance)
        self.add_motion(t_ns, sample)

    def add_motion(self, t_ns: int, sample: Sample) -> None:
        """A motion sample the timeline took (after :meth:`begin`)."""
        self.motion_t_ns.append(t_ns)
        self.motion_samples.append(sample)

    def add_scan(
        self,
        t_ns: int,
        z: NDArray[np.float64],
        R: NDArray[np.float64],
        landmark_ids: NDArray[np.int64],
        pose: NDArray[np.float64],
    ) -> None:
        """An applied scan: observations ``z`` (K, 2), noise ``R`` (K, 2, 2), the associated ``landmark_ids``
        (K,) (-1: unused) and the filter's ``pose`` (3,) after the update."""
        self.scan_t_ns.append(t_ns)
        self.scan_z.append(z)
        self.scan_R.append(R)
        self.scan_landmark_ids.append(landmark_ids)
        self.scan_poses.append(np.array(pose, dtype=np.float64))

    def observed_landmarks(self) -> NDArray[np.int64]:
        """The ids (ascending) the filter associated an observation of the history with."""
        ids = np.unique(np.concatenate([np.zeros(0, dtype=np.int64), *self.scan_landmark_ids]))
        return ids[ids >= 0]
