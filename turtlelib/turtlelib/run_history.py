"""The record of a filter's run that a smoother needs, kept by :class:`turtlelib.SlamTimeline`.

Since the run's start (or its last break: a restart of the timeline, a relocalization): the filter's pose
``q_0`` and covariance ``P_0`` at the first motion sample, every motion sample, and for every applied scan
its stamp, its observations ``z`` (K, 2) with their noise ``R`` (K, 2, 2), the landmark the filter associated
each with (-1: unused) and the filter's pose after the update. :meth:`RunHistory.smoothing_problem` turns it
into the factors of :mod:`turtlelib.smoothing_problem` with the filter's own models:

* poses at the start and at every scan stamp (scans of one stamp share a pose; a scan at the start's
  stamp is pose 0, on which the prior lies as the state before any update; its covariance floored at
  ``MIN_FACTOR_STD``, as the motion factors', so that an exactly known start stays invertible);
* the motion between them from the motion model and signal
  (:func:`~turtlelib.smoothing_problem.relative_motions`);
* the observations of the landmarks that are in the final map (those of tentative landmarks that were
  dropped are left out), each ``R`` scaled for errors correlated over the viewpoint as the filter does
  (:func:`~turtlelib.smoothing_problem.viewpoint_scales` with ``SlamConfig.fusion_scale``).

Memory grows with the run (a few hundred bytes per motion sample and per observation): it is kept only
when asked for.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from .ekf_slam import SlamConfig
from .motion_models import MotionModel
from .motion_signals import MotionSignal, Sample
from .smoothed_association import Unassigned
from .smoothing_problem import SmoothingProblem, relative_motions, viewpoint_scales

# (m, rad) added to the standard deviations of each motion factor and of the start prior: keeps the factor
# of a standing robot and of an exactly known start invertible, far below every sensor's resolution
MIN_FACTOR_STD = 1e-4


class RunHistory:
    """A filter's run since its start or last break (module docstring)."""

    def __init__(self) -> None:
        self.start_pose: NDArray[np.float64] | None = None
        self.start_covariance = np.zeros((3, 3))
        self._forget()

    def _forget(self) -> None:
        """No motion sample and no scan."""
        self.motion_t_ns: list[int] = []
        self.motion_samples: list[Sample] = []
        self._scan_t_ns: list[int] = []
        self._scan_poses: list[NDArray[np.float64]] = []
        self._z: list[NDArray[np.float64]] = []
        self._R: list[NDArray[np.float64]] = []
        self._landmark_ids: list[NDArray[np.int64]] = []

    @property
    def n_scans(self) -> int:
        return len(self._scan_t_ns)

    def begin(
        self, t_ns: int, sample: Sample, pose: NDArray[np.float64], covariance: NDArray[np.float64]
    ) -> None:
        """Forget everything and start at the motion sample ``(t_ns, sample)`` with the filter's ``pose`` (3,)
        and ``covariance`` (3, 3) there."""
        self._forget()
        self.start_pose, self.start_covariance = np.array(pose, dtype=np.float64), np.array(covariance)
        self.motion_t_ns.append(t_ns)
        self.motion_samples.append(sample)

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
        self._scan_t_ns.append(t_ns)
        self._z.append(z)
        self._R.append(R)
        self._landmark_ids.append(landmark_ids)
        self._scan_poses.append(np.array(pose, dtype=np.float64))

    def observed_landmarks(self) -> NDArray[np.int64]:
        """The ids (ascending) the filter associated an observation of the history with."""
        ids = np.unique(np.concatenate([np.zeros(0, dtype=np.int64), *self._landmark_ids]))
        return ids[ids >= 0]

    def smoothing_problem(
        self, motion: MotionModel, signal: MotionSignal, config: SlamConfig, landmark_ids: NDArray[np.int64]
    ) -> tuple[
        SmoothingProblem, NDArray[np.float64], Callable[[SmoothingProblem], NDArray[np.float64]], Unassigned
    ]:
        """``(problem, poses (P, 3), rescale, unassigned)``: the factors of the run (module docstring) for the
        final map's ``landmark_ids``, the filter's poses at the problem's stamps (the warm start: at a stamp
        of several scans, the pose after the last), the viewpoint scales of the noise for any labelling of
        the observations, and the usable observations of no landmark of the map (the last two for
        :func:`turtlelib.smoothed_association.revise_associations`). ValueError before :meth:`begin`."""
        if self.start_pose is None:
            raise ValueError("the run has not started: no motion sample yet")
        scan_t_ns = np.array(self._scan_t_ns, dtype=np.int64)
        pose_t_ns = np.unique(np.r_[self.motion_t_ns[0], scan_t_ns])
        poses = np.empty((len(pose_t_ns), 3))
        poses[0] = self.start_pose
        scan_pose = np.searchsorted(pose_t_ns, scan_t_ns)
        if self.n_scans:
            poses[scan_pose] = np.array(self._scan_poses)
        delta, Q = relative_motions(
            motion, signal, self.motion_t_ns, self.motion_samples, pose_t_ns, MIN_FACTOR_STD
        )
        per_scan = [len(z) for z in self._z]
        observation_pose = np.repeat(scan_pose, per_scan)
        associated = np.concatenate([np.zeros(0, dtype=np.int64), *self._landmark_ids])
        kept = np.isin(associated, landmark_ids)
        all_z = np.concatenate([np.zeros((0, 2)), *self._z])
        all_R = np.concatenate([np.zeros((0, 2, 2)), *self._R])
        z, R = all_z[kept], all_R[kept]
        problem = SmoothingProblem(
            pose_t_ns=pose_t_ns,
            prior_mean=self.start_pose,
            prior_covariance=self.start_covariance + MIN_FACTOR_STD**2 * np.eye(3),
            motion_delta=delta,
            motion_covariance=Q,
            observation_pose=observation_pose[kept],
            observation_landmark=associated[kept],
            z=z,
            R=R,
        )
        measurement = config.measurement_model()
        sensor_xy = np.array([measurement.sensor_xy(q) for q in poses])

        def rescale(labelled: SmoothingProblem) -> NDArray[np.float64]:
            return viewpoint_scales(
                sensor_xy, labelled.observation_pose, labelled.observation_landmark, config.fusion_scale
            )

        # the observations of no landmark that the sensor model takes (in its range, as the filter checks)
        free = ~kept & measurement.usable(all_z)
        unassigned = Unassigned(observation_pose[free], all_z[free], all_R[free])
        return replace(problem, noise_scale=rescale(problem)), poses, rescale, unassigned
