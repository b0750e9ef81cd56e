"""The smoother over a dataset run (``--smooth``): the filter's run re-estimated as a whole.

The factors come from the run's history (:class:`turtlelib.estimation.run_history.RunHistory`, kept by the
filter's timeline): poses at the start and at every applied scan, the motion between them from the
experiment's motion model and signal (as the filter predicted it), and the observations the filter associated
with a landmark of its final map, with the filter's noise model (correlated errors included).
:func:`smooth_run`
solves them from the filter's estimates (:func:`turtlelib.smoothing.run_smoothing.smooth_history`; with
unknown association the associations are revised) and gives an
:class:`~nuturtle_eval.datasets.experiment.ExperimentResult` that the evaluation and the figures take as they
take the filter's: the smoothed poses at the scans (no pose covariance: NaN) and the smoothed map with the
covariance of the information matrix.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from turtlelib.smoothing.association_revision import RevisionConfig
from turtlelib.smoothing.run_smoothing import smooth_history
from turtlelib.smoothing.smoother import SmootherConfig

from .experiment import Experiment, ExperimentResult


def smooth_run(
    experiment: Experiment,
    result: ExperimentResult,
    revise: bool,
    config: SmootherConfig | None = None,
    revision: RevisionConfig | None = None,
) -> tuple[ExperimentResult, dict]:
    """The smoothed run as an :class:`ExperimentResult` (module docstring; ``cpu_seconds`` the smoother's,
    building the factors included) and what it decided: with ``revise`` (unknown association), the filter's
    associations are revised. ``config`` and ``revision`` default to turtlelib's defaults, the ones the
    slam node and the replay use too (chosen on MRCLAM Dataset 7 robot 1, docs/real_data.md)."""
    cpu_start = time.process_time()
    outcome = smooth_history(
        result.history,
        experiment.motion,
        experiment.signal,
        experiment.config,
        result.landmark_ids,
        result.landmarks,
        revise,
        config,
        revision,
    )
    smoothed, problem = outcome.run, outcome.problem
    cpu_seconds = time.process_time() - cpu_start
    # the poses at the scans' stamps (the start's pose is the first unless a scan shares its stamp)
    scan_poses = smoothed.poses[np.searchsorted(problem.pose_t_ns, result.t_ns)]
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
    ), outcome.decisions()
