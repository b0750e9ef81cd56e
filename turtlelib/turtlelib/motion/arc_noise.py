"""Process noise of one motion step along a constant-twist arc, independent of how the motion is split.

Model
-----
A step moves the body for unit time ``s`` in [0, 1] at the constant body displacement twist
``xi = [omega, vx, vy]`` (rad, m, m: the twist over the step), from pose ``q = [x, y, theta]`` to
``q(1) = q (+) exp([xi])``. The twist is perturbed by white noise of intensity
``Sigma = Cov([dvx, dvy, domega])`` (per unit ``s``: the variances the whole step adds to the twist), with
``dvy`` independent of the others (``Sigma_vx_vy = Sigma_vy_omega = 0``). Through the linearised error
dynamics along the arc ``theta(s) = theta + omega s``, ``p(s)``::

    Q = integral_0^1 A(s) Sigma A(s)^T ds,   A(s) = [[cos(theta(s)), -sin(theta(s)), -(y(1) - y(s))],
                                                     [sin(theta(s)),  cos(theta(s)),   x(1) - x(s) ],
                                                     [0,              0,               1           ]]

(``A(s)`` is the transition ``[[1, 0, -dy], [0, 1, dx], [0, 0, 1]]`` from ``s`` to the step's end applied
to the noise input ``[R(theta(s)) [dvx, dvy], domega]``). Because these transitions compose and the
intensities of a noise proportional to travel, turn or time add up along the path, one step of a
constant-twist motion gives exactly the covariance of any number of shorter steps along it.

Closed form
-----------
In the frame of the step's end (heading ``theta_1 = theta + omega``), with the remaining fraction
``t = 1 - s`` and ``w = omega``, the columns of ``A`` are::

    a_vx = [cos(w t), -sin(w t), 0],   a_vy = [sin(w t), cos(w t), 0],
    a_omega = [vx g - vy f, vx f + vy g, 1],   f = sin(w t) / w,   g = (1 - cos(w t)) / w

(``J [p(1) - p(s)]``: the rest of the arc, turned by 90 degrees). So ``Q = Rot(theta_1) Q_end
Rot(theta_1)^T`` where ``Q_end`` is ``Sigma``-weighted sums of the integrals over ``t`` in [0, 1] of the
products of ``cos(w t)``, ``sin(w t)``, ``f``, ``g`` and 1, each in closed form (:func:`_arc_integrals`).
They are written through ``sinc(x) = sin(x) / x`` and the series of ``(x - sin x) / x^3`` for ``|x| < 1``,
so that none cancels for short or straight steps (relative error ~1e-15 at any ``w``, and ``w = 0`` is
the straight line).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

# a float (one step) or an array of floats (a batch of steps, elementwise)
Floats = float | NDArray[np.float64]

# Largest heading change of one step (rad): a turn of more than a thousand rad between two readings is a
# corrupt reading, not a motion.
MAX_STEP_TURN_RAD = 1000.0
# Below this |x| the series of (x - sin x) / x^3 and of its differences are used (their direct forms cancel)
SERIES_BELOW = 1.0
# (-1)^k / (2k + 3)!, k = 0 ... 9: the series (x - sin x) / x^3 = sum_k c_k x^(2k), truncated below 1e-19
# of its value for |x| < 1
_S3_SERIES = tuple((-1) ** k / math.factorial(2 * k + 3) for k in range(10))
# (-1)^(k+1) (4^k - 1) / (2k + 3)!, k = 1 ... 11: the series of S3(w) - S3(2 w), truncated below 1e-18 of
# its value for |w| < 1
_S3_DIFFERENCE_SERIES = tuple((-1) ** (k + 1) * (4**k - 1) / math.factorial(2 * k + 3) for k in range(1, 12))
# For |w| < 1, the coefficients of w^(2k), k = 0 ... 13, of S3(w), S3(2w), sinc(w), sinc(w/2) and
# S3(w) - S3(2w) (columns), each truncated below 1e-18 of its value: (-1)^k / (2k + 3)! times 1, 4^k;
# (-1)^k / (2k + 1)! times 1, 4^-k; (-1)^k (1 - 4^k) / (2k + 3)!
_SMALL_TURN_SERIES = np.array(
    [
        [
            (-1) ** k / math.factorial(2 * k + 3),
            (-1) ** k * 4**k / math.factorial(2 * k + 3),
            (-1) ** k / math.factorial(2 * k + 1),
            (-1) ** k / (4**k * math.factorial(2 * k + 1)),
            (-1) ** k * (1 - 4**k) / math.factorial(2 * k + 3),
        ]
        for k in range(14)
    ]
)


def _even_series(coefficients: tuple[float, ...], x2: float) -> float:
    """``sum_k coefficients[k] x2^k`` (Horner)."""
    total = 0.0
    for c in reversed(coefficients):
        total = total * x2 + c
    return total


class _Floats:
    """The elementary functions on floats (one step)."""

    cos = staticmethod(math.cos)
    sin = staticmethod(math.sin)

    @staticmethod
    def s3(x: float) -> float:
        """``S3(x) = (x - sin x) / x^3`` (1/6 at 0)."""
        if abs(x) < SERIES_BELOW:
            return _even_series(_S3_SERIES, x * x)
        return (x - math.sin(x)) / x**3

    @staticmethod
    def sinc(x: float) -> float:
        """``sin(x) / x`` (1 at 0)."""
        return math.sin(x) / x if x != 0.0 else 1.0

    @staticmethod
    def terms(w: float) -> tuple[float, float, float, float, float]:
        """``(S3(w), S3(2w), sinc(w), sinc(w/2), S3(w) - S3(2w))``, the last by its series where it
        cancels."""
        s3_w, s3_2w = _Floats.s3(w), _Floats.s3(2.0 * w)
        if abs(w) < SERIES_BELOW:
            difference = _even_series(_S3_DIFFERENCE_SERIES, w * w) * w * w
        else:
            difference = s3_w - s3_2w
        return s3_w, s3_2w, _Floats.sinc(w), _Floats.sinc(0.5 * w), difference


class _Arrays:
    """The same functions elementwise on arrays (a batch of steps)."""

    cos = staticmethod(np.cos)
    sin = staticmethod(np.sin)

    @staticmethod
    def terms(w: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        """:meth:`_Floats.terms` elementwise: for ``|w| < SERIES_BELOW`` (the usual short steps) all five by
        one product of the powers of ``w^2`` with :data:`_SMALL_TURN_SERIES`, the direct forms elsewhere."""
        small = np.abs(w) < SERIES_BELOW
        series = tuple(((w[:, None] ** (2 * np.arange(len(_SMALL_TURN_SERIES)))) @ _SMALL_TURN_SERIES).T)
        if small.all():
            return series
        # the direct forms where |w| >= 1 (1 stands in elsewhere, so nothing divides by 0)
        x = np.where(small, 1.0, w)
        s3_w = (x - np.sin(x)) / x**3
        s3_2w = (2.0 * x - np.sin(2.0 * x)) / (2.0 * x) ** 3
        direct = (s3_w, s3_2w, np.sin(x) / x, np.sin(0.5 * x) / (0.5 * x), s3_w - s3_2w)
        return tuple(np.where(small, by_series, d) for by_series, d in zip(series, direct, strict=True))


class _ArcIntegrals(NamedTuple):
    """The integrals over ``t`` in [0, 1] of the products of ``c = cos(w t)``, ``s = sin(w t)``,
    ``f = sin(w t) / w`` and ``g = (1 - cos(w t)) / w`` that ``Q_end`` needs, named by the product
    (``cc = 1 - ss``), with ``S3(x) = (x - sin x) / x^3``::

        ss = 2 w^2 S3(2w),         sc = w sinc(w)^2 / 2,     f = sinc(w/2)^2 / 2,   g = w S3(w)
        ff = 2 S3(2w),             fg = w sinc(w/2)^4 / 8,   gg = 2 (S3(w) - S3(2w))

    and those of the speed/turn correlation (:meth:`cross`). Also the terms they are made of."""

    w: Floats
    s3_w: Floats
    s3_2w: Floats
    sinc_w: Floats
    half2: Floats
    ss: Floats
    sc: Floats
    f: Floats
    g: Floats
    ff: Floats
    fg: Floats
    gg: Floats

    def cross(self) -> tuple[Floats, ...]:
        """``(c, s, cf, cg, sf, sg)``::

        c = sinc(w),         s = w sinc(w/2)^2 / 2,   cf = sinc(w)^2 / 2,   cg = w (2 S3(2w) - S3(w))
        sf = 2 w S3(2w),     sg = w^2 sinc(w/2)^4 / 8
        """
        w, half2 = self.w, self.half2
        return (
            self.sinc_w,
            0.5 * w * half2,
            0.5 * self.sinc_w * self.sinc_w,
            w * (2.0 * self.s3_2w - self.s3_w),
            2.0 * w * self.s3_2w,
            0.125 * w * w * half2 * half2,
        )


def _arc_integrals(w: Floats, fn: type[_Floats] | type[_Arrays]) -> _ArcIntegrals:
    """:class:`_ArcIntegrals` of turn ``w`` (a float, or an array with ``fn = _Arrays``)."""
    s3_w, s3_2w, sinc_w, sinc_half, difference = fn.terms(w)
    half2 = sinc_half * sinc_half
    return _ArcIntegrals(
        w=w,
        s3_w=s3_w,
        s3_2w=s3_2w,
        sinc_w=sinc_w,
        half2=half2,
        ss=2.0 * w * w * s3_2w,
        sc=0.5 * w * sinc_w * sinc_w,
        f=0.5 * half2,
        g=w * s3_w,
        ff=2.0 * s3_2w,
        fg=0.125 * w * half2 * half2,
        gg=2.0 * difference,
    )


def arc_covariance(
    theta_rad: float,
    omega: float,
    vx: float,
    vy: float,
    var_vx: float,
    cov_vx_omega: float,
    var_omega: float,
    var_vy: float = 0.0,
) -> NDArray[np.float64]:
    """The (3, 3) covariance of ``[x, y, theta]`` added by a step of twist ``[omega, vx, vy]`` from heading
    ``theta_rad``, for twist noise ``Sigma`` with entries ``var_vx``, ``cov_vx_omega``, ``var_omega``,
    ``var_vy`` (module docstring).

    ValueError for a step that turns the body by more than ``MAX_STEP_TURN_RAD``.
    """
    check_turn(omega)
    Q_xx, Q_xy, Q_xt, Q_yy, Q_yt, Q_tt = _arc_covariance_entries(
        _Floats, theta_rad, omega, vx, vy, var_vx, cov_vx_omega, var_omega, var_vy
    )
    return np.array([Q_xx, Q_xy, Q_xt, Q_xy, Q_yy, Q_yt, Q_xt, Q_yt, Q_tt]).reshape(3, 3)


def arc_covariances(
    theta_rad: ArrayLike,
    omega: ArrayLike,
    vx: ArrayLike,
    vy: ArrayLike,
    var_vx: ArrayLike,
    cov_vx_omega: ArrayLike,
    var_omega: ArrayLike,
    var_vy: ArrayLike = 0.0,
) -> NDArray[np.float64]:
    """:func:`arc_covariance` of a batch of steps: the arguments broadcast to a shape (n,) and the result
    is (n, 3, 3). ValueError if any step turns by more than ``MAX_STEP_TURN_RAD``."""
    args = np.broadcast_arrays(
        *(np.atleast_1d(np.asarray(value, dtype=np.float64)) for value in (theta_rad, omega, vx, vy))
    )
    theta_rad, omega, vx, vy = args
    turning = ~(np.abs(omega) <= MAX_STEP_TURN_RAD)
    if turning.any():
        _refuse_turn(float(omega[turning][0]))
    Q_xx, Q_xy, Q_xt, Q_yy, Q_yt, Q_tt = _arc_covariance_entries(
        _Arrays, theta_rad, omega, vx, vy, var_vx, cov_vx_omega, var_omega, var_vy
    )
    Q = np.empty((len(omega), 3, 3))
    Q[:, 0, 0], Q[:, 1, 1], Q[:, 2, 2] = Q_xx, Q_yy, Q_tt
    Q[:, 0, 1] = Q[:, 1, 0] = Q_xy
    Q[:, 0, 2] = Q[:, 2, 0] = Q_xt
    Q[:, 1, 2] = Q[:, 2, 1] = Q_yt
    return Q


def check_turn(omega: float) -> None:
    """ValueError unless ``|omega| <= MAX_STEP_TURN_RAD`` (rad): the turn of one step that is a motion."""
    if not abs(omega) <= MAX_STEP_TURN_RAD:
        _refuse_turn(omega)


def _refuse_turn(omega: float) -> None:
    raise ValueError(f"a step turning the body by {omega!r} rad is not a motion (> {MAX_STEP_TURN_RAD} rad)")


def _arc_covariance_entries(
    fn: type[_Floats] | type[_Arrays],
    theta_rad: Floats,
    omega: Floats,
    vx: Floats,
    vy: Floats,
    var_vx: Floats,
    cov_vx_omega: Floats,
    var_omega: Floats,
    var_vy: Floats,
) -> tuple[Floats, ...]:
    """``(Q_xx, Q_xy, Q_xt, Q_yy, Q_yt, Q_tt)`` of :func:`arc_covariance`, on floats or (``fn = _Arrays``)
    elementwise on arrays."""
    i = _arc_integrals(omega, fn)
    ss, sc = i.ss, i.sc
    cc = 1.0 - ss
    # Q_end = var_vx int a_vx a_vx^T + var_vy int a_vy a_vy^T + var_omega int a_w a_w^T
    #         + cov_vx_omega int (a_vx a_w^T + a_w a_vx^T),   a_w = [A, B, 1]
    # with A = vx g - vy f, B = vx f + vy g
    q_xx = var_vx * cc + var_vy * ss
    q_xy = (var_vy - var_vx) * sc
    q_yy = var_vx * ss + var_vy * cc
    # int A^2, int A B, int B^2, int A, int B
    aa = vx * vx * i.gg - 2.0 * vx * vy * i.fg + vy * vy * i.ff
    ab = (vx * vx - vy * vy) * i.fg + vx * vy * (i.gg - i.ff)
    bb = vx * vx * i.ff + 2.0 * vx * vy * i.fg + vy * vy * i.gg
    a1 = vx * i.g - vy * i.f
    b1 = vx * i.f + vy * i.g
    q_xx = q_xx + var_omega * aa
    q_xy = q_xy + var_omega * ab
    q_yy = q_yy + var_omega * bb
    q_xt = var_omega * a1
    q_yt = var_omega * b1
    # (a float first: np.ndim would convert it to an array)
    if (
        cov_vx_omega != 0.0
        if isinstance(cov_vx_omega, float)
        else np.ndim(cov_vx_omega) or cov_vx_omega != 0.0
    ):
        # int a_vx a_w^T = [[int c A, int c B, int c], [-int s A, -int s B, -int s], [0, 0, 0]]
        i_c, i_s, cf, cg, sf, sg = i.cross()
        ca = vx * cg - vy * cf
        cb = vx * cf + vy * cg
        sa = vx * sg - vy * sf
        sb = vx * sf + vy * sg
        q_xx = q_xx + 2.0 * cov_vx_omega * ca
        q_xy = q_xy + cov_vx_omega * (cb - sa)
        q_yy = q_yy - 2.0 * cov_vx_omega * sb
        q_xt = q_xt + cov_vx_omega * i_c
        q_yt = q_yt - cov_vx_omega * i_s
    # Q = Rot(theta_1) Q_end Rot(theta_1)^T
    heading = theta_rad + omega
    c, s = fn.cos(heading), fn.sin(heading)
    Q_xx = c * c * q_xx + s * s * q_yy - 2.0 * c * s * q_xy
    Q_xy = c * s * (q_xx - q_yy) + (c * c - s * s) * q_xy
    Q_yy = s * s * q_xx + c * c * q_yy + 2.0 * c * s * q_xy
    Q_xt = c * q_xt - s * q_yt
    Q_yt = s * q_xt + c * q_yt
    return Q_xx, Q_xy, Q_xt, Q_yy, Q_yt, var_omega
