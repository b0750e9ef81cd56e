"""How a stream of stamped samples becomes motion-model inputs, for :class:`turtlelib.SlamTimeline`.

A signal is sampled at times ``t_k`` (integer ns) with values ``s_k`` (tuples of floats). The timeline needs
its value between samples and the motion model's input ``u`` over a sub-interval:

* ``at(s0, s1, fraction)``: the value at ``t0 + fraction (t1 - t0)`` (``0 <= fraction < 1``) between
  consecutive samples ``s0`` at ``t0`` and ``s1`` at ``t1``;
* ``input(s_from, s_to, dt_ns)``: the input that moves the model from the value ``s_from`` to ``s_to``
  over ``dt_ns`` (both within one sample interval), or None when there is no motion to predict.

Signals:

* :class:`WheelAngles` (for :class:`~turtlelib.motion.motion_models.DiffDriveMotion`): cumulative wheel angles
  ``(phi_left, phi_right)`` (rad), constant wheel speeds between samples: linear interpolation,
  ``u = s_to - s_from``.
* :class:`OdometryPoses` (for :class:`~turtlelib.motion.motion_models.OdometryMotion`): cumulative odometry
  poses ``(x, y, theta)`` (``T_odom_body``), a constant body twist between samples:
  ``T(fraction) = T0 exp(fraction log(T0^-1 T1))``, ``u = (T_from^-1 T_to, dt_ns)``.
* :class:`MeasuredPoses` (for :class:`~turtlelib.motion.motion_models.MeasuredMotion`): odometry poses
  that carry the covariance of the motion since the previous sample (LiDAR odometry), interpolated as
  odometry poses, the covariance growing linearly over the interval.
* :class:`HeldInputs` (for :class:`~turtlelib.motion.motion_models.UnicycleMotion`,
  :class:`~turtlelib.motion.motion_models.AckermannMotion`): rates such as ``(v, omega)`` or ``(speed,
  steering)`` held from their sample until the next (a zero-order hold): ``at = s0``, ``u = (*s_from,
  dt_ns)``.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from ..geometry.se2 import Transform2D, integrate_twist
from ..util.validation import finite_real, integer
from .motion_models import from_upper_triangle, rotation_block, upper_triangle

Sample = tuple[float, ...]
TimedSample = tuple[int, Sample]


def timed_sample(t_ns: object, sample: Sequence[float], length: int | None = None) -> TimedSample:
    """``(t_ns, sample)`` as an int and a tuple of floats; ValueError unless the time is an integer (ns)
    and the values finite, ``length`` of them when given."""
    t_ns = integer("motion sample time (ns)", t_ns)
    values = tuple(finite_real("motion sample value", value) for value in sample)
    if length is not None and len(values) != length:
        raise ValueError(f"motion samples have {length} values, got {len(values)}")
    return t_ns, values


class MotionSignal(Protocol):
    """``at`` and ``input`` (module docstring)."""

    def at(self, s0: Sample, s1: Sample, fraction: float) -> Sample: ...

    def input(self, s_from: Sample, s_to: Sample, dt_ns: int) -> tuple | None: ...


@dataclass(frozen=True)
class WheelAngles:
    """Cumulative wheel angles ``(phi_left, phi_right)`` (rad)."""

    def at(self, s0: Sample, s1: Sample, fraction: float) -> Sample:
        (l0, r0), (l1, r1) = s0, s1
        # phi(t) = phi_(k-1) + fraction (phi_k - phi_(k-1))
        return l0 + fraction * (l1 - l0), r0 + fraction * (r1 - r0)

    def input(self, s_from: Sample, s_to: Sample, dt_ns: int) -> tuple | None:
        dphi_left, dphi_right = s_to[0] - s_from[0], s_to[1] - s_from[1]
        if dphi_left == 0.0 and dphi_right == 0.0:
            return None
        return dphi_left, dphi_right


@dataclass(frozen=True)
class OdometryPoses:
    """Cumulative odometry poses ``(x, y, theta)`` (m, m, rad) of the body in an odometry frame."""

    def at(self, s0: Sample, s1: Sample, fraction: float) -> Sample:
        T0 = Transform2D(*s0)
        # T(fraction) = T0 exp(fraction log(T0^-1 T1))
        T = T0 @ integrate_twist((T0.inverse() @ Transform2D(*s1)).log() * fraction)
        return T.x, T.y, T.theta

    def input(self, s_from: Sample, s_to: Sample, dt_ns: int) -> tuple | None:
        T_delta = Transform2D(*s_from).inverse() @ Transform2D(*s_to)
        if dt_ns == 0 and T_delta == Transform2D():
            return None
        return T_delta.x, T_delta.y, T_delta.theta, dt_ns


_ODOMETRY = OdometryPoses()


@dataclass(frozen=True)
class MeasuredPoses:
    """Cumulative poses ``(x, y, theta)`` (m, m, rad) of the body in an odometry frame, each with the
    length ``interval_ns`` (a float) of the interval that ends at it and the covariance ``Sigma_k`` of the
    motion over that interval (upper triangle ``s_xx, s_xy, s_xtheta, s_yy, s_ytheta, s_thetatheta``,
    additive ``[x, y, theta]`` in the odometry frame): the samples of
    :class:`turtlelib.estimation.lidar_odometry.LidarOdometry`, for
    :class:`~turtlelib.motion.motion_models.MeasuredMotion`. Within an interval the body moves along one
    constant twist and the uncertainty grows linearly in time (a random walk), so a piece of ``dt_ns`` of
    it, from the pose ``T_from``, is::

        T(fraction) = T0 exp(fraction log(T0^-1 T1))
        u = (T_from^-1 T_to, dt_ns, B(theta_from)^T (dt_ns / interval_ns) Sigma_k B(theta_from))

    (``B`` of :func:`~turtlelib.motion.motion_models.rotation_block`: the covariance in ``T_from``'s
    frame; the whole interval's is exact)."""

    def at(self, s0: Sample, s1: Sample, fraction: float) -> Sample:
        return (*_ODOMETRY.at(s0[:3], s1[:3], fraction), *s1[3:])

    def input(self, s_from: Sample, s_to: Sample, dt_ns: int) -> tuple | None:
        T_delta = Transform2D(*s_from[:3]).inverse() @ Transform2D(*s_to[:3])
        if dt_ns == 0 and T_delta == Transform2D():
            return None
        interval_ns = s_to[3]
        fraction = 1.0 if interval_ns <= 0.0 else dt_ns / interval_ns
        Sigma = fraction * from_upper_triangle(s_to[4:])
        B = rotation_block(s_from[2])
        # B(theta_from)^T Sigma B(theta_from)
        return T_delta.x, T_delta.y, T_delta.theta, dt_ns, *upper_triangle(B.T @ Sigma @ B)


@dataclass(frozen=True)
class HeldInputs:
    """Rates held from one sample to the next, e.g. ``(v_mps, omega_rad_s)`` or ``(speed_mps,
    steering_rad)``."""

    def at(self, s0: Sample, s1: Sample, fraction: float) -> Sample:
        return s0

    def input(self, s_from: Sample, s_to: Sample, dt_ns: int) -> tuple | None:
        if dt_ns == 0:
            return None
        return (*s_from, dt_ns)


def signal_at(signal: MotionSignal, times: Sequence[int], samples: Sequence[Sample], t_ns: int) -> Sample:
    """The signal's value at ``t_ns`` (``times[0] <= t_ns``; held after ``times[-1]``) from its samples
    ``samples`` at increasing ``times``: the newest sample of equal time, else ``at`` between the samples
    around it."""
    k = bisect.bisect_right(times, t_ns) - 1
    if k == len(times) - 1 or times[k] == t_ns:
        return samples[k]
    t0, t1 = times[k], times[k + 1]
    return signal.at(samples[k], samples[k + 1], (t_ns - t0) / (t1 - t0))


def signal_pieces(
    signal: MotionSignal,
    times: Sequence[int],
    samples: Sequence[Sample],
    t_from: int,
    s_from: Sample,
    t_to: int,
) -> list[tuple[int, Sample, tuple | None]]:
    """The motion from the value ``s_from`` at ``t_from`` to ``t_to`` (``t_from <= t_to``), one piece per
    sample interval: ``(t_end, s_end, u)`` for every sample time in ``(t_from, t_to]`` and then ``t_to``
    itself (its value from :func:`signal_at`), ``u`` the input over the piece or None where nothing moves.

    A motion model must not take two intervals as one step: the motion (the arc's twist) changes at the
    samples."""
    first = bisect.bisect_right(times, t_from)
    last = bisect.bisect_right(times, t_to)
    ends = [(times[k], samples[k]) for k in range(first, last)]
    ends.append((t_to, signal_at(signal, times, samples, t_to)))
    pieces = []
    for t_end, s_end in ends:
        pieces.append((t_end, s_end, signal.input(s_from, s_end, t_end - t_from)))
        t_from, s_from = t_end, s_end
    return pieces
