"""Motion models for :class:`turtlelib.estimation.ekf_slam.EkfSlam`: one protocol, any planar robot.

Protocol
--------
A motion model takes the pose ``q = [x, y, theta]`` (``T_map_body``; m, m, rad) and the input ``u`` of one
step and returns::

    q' = f(q, u),   G = df/dq (3, 3),   Q (3, 3) the covariance the step adds (map frame)

as ``step(T_map_body, u) -> (q', G, Q)``, and ``check(u)`` raises the ValueError ``step`` would raise for
``u`` from any pose, without computing the step (for callers that must refuse an input before changing
anything). The filter knows nothing else about the robot.

Every model here moves the body along the exact arc of a constant body displacement twist
``xi = [omega, vx, vy]`` (rad, m, m) over the step, ``T' = T exp([xi])``, so with ``[dx, dy] = p' - p``::

    G = [[1, 0, -dy],
         [0, 1,  dx],
         [0, 0,  1 ]]

and ``Q`` is the twist noise integrated along the arc (:func:`turtlelib.motion.arc_noise.arc_covariance`): one
step of a constant-twist motion has exactly the mean and covariance of any number of shorter steps along
it. The models differ in how ``u`` gives ``xi`` and in the twist noise:

* :class:`DiffDriveMotion`: wheel increments ``u = (dphi_left, dphi_right)`` (rad), random-walk wheel slip
  (:mod:`turtlelib.motion.wheel_noise`).
* :class:`OdometryMotion`: a relative pose ``u = (dx_m, dy_m, dtheta_rad, dt_ns)`` from any odometry source
  (``T_prev_next`` in the previous body frame), ``xi = log(T_prev_next)``; :class:`TwistNoise`.
* :class:`UnicycleMotion`: ``u = (v_mps, omega_rad_s, dt_ns)`` held over the step,
  ``xi = [omega dt, v dt, 0]``; :class:`TwistNoise`.
* :class:`AckermannMotion`: a car-like vehicle with the body at the rear-axle centre,
  ``u = (speed_mps, steering_rad, dt_ns)`` with the speed measured by a wheel encoder ``encoder_y_m`` to the
  left of the centreline; :class:`TwistNoise`. A sensor elsewhere on the car is the filter's sensor mount.

Time is in integer nanoseconds. Non-finite inputs, a negative ``dt_ns`` or an input of the wrong length
raise ValueError.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from ..geometry.se2 import Transform2D, Twist2D, integrate_twist, integrate_twists, normalize_angles
from ..util.timebase import NS_PER_S
from ..util.validation import covariance, finite_real, non_negative, positive, store
from .arc_noise import Floats, arc_covariance, arc_covariances, check_turn
from .kinematics import DiffDrive
from .wheel_noise import wheel_slip_covariance

# |steering| at or beyond this (rad) is not a steering angle (the car would turn on the spot or backwards)
MAX_STEERING_RAD = 0.5 * math.pi - 1e-3

Step = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
# (poses (n, 3), G (3, 3), Q (3, 3)) of a batch of steps (BatchMotionModel)
Steps = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


class MotionModel(Protocol):
    """``step(T_map_body, u) -> (q' (3,), G (3, 3), Q (3, 3))`` and ``check(u)`` (module docstring)."""

    def step(self, T_map_body: Transform2D, u: tuple) -> Step: ...

    def check(self, u: tuple) -> None: ...


@runtime_checkable
class BatchMotionModel(MotionModel, Protocol):
    """A motion model that also takes consecutive inputs at once: ``steps(T_map_body, (u_1, ..., u_n)) ->
    (poses (n, 3), G (3, 3), Q (3, 3))`` with ``poses[k-1] = q_k`` the pose after input ``k`` and ``G``,
    ``Q`` those of the composite step ``q_0 -> q_n``, so that one prediction with ``(q_n, G, Q)`` is the n
    predictions of :meth:`MotionModel.step` (to rounding)::

        G = G_n ... G_1,   Q = sum_k (G_n ... G_(k+1)) Q_k (G_n ... G_(k+1))^T

    ValueError, as ``step`` gives it, if any input is refused."""

    def steps(self, T_map_body: Transform2D, inputs: Sequence[tuple]) -> Steps: ...


def finite_step(step: Step) -> Step:
    """A motion model's ``(q', G, Q)``, checked finite: ValueError otherwise (a step so large it overflows
    would make a filter's covariance NaN for good)."""
    q_next, G, Q = step
    if not all(map(math.isfinite, [*q_next.tolist(), *G.ravel().tolist(), *Q.ravel().tolist()])):
        raise ValueError("the motion step gives a non-finite pose, Jacobian or noise (an implausible input)")
    return step


def composed_steps(motion: MotionModel, T_map_body: Transform2D, inputs: Sequence[tuple]) -> Steps:
    """``(poses (n, 3), G, Q)`` of consecutive ``inputs`` from ``T_map_body`` as one composite step
    (:class:`BatchMotionModel`): the model's own ``steps`` if it has them, else one checked ``step`` each::

        G <- G_k G,   Q <- G_k Q G_k^T + Q_k

    From the identity, ``poses[-1]`` is the motion ``T_start_end`` and ``Q`` its covariance in the start's
    frame. ValueError for an input the model refuses or a non-finite step."""
    if isinstance(motion, BatchMotionModel):
        return motion.steps(T_map_body, inputs)
    poses = np.empty((len(inputs), 3))
    G, Q = np.eye(3), np.zeros((3, 3))
    for k, u in enumerate(inputs):
        q_k, G_k, Q_k = finite_step(motion.step(T_map_body, u))
        # G <- G_k G,  Q <- G_k Q G_k^T + Q_k
        G, Q = G_k @ G, G_k @ Q @ G_k.T + Q_k
        poses[k] = q_k
        T_map_body = Transform2D(*q_k)
    return poses, G, Q


def _arc_step(T_map_body: Transform2D, T_next: Transform2D, Q: NDArray[np.float64]) -> Step:
    """``(q', G, Q)`` for a move to ``T_next`` along an arc: ``G = [[1, 0, -dy], [0, 1, dx], [0, 0, 1]]``."""
    dx, dy = T_next.x - T_map_body.x, T_next.y - T_map_body.y
    G = np.array([1.0, 0.0, -dy, 0.0, 1.0, dx, 0.0, 0.0, 1.0]).reshape(3, 3)
    return T_next.as_array(), G, Q


def _unpack(u: tuple, names: tuple[str, ...]) -> tuple:
    """``u`` as len(names) values: finite floats, and ``dt_ns`` (if named) a non-negative integer."""
    if len(u) != len(names):
        raise ValueError(f"input must be ({', '.join(names)}), got {len(u)} values")
    values = []
    for name, value in zip(names, u, strict=True):
        if name == "dt_ns":
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise ValueError(f"dt_ns must be an integer >= 0, got {value!r}")
            values.append(int(value))
        else:
            value = float(value)
            if not math.isfinite(value):
                raise ValueError(f"{name} must be finite, got {value!r}")
            values.append(value)
    return tuple(values)


@dataclass(frozen=True)
class DiffDriveMotion:
    """Wheel increments ``u = (dphi_left, dphi_right)`` (rad) of ``drive``; slip ``N(0, wheel_noise^2
    |dphi|)`` per wheel (``wheel_noise`` in sqrt(rad), >= 0; :mod:`turtlelib.motion.wheel_noise`)."""

    drive: DiffDrive
    wheel_noise: float

    def __post_init__(self) -> None:
        store(self, ("wheel_noise",), non_negative)

    def check(self, u: tuple) -> None:
        dphi_left, dphi_right = u
        check_turn(self.drive.body_twist(dphi_left, dphi_right).omega)

    def step(self, T_map_body: Transform2D, u: tuple) -> Step:
        dphi_left, dphi_right = u
        # q' = q (+) exp([F dphi])  (body_twist raises ValueError for non-finite increments)
        twist = self.drive.body_twist(dphi_left, dphi_right)
        T_next = T_map_body @ integrate_twist(twist)
        Q = wheel_slip_covariance(
            self.drive, T_map_body.theta, dphi_left, dphi_right, self.wheel_noise, twist=twist
        )
        return _arc_step(T_map_body, T_next, Q)


@dataclass(frozen=True)
class TwistNoise:
    """White noise on the body twist whose variances grow with travel, turn and time.

    Over a step of twist ``xi = [omega, vx, vy]`` lasting ``dt`` (s), with travel ``d = |[vx, vy]|`` (m) and
    turn ``|omega|`` (rad), the twist errors are independent with::

        var(dvx)    = forward_m2_per_m d + forward_m2_per_s dt
        var(dvy)    = lateral_m2_per_m d
        var(domega) = heading_rad2_per_m d + heading_rad2_per_rad |omega| + heading_rad2_per_s dt

    Each term is linear in travel, turn or time, so the variances of consecutive pieces of a motion add up
    to those of the whole (a random walk: the rate-independent form of the four-alpha odometry model of
    Probabilistic Robotics, whose squared terms would depend on how the motion is split). All >= 0
    (ValueError otherwise):

    * ``forward_m2_per_m`` (m^2/m): forward variance per metre travelled;
    * ``forward_m2_per_s`` (m^2/s): forward variance per second;
    * ``lateral_m2_per_m`` (m^2/m): sideways variance per metre travelled;
    * ``heading_rad2_per_m`` (rad^2/m): heading variance per metre travelled;
    * ``heading_rad2_per_rad`` (rad^2/rad): heading variance per radian turned;
    * ``heading_rad2_per_s`` (rad^2/s): heading variance per second.
    """

    forward_m2_per_m: float = 0.0
    forward_m2_per_s: float = 0.0
    lateral_m2_per_m: float = 0.0
    heading_rad2_per_m: float = 0.0
    heading_rad2_per_rad: float = 0.0
    heading_rad2_per_s: float = 0.0

    def __post_init__(self) -> None:
        store(self, tuple(self.__dataclass_fields__), non_negative)

    @classmethod
    def from_wheel_slip(cls, drive: DiffDrive, wheel_noise: float) -> TwistNoise:
        """The twist noise of a differential drive whose wheels slip ``N(0, wheel_noise^2 |dphi|)`` each
        (:class:`DiffDriveMotion`), for odometry computed from those wheels.

        With ``r`` the wheel radius and ``b`` the track, ``d xi = [r (dphi_r - dphi_l) / b, r (dphi_l +
        dphi_r) / 2, 0]`` and ``|dphi_l| + |dphi_r| = 2 d / r`` when both wheels roll forward (travel
        ``d``), ``b |domega| / r`` when turning on the spot::

            forward_m2_per_m = r sigma^2 / 2,   heading_rad2_per_m = 2 r sigma^2 / b^2
            heading_rad2_per_rad = r sigma^2 / b

        Exact for straight lines, and for the heading of turns on the spot; on an arc both heading terms
        count, so the heading variance is over-stated by the factor ``1 + b kappa / 2`` (curvature
        ``kappa``). Left out: the wheels' correlation of speed and turn errors, and the small forward error
        of a turn on the spot (``r sigma^2 b |domega| / 4``: the twist noise has no such term).
        """
        r, b = drive.wheel_radius, drive.track_width
        variance = non_negative("wheel_noise", wheel_noise) ** 2
        return cls(
            forward_m2_per_m=0.5 * r * variance,
            heading_rad2_per_m=2.0 * r * variance / b**2,
            heading_rad2_per_rad=r * variance / b,
        )

    def covariance(self, T_map_body: Transform2D, xi: Twist2D, dt_s: float) -> NDArray[np.float64]:
        """``Q`` (3, 3) of a step of twist ``xi`` over ``dt_s`` from ``T_map_body``, integrated along the
        arc."""
        var_vx, var_omega, var_vy = self._variances(math.hypot(xi.vx, xi.vy), abs(xi.omega), dt_s)
        return arc_covariance(T_map_body.theta, xi.omega, xi.vx, xi.vy, var_vx, 0.0, var_omega, var_vy)

    def covariances(
        self, theta_rad: NDArray[np.float64], xi: NDArray[np.float64], dt_s: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """:meth:`covariance` of a batch of steps: ``Q_k`` (n, 3, 3) of the twists ``xi`` (n, 3) ``[omega,
        vx, vy]`` over ``dt_s`` (n,) from the headings ``theta_rad`` (n,)."""
        omega, vx, vy = xi[:, 0], xi[:, 1], xi[:, 2]
        var_vx, var_omega, var_vy = self._variances(np.hypot(vx, vy), np.abs(omega), dt_s)
        return arc_covariances(theta_rad, omega, vx, vy, var_vx, 0.0, var_omega, var_vy)

    def _variances(self, travel_m: Floats, turn_rad: Floats, dt_s: Floats) -> tuple[Floats, Floats, Floats]:
        """``(var(dvx), var(domega), var(dvy))`` of the class docstring (floats, or elementwise)."""
        var_vx = self.forward_m2_per_m * travel_m + self.forward_m2_per_s * dt_s
        var_vy = self.lateral_m2_per_m * travel_m
        var_omega = (
            self.heading_rad2_per_m * travel_m
            + self.heading_rad2_per_rad * turn_rad
            + self.heading_rad2_per_s * dt_s
        )
        return var_vx, var_omega, var_vy


def _twist_step(
    T_map_body: Transform2D, T_delta: Transform2D, xi: Twist2D, dt_ns: int, noise: TwistNoise
) -> Step:
    # q' = q (+) T_delta,  T_delta = exp([xi])
    return _arc_step(T_map_body, T_map_body @ T_delta, noise.covariance(T_map_body, xi, dt_ns / NS_PER_S))


def _twist_steps(
    T_map_body: Transform2D, xi: NDArray[np.float64], dt_ns: NDArray[np.int64], noise: TwistNoise
) -> Steps:
    """n consecutive constant-twist steps ``xi`` (n, 3) ``[omega, vx, vy]`` lasting ``dt_ns`` (n,) from
    ``T_map_body`` as one composite step (module docstring)::

        q_k = q_(k-1) (+) exp([xi_k])
        G = G_n ... G_1 = [[1, 0, -(y_n - y_0)], [0, 1, x_n - x_0], [0, 0, 1]]
        Q = sum_k Phi_k Q_k Phi_k^T
        Phi_k = G_n ... G_(k+1) = [[1, 0, -(y_n - y_k)], [0, 1, x_n - x_k], [0, 0, 1]]

    (``Q_k`` the arc noise of step k from heading ``theta_(k-1)``): what n single steps give, in O(n)
    vectorised work (no steps: no motion)."""
    if len(xi) == 0:
        return np.zeros((0, 3)), np.eye(3), np.zeros((3, 3))
    omega = xi[:, 0]
    # theta_(k-1), the heading each step starts from (unwrapped)
    theta_before = T_map_body.theta + np.concatenate([[0.0], np.cumsum(omega[:-1])])
    # p_k = p_(k-1) + R(theta_(k-1)) V(omega_k) v_k
    p_body = integrate_twists(omega, xi[:, 1], xi[:, 2])
    c, s = np.cos(theta_before), np.sin(theta_before)
    x = T_map_body.x + np.cumsum(c * p_body[:, 0] - s * p_body[:, 1])
    y = T_map_body.y + np.cumsum(s * p_body[:, 0] + c * p_body[:, 1])
    poses = np.column_stack([x, y, normalize_angles(theta_before + omega)])
    Q_k = noise.covariances(theta_before, xi, dt_ns / NS_PER_S)
    Phi = np.broadcast_to(np.eye(3), Q_k.shape).copy()
    Phi[:, 0, 2], Phi[:, 1, 2] = -(y[-1] - y), x[-1] - x
    Q = np.einsum("kij,kjl,kml->im", Phi, Q_k, Phi)
    G = np.eye(3)
    G[0, 2], G[1, 2] = -(y[-1] - T_map_body.y), x[-1] - T_map_body.x
    return poses, G, 0.5 * (Q + Q.T)


def _unpack_batch(inputs: Sequence[tuple], names: tuple[str, ...]) -> tuple[NDArray, ...]:
    """Inputs ``(u_1, ..., u_n)``, each as :func:`_unpack` takes it, as one array (n,) per name: float64
    finite, ``dt_ns`` (if named) int64 >= 0 of integers; ValueError otherwise."""
    if any(len(u) != len(names) for u in inputs):
        raise ValueError(f"every input must be ({', '.join(names)})")
    columns = []
    by_name = list(zip(*inputs, strict=True)) if len(inputs) else [()] * len(names)
    for name, column in zip(names, by_name, strict=True):
        if name == "dt_ns":
            if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in column):
                raise ValueError("dt_ns must be an integer >= 0")
            values = np.array(column, dtype=np.int64)
            if (values < 0).any():
                raise ValueError(f"dt_ns must be an integer >= 0, got {values.min()}")
        else:
            values = np.array(column, dtype=np.float64)
            if not np.isfinite(values).all():
                raise ValueError(f"{name} must be finite")
        columns.append(values)
    return tuple(columns)


@dataclass(frozen=True)
class OdometryMotion:
    """A relative pose ``u = (dx_m, dy_m, dtheta_rad, dt_ns)``: ``T_prev_next`` from any odometry source
    (wheel odometry, visual odometry, a recorded ``odom`` frame), taken as the arc ``xi = log(T_prev_next)``
    (so a reference point that moves sideways is fine); ``noise`` on that twist."""

    noise: TwistNoise

    def check(self, u: tuple) -> None:
        # the turn of log(T_prev_next) lies in (-pi, pi]
        _unpack(u, ("dx_m", "dy_m", "dtheta_rad", "dt_ns"))

    def step(self, T_map_body: Transform2D, u: tuple) -> Step:
        dx_m, dy_m, dtheta_rad, dt_ns = _unpack(u, ("dx_m", "dy_m", "dtheta_rad", "dt_ns"))
        T_delta = Transform2D(dx_m, dy_m, dtheta_rad)
        return _twist_step(T_map_body, T_delta, T_delta.log(), dt_ns, self.noise)


@dataclass(frozen=True)
class MeasuredMotion:
    """A relative pose that comes with its own covariance (a registered LiDAR scan,
    :mod:`turtlelib.estimation.lidar_odometry`): ``u = (dx_m, dy_m, dtheta_rad, dt_ns, s_xx, s_xy, s_xtheta,
    s_yy, s_ytheta, s_thetatheta)``, the motion ``T_prev_next`` and the upper triangle of its covariance
    ``Sigma_u`` (3, 3) in the frame of ``T_prev`` (additive ``[x, y, theta]``, m and rad). With
    ``B(theta) = blockdiag(R(theta), 1)``::

        q' = q (+) T_prev_next,   Q = B(theta_q) Sigma_u B(theta_q)^T

    ValueError for a covariance that is not symmetric positive semi-definite."""

    def check(self, u: tuple) -> None:
        self._unpack(u)

    def step(self, T_map_body: Transform2D, u: tuple) -> Step:
        T_delta, Sigma_u = self._unpack(u)
        B = rotation_block(T_map_body.theta)
        # Q = B Sigma_u B^T
        return _arc_step(T_map_body, T_map_body @ T_delta, B @ Sigma_u @ B.T)

    @staticmethod
    def _unpack(u: tuple) -> tuple[Transform2D, NDArray[np.float64]]:
        names = ("dx_m", "dy_m", "dtheta_rad", "dt_ns", "s_xx", "s_xy", "s_xtheta", "s_yy", "s_ytheta")
        dx_m, dy_m, dtheta_rad, _, *upper = _unpack(u, (*names, "s_thetatheta"))
        Sigma_u = covariance("motion covariance", from_upper_triangle(upper), (3, 3), definite=False)
        return Transform2D(dx_m, dy_m, dtheta_rad), Sigma_u


def upper_triangle(S: NDArray[np.float64]) -> tuple[float, ...]:
    """The upper triangle ``(s_xx, s_xy, s_xtheta, s_yy, s_ytheta, s_thetatheta)`` of a symmetric (3, 3)."""
    return float(S[0, 0]), float(S[0, 1]), float(S[0, 2]), float(S[1, 1]), float(S[1, 2]), float(S[2, 2])


def from_upper_triangle(upper: Sequence[float]) -> NDArray[np.float64]:
    """The symmetric (3, 3) of its upper triangle (:func:`upper_triangle`)."""
    s_xx, s_xy, s_xt, s_yy, s_yt, s_tt = upper
    return np.array([[s_xx, s_xy, s_xt], [s_xy, s_yy, s_yt], [s_xt, s_yt, s_tt]])


def rotation_block(theta_rad: float) -> NDArray[np.float64]:
    """``B(theta) = blockdiag(R(theta), 1)`` (3, 3): an additive ``[x, y, theta]`` perturbation in a frame
    turned by ``theta`` expressed in the outer frame."""
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class UnicycleMotion:
    """A forward speed and turn rate ``u = (v_mps, omega_rad_s, dt_ns)`` held over the step (e.g. velocity
    commands): ``xi = [omega dt, v dt, 0]``; ``noise`` on that twist."""

    noise: TwistNoise

    def check(self, u: tuple) -> None:
        check_turn(self._twist(u)[0].omega)

    def step(self, T_map_body: Transform2D, u: tuple) -> Step:
        xi, dt_ns = self._twist(u)
        return _twist_step(T_map_body, integrate_twist(xi), xi, dt_ns, self.noise)

    @staticmethod
    def _twist(u: tuple) -> tuple[Twist2D, int]:
        """``(xi = [omega dt, v dt, 0], dt_ns)`` of a validated input (ValueError for a non-finite ``xi``)."""
        v_mps, omega_rad_s, dt_ns = _unpack(u, ("v_mps", "omega_rad_s", "dt_ns"))
        dt_s = dt_ns / NS_PER_S
        return Twist2D(omega_rad_s * dt_s, v_mps * dt_s, 0.0), dt_ns

    def steps(self, T_map_body: Transform2D, inputs: Sequence[tuple]) -> Steps:
        """:meth:`step` of consecutive inputs as one composite step (:class:`BatchMotionModel`)."""
        v_mps, omega_rad_s, dt_ns = _unpack_batch(inputs, ("v_mps", "omega_rad_s", "dt_ns"))
        dt_s = dt_ns / NS_PER_S
        xi = np.column_stack([omega_rad_s * dt_s, v_mps * dt_s, np.zeros(len(dt_s))])
        return _twist_steps(T_map_body, xi, dt_ns, self.noise)


@dataclass(frozen=True)
class AckermannMotion:
    """A car-like vehicle: the body frame at the rear-axle centre (x forward), ``u = (speed_mps,
    steering_rad, dt_ns)`` held over the step, with the speed measured by a wheel encoder on the rear axle
    ``encoder_y_m`` to the left of the centreline (0 for the axle centre) and the front-wheel steering
    angle ``alpha`` (+ left). With wheelbase ``L`` (``wheelbase_m`` > 0)::

        omega = v_c tan(alpha) / L,   v_e = v_c - omega y_e   =>   v_c = v_e / (1 - tan(alpha) y_e / L)
        xi = [omega dt, v_c dt, 0]

    (a unicycle at the rear axle; Guivant & Nebot 2001 for Victoria Park). ``noise`` on that twist.
    ValueError for ``|alpha| >= MAX_STEERING_RAD`` or a steering whose turn centre lies at the encoder.
    """

    wheelbase_m: float
    encoder_y_m: float
    noise: TwistNoise

    def __post_init__(self) -> None:
        store(self, ("wheelbase_m",), positive)
        store(self, ("encoder_y_m",), finite_real)

    def check(self, u: tuple) -> None:
        check_turn(self._twist(u)[0].omega)

    def step(self, T_map_body: Transform2D, u: tuple) -> Step:
        xi, dt_ns = self._twist(u)
        return _twist_step(T_map_body, integrate_twist(xi), xi, dt_ns, self.noise)

    def _twist(self, u: tuple) -> tuple[Twist2D, int]:
        """``(xi, dt_ns)`` of a validated input: ``xi = [v_c tan(alpha) / L dt, v_c dt, 0]`` (ValueError for
        a non-finite one); :meth:`_arc` on floats."""
        speed_mps, steering_rad, dt_ns = _unpack(u, ("speed_mps", "steering_rad", "dt_ns"))
        curvature, travel_m = self._arc(speed_mps, steering_rad, dt_ns)
        return Twist2D(curvature * travel_m, travel_m, 0.0), dt_ns

    def steps(self, T_map_body: Transform2D, inputs: Sequence[tuple]) -> Steps:
        """:meth:`step` of consecutive inputs as one composite step (:class:`BatchMotionModel`)."""
        speed_mps, steering_rad, dt_ns = _unpack_batch(inputs, ("speed_mps", "steering_rad", "dt_ns"))
        curvature, travel_m = self._arc(speed_mps, steering_rad, dt_ns)
        xi = np.column_stack([curvature * travel_m, travel_m, np.zeros(len(travel_m))])
        return _twist_steps(T_map_body, xi, dt_ns, self.noise)

    def _arc(self, speed_mps: Floats, steering_rad: Floats, dt_ns: Floats) -> tuple[Floats, Floats]:
        """The curvature ``tan(alpha) / L`` (1/m) and the axle centre's travel ``v_c dt`` (m) of each step
        (finite floats, or arrays (n,) of them); ValueError for a steering the class docstring refuses."""
        # |alpha| < MAX_STEERING_RAD, and 1 - tan(alpha) y_e / L > 0 (the turn centre not at the encoder)
        beyond = np.abs(steering_rad) >= MAX_STEERING_RAD
        if np.any(beyond):
            raise ValueError(
                f"steering angle {float(np.extract(beyond, steering_rad)[0])!r} rad is beyond "
                f"+-{MAX_STEERING_RAD:.4f} rad"
            )
        curvature = np.tan(steering_rad) / self.wheelbase_m
        # v_c = v_e / (1 - tan(alpha) y_e / L)
        scale = 1.0 - curvature * self.encoder_y_m
        about_encoder = scale <= 0.0
        if np.any(about_encoder):
            raise ValueError(
                f"steering angle {float(np.extract(about_encoder, steering_rad)[0])!r} rad turns the car "
                "about its encoder wheel"
            )
        return curvature, speed_mps / scale * (dt_ns / NS_PER_S)
