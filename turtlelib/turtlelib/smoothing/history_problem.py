"""The smoothing problem of a filter's run: a :class:`turtlelib.estimation.run_history.RunHistory` turned
into the factors of :mod:`turtlelib.smoothing.smoothing_problem` with the filter's own models.

* poses at the start and at every scan stamp (scans of one stamp share a pose; a scan at the start's
  stamp is pose 0, on which the prior lies as the state before any update; its covariance floored at
  ``MIN_FACTOR_STD``, as the motion factors', so that an exactly known start stays invertible);
* the motion between them from the motion model and signal
  (:func:`~turtlelib.smoothing.smoothing_problem.relative_motions`);
* the loops (:class:`~turtlelib.smoothing.smoothing_problem.LoopEdge`) whose stamps the history's motion
  covers, with a pose at each of their stamps, and a pose at each further stamp asked for (``extra_t_ns``:
  e.g. every scan an occupancy grid keeps, so that the smoothed run places each; at a stamp that is not a
  scan's, the warm start is the pose before it moved on by the motion between them);
* the observations of the landmarks that are in the final map (those of tentative landmarks that were
  dropped are left out), each ``R`` scaled for errors correlated over the viewpoint as the filter does
  (:func:`~turtlelib.smoothing.smoothing_problem.viewpoint_scales` with ``SlamConfig.fusion_scale``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from ..estimation.ekf_slam import SlamConfig
from ..estimation.run_history import RunHistory
from ..geometry.se2 import Transform2D
from ..motion.motion_models import MotionModel
from ..motion.motion_signals import MotionSignal
from .association_revision import Unassigned
from .smoothing_problem import LoopEdge, SmoothingProblem, relative_motions, viewpoint_scales

# (m, rad) added to the standard deviations of each motion factor and of the start prior: keeps the factor
# of a standing robot and of an exactly known start invertible, far below every sensor's resolution
MIN_FACTOR_STD = 1e-4

Rescale = Callable[[SmoothingProblem], NDArray[np.float64]]


def problem_from_history(
    history: RunHistory,
    motion: MotionModel,
    signal: MotionSignal,
    config: SlamConfig,
    landmark_ids: NDArray[np.int64],
    loops: Sequence[LoopEdge] = (),
    extra_t_ns: Sequence[int] = (),
    removed_ids: Sequence[int] = (),
) -> tuple[SmoothingProblem, NDArray[np.float64], Rescale, Unassigned]:
    """``(problem, poses (P, 3), rescale, unassigned)``: the factors of ``history`` (module docstring) for
    the final map's ``landmark_ids``, the filter's poses at the problem's stamps (the warm start: at a stamp
    of several scans, the pose after the last), the viewpoint scales of the noise for any labelling of the
    observations, and the usable observations of no landmark of the map (the last two for
    :func:`turtlelib.smoothing.association_revision.revise_associations`), but for those the filter had
    associated with a landmark it later removed as gone (``removed_ids``: a post the LiDAR saw through,
    :mod:`turtlelib.estimation.landmark_removal`), which no landmark of the revision may take. ValueError
    before the history's start."""
    if history.start_pose is None:
        raise ValueError("the run has not started: no motion sample yet")
    scan_t_ns = np.array(history.scan_t_ns, dtype=np.int64)
    t_first, t_last = history.motion_t_ns[0], history.motion_t_ns[-1]
    loops = [
        loop
        for loop in loops
        if t_first <= min(loop.t_a_ns, loop.t_b_ns) and max(loop.t_a_ns, loop.t_b_ns) <= t_last
    ]
    loop_t_ns = np.array([(loop.t_a_ns, loop.t_b_ns) for loop in loops], dtype=np.int64).reshape(-1, 2)
    extra = np.array(extra_t_ns, dtype=np.int64).reshape(-1)
    extra = extra[(extra >= t_first) & (extra <= t_last)]
    pose_t_ns = np.unique(np.r_[t_first, scan_t_ns, loop_t_ns.ravel(), extra])
    poses = np.full((len(pose_t_ns), 3), np.nan)
    poses[0] = history.start_pose
    scan_pose = np.searchsorted(pose_t_ns, scan_t_ns)
    if history.n_scans:
        poses[scan_pose] = np.array(history.scan_poses)
    delta, Q = relative_motions(
        motion, signal, history.motion_t_ns, history.motion_samples, pose_t_ns, MIN_FACTOR_STD
    )
    for k in np.flatnonzero(np.isnan(poses[:, 0])):  # a stamp between scans: q_k = q_k-1 delta_k-1
        poses[k] = (Transform2D(*poses[k - 1]) @ Transform2D(*delta[k - 1])).as_array()
    per_scan = [len(z) for z in history.scan_z]
    observation_pose = np.repeat(scan_pose, per_scan)
    associated = np.concatenate([np.zeros(0, dtype=np.int64), *history.scan_landmark_ids])
    kept = np.isin(associated, landmark_ids)
    all_z = np.concatenate([np.zeros((0, 2)), *history.scan_z])
    all_R = np.concatenate([np.zeros((0, 2, 2)), *history.scan_R])
    problem = SmoothingProblem(
        pose_t_ns=pose_t_ns,
        prior_mean=history.start_pose,
        prior_covariance=history.start_covariance + MIN_FACTOR_STD**2 * np.eye(3),
        motion_delta=delta,
        motion_covariance=Q,
        observation_pose=observation_pose[kept],
        observation_landmark=associated[kept],
        z=all_z[kept],
        R=all_R[kept],
        loop_pose=np.searchsorted(pose_t_ns, loop_t_ns),
        loop_delta=np.array([loop.Z.as_array() for loop in loops]).reshape(-1, 3),
        loop_covariance=np.array([loop.S for loop in loops]).reshape(-1, 3, 3),
    )
    measurement = config.measurement_model()
    sensor_xy = np.array([measurement.sensor_xy(q) for q in poses])

    def rescale(labelled: SmoothingProblem) -> NDArray[np.float64]:
        return viewpoint_scales(
            sensor_xy, labelled.observation_pose, labelled.observation_landmark, config.fusion_scale
        )

    # the observations of no landmark that the sensor model takes (in its range, as the filter checks),
    # but those of a landmark that is gone
    gone = np.isin(associated, np.asarray(removed_ids, dtype=np.int64))
    free = ~kept & ~gone & measurement.usable(all_z)
    unassigned = Unassigned(observation_pose[free], all_z[free], all_R[free])
    return replace(problem, noise_scale=rescale(problem)), poses, rescale, unassigned
