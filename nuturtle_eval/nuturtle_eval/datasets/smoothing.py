"""The smoother over a dataset run (``--smooth``): the filter's run re-estimated as a whole.

:func:`smoothing_problem` builds the factors of :mod:`turtlelib.smoothing_problem` from the experiment and
the filter's result: poses at the start and at every applied scan, the motion between them from the
experiment's motion model and signal (as the filter predicted it), the observations that the filter
associated with a landmark of its final map (tentative landmarks it dropped are left out), with the
filter's noise model (correlated errors included). :func:`smooth_run` solves it from the filter's
estimates and gives an :class:`~nuturtle_eval.datasets.experiment.ExperimentResult` that the evaluation and
the figures take as they take the filter's: the smoothed poses at the scans (no pose covariance: NaN) and
the smoothed map with the covariance of the information matrix.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np

from turtlelib import SlamConfig
from turtlelib.smoothed_association import RevisionConfig, revise_associations
from turtlelib.smoother import Smoother, SmootherConfig
from turtlelib.smoothing_problem import SmoothingProblem, relative_motions, viewpoint_scales

from .experiment import Experiment, ExperimentResult

# the smoother's defaults, chosen on MRCLAM Dataset 7 robot 1 (docs/real_data.md, "Smoother"): a narrow
# kernel, since the camera's errors have heavy tails (barcode misreads, tubes hiding each other)
SMOOTHER = SmootherConfig(kernel_width=1.0)
REVISION = RevisionConfig()
# (m, rad) added to each motion factor's standard deviations: keeps a standing robot's factor invertible,
# far below every sensor's resolution
MIN_MOTION_STD = 1e-4


def smoothing_problem(
    experiment: Experiment, result: ExperimentResult
) -> tuple[SmoothingProblem, np.ndarray, np.ndarray, np.ndarray, Callable[[SmoothingProblem], np.ndarray]]:
    """``(problem, poses (P, 3), landmark_ids (n,), landmarks (n, 2), noise)``: the factors, the filter's
    estimates as the warm start, and the observation noise of a labelling (module docstring)."""
    config = experiment.config
    t0 = int(experiment.motion_t_ns[0])
    start_pose = experiment.T_map_body0.as_array()
    # the start is pose 0 unless a scan was applied at that very stamp (then that scan's pose is)
    with_start = len(result.t_ns) == 0 or int(result.t_ns[0]) > t0
    pose_t_ns = np.r_[t0, result.t_ns] if with_start else result.t_ns.copy()
    poses = np.vstack([start_pose, result.poses]) if with_start else result.poses.copy()
    delta, Q = relative_motions(
        experiment.motion,
        experiment.signal,
        experiment.motion_t_ns.tolist(),
        [tuple(sample) for sample in experiment.motion_samples.tolist()],
        pose_t_ns,
        MIN_MOTION_STD,
    )
    scans = experiment.scans
    first_row = int(scans.start[result.first_scan])
    z = scans.z[first_row : first_row + len(result.observation_landmark_ids)]
    # the pose index of every row of the applied scans
    per_scan = np.diff(scans.start[result.first_scan : result.first_scan + len(result.t_ns) + 1])
    observation_pose = np.repeat(np.arange(len(result.t_ns)) + int(with_start), per_scan)
    kept = np.isin(result.observation_landmark_ids, result.landmark_ids)
    observation_pose, z = observation_pose[kept], z[kept]
    observation_landmark = result.observation_landmark_ids[kept]
    problem = SmoothingProblem(
        pose_t_ns=pose_t_ns,
        prior_mean=start_pose if with_start else result.poses[0],
        prior_covariance=config.initial_pose_covariance() if with_start else result.covariances[0],
        motion_delta=delta,
        motion_covariance=Q,
        observation_pose=observation_pose,
        observation_landmark=observation_landmark,
        z=z,
        R=np.zeros((len(z), 2, 2)),
    )
    noise = _noise_model(experiment.config, poses)
    return dataclasses.replace(problem, R=noise(problem)), poses, result.landmark_ids, result.landmarks, noise


def _noise_model(config: SlamConfig, poses: np.ndarray) -> Callable[[SmoothingProblem], np.ndarray]:
    """The observations' ``R`` of a labelling: the filter's noise model, each view scaled for the errors
    correlated over the viewpoint (:func:`turtlelib.smoothing_problem.viewpoint_scales`, with the sensor
    positions at the warm-start ``poses``)."""
    measurement = config.measurement_model()
    sensor_xy = np.array([measurement.sensor_xy(q) for q in poses])

    def noise(problem: SmoothingProblem) -> np.ndarray:
        scale = viewpoint_scales(
            sensor_xy, problem.observation_pose, problem.observation_landmark, config.fusion_scale
        )
        return measurement.noise(problem.z) * scale[:, None, None]

    return noise


def smooth_run(
    experiment: Experiment,
    result: ExperimentResult,
    revise: bool,
    config: SmootherConfig = SMOOTHER,
    revision: RevisionConfig = REVISION,
) -> tuple[ExperimentResult, dict]:
    """The smoothed run as an :class:`ExperimentResult` (module docstring; ``cpu_seconds`` the smoother's,
    building the factors included) and what it decided: with ``revise`` (unknown association), the filter's
    associations are revised (:func:`turtlelib.smoothed_association.revise_associations`)."""
    cpu_start = time.process_time()
    problem, poses, landmark_ids, landmarks, noise = smoothing_problem(experiment, result)
    smoother = Smoother(experiment.config.measurement_model(), config)
    if not revise:
        smoothed = smoother.solve(problem, poses, landmark_ids, landmarks)
        decisions = {}
    else:
        revised = revise_associations(smoother, problem, poses, landmark_ids, landmarks, noise, revision)
        smoothed, problem = revised.run, revised.problem
        decisions = {
            "landmarks_merged_by_smoother": len(revised.merged),
            "landmarks_removed_by_smoother": int(len(revised.removed)),
            "landmarks_created_by_smoother": len(revised.created),
            "observations_outliers": revised.outliers,
        }
    decisions.update(
        {
            "smoother_iterations": smoothed.iterations,
            "observations_used": int(len(problem.z)),
        }
    )
    cpu_seconds = time.process_time() - cpu_start
    scan_poses = smoothed.poses[len(problem.pose_t_ns) - len(result.t_ns) :]
    return dataclasses.replace(
        result,
        poses=scan_poses,
        covariances=np.full((len(scan_poses), 3, 3), np.nan),
        track_t_ns=problem.pose_t_ns,
        track=smoothed.poses,
        landmark_ids=smoothed.landmark_ids,
        landmarks=smoothed.landmarks,
        landmark_covariances=smoothed.landmark_covariances,
        cpu_seconds=cpu_seconds,
        update_ms=np.zeros(0),
    ), decisions
