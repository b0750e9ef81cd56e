"""Time alignment of motion samples and stamped observations for
:class:`turtlelib.estimation.ekf_slam.EkfSlam`.

Motion arrives as samples ``(t_k, s_k)`` of a signal (wheel angles at 20 Hz on a Burger, odometry poses,
velocity commands; :mod:`turtlelib.motion.motion_signals` says how a signal becomes motion-model inputs); an
observation carries the stamp ``t_o`` of the scan it came from and reaches the filter later (detection,
transport), possibly after the next motion samples. An observation must be applied with the filter at
``t_o``, not at whatever pose is current, so the filter runs a little behind the newest sample ``t_w``.
Times are integer nanoseconds.

* Between samples the signal's value at any ``t`` in ``[t_(k-1), t_k]`` is the signal's
  ``at(s_(k-1), s_k, (t - t_(k-1)) / (t_k - t_(k-1)))`` (linear for wheel angles, held for rates).
* The filter is at time ``t_f`` with signal value ``s_f``; bringing it to ``t >= t_f`` is one prediction
  per sample interval crossed (to each sample in ``(t_f, t]``, then to the value at ``t``): within an
  interval the motion is one constant-twist arc, and the process noise of an arc does not depend on how it
  is split (:mod:`turtlelib.motion.arc_noise`). So where the motion is split into predictions (observation
  stamps, ``max_observation_delay``) does not matter.
* When a motion sample arrives, every waiting observation with ``t_o <= t_w`` is applied in stamp order,
  each after bringing the filter to ``t_o``; then the filter is brought to ``t_w - max_observation_delay``
  (observations may arrive up to that late). First (``check_motion``) the motion model must take the
  motion from the previous sample to this one and the motion the sample starts (a held rate is the input
  of the interval after its sample), held as long as the interval before it (its ``check``): a sample
  whose motion the model refuses (a corrupt reading) is refused and changes nothing, so the samples after
  it continue from the one before.
* An observation with ``t_o <= t_w`` is applied at once (filter brought to ``t_o``); one newer than every
  motion sample waits for the samples that reach it; one older than ``t_f`` came too late and is refused
  (ValueError): applying it at a later pose would be wrong.
* Only observations that can be applied wait: one stamped more than ``max_observation_lead`` after
  ``t_w`` is refused (a scan is processed after it was taken, so the motion samples of its time are
  normally there already), and when ``max_pending_observations`` wait, a newer observation is refused
  while an older one takes the place of the newest waiting one (the one furthest from ever being
  reached), so a few bad stamps can never block the queue.
* The pose at ``t_w`` (what a node publishes) is the filter's pose moved on by the motion from ``t_f`` to
  ``t_w``, interval by interval, with its covariance propagated alongside
  (:meth:`EkfSlam.propagated_pose_along`), without changing the filter; the pose at any ``t`` in
  ``[t_f, t_w]`` (where a scan is placed in the occupancy grid) likewise (:meth:`SlamTimeline.pose_at`).

Lifecycle
---------
What acts on a measurement at its stamp is a :class:`~turtlelib.estimation.scan_steps.ScanStep`: the
landmark observations go to ``step`` (the plain update by default, slip recovery on a robot), and any
other pose source (a scan registration, a pose measurement) is attached with its own step
(:meth:`SlamTimeline.attach`) and queues its measurements with :meth:`SlamTimeline.add`: they wait for the
motion and are applied in stamp order with the landmark observations. Each applied measurement gives a
:class:`ScanResult` that says what happened (applied, held, relocalized). :meth:`SlamTimeline.reset` and
:meth:`SlamTimeline.relocalize` set the filter's pose from outside and reach everything that depends on
it: every step, the kept history (started again) and the listeners (:meth:`SlamTimeline.listen`:
``cleared`` at a reset; every applied measurement's posterior pose at its stamp goes to ``corrected``).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass
from functools import partial
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..geometry.se2 import Transform2D
from ..mapping.landmark_map import LandmarkMap
from ..motion.motion_signals import MotionSignal, Sample, signal_pieces, timed_sample
from ..util.timebase import NS_PER_S
from ..util.validation import integer, non_negative, positive, store
from .ekf_slam import Association, EkfSlam
from .run_history import RunHistory
from .scan_steps import FilterUpdate, Outcome, PoseListener, ScanStep


@dataclass(frozen=True)
class TimelineConfig:
    """``max_observation_delay`` (s, finite, >= 0): how late an observation may arrive after the motion
    samples of its time; ``max_observation_lead`` (s, > 0): how far past the newest motion sample an
    observation may be stamped and still wait for motion; ``max_pending_observations`` (int >= 1):
    observations that may wait for motion samples. Invalid values raise ValueError."""

    max_observation_delay: float = 0.25
    max_observation_lead: float = 1.0
    max_pending_observations: int = 20

    def __post_init__(self) -> None:
        store(self, ("max_observation_delay",), non_negative)
        store(self, ("max_observation_lead",), positive)
        store(self, ("max_pending_observations",), partial(integer, minimum=1))


class ScanResult(NamedTuple):
    """A measurement the timeline applied: its stamp ``t_ns``, the step's ``association`` (landmark
    observations; None for a measurement of another kind) and what happened (``outcome``)."""

    t_ns: int
    association: Association | None
    outcome: Outcome


@dataclass(frozen=True, eq=False)
class _Pending:
    """A measurement waiting for the motion to reach ``t_ns``: ``payload`` for ``step``."""

    t_ns: int
    step: ScanStep
    payload: Any


class SlamTimeline:
    """Feeds an :class:`EkfSlam` motion samples of ``signal`` and stamped measurements in time order
    (module docstring); ``signal`` must give the inputs of the filter's motion model.

    ``add_motion``, ``add_observations`` and ``add`` return the measurements applied by the call as
    :class:`ScanResult`, oldest first. ``step`` acts on the landmark observations
    (:class:`~turtlelib.estimation.scan_steps.FilterUpdate` by default;
    :class:`turtlelib.estimation.slip_recovery.SlipRecovery`: motion the LiDAR contradicts is detected and
    the filter relocalized against its map). With ``keep_track`` the timeline also keeps the filter's pose
    after every prediction, for :meth:`take_track` (offline runs: it grows until taken). With
    ``check_motion`` (default) a motion sample the filter's model refuses is refused before anything
    changes (:meth:`add_motion`); without, the check's cost per sample (a few microseconds, about 10 % of
    an offline run) is saved, and a refused sample leaves the filter where the refusal stopped it: for runs
    that end on the first error (recorded data). With ``keep_history`` the timeline records the run for a
    smoother (:attr:`history`, :class:`turtlelib.estimation.run_history.RunHistory`; it grows with the
    run), starting again at each :meth:`restart`, :meth:`reset`, :meth:`relocalize` and relocalization by a
    step.
    """

    def __init__(
        self,
        slam: EkfSlam,
        signal: MotionSignal,
        config: TimelineConfig | None = None,
        *,
        step: ScanStep | None = None,
        keep_track: bool = False,
        check_motion: bool = True,
        keep_history: bool = False,
    ) -> None:
        self.slam = slam
        self.step: ScanStep = FilterUpdate() if step is None else step
        self._steps: list[ScanStep] = [self.step]
        self._listeners: list[PoseListener] = []
        self.signal = signal
        self._check_motion = check_motion
        self.config = TimelineConfig() if config is None else config
        self._delay_ns = round(self.config.max_observation_delay * NS_PER_S)
        self._lead_ns = round(self.config.max_observation_lead * NS_PER_S)
        # motion samples (t_ns, s) from the last one at or before t_f, times ascending
        self._times: list[int] = []
        self._samples: list[Sample] = []
        self._t_f: int | None = None
        self._s_f: Sample = ()
        self._pending: list[_Pending] = []
        self._track: list[tuple[NDArray[np.int64], NDArray[np.float64]]] | None = [] if keep_track else None
        self.history: RunHistory | None = RunHistory() if keep_history else None

    @property
    def filter_time_ns(self) -> int | None:
        """``t_f``, the time the filter is at (None before the first motion sample)."""
        return self._t_f

    @property
    def latest_time_ns(self) -> int | None:
        """``t_w``, the time of the newest motion sample (None before the first)."""
        return self._times[-1] if self._times else None

    @property
    def pending_count(self) -> int:
        """Observations waiting for motion samples that reach their time."""
        return len(self._pending)

    def attach(self, step: ScanStep) -> ScanStep:
        """Attach another step (a second pose source) for :meth:`add`; it hears every relocalization."""
        self._steps.append(step)
        return step

    def listen(self, listener: PoseListener) -> None:
        """Tell ``listener`` each applied measurement's posterior pose and every reset (module docstring)."""
        self._listeners.append(listener)

    def add_motion(self, t_ns: int, sample: ArrayLike) -> list[ScanResult]:
        """A motion sample: the signal's value ``sample`` at ``t_ns``. The first only starts the timeline.

        ValueError (nothing changed) for non-finite values, a sample of another length than the first, a
        time earlier than the newest sample, or (``check_motion``) a motion the filter's model refuses:
        the one from the newest sample to this one, or the one this sample starts, held as long as that
        interval (at least 1 ns). The predictions take pieces of these motions (split at observation stamps),
        each a part of a motion the model took: a shorter arc at the same rates, or between two values it
        took.
        """
        t_ns, sample = self._checked_sample(t_ns, sample)
        t_w = self.latest_time_ns
        if t_w is None:
            self._times, self._samples = [t_ns], [sample]
            self._t_f, self._s_f = t_ns, sample
            self._begin_history(t_ns, sample)
            return []
        if t_ns < t_w:
            raise ValueError(f"time went backwards: motion sample at {t_ns} ns after one at {t_w} ns")
        if self._check_motion:
            self._check(t_w, self._samples[-1], t_ns, sample)
        released = [o.t_ns for o in self._pending if o.t_ns <= t_ns]
        self._times.append(t_ns)
        self._samples.append(sample)
        if self.history is not None:
            self.history.add_motion(t_ns, sample)
        applied = [self._apply(self._pending.pop(0)) for _ in released]
        if t_ns - self._delay_ns > self._t_f:
            self._advance_to(t_ns - self._delay_ns)
        return applied

    def add_observations(
        self, t_ns: int, z: ArrayLike, R: ArrayLike | None = None, ids: ArrayLike | None = None
    ) -> list[ScanResult]:
        """One scan's observations ``z`` (K, 2) [range_m, bearing_rad] stamped ``t_ns``, with noise ``R``
        (K, 2, 2) (default from the filter's config) and, for known association, landmark ``ids`` (K,).

        Applied now if motion samples reach ``t_ns``, else queued. ValueError (nothing changed) for invalid
        observations (also: with ids when the filter or the waiting observations run without, or the
        reverse), before the first motion sample, for a stale stamp (``t_ns < t_f``), one too far ahead
        (``t_ns > t_w + max_observation_lead``), or one newer than every waiting observation when
        ``max_pending_observations`` are already waiting (an older one displaces the newest waiting one).
        """
        t_ns = integer("observation stamp (ns)", t_ns)
        checked = self.slam.checked_observations(z, R, ids)
        waiting = [pending.payload for pending in self._pending if pending.step is self.step]
        if waiting and (waiting[0].ids is None) != (checked.ids is None):
            # the first update fixes the filter's association mode: the waiting ones would be refused
            raise ValueError("observations with and without ids cannot wait together (one association mode)")
        return self.add(t_ns, self.step, checked)

    def add(self, t_ns: int, step: ScanStep, payload: Any) -> list[ScanResult]:
        """A measurement ``payload`` stamped ``t_ns`` for ``step`` (:attr:`step` or one attached): applied
        now if motion samples reach ``t_ns``, else queued. ValueError (nothing changed) for a step that is
        not attached, before the first motion sample, for a stale stamp (``t_ns < t_f``), one too far ahead
        (``t_ns > t_w + max_observation_lead``), or one newer than every waiting measurement when
        ``max_pending_observations`` are already waiting (an older one displaces the newest waiting one)."""
        t_ns = integer("measurement stamp (ns)", t_ns)
        if not any(step is attached for attached in self._steps):
            raise ValueError("the step is not attached to this timeline (attach it first)")
        if self._t_f is None:
            raise ValueError("no motion sample yet: an observation cannot be placed in time")
        if t_ns < self._t_f:
            raise ValueError(
                f"stale observation: stamped {t_ns} ns, the filter is already at {self._t_f} ns "
                f"(more than max_observation_delay = {self.config.max_observation_delay} s late)"
            )
        t_w = self._times[-1]
        if t_ns > t_w + self._lead_ns:
            raise ValueError(
                f"observation stamped {(t_ns - t_w) * 1e-9:.3f} s after the newest motion sample (more than "
                f"max_observation_lead = {self.config.max_observation_lead} s): no motion may ever reach it"
            )
        observation = _Pending(t_ns, step, payload)
        if t_ns <= t_w:
            return [self._apply(observation)]
        if len(self._pending) >= self.config.max_pending_observations:
            if t_ns >= self._pending[-1].t_ns:
                raise ValueError(
                    f"{len(self._pending)} observations already wait for motion samples past {t_w} ns"
                )
            self._pending.pop()  # the newest waits longest: the older observation is the more useful
        bisect.insort(self._pending, observation, key=lambda o: o.t_ns)
        return []

    def restart(self, t_ns: int, sample: ArrayLike) -> None:
        """Take this motion sample as the new start of time, keeping the filter's estimate (for a clock that
        jumped back: a restarted simulator or a looped recording). The filter is first brought to the newest
        sample, so no motion is lost (as far as it can be: the estimate stops before a sample whose input
        the motion model refuses, e.g. a corrupt reading); observations still waiting are dropped.
        """
        t_ns, sample = self._checked_sample(t_ns, sample)
        if self._t_f is not None:
            try:
                self._advance_to(self._times[-1])
            except ValueError:
                pass  # that motion is lost; the estimate is kept where the last valid input left it
        self._times, self._samples = [t_ns], [sample]
        self._t_f, self._s_f = t_ns, sample
        self._pending.clear()
        self._begin_history(t_ns, sample)

    def reset(self, T_map_body: Transform2D | None = None, landmark_map: LandmarkMap | None = None) -> None:
        """Start the run again at ``T_map_body`` (default identity; covariance from the filter's config)
        with no map, or with ``landmark_map`` (:meth:`EkfSlam.load_map`): the filter, every step, the
        history and the listeners (``cleared``) all start again; the time base is kept."""
        if landmark_map is None:
            self.slam.reset(T_map_body)
        else:
            self.slam.load_map(landmark_map, T_map_body)
        self._moved_from_outside()
        for listener in self._listeners:
            listener.cleared()

    def relocalize(
        self, T_map_body: Transform2D, pose_covariance: ArrayLike, *, explained: bool = False
    ) -> None:
        """The filter's pose becomes ``T_map_body`` with ``pose_covariance`` (3, 3), independent of the map,
        which is kept (:meth:`EkfSlam.reset` with ``keep_map``): every step hears it and the history starts
        again, unless the move is ``explained`` by factors a smoother of the history is given (a loop
        closure's: :func:`turtlelib.smoothing.run_smoothing.smooth_history`'s ``loops``), so that the
        smoother still sees the run before it."""
        self.slam.reset(T_map_body, pose_covariance, keep_map=True)
        self._moved_from_outside(keep_history=explained)

    def pose_at(self, t_ns: int) -> Transform2D | None:
        """``T_map_body`` at ``t_ns`` in ``[t_f, t_w]``: the filter moved on by the motion from ``t_f``, one
        step per sample interval (the filter is unchanged); None outside that span."""
        if self._t_f is None or not self._t_f <= t_ns <= self._times[-1]:
            return None
        pieces = signal_pieces(self.signal, self._times, self._samples, self._t_f, self._s_f, t_ns)
        return self.slam.propagated_pose_along([u for _, _, u in pieces if u is not None])[0]

    def _moved_from_outside(self, by: ScanStep | None = None, keep_history: bool = False) -> None:
        """The filter's pose was set from outside the steps (or by the step ``by``): the other steps hear
        it, the history starts again (unless ``keep_history``)."""
        for step in self._steps:
            if step is not by:
                step.relocalized(self.slam.pose)
        if not keep_history:
            self._break_history()

    def _break_history(self) -> None:
        """Start the kept history again from the filter as it is now (at ``t_f``); nothing without
        ``keep_history`` or before the first motion sample."""
        if self._t_f is None or self.history is None:
            return
        self._begin_history(self._t_f, self._s_f)
        for t_ns, sample in zip(self._times, self._samples, strict=True):
            if t_ns > self._t_f:
                self.history.add_motion(t_ns, sample)

    def take_track(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """The filter's pose mean after every prediction since the last call, as stamps (m,) (ns) and poses
        (m, 3) ``T_map_body``, oldest first (ValueError unless made with ``keep_track``)."""
        if self._track is None:
            raise ValueError("this timeline keeps no track (keep_track=False)")
        stamps = np.concatenate([np.zeros(0, dtype=np.int64), *(t for t, _ in self._track)])
        poses = np.concatenate([np.zeros((0, 3)), *(p for _, p in self._track)])
        self._track.clear()
        return stamps, poses

    def latest_pose(self) -> tuple[Transform2D, NDArray[np.float64]]:
        """``T_map_body`` at ``t_w`` and its covariance (3, 3): the filter moved on by the motion since
        ``t_f``, one step per sample interval as :meth:`_advance_to` would (the filter is unchanged).
        ValueError before the first motion sample."""
        if self._t_f is None:
            raise ValueError("no motion sample yet")
        inputs = []
        t_from, s_from = self._t_f, self._s_f
        for k in range(bisect.bisect_right(self._times, self._t_f), len(self._times)):
            u = self.signal.input(s_from, self._samples[k], self._times[k] - t_from)
            if u is not None:
                inputs.append(u)
            t_from, s_from = self._times[k], self._samples[k]
        return self.slam.propagated_pose_along(inputs)

    # --- helpers -----------------------------------------------------------------------------------------

    def _check(self, t_w: int, s_w: Sample, t_ns: int, sample: Sample) -> None:
        """ValueError if the motion model refuses the motion from ``(t_w, s_w)`` to ``(t_ns, sample)`` or the
        one ``sample`` starts, held as long as that interval: the predictions take pieces of these, which a
        model that takes the whole takes too."""
        for u in (
            self.signal.input(s_w, sample, t_ns - t_w),
            self.signal.input(sample, sample, max(t_ns - t_w, 1)),
        ):
            if u is not None:
                self.slam.motion.check(u)

    def _checked_sample(self, t_ns: object, sample: ArrayLike) -> tuple[int, Sample]:
        """``(t_ns, sample)`` validated (:func:`~turtlelib.motion.motion_signals.timed_sample`), as many
        values as the first sample's."""
        return timed_sample(t_ns, sample, len(self._samples[0]) if self._samples else None)

    def _apply(self, pending: _Pending) -> ScanResult:
        """Bring the filter to the measurement's stamp, let its step act, and tell whom it concerns."""
        t_ns = pending.t_ns
        self._advance_to(t_ns)
        result = pending.step.apply(self.slam, pending.payload, t_ns)
        association = result.association
        if result.outcome is Outcome.RELOCALIZED:
            self._moved_from_outside(by=pending.step)
        elif self.history is not None and association is not None:
            z, R, _ = pending.payload
            self.history.add_scan(t_ns, z, R, association.landmark_ids, self.slam.pose.as_array())
        if result.outcome is not Outcome.HELD:
            for listener in self._listeners:
                listener.corrected(t_ns, self.slam.pose)
        return ScanResult(t_ns, association, result.outcome)

    def _begin_history(self, t_ns: int, sample: Sample) -> None:
        if self.history is not None:
            self.history.begin(t_ns, sample, self.slam.pose.as_array(), self.slam.pose_covariance)

    def _advance_to(self, t_ns: int) -> None:
        """Predict the filter from ``t_f`` to ``t_ns`` (``t_f <= t_ns <= t_w``) and drop older samples.

        One prediction per sample interval: the motion (the arc's twist) changes only at the samples, and
        one prediction over two intervals would follow a different arc than the robot did. They are
        handed to the filter together (:meth:`EkfSlam.predict_along`); if it refuses them, one by one, so
        that the filter stops right before the refused input.
        """
        pieces = signal_pieces(self.signal, self._times, self._samples, self._t_f, self._s_f, t_ns)
        stamps = [t_to for t_to, _, u in pieces if u is not None]
        inputs = [u for _, _, u in pieces if u is not None]
        try:
            self._keep_track(stamps, self.slam.predict_along(inputs))
        except ValueError:
            # one by one: the refused input raises again, with the filter right before it
            poses = []
            try:
                for t_to, s_to, u in pieces:
                    self._predict_to(t_to, s_to)
                    if u is not None:
                        poses.append(self.slam.pose.as_array())
            finally:
                self._keep_track(stamps[: len(poses)], np.array(poses).reshape(-1, 3))
        self._t_f, self._s_f = pieces[-1][:2]
        # keep the last sample at or before t_f: interpolation from t_f needs it
        first_kept = bisect.bisect_right(self._times, t_ns) - 1
        if first_kept > 0:
            del self._times[:first_kept], self._samples[:first_kept]

    def _keep_track(self, stamps: list[int], poses: NDArray[np.float64]) -> None:
        if self._track is not None and len(stamps):
            self._track.append((np.array(stamps, dtype=np.int64), poses))

    def _predict_to(self, t_ns: int, sample: Sample) -> None:
        """One prediction with the input from ``(t_f, s_f)`` to ``(t_ns, sample)`` (none if no motion)."""
        u = self.signal.input(self._s_f, sample, t_ns - self._t_f)
        if u is not None:
            self.slam.predict(u)
        self._t_f, self._s_f = t_ns, sample
