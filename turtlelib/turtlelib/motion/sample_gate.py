"""Plausibility of a stream of motion samples (wheel angles, odometry poses): which to take, which to
refuse, when a silence is bridged and when the source has restarted.

A sample ``(t_k, s_k)`` (integer ns; a tuple of values, e.g. the two wheel angles in rad) **continues** an
earlier sample ``(t_a, s_a)`` over at most ``gap`` when

* time moves forward without a jump: ``0 < t_k - t_a <= gap``, and
* no value moves faster than the source can: for every value ``i``
  ``|s_k,i - s_a,i| <= (1 + speed_margin) max_rate_i (t_k - t_a) + slack_i``
  (``max_rate`` e.g. the robot's maximum wheel speed, ``slack`` the sensor's resolution).

The gate holds the newest accepted sample ``a``. A new sample

* that continues ``a`` over ``max_sample_gap`` is **accepted**;
* that repeats ``a`` exactly (time and values) is a **duplicate**, ignored;
* otherwise is **refused** (one replayed or future-stamped message, a corrupt reading, the first sample
  after a silence), and kept as a candidate. Refused samples that continue each other form a candidate
  stream; a sample that continues ``a`` clears it, so a lone bad message among real ones is refused and
  forgotten. When the candidate stream ``c_1 ... c_n`` reaches ``n = restart_samples`` it is a real
  stream, and either the same source after a silence or a restarted one:

  - **bridged** when ``c_1`` continues ``a`` over ``max_bridged_gap`` and is not a return to the source's
    origin (below): the candidates are applied as motion on from ``a``, the silence ``a -> c_1`` as one
    step;
  - **restarted** otherwise (time went backwards: a restarted simulator, a looped recording; a change the
    rate bound cannot explain over the silence; encoders or odometry reset to zero): the stream starts
    again at ``c_1`` and the motion along the others follows.

Why a silence is bridged: the values are *integrals* of the motion (encoder angles, an odometry pose), so
across a silence the net change ``s_c1 - s_a`` is still measured; only the path's shape within it is
unknown. Any real motion over the silence fits the rate bound over it. Bridged, the motion model takes
``a -> c_1`` as one step with its noise over that whole step (the arc's travel and turn, its duration
``t_c1 - t_a``): the measured net motion, as good as the source itself for an odometry pose. For wheel
angles the heading change is exact, but the position depends on the order of the wheels' turns, which the
arc guesses (the arc's end and the robot's both lie within the travel bound
``(1 + speed_margin) max_rate (t_c1 - t_a)`` of ``a``'s position; that error is not in the step's noise).
A restart instead keeps the estimate where it was: it takes the motion across the silence as zero with no
noise added, wrong by the whole change, which the source measured. ``max_bridged_gap`` (10 s) bounds the
silence so that the rate bound still tells a restart from a source that went on: a stall of a driver,
network or recorder takes seconds (the Radish ACES odometry's: 3.0 s), a reboot of the robot longer.

Why a return to the origin is a restart even when the rate bound allows it: a restarted integrating source
starts at its origin (encoders reset to zero at a reboot, an odometry node at the identity), while a robot
that went on returns to within the slack of the origin in every value at once only by chance. So ``c_1``
is a reset when every value lies within its slack of the origin, and ``a`` did not: ``|s_i - p_i
round(s_i / p_i)| <= slack_i`` for a value read modulo a period ``p_i`` (a heading, 2 pi, unwrapped by its
source), ``|s_i| <= slack_i`` for any other. A reset whose first sample is already off the origin, within
the rate bound of ``a`` over the silence, is bridged (its error bounded as above), and counted as a bridge.

Values are compared as plain differences (unwrapped angles, as encoders report them). Every refusal,
bridge and restart is counted (:class:`GateTally`), so that a source the bounds do not fit (a robot faster
than the one described) or one that falls silent is reported, never silent.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from functools import partial

import numpy as np

from ..util.timebase import NS_PER_S
from ..util.validation import integer, non_negative, positive, store
from .motion_signals import TimedSample, timed_sample


@dataclass(frozen=True)
class SampleGateConfig:
    """Limits of :class:`SampleGate`; the field names are the ROS parameters of the nodes that read
    a motion source (wheel angles, odometry poses). ValueError for invalid values.

    * ``speed_margin`` (>= 0): how far above the stated maximum rate a value may still move (0.5: up to
      1.5 times the robot's maximum wheel speed);
    * ``max_sample_gap`` (s, > 0): the longest plausible time between two consecutive samples;
    * ``max_bridged_gap`` (s, >= ``max_sample_gap``): the longest silence bridged as one step once the
      samples after it agree, their change across it fits the rate bound and they do not start at the
      source's origin (a reset); after a longer one the stream restarts;
    * ``restart_samples`` (int >= 1): refused samples in a row, continuing each other, after which the
      source has gone on after a silence (bridged) or restarted.
    """

    speed_margin: float = 0.5
    max_sample_gap: float = 0.5
    max_bridged_gap: float = 10.0
    restart_samples: int = 3

    def __post_init__(self) -> None:
        store(self, ("speed_margin",), non_negative)
        store(self, ("max_sample_gap", "max_bridged_gap"), positive)
        store(self, ("restart_samples",), partial(integer, minimum=1))
        if self.max_bridged_gap < self.max_sample_gap:
            raise ValueError(
                f"need max_bridged_gap >= max_sample_gap, got {self.max_bridged_gap}, {self.max_sample_gap}"
            )


class Verdict(Enum):
    ACCEPTED = "accepted"
    DUPLICATE = "duplicate"
    REFUSED = "refused"
    BRIDGED = "bridged"
    RESTARTED = "restarted"


@dataclass(frozen=True)
class GateResult:
    """What :meth:`SampleGate.offer` decided. ``samples``: to apply in order, as motion from the last
    applied sample when ``ACCEPTED`` (the one offered) or ``BRIDGED`` (the candidate stream, the first one
    step across the silence), and when ``RESTARTED`` the new start first, then the motion from it; empty
    otherwise. ``reason``: why a sample was refused, a silence bridged or the stream restarted (empty when
    accepted)."""

    verdict: Verdict
    samples: tuple[TimedSample, ...] = ()
    reason: str = ""


@dataclass
class GateTally:
    """What a :class:`SampleGate` refused, bridged and restarted so far (never reset): ``refused`` offers
    (a sample later taken in a bridged or restarted candidate stream was refused when offered, and
    counts), ``bridged`` silences and the ``longest_bridge_s`` of them (s), ``restarts`` of the stream, and
    ``last_reason`` (why the newest refusal, bridge or restart happened; empty before any)."""

    refused: int = 0
    bridged: int = 0
    longest_bridge_s: float = 0.0
    restarts: int = 0
    last_reason: str = ""


class SampleGate:
    """The gate of the module docstring over samples of ``len(max_rates)`` values.

    ``max_rates`` (per value, units per second, > 0) and ``slack`` (per value, >= 0) set the rate bound;
    ``periods`` (per value, None or > 0; default all None) the period of a value read modulo one (a
    heading unwrapped by its source: 2 pi), for telling the source's origin; ``rate_hint`` ends the reason a
    sample moved too fast (where the max rates come from, what to change).
    """

    def __init__(
        self,
        config: SampleGateConfig,
        max_rates: Sequence[float],
        slack: Sequence[float],
        rate_hint: str = "",
        periods: Sequence[float | None] | None = None,
    ) -> None:
        rates = [positive("max_rate", rate) for rate in max_rates]
        slacks = [non_negative("slack", value) for value in slack]
        if periods is None:
            periods = [None] * len(rates)
        if not rates or len(slacks) != len(rates) or len(periods) != len(rates):
            raise ValueError(
                f"need one slack and one period per max_rate, got {len(rates)} rates, {len(slacks)} "
                f"slacks and {len(periods)} periods"
            )
        self.config = config
        self._max_speed = (1.0 + config.speed_margin) * np.array(rates) / NS_PER_S  # per ns
        self._slack = np.array(slacks)
        # 0 for a value not read modulo a period
        self._periods = np.array([0.0 if p is None else positive("period", p) for p in periods])
        self._rate_hint = f"; {rate_hint}" if rate_hint else ""
        self._gap_ns = round(config.max_sample_gap * NS_PER_S)
        self._bridged_gap_ns = round(config.max_bridged_gap * NS_PER_S)
        self._accepted: TimedSample | None = None
        self._candidates: list[TimedSample] = []
        self.tally = GateTally()

    @property
    def accepted(self) -> TimedSample | None:
        """The newest accepted sample (None before the first)."""
        return self._accepted

    def reset(self) -> None:
        """Forget the stream: the next sample is accepted as a new start."""
        self._accepted = None
        self._candidates.clear()

    def offer(self, t_ns: int, sample: Sequence[float]) -> GateResult:
        """Decide on the sample ``sample`` at ``t_ns`` (module docstring). ValueError (nothing changed) for
        a non-integer time, non-finite values or a sample of the wrong length."""
        new = timed_sample(t_ns, sample, len(self._slack))
        if self._accepted is None:
            self._accepted = new
            return GateResult(Verdict.ACCEPTED, (new,))
        if new == self._accepted:
            return GateResult(Verdict.DUPLICATE)
        reason = self._discontinuity(self._accepted, new)
        if reason is None:
            self._accepted = new
            self._candidates.clear()
            return GateResult(Verdict.ACCEPTED, (new,))
        if self._candidates and self._discontinuity(self._candidates[-1], new) is not None:
            self._candidates.clear()
        self._candidates.append(new)
        if len(self._candidates) < self.config.restart_samples:
            self.tally.refused += 1
            self.tally.last_reason = reason
            return GateResult(Verdict.REFUSED, reason=reason)
        candidates, previous = tuple(self._candidates), self._accepted
        self._candidates.clear()
        self._accepted = candidates[-1]
        not_bridged = self._not_bridged(previous, candidates[0])
        if not_bridged is None:
            silence_s = (candidates[0][0] - previous[0]) / NS_PER_S
            self.tally.bridged += 1
            self.tally.longest_bridge_s = max(self.tally.longest_bridge_s, silence_s)
            self.tally.last_reason = (
                f"silent for {silence_s:.3f} s, then {len(candidates)} samples in a row whose change fits "
                "the rate bound over the silence: bridged as one step"
            )
            return GateResult(Verdict.BRIDGED, candidates, self.tally.last_reason)
        self.tally.restarts += 1
        self.tally.last_reason = (
            f"{len(candidates)} samples in a row do not continue the stream ({not_bridged}): restarted"
        )
        return GateResult(Verdict.RESTARTED, candidates, self.tally.last_reason)

    def _not_bridged(self, a: TimedSample, c: TimedSample) -> str | None:
        """Why the silence from ``a`` to the candidate stream's first sample ``c`` is not bridged (None when
        it is): ``c`` does not continue ``a`` over ``max_bridged_gap``, or is a return to the origin."""
        reason = self._discontinuity(a, c, bridging=True)
        if reason is None and self._at_origin(c[1]) and not self._at_origin(a[1]):
            return "the first is at the source's origin: encoders or odometry reset to zero"
        return reason

    def _at_origin(self, values: tuple[float, ...]) -> bool:
        """Every value within its slack of the origin: of 0, or of a multiple of its period."""
        s = np.array(values)
        periodic = self._periods > 0.0
        s[periodic] -= self._periods[periodic] * np.round(s[periodic] / self._periods[periodic])
        return bool((np.abs(s) <= self._slack).all())

    def _discontinuity(self, a: TimedSample, b: TimedSample, bridging: bool = False) -> str | None:
        """Why ``b`` does not continue ``a`` (None when it does) over ``max_sample_gap``, or with
        ``bridging`` over ``max_bridged_gap``."""
        dt_ns = b[0] - a[0]
        if dt_ns <= 0:
            return f"stamp {b[0]} ns is not after {a[0]} ns"
        name, gap_ns = (
            ("max_bridged_gap", self._bridged_gap_ns) if bridging else ("max_sample_gap", self._gap_ns)
        )
        if dt_ns > gap_ns:
            return f"{dt_ns * 1e-9:.3f} s after the last sample ({name} = {getattr(self.config, name)} s)"
        step = np.abs(np.subtract(b[1], a[1]))
        bound = self._max_speed * dt_ns + self._slack
        if (step > bound).any():
            i = int(np.argmax(step - bound))
            return (
                f"value {i} moved {step[i]:.6g} in {dt_ns * 1e-9:.3f} s, more than {bound[i]:.6g} "
                f"(max rate x (1 + speed_margin) x dt + slack){self._rate_hint}"
            )
        return None
