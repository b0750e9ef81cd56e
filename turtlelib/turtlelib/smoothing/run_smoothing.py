"""A filter's run smoothed as a whole: the one entry point of the dataset command, the replay and the slam
node's map saving.

From the run's history (:class:`turtlelib.estimation.run_history.RunHistory`, kept by the timeline), the
filter's models and its final map: the factors
(:func:`turtlelib.smoothing.history_problem.problem_from_history`), then the smoother
(:class:`turtlelib.smoothing.smoother.Smoother`) from the filter's estimates, or with unknown association the
revised associations (:func:`turtlelib.smoothing.association_revision.revise_associations`): with known ids
there is no association to revise.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..estimation.ekf_slam import SlamConfig
from ..estimation.run_history import RunHistory
from ..geometry.se2 import Transform2D
from ..mapping.landmark_map import LandmarkMap
from ..motion.motion_models import MotionModel
from ..motion.motion_signals import MotionSignal
from .association_revision import Revision, RevisionConfig, revise_associations
from .history_problem import problem_from_history
from .smoother import SmoothedRun, Smoother, SmootherConfig
from .smoothing_problem import LoopEdge, SmoothingProblem


@dataclass(frozen=True)
class SmoothingOutcome:
    """The smoothed ``run`` of ``problem`` (its poses at ``problem.pose_t_ns``) and, with unknown
    association, the ``revision`` that made it (else None)."""

    run: SmoothedRun
    problem: SmoothingProblem
    revision: Revision | None

    def decisions(self) -> dict[str, int]:
        """What the smoother did, for a report: linearisations, observations used and, with a revision,
        landmarks merged, removed and created, observations adopted, and those left as outliers or
        unassigned."""
        values = {"smoother_iterations": self.run.iterations, "observations_used": len(self.problem.z)}
        if self.revision is not None:
            values.update(
                {
                    "landmarks_merged_by_smoother": len(self.revision.merged),
                    "landmarks_removed_by_smoother": len(self.revision.removed),
                    "landmarks_created_by_smoother": len(self.revision.created),
                    "observations_adopted_by_smoother": self.revision.adopted,
                    "observations_outliers": self.revision.outliers,
                    "observations_unassigned": self.revision.unassigned,
                }
            )
        return values

    def pose_at(self, stamp_ns: int) -> Transform2D | None:
        """The smoothed ``T_map_body`` at a pose stamp of the problem (a scan's), None at any other time."""
        stamps = self.problem.pose_t_ns
        k = int(np.searchsorted(stamps, stamp_ns))
        if k == len(stamps) or stamps[k] != stamp_ns:
            return None
        return Transform2D(*self.run.poses[k])

    def landmark_map(self, frame_id: str, stamp_ns: int, parameters: dict | None = None) -> LandmarkMap:
        """The smoothed map as :class:`turtlelib.mapping.landmark_map.LandmarkMap` (ids ascending, the joint
        covariance of the information matrix), as :meth:`EkfSlam.landmark_map` gives the filter's."""
        run = self.run
        return LandmarkMap(
            frame_id=frame_id,
            stamp_ns=stamp_ns,
            ids=run.landmark_ids,
            xy=run.landmarks,
            covariance=run.landmark_covariance,
            parameters={} if parameters is None else parameters,
        )


def smooth_history(
    history: RunHistory,
    motion: MotionModel,
    signal: MotionSignal,
    slam_config: SlamConfig,
    landmark_ids: NDArray[np.int64],
    landmarks: NDArray[np.float64],
    revise: bool,
    config: SmootherConfig | None = None,
    revision: RevisionConfig | None = None,
    loops: Sequence[LoopEdge] = (),
    extra_t_ns: Sequence[int] = (),
    removed_ids: Sequence[int] = (),
) -> SmoothingOutcome:
    """The run of ``history`` smoothed with the filter's ``motion`` model (its samples read through
    ``signal``), its ``slam_config`` and its final map (``landmark_ids`` (n,), ``landmarks`` (n, 2)), as the
    module docstring says; ``revise`` for unknown association; ``loops`` closed during the run (their
    factors join the problem's), ``extra_t_ns`` further stamps to give a pose and ``removed_ids`` the
    landmarks the filter removed as gone, whose observations the revision leaves out
    (:func:`~turtlelib.smoothing.history_problem.problem_from_history`). The
    landmarks of the map that the history never saw (before a relocalization) have no factor and are left
    out of the smoothed map. ValueError for a history that has not started, or a problem without a unique
    optimum."""
    # only the landmarks the history saw (a relocalization starts it again): the others have no factor
    seen = np.isin(landmark_ids, history.observed_landmarks())
    landmark_ids, landmarks = landmark_ids[seen], landmarks[seen]
    problem, poses, rescale, unassigned = problem_from_history(
        history, motion, signal, slam_config, landmark_ids, loops, extra_t_ns, removed_ids
    )
    smoother = Smoother(slam_config.measurement_model(), config)
    if not revise:
        return SmoothingOutcome(smoother.solve(problem, poses, landmark_ids, landmarks), problem, None)
    revised = revise_associations(
        smoother, problem, poses, landmark_ids, landmarks, rescale, revision, unassigned
    )
    return SmoothingOutcome(revised.run, revised.problem, revised)
