"""Mapped landmarks that are gone, removed: the LiDAR sees through where they were.

A confirmed landmark stays in the map for ever unless something takes it out: a chair leg moved after it
was confirmed, another robot that stood still long enough to be mapped, furniture moved between two mapping
sessions. Nearby detections may then be associated with it and pull the pose. The negative evidence is in
the range scan itself (:mod:`turtlelib.sensing.beam_evidence`): at the scan's stamp the filter predicts
each confirmed landmark's range and bearing with their covariance ``H P H^T``
(:meth:`~turtlelib.estimation.ekf_slam.EkfSlam.predicted_landmarks`), carried into the scan's frame, and
the beams that surely meet a post of ``see_through_radius`` there either pass beyond its far side (seen
through), return at it (present), or say nothing (occluded, out of reach or view, a dropout).

Bookkeeping per landmark id: a scan that sees it through counts one (the robot's position at the first
such scan kept); a scan where it is present starts the count again; a scan that says nothing leaves the
count as it is. At ``see_through_scans`` counted scans, once the robot has moved ``see_through_travel``
since the first of them (a moment's glitch, or a robot parked beside a dark post, never removes one), the
landmark is marginalised out of the filter (:meth:`~turtlelib.estimation.ekf_slam.EkfSlam.remove_landmark`,
the path a tentative landmark's timeout takes). A scan in which several landmarks are seen through and
fewer are present counts for none: many posts gone at once is a pose gone wrong (slip, a bump), not a
changed world. A relocalization or reset starts every count again. ``see_through_scans = 0`` disables it.

:class:`LandmarkRemoval` is a :class:`~turtlelib.estimation.scan_steps.ScanStep` attached to the timeline,
so each scan is judged with the filter at the scan's stamp, in stamp order with the landmark updates. It
never changes the filter otherwise: with no landmark seen through, the run is the same as without it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..geometry.se2 import Transform2D
from ..sensing.beam_evidence import Evidence, post_evidence
from ..sensing.range_scan import RangeScan
from ..util.validation import integer, non_negative, positive, store
from .ekf_slam import EkfSlam
from .scan_steps import Outcome, StepResult


@dataclass(frozen=True)
class LandmarkRemovalConfig:
    """Parameters of :class:`LandmarkRemoval` (the slam node's ROS parameters; ValueError for invalid ones):

    * ``see_through_scans`` (int >= 0): scans that must see a confirmed landmark through (none of them in
      between seeing it present) before it is removed; 0 disables removal.
    * ``see_through_sigmas`` (> 0): standard deviations of the margins: a beam must pass this many beyond
      the post's far side (LiDAR range noise and the predicted range's uncertainty), and lie this many
      (bearing uncertainty) inside the post's silhouette.
    * ``see_through_radius`` (m, > 0): the radius every mapped landmark is taken to have; no larger than the
      smallest real post (the detector's ``min_radius``), or beams beside a thinner post would count as
      seen through.
    * ``see_through_travel`` (m, >= 0): how far the robot must have moved between the first and the last
      of those scans.
    * ``see_through_range_std`` (m, > 0): the LiDAR's range noise (one standard deviation).
    """

    see_through_scans: int = 5
    see_through_sigmas: float = 3.0
    see_through_radius: float = 0.02
    see_through_travel: float = 0.1
    see_through_range_std: float = 0.01

    def __post_init__(self) -> None:
        store(self, ("see_through_scans",), partial(integer, minimum=0))
        store(self, ("see_through_sigmas", "see_through_radius", "see_through_range_std"), positive)
        store(self, ("see_through_travel",), non_negative)

    @property
    def enabled(self) -> bool:
        return self.see_through_scans > 0


class MountedScan(NamedTuple):
    """One scan and the pose of its frame in the body frame, ``T_body_scan``."""

    scan: RangeScan
    T_body_scan: Transform2D


class Removal(NamedTuple):
    """A landmark removed: its id, its last estimate ``xy`` (m, map frame), at ``stamp_ns``, after ``scans``
    scans that saw through it."""

    landmark_id: int
    xy: NDArray[np.float64]
    stamp_ns: int
    scans: int


class LandmarkRemoval:
    """The step that removes mapped landmarks the LiDAR sees through (module docstring); ``removals`` lists
    every landmark it removed, oldest first."""

    def __init__(self, config: LandmarkRemovalConfig) -> None:
        self.config = config
        # landmark id -> (scans that saw it through, the robot's position (2,) at the first)
        self._counts: dict[int, tuple[int, NDArray[np.float64]]] = {}
        self.removals: list[Removal] = []

    def apply(self, slam: EkfSlam, payload: MountedScan, stamp_ns: int) -> StepResult:
        """Judge the confirmed landmarks against ``payload`` with the filter at ``stamp_ns``; remove the ones
        due. ``APPLIED`` (the filter changed only by removals)."""
        config = self.config
        if not config.enabled:
            return StepResult(Outcome.APPLIED)
        ids, z_hat, covariance = slam.predicted_landmarks()
        if len(ids) == 0:
            return StepResult(Outcome.APPLIED)
        scan, T_body_scan = payload
        p_scan, covariance_scan = _in_scan_frame(
            z_hat, covariance, T_body_scan.inverse() @ slam.config.T_body_sensor
        )
        evidence = post_evidence(
            scan,
            p_scan,
            covariance_scan,
            config.see_through_radius,
            config.see_through_range_std,
            config.see_through_sigmas,
        )
        present = set(ids[evidence == Evidence.PRESENT].tolist())
        seen_through = ids[evidence == Evidence.SEEN_THROUGH].tolist()
        held = set(ids.tolist())
        self._counts = {i: count for i, count in self._counts.items() if i in held and i not in present}
        if len(seen_through) > 1 and len(present) < len(seen_through):
            return StepResult(Outcome.APPLIED)  # many posts gone at once: the pose, not the world
        robot_xy = slam.pose.translation
        for landmark_id in seen_through:
            scans, first_xy = self._counts.get(landmark_id, (0, robot_xy))
            scans += 1
            self._counts[landmark_id] = (scans, first_xy)
            travelled = float(np.hypot(*(robot_xy - first_xy)))
            if scans >= config.see_through_scans and travelled >= config.see_through_travel:
                xy, _ = slam.landmark_estimate(landmark_id)
                slam.remove_landmark(landmark_id)
                del self._counts[landmark_id]
                self.removals.append(Removal(landmark_id, xy, stamp_ns, scans))
        return StepResult(Outcome.APPLIED)

    def relocalized(self, T_map_body: Transform2D) -> None:
        """The pose was set from outside: every count starts again (a reset's ids are new ones)."""
        self._counts.clear()


def _in_scan_frame(
    z_hat: NDArray[np.float64], covariance: NDArray[np.float64], T_scan_sensor: Transform2D
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Range-bearing predictions ``z_hat`` (n, 2) in the sensor frame with covariance (n, 2, 2) as points
    (n, 2) in the scan frame with their covariance (n, 2, 2)::

        p_sensor = r [cos b, sin b],   J = [[cos b, -r sin b], [sin b, r cos b]],   Sigma_p = J Sigma_z J^T
        p_scan = T_scan_sensor p_sensor,   Sigma_scan = R Sigma_p R^T
    """
    r, b = z_hat[:, 0], z_hat[:, 1]
    c, s = np.cos(b), np.sin(b)
    J = np.stack([np.stack([c, -r * s], axis=1), np.stack([s, r * c], axis=1)], axis=1)
    R = T_scan_sensor.rotation_matrix()
    JR = R @ J
    p_sensor = np.stack([r * c, r * s], axis=1)
    return p_sensor @ R.T + T_scan_sensor.translation, JR @ covariance @ JR.transpose(0, 2, 1)
