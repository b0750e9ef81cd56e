"""Plausibility of a stream of motion samples (wheel angles): which to take, which to refuse, and when the
source has restarted.

A sample ``(t_k, s_k)`` (integer ns; a tuple of values, e.g. the two wheel angles in rad) **continues** an
earlier sample ``(t_a, s_a)`` when

* time moves forward without a jump: ``0 < t_k - t_a <= max_sample_gap``, and
* no value moves faster than the source can: for every value ``i``
  ``|s_k,i - s_a,i| <= (1 + speed_margin) max_rate_i (t_k - t_a) + slack_i``
  (``max_rate`` e.g. the robot's maximum wheel speed, ``slack`` the sensor's resolution).

The gate holds the newest accepted sample ``a``. A new sample

* that continues ``a`` is **accepted**;
* that repeats ``a`` exactly (time and values) is a **duplicate**, ignored;
* otherwise is **refused** (one replayed or future-stamped message, a corrupt reading), and kept as a
  candidate. Refused samples that continue each other form a candidate stream; a sample that continues
  ``a`` clears it, so a lone bad message among real ones is refused and forgotten. When the candidate
  stream reaches ``restart_samples`` samples the source has restarted (a restarted simulator, a looped
  recording, encoders reset at a reboot, or a silence longer than ``max_sample_gap``): if its first sample
  comes at most ``max_bridged_gap`` after ``a`` and within the rate bound (only the gap was too long: a
  driver's hiccup), the candidates are **accepted** as a continuation and no motion is lost (the gap is
  one arc); otherwise the stream **restarted** at the first candidate, and the motion along the others
  follows (over a longer silence nobody knows how the robot moved: one arc would be made up).

Values are compared as plain differences (unwrapped angles, as encoders report them). Every refusal and
restart is counted (:class:`GateTally`), so that a source the bounds do not fit (a robot faster than the
one described) is reported, never silent.
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
    wheel angles. ValueError for invalid values.

    * ``speed_margin`` (>= 0): how far above the stated maximum rate a value may still move (0.5: up to
      1.5 times the robot's maximum wheel speed);
    * ``max_sample_gap`` (s, > 0): the longest plausible time between two consecutive samples;
    * ``max_bridged_gap`` (s, >= ``max_sample_gap``): the longest silence taken as one arc of motion once
      the samples after it agree; after a longer one the stream restarts;
    * ``restart_samples`` (int >= 1): refused samples in a row, continuing each other, after which the
      source is taken to have restarted.
    """

    speed_margin: float = 0.5
    max_sample_gap: float = 0.5
    max_bridged_gap: float = 2.0
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
    RESTARTED = "restarted"


@dataclass(frozen=True)
class GateResult:
    """What :meth:`SampleGate.offer` decided. ``samples``: to apply in order, as motion from the last
    applied sample when ``ACCEPTED`` (usually the one offered; after a gap, the candidate stream), and
    when ``RESTARTED`` the new start first, then the motion from it; empty otherwise. ``reason``: why a
    sample was refused or the stream restarted (empty when accepted)."""

    verdict: Verdict
    samples: tuple[TimedSample, ...] = ()
    reason: str = ""


@dataclass
class GateTally:
    """What a :class:`SampleGate` refused so far (never reset): ``refused`` offers (a sample later taken in a
    bridged or restarted candidate stream was refused when offered, and counts), ``restarts`` of the
    stream, and ``last_reason`` (why the newest refusal or restart happened; empty before any)."""

    refused: int = 0
    restarts: int = 0
    last_reason: str = ""


class SampleGate:
    """The gate of the module docstring over samples of ``len(max_rates)`` values.

    ``max_rates`` (per value, units per second, > 0) and ``slack`` (per value, >= 0) set the rate bound;
    ``rate_hint`` ends the reason a sample moved too fast (where the max rates come from, what to change).
    """

    def __init__(
        self,
        config: SampleGateConfig,
        max_rates: Sequence[float],
        slack: Sequence[float],
        rate_hint: str = "",
    ) -> None:
        rates = [positive("max_rate", rate) for rate in max_rates]
        slacks = [non_negative("slack", value) for value in slack]
        if not rates or len(slacks) != len(rates):
            raise ValueError(f"need one slack per max_rate, got {len(rates)} rates and {len(slacks)} slacks")
        self.config = config
        self._max_speed = (1.0 + config.speed_margin) * np.array(rates) / NS_PER_S  # per ns
        self._slack = np.array(slacks)
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
        if self._discontinuity(previous, candidates[0], self._bridged_gap_ns) is None:
            return GateResult(Verdict.ACCEPTED, candidates)
        self.tally.restarts += 1
        self.tally.last_reason = (
            f"{len(candidates)} samples in a row do not continue the stream ({reason}): restarted"
        )
        return GateResult(Verdict.RESTARTED, candidates, self.tally.last_reason)

    def _discontinuity(self, a: TimedSample, b: TimedSample, gap_ns: int | None = None) -> str | None:
        """Why ``b`` does not continue ``a`` (None when it does), allowing ``gap_ns`` between them
        (default ``max_sample_gap``)."""
        dt_ns = b[0] - a[0]
        if dt_ns <= 0:
            return f"stamp {b[0]} ns is not after {a[0]} ns"
        if dt_ns > (self._gap_ns if gap_ns is None else gap_ns):
            gap_s = self.config.max_sample_gap
            return f"{dt_ns * 1e-9:.3f} s after the last sample (max_sample_gap = {gap_s} s)"
        step = np.abs(np.subtract(b[1], a[1]))
        bound = self._max_speed * dt_ns + self._slack
        if (step > bound).any():
            i = int(np.argmax(step - bound))
            return (
                f"value {i} moved {step[i]:.6g} in {dt_ns * 1e-9:.3f} s, more than {bound[i]:.6g} "
                f"(max rate x (1 + speed_margin) x dt + slack){self._rate_hint}"
            )
        return None
