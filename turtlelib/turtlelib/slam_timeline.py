"""Time alignment of wheel odometry and stamped observations for :class:`turtlelib.ekf_slam.EkfSlam`.

Wheel angles arrive as samples ``(t_k, phi_left_k, phi_right_k)`` (20 Hz on a Burger); an observation
carries the stamp ``t_o`` of the scan it came from and reaches the filter later (detection, transport),
possibly after the next wheel samples. An observation must be applied with the filter at ``t_o``, not at
whatever pose is current, so the filter runs a little behind the newest wheel sample ``t_w``:

* Between samples the wheels turn at constant speed, so the angles at any ``t`` in ``[t_(k-1), t_k]``
  are interpolated linearly::

      phi(t) = phi_(k-1) + (t - t_(k-1)) / (t_k - t_(k-1)) (phi_k - phi_(k-1))

* The filter is at time ``t_f`` with wheel angles ``phi_f``; bringing it to ``t >= t_f`` is one
  prediction per sample interval crossed (to each wheel sample in ``(t_f, t]``, then to ``phi(t)``): within
  an interval the wheel speeds are constant, so each prediction follows one arc, and the process noise of
  an arc does not depend on how it is split (:mod:`turtlelib.wheel_noise`). So where the motion is split
  into predictions (observation stamps, ``max_observation_delay``) does not matter.
* When a wheel sample arrives, every waiting observation with ``t_o <= t_w`` is applied in stamp order,
  each after bringing the filter to ``t_o``; then the filter is brought to ``t_w - max_observation_delay``
  (observations may arrive up to that late).
* An observation with ``t_o <= t_w`` is applied at once (filter brought to ``t_o``); one newer than every
  wheel sample waits for the wheel samples that reach it; one older than ``t_f`` came too late and is
  refused (ValueError): applying it at a later pose would be wrong.
* The pose at ``t_w`` (what a node publishes) is the filter's pose moved on by the wheel increments from
  ``t_f`` to ``t_w``, interval by interval, with its covariance propagated alongside
  (:meth:`EkfSlam.propagated_pose_along`), without changing the filter.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .ekf_slam import Association, EkfSlam
from .geometry import Transform2D
from .validation import finite_real, integer, non_negative, store


@dataclass(frozen=True)
class TimelineConfig:
    """``max_observation_delay`` (s, finite, >= 0): how late an observation may arrive after the wheel
    samples of its time; ``max_pending_observations`` (int >= 1): observations that may wait for wheel
    samples. Invalid values raise ValueError."""

    max_observation_delay: float = 0.25
    max_pending_observations: int = 20

    def __post_init__(self) -> None:
        store(self, ("max_observation_delay",), non_negative)
        store(self, ("max_pending_observations",), partial(integer, minimum=1))


@dataclass(frozen=True, eq=False)
class _Observation:
    """One scan's observations: validated ``z`` (K, 2), ``R`` (K, 2, 2), ``ids`` (K,) or None (unknown)."""

    t_s: float
    z: NDArray[np.float64]
    R: NDArray[np.float64]
    ids: NDArray[np.int64] | None


class SlamTimeline:
    """Feeds an :class:`EkfSlam` wheel samples and stamped observations in time order (module docstring).

    ``add_wheels`` and ``add_observations`` return the observations applied by the call as ``(t_o,
    Association)`` pairs, oldest first.
    """

    def __init__(self, slam: EkfSlam, config: TimelineConfig | None = None) -> None:
        self.slam = slam
        self.config = TimelineConfig() if config is None else config
        # wheel samples (t, phi_left, phi_right) from the last one at or before t_f, times ascending
        self._times: list[float] = []
        self._angles: list[tuple[float, float]] = []
        self._t_f: float | None = None
        self._phi_f = (0.0, 0.0)
        self._pending: list[_Observation] = []

    @property
    def filter_time_s(self) -> float | None:
        """``t_f``, the time the filter is at (None before the first wheel sample)."""
        return self._t_f

    @property
    def latest_time_s(self) -> float | None:
        """``t_w``, the time of the newest wheel sample (None before the first)."""
        return self._times[-1] if self._times else None

    @property
    def pending_count(self) -> int:
        """Observations waiting for wheel samples that reach their time."""
        return len(self._pending)

    def add_wheels(
        self, t_s: float, phi_left_rad: float, phi_right_rad: float
    ) -> list[tuple[float, Association]]:
        """A wheel sample: angles (rad) at time ``t_s`` (s). The first only starts the timeline.

        ValueError (nothing changed) for non-finite values or a time earlier than the newest sample.
        """
        t_s, phi_left_rad, phi_right_rad = _finite_sample(t_s, phi_left_rad, phi_right_rad)
        t_w = self.latest_time_s
        if t_w is not None and t_s < t_w:
            raise ValueError(f"time went backwards: wheel sample at {t_s!r} s after one at {t_w!r} s")
        self._times.append(t_s)
        self._angles.append((phi_left_rad, phi_right_rad))
        if self._t_f is None:
            self._t_f, self._phi_f = t_s, (phi_left_rad, phi_right_rad)
            return []
        applied = []
        while self._pending and self._pending[0].t_s <= t_s:
            applied.append(self._apply(self._pending.pop(0)))
        self._advance_to(max(self._t_f, t_s - self.config.max_observation_delay))
        return applied

    def add_observations(
        self, t_s: float, z: ArrayLike, R: ArrayLike | None = None, ids: ArrayLike | None = None
    ) -> list[tuple[float, Association]]:
        """One scan's observations ``z`` (K, 2) [range_m, bearing_rad] stamped ``t_s`` (s), with noise ``R``
        (K, 2, 2) (default from the filter's config) and, for known association, landmark ``ids`` (K,).

        Applied now if wheel samples reach ``t_s``, else queued. ValueError (nothing changed) for invalid
        observations (also: with ids when the filter or the waiting observations run without, or the
        reverse), before the first wheel sample, for a stale stamp (``t_s < t_f``), or when
        ``max_pending_observations`` are already waiting.
        """
        t_s = finite_real("observation stamp", t_s)
        z, R, landmark_ids = self.slam.checked_observations(z, R, ids)
        if self._t_f is None:
            raise ValueError("no wheel sample yet: an observation cannot be placed in time")
        if self._pending and (self._pending[0].ids is None) != (landmark_ids is None):
            # the first update fixes the filter's association mode: the waiting ones would be refused
            raise ValueError("observations with and without ids cannot wait together (one association mode)")
        if t_s < self._t_f:
            raise ValueError(
                f"stale observation: stamped {t_s:.9f} s, the filter is already at {self._t_f:.9f} s "
                f"(more than max_observation_delay = {self.config.max_observation_delay} s late)"
            )
        observation = _Observation(t_s, z, R, landmark_ids)
        if t_s <= self._times[-1]:
            return [self._apply(observation)]
        if len(self._pending) >= self.config.max_pending_observations:
            raise ValueError(
                f"{len(self._pending)} observations already wait for wheel samples past "
                f"{self._times[-1]:.9f} s"
            )
        bisect.insort(self._pending, observation, key=lambda o: o.t_s)
        return []

    def restart(self, t_s: float, phi_left_rad: float, phi_right_rad: float) -> None:
        """Take this wheel sample as the new start of time, keeping the filter's estimate (for a clock that
        jumped back: a restarted simulator or a looped recording). The filter is first brought to the newest
        wheel sample, so no motion is lost (as far as it can be: the estimate stops before a sample whose
        increment the motion model refuses, e.g. a corrupt reading); observations still waiting are dropped.
        """
        t_s, phi_left_rad, phi_right_rad = _finite_sample(t_s, phi_left_rad, phi_right_rad)
        if self._t_f is not None:
            try:
                self._advance_to(self._times[-1])
            except ValueError:
                pass  # that motion is lost; the estimate is kept where the last valid increment left it
        self._times, self._angles = [t_s], [(phi_left_rad, phi_right_rad)]
        self._t_f, self._phi_f = t_s, (phi_left_rad, phi_right_rad)
        self._pending.clear()

    def latest_pose(self) -> tuple[Transform2D, NDArray[np.float64]]:
        """``T_map_body`` at ``t_w`` and its covariance (3, 3): the filter moved on by the wheel increments
        since ``t_f``, one arc per sample interval as :meth:`_advance_to` would (the filter is unchanged).
        ValueError before the first wheel sample."""
        if self._t_f is None:
            raise ValueError("no wheel sample yet")
        later = self._angles[bisect.bisect_right(self._times, self._t_f) :]
        angles = np.array([self._phi_f, *later])
        return self.slam.propagated_pose_along(np.diff(angles, axis=0))

    # --- helpers -----------------------------------------------------------------------------------------

    def _apply(self, observation: _Observation) -> tuple[float, Association]:
        self._advance_to(observation.t_s)
        if observation.ids is None:
            association = self.slam.update_unknown(observation.z, observation.R)
        else:
            association = self.slam.update_known(observation.ids, observation.z, observation.R)
        return observation.t_s, association

    def _advance_to(self, t_s: float) -> None:
        """Predict the filter from ``t_f`` to ``t_s`` (``t_f <= t_s <= t_w``) and drop older samples.

        One prediction per sample interval: the wheel speeds (so the arc's curvature) change only at the
        samples, and one prediction over two intervals would follow a different arc than the robot did.
        """
        for k in range(bisect.bisect_right(self._times, self._t_f), bisect.bisect_right(self._times, t_s)):
            self._predict_to(self._angles[k])
        self._predict_to(self._angles_at(t_s))
        self._t_f = t_s
        # keep the last sample at or before t_f: interpolation from t_f needs it
        first_kept = bisect.bisect_right(self._times, t_s) - 1
        if first_kept > 0:
            del self._times[:first_kept], self._angles[:first_kept]

    def _predict_to(self, angles: tuple[float, float]) -> None:
        """One prediction with the increments from ``phi_f`` to ``angles`` (none if they are equal)."""
        dphi_left, dphi_right = angles[0] - self._phi_f[0], angles[1] - self._phi_f[1]
        if dphi_left != 0.0 or dphi_right != 0.0:
            self.slam.predict(dphi_left, dphi_right)
        self._phi_f = angles

    def _angles_at(self, t_s: float) -> tuple[float, float]:
        """``phi(t)``, linear between the samples around ``t_s`` (the newest sample of equal time)."""
        k = bisect.bisect_right(self._times, t_s) - 1
        if k == len(self._times) - 1 or self._times[k] == t_s:
            return self._angles[k]
        t0, t1 = self._times[k], self._times[k + 1]
        (l0, r0), (l1, r1) = self._angles[k], self._angles[k + 1]
        # phi(t) = phi_(k-1) + (t - t_(k-1)) / (t_k - t_(k-1)) (phi_k - phi_(k-1))
        s = (t_s - t0) / (t1 - t0)
        return l0 + s * (l1 - l0), r0 + s * (r1 - r0)


def _finite_sample(t_s: object, phi_left_rad: object, phi_right_rad: object) -> tuple[float, float, float]:
    """A wheel sample as floats; ValueError unless every value is a finite number."""
    return (
        finite_real("wheel sample time", t_s),
        finite_real("wheel sample angle (left)", phi_left_rad),
        finite_real("wheel sample angle (right)", phi_right_rad),
    )
