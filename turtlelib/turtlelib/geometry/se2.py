"""Planar rigid-body geometry: angles, twists and the SE(2) group.

Conventions
-----------
* Angles are in rad; a normalised angle lies in the half-open interval (-pi, pi] (so both pi and -pi map
  to pi).
* ``T_ab = Transform2D(x, y, theta)`` is the pose of frame ``b`` in frame ``a``: ``(x, y)`` (m) is the origin
  of ``b`` expressed in ``a`` and ``theta`` (rad) the angle from ``a``'s x axis to ``b``'s x axis. As a
  homogeneous matrix::

      T_ab = [[cos(theta), -sin(theta), x],
              [sin(theta),  cos(theta), y],
              [0,           0,          1]]

  Frames chain like matrices: ``T_ab @ T_bc = T_ac`` and ``T_ab @ p_b = p_a`` for points.
* ``Twist2D(omega, vx, vy)`` is a planar twist ``V = [omega, vx, vy]`` (rad/s, m/s, m/s), the order of
  Modern Robotics (Lynch & Park), ch. 3: angular part first. A body twist ``V_b`` is expressed in the
  moving frame. Over a time ``dt`` the displacement is the twist ``V * dt`` applied for unit time, and
  ``integrate_twist(V) = exp([V])`` is the exact pose reached by holding ``V`` for unit time
  (a circular arc, or a straight line when ``omega == 0``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Real

import numpy as np
from numpy.typing import ArrayLike, NDArray

# Below this |omega| (rad) the sin/cos ratios of exp and log use their Taylor series: the closed forms are
# 0/0 at omega = 0, and the series truncation error here is below 1e-16.
SMALL_ANGLE_RAD = 1e-2


def normalize_angle(theta: float) -> float:
    """The angle equivalent to ``theta`` (rad) in (-pi, pi]; ``pi`` and ``-pi`` both map to ``pi``.

    Exact: angles already in range are returned unchanged, others are reduced by an exact ``fmod`` by
    2 pi and one exact (Sterbenz) shift. Non-finite input raises ValueError.
    """
    theta = float(theta)
    if not math.isfinite(theta):
        raise ValueError(f"angle must be finite, got {theta!r}")
    # r = theta - 2 pi k with |r| < 2 pi, computed without rounding
    wrapped = math.fmod(theta, math.tau)
    if wrapped > math.pi:
        wrapped -= math.tau
    elif wrapped <= -math.pi:
        wrapped += math.tau
    return wrapped


def normalize_angles(angles: ArrayLike) -> NDArray[np.float64]:
    """Element-wise :func:`normalize_angle`: a new float64 array of the same shape, values in (-pi, pi].

    Non-finite entries raise ValueError.
    """
    wrapped = np.array(angles, dtype=np.float64)
    if not np.all(np.isfinite(wrapped)):
        raise ValueError("angles must be finite")
    # r = theta - 2 pi k with |r| < 2 pi, computed without rounding
    wrapped = np.fmod(wrapped, math.tau)
    wrapped[wrapped > math.pi] -= math.tau
    wrapped[wrapped <= -math.pi] += math.tau
    return wrapped


def _finite_float(name: str, value: float) -> float:
    """``float(value)``; ValueError unless it is finite.

    Not :func:`turtlelib.util.validation.finite_real`: Twist2D and Transform2D are built in every filter step,
    odometry update and simulated physics step, and finite_real's ``numbers.Real`` (ABC) isinstance check
    costs about 0.6-1.1 us per field against 0.15-0.2 us for this ``float()`` (measured with timeit),
    which makes their construction (about 2.5 us) about twice as slow. So, unlike finite_real, this
    accepts whatever ``float()`` converts (bools, numeric strings, 0-d arrays), as it always has.
    """
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return value


@dataclass(frozen=True, slots=True)
class Twist2D:
    """Planar twist ``V = [omega, vx, vy]``: angular rate (rad/s) and linear velocity (m/s).

    The frame it is expressed in is carried by the variable name (``V_body``, ``V_world``). Multiplying
    by a scalar scales every component (``V * dt`` is the displacement twist over ``dt`` seconds).
    Non-finite components raise ValueError.
    """

    omega: float = 0.0
    vx: float = 0.0
    vy: float = 0.0

    # numpy defers `np.float64(dt) * twist` to Twist2D.__rmul__ instead of building object arrays
    __array_ufunc__ = None

    def __post_init__(self) -> None:
        for name in ("omega", "vx", "vy"):
            object.__setattr__(self, name, _finite_float(name, getattr(self, name)))

    def as_array(self) -> NDArray[np.float64]:
        """``[omega, vx, vy]``, shape (3,)."""
        return np.array([self.omega, self.vx, self.vy])

    def __mul__(self, scale: float) -> Twist2D:
        if not isinstance(scale, Real):
            return NotImplemented
        return Twist2D(self.omega * scale, self.vx * scale, self.vy * scale)

    __rmul__ = __mul__


@dataclass(frozen=True, slots=True)
class Transform2D:
    """An element of SE(2), the pose ``T_ab`` of frame b in frame a (see the module docstring).

    ``x``, ``y`` in m, ``theta`` in rad, normalised into (-pi, pi] at construction; immutable and
    hashable. ``T_ab @ T_bc -> T_ac``; ``T_ab @ p_b -> p_a`` for a point of shape (2,) or points of shape
    (N, 2). Non-finite fields raise ValueError.
    """

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0

    # numpy defers `points @ T` to Transform2D (which refuses it) instead of building object arrays
    __array_ufunc__ = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "x", _finite_float("x", self.x))
        object.__setattr__(self, "y", _finite_float("y", self.y))
        object.__setattr__(self, "theta", normalize_angle(_finite_float("theta", self.theta)))

    @classmethod
    def identity(cls) -> Transform2D:
        return cls()

    @classmethod
    def from_matrix(cls, matrix: ArrayLike) -> Transform2D:
        """From a 3x3 homogeneous matrix ``[[R, p], [0, 0, 1]]``; ``theta = atan2(R[1, 0], R[0, 0])``.

        ValueError unless ``R`` is a rotation (orthonormal, det +1) and the last row is ``[0, 0, 1]``,
        both to 1e-9.
        """
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape != (3, 3) or not np.all(np.isfinite(m)):
            raise ValueError(f"expected a finite 3x3 matrix, got shape {m.shape}")
        rotation = m[:2, :2]
        is_rotation = np.allclose(rotation.T @ rotation, np.eye(2), rtol=0.0, atol=1e-9) and (
            np.linalg.det(rotation) > 0.0
        )
        if not is_rotation or not np.allclose(m[2], [0.0, 0.0, 1.0], rtol=0.0, atol=1e-9):
            raise ValueError(f"not a homogeneous SE(2) matrix:\n{m}")
        return cls(m[0, 2], m[1, 2], math.atan2(m[1, 0], m[0, 0]))

    @classmethod
    def exp(cls, twist: Twist2D) -> Transform2D:
        """``exp([V])``: the pose reached by holding ``twist`` for unit time (see :func:`integrate_twist`)."""
        return integrate_twist(twist)

    @property
    def translation(self) -> NDArray[np.float64]:
        """``p = [x, y]`` (m), shape (2,)."""
        return np.array([self.x, self.y])

    def rotation_matrix(self) -> NDArray[np.float64]:
        """``R = [[c, -s], [s, c]]`` with ``c, s = cos(theta), sin(theta)``, shape (2, 2)."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return np.array([[c, -s], [s, c]])

    def as_matrix(self) -> NDArray[np.float64]:
        """The homogeneous matrix ``[[R, p], [0, 0, 1]]``, shape (3, 3)."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return np.array([[c, -s, self.x], [s, c, self.y], [0.0, 0.0, 1.0]])

    def as_array(self) -> NDArray[np.float64]:
        """``[x, y, theta]``, shape (3,)."""
        return np.array([self.x, self.y, self.theta])

    def inverse(self) -> Transform2D:
        """``T_ba = T_ab^-1 = (R^T, -R^T p)``."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        # -R^T p
        return Transform2D(-c * self.x - s * self.y, s * self.x - c * self.y, -self.theta)

    def __matmul__(self, other: Transform2D | ArrayLike) -> Transform2D | NDArray[np.float64]:
        """``T_ab @ T_bc = T_ac`` = ``(R_ab R_bc, R_ab p_bc + p_ab)``; ``T_ab @ p_b = R_ab p_b + p_ab``."""
        if isinstance(other, Transform2D):
            c, s = math.cos(self.theta), math.sin(self.theta)
            # p_ac = R_ab p_bc + p_ab, theta_ac = theta_ab + theta_bc
            return Transform2D(
                c * other.x - s * other.y + self.x,
                s * other.x + c * other.y + self.y,
                self.theta + other.theta,
            )
        if isinstance(other, Twist2D):
            return NotImplemented
        try:
            p_b = np.asarray(other, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise ValueError(f"cannot read {type(other).__name__} as points") from error
        if not (p_b.shape == (2,) or (p_b.ndim == 2 and p_b.shape[1] == 2)):
            raise ValueError(f"points must have shape (2,) or (N, 2), got {p_b.shape}")
        if not np.all(np.isfinite(p_b)):
            raise ValueError("points must be finite")
        # p_a = R p_b + p  (row-vector form for (N, 2): p_a = p_b R^T + p)
        return p_b @ self.rotation_matrix().T + self.translation

    def transform_twist(self, twist_b: Twist2D) -> Twist2D:
        """The same twist expressed in frame a: ``V_a = [Ad_T_ab] V_b``.

        ``[Ad_T] = [[1, 0, 0], [y, c, -s], [-x, s, c]]`` for ``V = [omega, vx, vy]``, i.e.
        ``omega_a = omega_b`` and ``v_a = R v_b + omega_b * [y, -x]``.
        """
        c, s = math.cos(self.theta), math.sin(self.theta)
        omega = twist_b.omega
        # v_a = R v_b + omega * [y, -x]
        return Twist2D(
            omega,
            c * twist_b.vx - s * twist_b.vy + self.y * omega,
            s * twist_b.vx + c * twist_b.vy - self.x * omega,
        )

    def log(self) -> Twist2D:
        """The twist ``V`` with ``exp([V]) = T`` and ``omega = theta`` in (-pi, pi].

        ``v = V(theta)^-1 p`` with ``V(theta)^-1 = [[alpha, theta/2], [-theta/2, alpha]]`` and
        ``alpha = (theta/2) cot(theta/2)`` (Taylor series ``1 - theta^2/12 - theta^4/720 - theta^6/30240``
        for ``|theta| < SMALL_ANGLE_RAD``). At ``theta = pi``, ``alpha = 0``.
        """
        theta = self.theta
        half = 0.5 * theta
        if abs(theta) < SMALL_ANGLE_RAD:
            theta2 = theta * theta
            alpha = 1.0 - theta2 * (1.0 / 12.0 + theta2 * (1.0 / 720.0 + theta2 / 30240.0))
        else:
            alpha = half * math.cos(half) / math.sin(half)
        # v = V(theta)^-1 p
        return Twist2D(theta, alpha * self.x + half * self.y, -half * self.x + alpha * self.y)


def right_composition_jacobian(T_from: Transform2D, T_to: Transform2D) -> NDArray[np.float64]:
    """``G`` (3, 3): the Jacobian of ``T_to = T_from U`` (``U`` fixed) with respect to ``T_from``, both as
    ``[x, y, theta]`` of the outer frame; a heading error at ``T_from`` swings ``T_to`` about it::

        G = [[1, 0, -(y_to - y_from)], [0, 1, x_to - x_from], [0, 0, 1]]

    so a covariance ``P`` of ``T_from`` is ``G P G^T`` at ``T_to``."""
    G = np.eye(3)
    G[0, 2], G[1, 2] = -(T_to.y - T_from.y), T_to.x - T_from.x
    return G


def integrate_twist(twist: Twist2D) -> Transform2D:
    """``exp([V])``: the pose, relative to the start frame, after holding body twist ``V`` for unit time.

    ``theta = omega`` and ``p = V(omega) v`` with the SE(2) left Jacobian::

        V(omega) = [[a, -b], [b, a]],   a = sin(omega) / omega,   b = (1 - cos(omega)) / omega

    so pure translation (``omega = 0``: ``a = 1, b = 0``), pure rotation (``v = 0``) and arcs of radius
    ``|v| / |omega|`` are all exact. ``b`` is evaluated as ``2 sin^2(omega/2) / omega`` (no cancellation)
    and both use their Taylor series for ``|omega| < SMALL_ANGLE_RAD``.
    """
    omega = twist.omega
    if abs(omega) < SMALL_ANGLE_RAD:
        omega2 = omega * omega
        a = 1.0 - omega2 * (1.0 / 6.0 - omega2 / 120.0)
        b = omega * (0.5 - omega2 * (1.0 / 24.0 - omega2 / 720.0))
    else:
        a = math.sin(omega) / omega
        b = 2.0 * math.sin(0.5 * omega) ** 2 / omega
    # p = V(omega) v
    return Transform2D(a * twist.vx - b * twist.vy, b * twist.vx + a * twist.vy, omega)


def integrate_twists(
    omega: NDArray[np.float64], vx: NDArray[np.float64], vy: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The translations ``p_k = V(omega_k) v_k`` (n, 2) of ``exp([V_k])`` for twists given by arrays
    ``omega``, ``vx``, ``vy`` (n,): :func:`integrate_twist` elementwise (its heading is ``omega_k``), with the
    same closed forms and series."""
    omega2 = omega * omega
    small = np.abs(omega) < SMALL_ANGLE_RAD
    a = 1.0 - omega2 * (1.0 / 6.0 - omega2 / 120.0)
    b = omega * (0.5 - omega2 * (1.0 / 24.0 - omega2 / 720.0))
    if not small.all():
        # the closed forms where they do not cancel (1 stands in elsewhere)
        closed = np.where(small, 1.0, omega)
        a = np.where(small, a, np.sin(closed) / closed)
        b = np.where(small, b, 2.0 * np.sin(0.5 * closed) ** 2 / closed)
    # p = V(omega) v
    return np.column_stack([a * vx - b * vy, b * vx + a * vy])
