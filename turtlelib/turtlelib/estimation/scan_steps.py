"""What acts on a stamped measurement in :class:`turtlelib.estimation.slam_timeline.SlamTimeline`: one
small protocol, so that a second pose source plugs in beside the landmark update without touching the
filter or the timeline.

The timeline brings the filter to a measurement's stamp ``t`` (the motion predicted exactly to it), then
hands the measurement to the step it was queued for::

    result = step.apply(slam, payload, t)        # the filter at t, before and after

A step may update the filter (:meth:`EkfSlam.update` with landmark observations, :meth:`EkfSlam.update_pose`
with a pose measurement), hold the measurement (nothing fused), or relocalize the filter (its pose set
anew, the map kept); its :class:`StepResult` says which (:class:`Outcome`), so nothing has to be inferred
from counters. When the filter's pose is set from outside a step (a reset, an initial pose, another step's
relocalization) every step hears it through :meth:`ScanStep.relocalized`, to drop what it kept about the
old pose.

Listeners (:class:`PoseListener`, e.g. the occupancy grid's keyframes) hear the filter's posterior pose at
each applied measurement's stamp (``corrected``) and that the run started again (``cleared``).

Implementations: :class:`FilterUpdate` (the plain landmark update, the default) and
:class:`turtlelib.estimation.slip_recovery.SlipRecovery` (motion the LiDAR contradicts, undone against the
map).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import Any, Protocol

from ..geometry.se2 import Transform2D
from .ekf_slam import Association, CheckedObservations, EkfSlam


class Outcome(Enum):
    """What a step did with one measurement."""

    APPLIED = "applied"  # fused into the filter
    HELD = "held"  # not fused (its evidence contradicts the filter; kept out until it is confirmed)
    RELOCALIZED = "relocalized"  # the filter's pose was set anew (map kept), then the measurement fused


@dataclass(frozen=True)
class StepResult:
    """A step's ``outcome`` and, for landmark observations, their ``association`` (None for a measurement
    of another kind, e.g. a pose)."""

    outcome: Outcome
    association: Association | None = None


class ScanStep(Protocol):
    """What acts on a measurement at its stamp (module docstring)."""

    def apply(self, slam: EkfSlam, payload: Any, stamp_ns: int) -> StepResult:
        """Act on ``payload`` with the filter at ``stamp_ns`` (integer ns)."""
        ...

    def relocalized(self, T_map_body: Transform2D) -> None:
        """The filter's pose was set to ``T_map_body`` from outside this step."""
        ...


class PoseListener(Protocol):
    """Something placed at the filter's poses by stamp (module docstring)."""

    def corrected(self, t_ns: int, T_map_body: Transform2D) -> None:
        """The filter's posterior pose at ``t_ns``, right after a measurement stamped ``t_ns`` was fused."""
        ...

    def cleared(self) -> None:
        """The run started again without its map (a reset)."""
        ...


class FilterUpdate:
    """The plain landmark update: :meth:`EkfSlam.update` with one scan's checked observations."""

    def apply(self, slam: EkfSlam, payload: CheckedObservations, stamp_ns: int) -> StepResult:
        return StepResult(Outcome.APPLIED, slam.update(payload, stamp_ns=stamp_ns))

    def relocalized(self, T_map_body: Transform2D) -> None:
        """Nothing is kept between scans."""
