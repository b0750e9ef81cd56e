"""Motion the LiDAR contradicts (wheel slip, bumps): detect it, report it, undo it against the map.

Why
---
The motion models take the wheels' word with a noise proportional to their travel. A slip event (the wheels
report a turn the body does not make) or a bump (the robot pushes against an obstacle, its wheels spinning)
breaks that model: the pose moves on by motion that never happened, far outside its covariance. Then every
observation of a mapped landmark lands outside the association gates, the filter dead-reckons on the wrong
pose, starts landmarks beside the true ones and never finds its way back. Two checks run on each scan's
detections ``p_k`` (body frame) before it reaches the filter.

Stall (:class:`StallDetector`): the wheels turn, the body stands still
--------------------------------------------------------------------
Against a reference scan (the last one whose detections moved as the wheels said, pose ``T_ref``): with
``M = T_ref^-1 T_hat`` the motion the wheels say the body made since (``T_ref`` follows the updates'
corrections of the filter's pose ``T_hat``, so ``M`` is the predictions' motion only), each detection
``p_k`` and its nearest reference detection ``q_k``, the body stood still while the wheels moved it when::

    |p_k - q_k| <= stall_tolerance   and   |M^-1 q_k - q_k| > 2 stall_tolerance    for every k

(no detection moved, and the motion would have moved each by more than twice as much), with two detections
at least (one standing still is also what circling around it looks like). Then the filter goes back to
``T_ref`` (:meth:`EkfSlam.reset` with ``keep_map``, its covariance kept), and stays there while the
stall lasts: a zero-velocity update. Detections that moved as the wheels said (``|p_k - M^-1 q_k| <=
stall_tolerance``), or a scene with nothing of the reference's, make their scan the reference.

Contradiction: the map puts the body elsewhere
----------------------------------------------
* ``n(T)``, the detections a pose ``T`` explains (:func:`turtlelib.estimation.map_alignment.explained`, within
  ``match_radius`` of a confirmed landmark), and ``T*`` the best rigid alignment of the detections with the
  map (:func:`turtlelib.estimation.map_alignment.align_to_map`; known association: the fit of the ids' pairs).
* Slip and bumps only ever take motion away from a wheel, so ``T*`` is searched within what the wheels
  reported since the last scan the map confirmed (``T_good``, two detections matched): with ``d`` the
  distance from ``p_good`` to ``p_hat``, a heading within ``|theta_hat - theta_good| + turn_per_m d +
  margin_rad`` of ``theta_hat`` (``turn_per_m``: the heading a lost wheel invents per metre of travel, ``2 /
  track_width`` for a differential drive whose one wheel spins in place) and a position within ``d (1 +
  that heading bound, at most pi) + margin_m`` of ``p_hat``, and no further than ``d + margin_m`` from
  ``p_good`` (slip only takes motion away: the body cannot be further from where the map last confirmed it
  than the wheels reported; a pose beyond is a false alignment on clutter, or a robot carried). A
  repetitive world (a grid of cylinders) has other alignments further away; these are never candidates
  while the map confirms the scans.
* A scan *contradicts the motion* when ``T*`` explains at least ``min_matches`` detections and two more than
  ``T_hat``, and lies outside ``T_hat``'s uncertainty: ``d^T (P_rr + Sigma*)^-1 d > chi2_3^-1(0.999)`` for
  ``d = [t* - t_hat, theta* (-) theta_hat]`` (``Sigma*`` the fit's covariance). It *agrees* when all its
  detections but one are explained by ``T_hat``, or no alignment explains more; otherwise it tells nothing
  (fewer than ``min_matches`` detections, no alignment within the search).

A contradicting scan is held (not fused: its detections would start landmarks beside the true ones), and so
is every scan that tells nothing while the episode lasts (at most ``MAX_EPISODE_S``). When
``confirm_scans`` contradicting scans' alignments agree with each other (the body moved from one ``T*`` to
the next by no more than the wheels reported between them, plus ``2 match_radius`` and
``AGREEMENT_SLACK_RAD``: slip only takes motion away), the filter is relocalized at the last ``T*`` with the
fit's covariance and no correlation with the map (:meth:`EkfSlam.reset` with ``keep_map``), and that scan
is fused from there. An agreeing scan ends the episode.

Report (:attr:`SlipRecovery.status`): ``ok``; ``warn`` while scans are held and for ``report_s`` after an
event (corrections of one cause at most ``EVENT_GAP_S`` apart), naming the cause (a correction that takes
back travel: "bump or stall"; one that takes back a heading the wheels invented: "wheel slip"); ``error``
while an event has lasted ``MAX_EPISODE_S`` or when ``REPEATS_FOR_ERROR`` events come within ``report_s``:
the robot is stuck or the wheels keep slipping.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from enum import Enum
from functools import partial

import numpy as np
from numpy.typing import NDArray
from scipy.special import chdtri

from ..geometry.se2 import Transform2D, normalize_angle
from ..util.timebase import NS_PER_S
from ..util.validation import integer, non_negative, positive, store
from .association_policies import REJECTED
from .ekf_slam import Association, CheckedObservations, EkfSlam
from .map_alignment import Alignment, Search, align_known, align_to_map, explained
from .scan_steps import Outcome, StepResult

# chi2_3^-1(0.999) (chdtri: the inverse of chi2's upper tail, without importing scipy.stats): a
# correction outside this is not the filter's own uncertainty
SIGNIFICANT_D2 = float(chdtri(3, 0.001))
# consecutive held alignments differ by no more than the reported motion, plus 2 match radii and this (rad)
AGREEMENT_SLACK_RAD = 0.1
# longest run of held scans (s) before the filter takes scans again unconfirmed; an event lasting this long is
# an error (the robot is stuck, or the wheels keep slipping)
MAX_EPISODE_S = 2.0
# a stall reference this old (s) gives way to a scan that pairs with none of its detections
STALE_REFERENCE_S = 1.0
# corrections at most this far apart (s) are one event
EVENT_GAP_S = 0.5
# events within report_s that make the status an error (the wheels keep slipping)
REPEATS_FOR_ERROR = 3


def lost_wheel_turn_per_m(track_width_m: float) -> float:
    """The heading (rad) a differential drive's wheels invent per metre of reported travel when one wheel
    spins in place: ``2 / track_width`` (its own travel turns the robot by ``travel / track_width``, and the
    reported travel is half the two wheels' sum)."""
    return 2.0 / track_width_m


@dataclass(frozen=True)
class SlipRecoveryConfig:
    """``slip_recovery`` (bool): detect and recover (else the filter runs as it is);
    ``slip_min_matches`` (int >= 2): detections an alignment with the map must explain;
    ``slip_match_radius`` (m, > 0): how near a mapped landmark a detection must fall to be explained;
    ``slip_confirm_scans`` (int >= 1): scans in a row that must contradict the motion the same way;
    ``slip_margin_m`` (m, >= 0), ``slip_margin_rad`` (rad, >= 0): how far the search reaches beyond the
    motion reported since the last confirmed scan; ``slip_turn_per_m`` (rad/m, >= 0): the heading slip can
    invent per metre of reported travel (:func:`lost_wheel_turn_per_m` of the robot; the Burger's by default);
    ``slip_stall_tolerance`` (m, > 0): how far a detection may move between scans of a robot standing
    still; ``slip_report_s`` (s, > 0): how long a correction
    stays in the status. Invalid values raise ValueError."""

    slip_recovery: bool = True
    slip_min_matches: int = 2
    slip_match_radius: float = 0.06
    slip_confirm_scans: int = 2
    slip_margin_m: float = 0.15
    slip_margin_rad: float = 0.15
    slip_turn_per_m: float = lost_wheel_turn_per_m(0.16)
    slip_stall_tolerance: float = 0.03
    slip_report_s: float = 5.0

    def __post_init__(self) -> None:
        if not isinstance(self.slip_recovery, bool):
            raise ValueError(f"slip_recovery must be a bool, got {self.slip_recovery!r}")
        store(self, ("slip_min_matches",), partial(integer, minimum=2))
        store(self, ("slip_confirm_scans",), partial(integer, minimum=1))
        store(self, ("slip_match_radius", "slip_stall_tolerance", "slip_report_s"), positive)
        store(self, ("slip_margin_m", "slip_margin_rad", "slip_turn_per_m"), non_negative)


class StallDetector:
    """Wheels that turn while the LiDAR sees the body stand still (module docstring), from each scan's
    filter pose ``T_hat`` and detections ``p_body`` (K, 2, body frame)."""

    def __init__(self, tolerance_m: float) -> None:
        self.tolerance_m = tolerance_m
        self._reference: tuple[Transform2D, NDArray[np.float64], int] | None = None
        # a stall was found and every detection has stood still since
        self._stalled = False

    def observe(self, T_hat: Transform2D, p_body: NDArray[np.float64], stamp_ns: int) -> Transform2D | None:
        """``T_ref`` if the body stood still since the reference scan while the wheels moved it, else None.

        Each detection is paired with the nearest reference detection ``q`` (it stood still) and with the
        nearest ``M^-1 q`` (it moved as the wheels said), within ``tolerance_m``; a pair decides only where
        the motion moves ``q`` by more than twice that. Every detection of two or more standing still: a
        stall (one detection standing still is also what driving around it looks like), which lasts while
        every detection stands still where the wheels moved it by half the tolerance or more. Some moving
        as the wheels said and none standing still: this scan (at ``stamp_ns``) becomes the reference, as
        does one with no pair at all once the reference is ``STALE_REFERENCE_S`` old (another scene; before
        that, a scan that pairs with nothing may be one taken while the wheels slip). Anything else (too
        little motion yet, noise) keeps the reference."""
        if len(p_body) == 0:
            return None
        if self._reference is None:
            self._reference = (T_hat, p_body, stamp_ns)
            return None
        T_ref, q, ref_ns = self._reference
        tolerance = self.tolerance_m
        # M^-1 q: the reference detections seen from where the wheels put the body
        predicted = (T_hat.inverse() @ T_ref) @ q
        shift = np.linalg.norm(predicted - q, axis=1)
        decides, budges = shift > 2.0 * tolerance, shift > 0.5 * tolerance
        still = np.linalg.norm(p_body[:, None, :] - q[None, :, :], axis=2)
        moving = np.linalg.norm(p_body[:, None, :] - predicted[None, :, :], axis=2)
        near_still, near_moving = still.argmin(axis=1), moving.argmin(axis=1)
        rows = np.arange(len(p_body))
        paired_still = still[rows, near_still] <= tolerance
        paired_moving = moving[rows, near_moving] <= tolerance
        stood = paired_still & decides[near_still]
        moved = paired_moving & decides[near_moving]
        # two points fix the body: one that stands still is also what circling around it looks like
        if (stood.all() and len(p_body) >= 2) or (
            self._stalled and (paired_still & budges[near_still]).all()
        ):
            self._stalled = True
            return T_ref
        self._stalled = False
        stale = stamp_ns - ref_ns > STALE_REFERENCE_S * NS_PER_S
        if (moved.any() and not stood.any()) or (stale and not (paired_still | paired_moving).any()):
            self._reference = (T_hat, p_body, stamp_ns)
        return None

    def correct(self, C_map: Transform2D) -> None:
        """The filter's pose was corrected by ``T' = C_map T`` (an update): so is the reference's."""
        if self._reference is not None:
            T_ref, q, ref_ns = self._reference
            self._reference = (C_map @ T_ref, q, ref_ns)

    def rebase(self, T_hat: Transform2D, p_body: NDArray[np.float64] | None, stamp_ns: int = 0) -> None:
        """The reference is this pose and its detections at ``stamp_ns`` (None: no reference): after a pose
        set from outside, or relocalized."""
        self._reference = None if p_body is None or len(p_body) == 0 else (T_hat, p_body, stamp_ns)
        self._stalled = False


@dataclass(frozen=True)
class SlipEvent:
    """Corrections of one cause on scans at most ``EVENT_GAP_S`` apart, from ``start_ns`` to ``stamp_ns``:
    their ``scans``, the ``correction`` they add up to (``T_hat^-1 T_new`` of each, composed in order, in the
    body frame) and their ``cause`` (``"wheel slip"`` or ``"bump or stall"``)."""

    start_ns: int
    stamp_ns: int
    scans: int
    correction: Transform2D
    cause: str

    def then(self, stamp_ns: int, correction: Transform2D) -> SlipEvent:
        """This event continued by a correction at ``stamp_ns``."""
        return replace(self, stamp_ns=stamp_ns, scans=self.scans + 1, correction=self.correction @ correction)


class _Evidence(Enum):
    AGREES = "agrees"
    NOTHING = "nothing"


@dataclass
class _Episode:
    """Scans held in a row since ``since_ns``: ``contradictions`` of them agreeing with each other, the last
    one's filter pose ``T_hat`` and alignment ``T_star`` (None before the first contradiction)."""

    since_ns: int
    contradictions: int = 0
    T_hat: Transform2D | None = None
    T_star: Transform2D | None = None

    @property
    def correction(self) -> Transform2D | None:
        """``T_hat^-1 T*``."""
        return None if self.T_hat is None or self.T_star is None else self.T_hat.inverse() @ self.T_star


@dataclass
class SlipStatus:
    """What :class:`SlipRecovery` reports: ``level`` (``"ok"``, ``"warn"``, ``"error"``), ``message``,
    and the totals ``held`` (scans not fused), ``relocalized`` (against the map) and ``stalls`` (scans of a
    stall), and ``last_correction`` (``T_hat^-1 T_new`` of the newest relocalization or stall, body frame;
    None before any)."""

    level: str = "ok"
    message: str = "the LiDAR agrees with the motion"
    held: int = 0
    relocalized: int = 0
    stalls: int = 0
    last_correction: Transform2D | None = None
    events: list[SlipEvent] = field(default_factory=list)


class SlipRecovery:
    """A :class:`~turtlelib.estimation.scan_steps.ScanStep`: updates an :class:`EkfSlam` with one scan's
    observations as :meth:`EkfSlam.update` does, after the stall and contradiction checks of the module
    docstring: a stalled body is put back where it stood, a scan that contradicts the motion is held, and
    the filter relocalized once ``slip_confirm_scans`` agree. With known association the pairs are the
    ids'. Switched off (``slip_recovery`` false) it is
    :class:`~turtlelib.estimation.scan_steps.FilterUpdate`."""

    def __init__(self, config: SlipRecoveryConfig | None = None) -> None:
        self.config = SlipRecoveryConfig() if config is None else config
        self._stall = StallDetector(self.config.slip_stall_tolerance)
        self._T_good: Transform2D | None = None
        self._episode: _Episode | None = None
        self._status = SlipStatus()
        self._now_ns = 0

    @property
    def status(self) -> SlipStatus:
        """The report at the newest scan's time (module docstring)."""
        return self._status

    def apply(self, slam: EkfSlam, observations: CheckedObservations, stamp_ns: int) -> StepResult:
        """Check, then fuse or hold one scan taken at ``stamp_ns`` (ns) (class docstring): the outcome is
        ``HELD`` (nothing fused), ``RELOCALIZED`` (the filter relocalized against the map, then the scan
        fused) or ``APPLIED``."""
        self._now_ns = stamp_ns
        if not self.config.slip_recovery:
            return StepResult(Outcome.APPLIED, slam.update(observations, stamp_ns=stamp_ns))
        relocalized_before = self._status.relocalized
        if self._T_good is None:
            self._T_good = slam.pose
        z, R, _ = observations
        usable = slam.measurement.usable(z)
        # the detections in the body frame and their position covariance G_z R G_z^T
        p_body, _, G_z = slam.measurement.inverse(np.zeros(3), z[usable])
        T_ref = self._stall.observe(slam.pose, p_body, stamp_ns)
        if T_ref is not None:
            self._status.stalls += 1
            self._correct(slam, T_ref, slam.pose_covariance, stamp_ns)
            self._episode = None
        else:
            position_cov = np.einsum("kij,kjl,kml->kim", G_z, R[usable], G_z)
            evidence = self._evidence(slam, observations.ids, usable, p_body, position_cov)
            if self._hold(slam, evidence, p_body, stamp_ns):
                self._status.held += 1
                self._report()
                count = len(z)
                held = Association(
                    np.full(count, REJECTED, dtype=np.int8), np.full(count, -1, dtype=np.int64)
                )
                return StepResult(Outcome.HELD, held)
        T_before = slam.pose
        association = slam.update(observations, stamp_ns=stamp_ns)
        # the reference moves with the update's correction: only the wheels' motion is compared
        self._stall.correct(slam.pose @ T_before.inverse())
        if association.counts["matched"] >= 2:
            self._T_good = slam.pose
        self._report()
        relocalized = self._status.relocalized != relocalized_before
        return StepResult(Outcome.RELOCALIZED if relocalized else Outcome.APPLIED, association)

    def relocalized(self, T_map_body: Transform2D) -> None:
        """Start over from a pose set from outside (a reset, an initial pose, another step's
        relocalization): nothing held, no stall reference, the search bounded by the motion from
        ``T_map_body``."""
        self._T_good, self._episode = T_map_body, None
        self._stall.rebase(T_map_body, None)

    # --- helpers -----------------------------------------------------------------------------------------

    def _hold(
        self, slam: EkfSlam, evidence: Alignment | _Evidence, p_body: NDArray[np.float64], stamp_ns: int
    ) -> bool:
        """Whether to hold this scan; relocalizes the filter when the episode's contradictions agree."""
        episode = self._episode
        if evidence is _Evidence.AGREES or (
            episode is not None and stamp_ns - episode.since_ns > round(MAX_EPISODE_S * NS_PER_S)
        ):
            self._episode = None
            return False
        if evidence is _Evidence.NOTHING:
            return episode is not None
        if episode is None:
            episode = self._episode = _Episode(stamp_ns)
        agrees = self._agree(episode, slam.pose, evidence.T_map_body)
        episode.contradictions = episode.contradictions + 1 if agrees else 1
        episode.T_hat, episode.T_star = slam.pose, evidence.T_map_body
        if episode.contradictions < self.config.slip_confirm_scans:
            return True
        self._status.relocalized += 1
        self._correct(slam, evidence.T_map_body, evidence.covariance, stamp_ns)
        self._stall.rebase(evidence.T_map_body, p_body, stamp_ns)
        self._episode = None
        return False

    def _evidence(
        self,
        slam: EkfSlam,
        ids: NDArray[np.int64] | None,
        usable: NDArray[np.bool_],
        p_body: NDArray[np.float64],
        position_cov: NDArray[np.float64],
    ) -> Alignment | _Evidence:
        """What this scan says about the filter's pose (module docstring): the alignment ``T*`` if it
        contradicts the motion, else whether it agrees or tells nothing."""
        config = self.config
        if len(p_body) < config.slip_min_matches or len(slam.landmark_ids) < 2:
            return _Evidence.NOTHING
        T_hat, landmarks = slam.pose, slam.landmarks
        radius = config.slip_match_radius
        if ids is None:
            n_hat = len(explained(T_hat, p_body, landmarks, radius))
            if len(p_body) - n_hat < 2:
                return _Evidence.AGREES
        T_good = self._T_good if self._T_good is not None else T_hat
        travel = float(np.linalg.norm(T_hat.translation - T_good.translation))
        # no heading is further than pi away: the bound (and the position's with it) stops growing there
        max_turn = min(
            abs(normalize_angle(T_hat.theta - T_good.theta))
            + config.slip_turn_per_m * travel
            + config.slip_margin_rad,
            math.pi,
        )
        max_offset = travel * (1.0 + max_turn) + config.slip_margin_m
        landmark_var = float(np.trace(slam.landmark_covariances, axis1=1, axis2=2).mean()) / 2.0
        variance = float(np.trace(position_cov, axis1=1, axis2=2).mean()) / 2.0 + landmark_var
        search = Search(T_hat, max_offset, max_turn, radius, variance)
        if ids is None:
            alignment = align_to_map(p_body, landmarks, search)
        else:
            n_hat, alignment = align_known(ids[usable], slam.landmark_ids, p_body, landmarks, search)
        # slip only takes motion away: the body is no further from the last confirmed pose than the wheels
        # reported (a pose beyond is a false alignment, or a robot carried: no slip explains it)
        beyond = np.linalg.norm(alignment.T_map_body.translation - T_good.translation) if alignment else 0.0
        if alignment is None or beyond > travel + config.slip_margin_m:
            return _Evidence.NOTHING
        if len(alignment.pairs) < max(config.slip_min_matches, n_hat + 2):
            return _Evidence.AGREES
        d = alignment.T_map_body.as_array() - T_hat.as_array()
        d[2] = normalize_angle(d[2])
        S = slam.pose_covariance + alignment.covariance
        if float(d @ np.linalg.solve(S, d)) <= SIGNIFICANT_D2:
            return _Evidence.AGREES
        return alignment

    def _agree(self, episode: _Episode, T_hat: Transform2D, T_star: Transform2D) -> bool:
        """Whether the body moved from the episode's last ``T*`` to ``T_star`` by no more than the wheels
        reported (its ``T_hat`` to ``T_hat``), to within the slack (False before its first ``T*``)."""
        if episode.T_hat is None or episode.T_star is None:
            return False
        reported = episode.T_hat.inverse() @ T_hat
        aligned = episode.T_star.inverse() @ T_star
        slack_m = 2.0 * self.config.slip_match_radius
        return (
            float(np.linalg.norm(aligned.translation))
            <= float(np.linalg.norm(reported.translation)) + slack_m
            and abs(aligned.theta) <= abs(reported.theta) + AGREEMENT_SLACK_RAD
        )

    def _correct(
        self, slam: EkfSlam, T_new: Transform2D, covariance: NDArray[np.float64], stamp_ns: int
    ) -> None:
        """The filter's pose becomes ``T_new`` with ``covariance`` (3, 3), independent of the map; the event
        recorded with its cause: a heading the wheels invented is wheel slip, a correction that takes back
        travel (runs against the motion reported since the last confirmed scan) a bump or stall."""
        correction = slam.pose.inverse() @ T_new
        motion = (self._T_good or slam.pose).inverse() @ slam.pose
        takes_back_travel = float(correction.translation @ motion.translation) < 0.0
        cause = "bump or stall" if takes_back_travel and abs(correction.theta) < 0.1 else "wheel slip"
        slam.reset(T_new, covariance, keep_map=True)
        self._T_good = T_new
        self._status.last_correction = correction
        events = self._status.events
        if events and events[-1].cause == cause and stamp_ns - events[-1].stamp_ns <= EVENT_GAP_S * NS_PER_S:
            events[-1] = events[-1].then(stamp_ns, correction)
        else:
            events.append(SlipEvent(stamp_ns, stamp_ns, 1, correction, cause))

    def _report(self) -> None:
        """The status at ``_now_ns``: recent events (an error when one lasts ``MAX_EPISODE_S`` or
        ``REPEATS_FOR_ERROR`` come within ``report_s``), held scans."""
        status, config = self._status, self.config
        since = self._now_ns - round(config.slip_report_s * NS_PER_S)
        recent = [event for event in status.events if event.stamp_ns >= since]
        del status.events[: len(status.events) - len(recent)]
        last = recent[-1] if recent else None
        if last is not None and (
            len(recent) >= REPEATS_FOR_ERROR or last.stamp_ns - last.start_ns >= MAX_EPISODE_S * NS_PER_S
        ):
            status.level = "error"
            span_s = (last.stamp_ns - recent[0].start_ns) / NS_PER_S
            causes = ", ".join(sorted({event.cause for event in recent}))
            status.message = (
                f"{causes}: the wheels keep reporting motion the LiDAR does not see ({len(recent)} events, "
                f"{sum(event.scans for event in recent)} corrections in {span_s:.1f} s): slipping, or stuck"
            )
        elif last is not None:
            c = last.correction
            status.level = "warn"
            status.message = (
                f"{last.cause}: the wheels reported motion the LiDAR did not see; pose corrected by "
                f"{np.hypot(c.x, c.y):.3f} m, {c.theta:+.3f} rad over {last.scans} scans"
            )
        elif self._episode is not None:
            status.level = "warn"
            c = self._episode.correction
            status.message = "the LiDAR contradicts the motion (slip or bump?): scans held" + (
                ""
                if c is None
                else f", the map says the pose is off by {np.hypot(c.x, c.y):.3f} m, {c.theta:+.3f} rad"
            )
        else:
            status.level, status.message = "ok", SlipStatus.message
