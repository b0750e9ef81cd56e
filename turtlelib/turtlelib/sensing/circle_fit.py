"""Algebraic circle fitting: the "hyper" fit of Al-Sharadqah & Chernov (2009), batched over point sets.

Model
-----
A circle is the zero set of ``A0 z + A1 x + A2 y + A3 = 0`` with ``z = x^2 + y^2``: centre
``(-A1, -A2) / (2 A0)``, radius ``sqrt(A1^2 + A2^2 - 4 A0 A3) / (2 |A0|)``; ``A0 = 0`` is a line. With the
data matrix ``Z`` (N, 4) of rows ``[z_i, x_i, y_i, 1]`` and the moment matrix ``M = Z^T Z / N``, the
hyper fit minimises the algebraic error ``A^T M A`` subject to ``A^T H A = 1`` with::

    H = 2 T - P = [[8 z_bar, 4 x_bar, 4 y_bar, 2],
                   [4 x_bar, 1,       0,       0],
                   [4 y_bar, 0,       1,       0],
                   [2,       0,       0,       0]]

(``T`` is Taubin's constraint matrix, ``P`` Pratt's), so ``A`` is the generalised eigenvector of
``M A = eta H A`` with the smallest non-negative ``eta``
(Al-Sharadqah & Chernov, "Error analysis for circle fitting algorithms", Electron. J. Stat. 3, 2009:
no essential bias to second order). ``H`` is indefinite (one negative eigenvalue), so exactly one ``eta``
is negative and the wanted one is the second smallest.

Numerics
--------
Each point set is first centred on its centroid and scaled by its RMS distance ``s`` from it (the fit is
invariant under translation, rotation and scaling), so ``x_bar = y_bar = 0``, ``z_bar = 1`` and ``H`` is
a constant. As in Chernov's SVD formulation, with ``M = Y^2`` (``Y`` the symmetric square root),
``Q = Y H^-1 Y`` is symmetric with the same eigenvalues ``eta`` and eigenvectors ``B = Y A``, so
``A = Y^-1 B``. An exact fit (singular ``M``) drives the wanted eigenvalue to 0 and ``A`` to ``M``'s null
vector; the eigenvalues of ``M`` are floored at ``_EIGEN_FLOOR`` so that this limit is taken smoothly
(``A`` is dominated by the null vector, whatever the floor). Every point set is solved in one batched
pass (stacked ``eigh``), with no Python loop.

Degenerate input: the best fit to collinear points is their line (``A0 = 0``), the limit of a circle of
infinite radius. A set whose fit has ``|A0| <= COLLINEAR_TOL |A|`` in the scaled frame (a circle more than
about 5e9 times wider than the points' RMS spread) is reported as a line: no circle. Points that are
collinear only up to rounding may instead give a finite circle of enormous radius (rounding errors of
the coordinates, relative to the spread, bend the line), which any radius bound rejects.

Range-sensor refinement
-----------------------
The hyper fit is optimal for isotropic point noise. A LiDAR's noise runs along its beams, and a scan also
shows where a cylinder's outline (silhouette) lies; :func:`refine_for_range_sensor` takes one
Gauss-Newton step of that likelihood from the hyper fits (see its docstring).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..util.validation import finite_real, positive, store

# |A0| / |A| at or below this (scaled frame) means the fitted curve is a line (radius / spread > 5e9).
COLLINEAR_TOL = 1e-10
# Floor on the eigenvalues of the scaled moment matrix (whose largest is >= 1) before taking Y^-1.
_EIGEN_FLOOR = 1e-200
# Relative Tikhonov term in the Gauss-Newton step: J^T J + _GN_DAMPING tr(J^T J) I.
_GN_DAMPING = 1e-13
_IDENTITY_3 = np.eye(3)
# Floor on point-to-centre distances in the Gauss-Newton step (a point exactly at the centre).
_TINY = 1e-300
# H^-1 in the scaled frame (x_bar = y_bar = 0, z_bar = 1).
_H_INV = np.array(
    [
        [0.0, 0.0, 0.0, 0.5],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.5, 0.0, 0.0, -2.0],
    ]
)


@dataclass(frozen=True)
class Circle:
    """A circle with centre ``(x, y)`` and ``radius`` (m, or the units of the fitted points).

    Fields must be finite with ``radius > 0`` (ValueError).
    """

    x: float
    y: float
    radius: float

    def __post_init__(self) -> None:
        store(self, ("x", "y"), finite_real, prefix="circle ")
        store(self, ("radius",), positive, prefix="circle ")

    @property
    def centre(self) -> NDArray[np.float64]:
        """``[x, y]``, shape (2,)."""
        return np.array([self.x, self.y])


@dataclass(frozen=True, eq=False)
class CircleFits:
    """Circle fits of K point sets (hyper fits or their refinements): ``centre`` (K, 2), ``radius`` (K,),
    ``residual`` (K,).

    ``residual`` is the RMS geometric error ``sqrt(mean_i (|p_i - c| - R)^2)`` of each set, in the
    points' units. A set that is collinear to rounding (see the module docstring) or whose points all
    coincide has no circle: ``radius = inf`` and ``centre``, ``residual`` NaN.
    """

    centre: NDArray[np.float64]
    radius: NDArray[np.float64]
    residual: NDArray[np.float64]

    def __len__(self) -> int:
        return self.radius.shape[0]

    @property
    def is_circle(self) -> NDArray[np.bool_]:
        """Which sets have a finite fitted circle, shape (K,)."""
        return np.isfinite(self.radius)


def _checked_points(points: ArrayLike) -> NDArray[np.float64]:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points must have shape (N, 2), got {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError("points must be finite")
    return p


def _checked_sets(points: ArrayLike, offsets: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """Validated points (P, 2) and offsets (K + 1,) rising from 0 to P in steps of at least 3."""
    p = _checked_points(points)
    offsets = np.asarray(offsets)
    if offsets.ndim != 1 or offsets.size < 1 or not np.issubdtype(offsets.dtype, np.integer):
        raise ValueError("offsets must be a 1-D integer array [0, ..., P]")
    if offsets[0] != 0 or offsets[-1] != p.shape[0] or np.any(np.diff(offsets) < 3):
        raise ValueError("offsets must rise from 0 to len(points) in steps of at least 3")
    return p, offsets.astype(np.intp)


def fit_circles(points: ArrayLike, offsets: ArrayLike) -> CircleFits:
    """Hyper-fit a circle to each of K point sets in one vectorised pass.

    ``points`` (P, 2) holds the sets back to back: set k is ``points[offsets[k]:offsets[k + 1]]``, with
    ``offsets`` (K + 1,) integers rising from ``offsets[0] = 0`` to ``offsets[K] = P`` by at least 3 (a
    circle needs three points; the sets should hold at least three distinct points, otherwise the fit
    is one of the many exact circles through them). ValueError for bad shapes, non-finite points or bad
    offsets. See the module docstring for the algorithm and :class:`CircleFits` for the result.
    """
    p, offsets = _checked_sets(points, offsets)
    if offsets.shape[0] == 1:
        return CircleFits(np.empty((0, 2)), np.empty(0), np.empty(0))
    starts, n = offsets[:-1], np.diff(offsets)
    centre, radius = hyper_fit_sets(p, starts, n)
    with np.errstate(invalid="ignore"):
        return CircleFits(centre, radius, rms_residual(p, starts, n, centre, radius))


def hyper_fit_sets(
    p: NDArray[np.float64], starts: NDArray[np.intp], n: NDArray[np.intp]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The batched hyper fit without input checks: ``centre`` (K, 2) and ``radius`` (K,).

    Set k is ``p[starts[k]:starts[k] + n[k]]`` (``n >= 3``, sets back to back, ``p`` finite); this is the
    hot path of :func:`fit_circles`, which validates its input first. Sets without a finite circle get
    ``radius = inf`` and a NaN centre.
    """
    nf = n.astype(np.float64)
    # centre each set on its centroid and scale it to unit RMS distance: u = (p - p_bar) / s
    centroid = np.add.reduceat(p, starts, axis=0) / nf[:, None]
    d = p - centroid.repeat(n, axis=0)
    d2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
    spread = np.sqrt(np.add.reduceat(d2, starts) / nf)
    has_spread = spread > 0.0
    inv_scale = (1.0 / np.where(has_spread, spread, 1.0)).repeat(n)

    # M = Z^T Z / N with rows [z, x, y, 1], z = x^2 + y^2 (so z_bar = 1)
    z_rows = np.empty((p.shape[0], 4))
    z_rows[:, 0] = d2 * inv_scale * inv_scale
    z_rows[:, 1:3] = d * inv_scale[:, None]
    z_rows[:, 3] = 1.0
    moments = np.add.reduceat(z_rows[:, :, None] * z_rows[:, None, :], starts, axis=0) / nf[:, None, None]

    # M = Y^2,  Q = Y H^-1 Y,  Q B = eta B,  A = Y^-1 B for the second-smallest eta
    m_eigenvalues, m_eigenvectors = np.linalg.eigh(moments)
    root = np.sqrt(np.maximum(m_eigenvalues, _EIGEN_FLOOR))[:, None, :]
    m_eigenvectors_t = m_eigenvectors.transpose(0, 2, 1)
    y = (m_eigenvectors * root) @ m_eigenvectors_t
    y_inv = (m_eigenvectors / root) @ m_eigenvectors_t
    _, b = np.linalg.eigh(y @ _H_INV @ y)
    a = (y_inv @ b[:, :, 1:2])[:, :, 0]

    # centre (-A1, -A2) / (2 A0), radius sqrt(A1^2 + A2^2 - 4 A0 A3) / (2 |A0|)  (scaled frame)
    is_circle = has_spread & (a[:, 0] * a[:, 0] > COLLINEAR_TOL**2 * (a * a).sum(axis=1))
    half_inv_a0 = 0.5 / np.where(is_circle, a[:, 0], 1.0)
    discriminant = np.maximum(a[:, 1] ** 2 + a[:, 2] ** 2 - 4.0 * a[:, 0] * a[:, 3], 0.0)
    centre = centroid - (spread * half_inv_a0)[:, None] * a[:, 1:3]
    radius = spread * np.sqrt(discriminant) * np.abs(half_inv_a0)
    if not is_circle.all():
        centre[~is_circle] = np.nan
        radius[~is_circle] = np.inf
    return centre, radius


def rms_residual(
    p: NDArray[np.float64],
    starts: NDArray[np.intp],
    n: NDArray[np.intp],
    centre: NDArray[np.float64],
    radius: NDArray[np.float64],
) -> NDArray[np.float64]:
    """``sqrt(mean_i (|p_i - c| - R)^2)`` per set; no input checks (NaN, with a floating-point warning
    unless the caller silences it, where the circle is not finite)."""
    offset = p - centre.repeat(n, axis=0)
    error = np.hypot(offset[:, 0], offset[:, 1]) - radius.repeat(n)
    return np.sqrt(np.add.reduceat(error * error, starts) / n)


def refine_for_range_sensor(
    points: ArrayLike,
    offsets: ArrayLike,
    fits: CircleFits,
    range_std: float,
    min_cos_incidence: float = 0.2,
    edge_directions: ArrayLike | None = None,
    edge_std: ArrayLike | None = None,
) -> CircleFits:
    """One Gauss-Newton step from ``fits`` towards the maximum-likelihood circles of a range sensor.

    The sensor sits at the origin and measures ``p_i = rho_i u_i`` (``u_i = p_i / |p_i|``) with range
    noise of standard deviation ``range_std`` along the beam. To first order a range error ``delta``
    moves ``p_i`` off the circle by ``delta cos(gamma_i)``, with ``cos(gamma_i) = |u_i . n_i|`` and the
    circle normal ``n_i = (p_i - c) / |p_i - c|``, so the point residual is::

        e_i = (|p_i - c| - R) w_i,   de_i / d(c, R) = -[n_i, 1] w_i,   w_i = 1 / (range_std cos(gamma_i))

    with ``cos(gamma_i)`` floored at ``min_cos_incidence`` (grazing beams) and held fixed in the step.
    Optionally each set also has up to two silhouette edges: unit rays ``v_j`` from the origin tangent to
    the circle (``edge_directions`` (K, 2, 2)) known to a lateral standard deviation ``sigma_j`` (m, at
    the circle; ``edge_std`` (K, 2), ``inf`` where a set lacks that edge). A ray is tangent when the
    distance of ``c`` from it equals ``R``::

        e_j = (|v_j x c| - R) / sigma_j,   de_j / d(c, R) = [-s v_jy, s v_jx, -1] / sigma_j,
        s = sign(v_j x c)

    The step solves ``(J^T J) delta = -J^T e`` per set; from the isotropic hyper fit one step recovers
    most of the gain. A set keeps its input circle when the step is not finite, moves the centre or the
    radius by more than the input radius, or leaves a non-positive radius; sets without a finite circle
    pass through unchanged. ``residual`` is the RMS geometric error of the returned circles. Same
    ``points``/``offsets`` layout as :func:`fit_circles`.
    ValueError for ``range_std <= 0``, ``min_cos_incidence`` outside (0, 1], points at the origin, bad
    shapes, or ``edge_std`` that is not > 0.
    """
    if not (math.isfinite(range_std) and range_std > 0.0):
        raise ValueError(f"range_std must be finite and > 0, got {range_std}")
    if not 0.0 < min_cos_incidence <= 1.0:
        raise ValueError(f"min_cos_incidence must lie in (0, 1], got {min_cos_incidence}")
    p, offsets = _checked_sets(points, offsets)
    k = offsets.shape[0] - 1
    if fits.radius.shape != (k,):
        raise ValueError(f"expected {k} fits, got {fits.radius.shape[0]}")
    if np.any((p[:, 0] == 0.0) & (p[:, 1] == 0.0)):
        raise ValueError("a range sensor cannot measure a point at its origin")
    if (edge_directions is None) != (edge_std is None):
        raise ValueError("give both edge_directions and edge_std, or neither")
    if edge_directions is None:
        edge_v, edge_inv_std = np.ones((k, 2, 2)), np.zeros((k, 2))
    else:
        edge_v = np.asarray(edge_directions, dtype=np.float64)
        sigma = np.asarray(edge_std, dtype=np.float64)
        if edge_v.shape != (k, 2, 2) or sigma.shape != (k, 2) or not np.isfinite(edge_v).all():
            raise ValueError("edge_directions must be finite (K, 2, 2) and edge_std (K, 2)")
        if not np.all(sigma > 0.0):
            raise ValueError("edge_std must be > 0 (inf for a missing edge)")
        edge_inv_std = 1.0 / sigma
    if k == 0:
        return fits
    starts, n = offsets[:-1], np.diff(offsets)
    # sets without a finite circle take a dummy start and keep their input
    usable = fits.is_circle
    centre, radius = range_sensor_step(
        p,
        np.hypot(p[:, 0], p[:, 1]),
        starts,
        n,
        np.where(usable[:, None], fits.centre, 0.0),
        np.where(usable, fits.radius, 1.0),
        range_std,
        min_cos_incidence,
        edge_v,
        np.where(usable[:, None], edge_inv_std, 0.0),
    )
    centre = np.where(usable[:, None], centre, fits.centre)
    radius = np.where(usable, radius, fits.radius)
    with np.errstate(invalid="ignore"):
        return CircleFits(centre, radius, rms_residual(p, starts, n, centre, radius))


def range_sensor_step(
    p: NDArray[np.float64],
    rho: NDArray[np.float64],
    starts: NDArray[np.intp],
    n: NDArray[np.intp],
    centre0: NDArray[np.float64],
    radius0: NDArray[np.float64],
    range_std: float,
    min_cos_incidence: float,
    edge_v: NDArray[np.float64],
    edge_inv_std: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The Gauss-Newton step of :func:`refine_for_range_sensor` without input checks.

    Every input must be finite, with ``rho = |p| > 0`` and ``radius0 > 0``; ``edge_inv_std`` (K, 2)
    holds ``1 / sigma_j`` (0 for a missing edge). Returns ``centre`` (K, 2) and ``radius`` (K,).
    """
    # cos(gamma_i) = max(|u_i . n_i|, floor),  u_i = p_i / |p_i|,  n_i = (p_i - c) / |p_i - c|
    offset = p - centre0.repeat(n, axis=0)
    dist = np.maximum(np.hypot(offset[:, 0], offset[:, 1]), _TINY)
    normal = offset / dist[:, None]
    cos_incidence = np.abs(p[:, 0] * normal[:, 0] + p[:, 1] * normal[:, 1]) / rho
    w = 1.0 / (range_std * np.maximum(cos_incidence, min_cos_incidence))
    # e_i = (|p_i - c| - R) w_i,  J_i = -[n_x, n_y, 1] w_i
    jac = np.empty((p.shape[0], 3))
    jac[:, :2] = normal * -w[:, None]
    jac[:, 2] = -w
    e = (dist - radius0.repeat(n)) * w
    jtj = np.add.reduceat(jac[:, :, None] * jac[:, None, :], starts, axis=0)
    jte = np.add.reduceat(jac * e[:, None], starts, axis=0)

    # e_j = (|v_j x c| - R) / sigma_j,  J_j = [-s v_y, s v_x, -1] / sigma_j,  s = sign(v_j x c)
    h = edge_v[:, :, 0] * centre0[:, None, 1] - edge_v[:, :, 1] * centre0[:, None, 0]
    signed_inv_std = np.copysign(edge_inv_std, h)
    jac_edge = np.empty(edge_v.shape[:2] + (3,))
    jac_edge[:, :, 0] = -signed_inv_std * edge_v[:, :, 1]
    jac_edge[:, :, 1] = signed_inv_std * edge_v[:, :, 0]
    jac_edge[:, :, 2] = -edge_inv_std
    e_edge = (np.abs(h) - radius0[:, None]) * edge_inv_std
    jtj += np.einsum("kji,kjl->kil", jac_edge, jac_edge)
    jte += np.einsum("kji,kj->ki", jac_edge, e_edge)

    # (J^T J + eps tr(J^T J) I) delta = -J^T e: the relative damping keeps every solve non-singular
    damping = _GN_DAMPING * np.trace(jtj, axis1=1, axis2=2)
    delta = np.linalg.solve(jtj + damping[:, None, None] * _IDENTITY_3, -jte[:, :, None])[:, :, 0]
    centre = centre0 + delta[:, :2]
    radius = radius0 + delta[:, 2]
    # a NaN step fails both comparisons
    accept = (np.abs(delta) <= radius0[:, None]).all(axis=1) & (radius > 0.0)
    if not accept.all():
        centre[~accept] = centre0[~accept]
        radius[~accept] = radius0[~accept]
    return centre, radius


def fit_circle(points: ArrayLike) -> Circle:
    """The hyper fit (Al-Sharadqah & Chernov 2009) of a circle to ``points`` (N, 2).

    ValueError when N < 3, a point is not finite, fewer than three points are distinct, or the fit is a
    line: collinear points have no finite best-fitting circle (the algebraic fit is the line itself, a
    circle of infinite radius). Points collinear only up to rounding may give a huge finite circle
    instead; see the module docstring.
    """
    p = _checked_points(points)
    if p.shape[0] < 3:
        raise ValueError(f"a circle fit needs at least 3 points, got {p.shape[0]}")
    if np.unique(p, axis=0).shape[0] < 3:
        raise ValueError("a circle fit needs at least 3 distinct points")
    centre, radius = hyper_fit_sets(p, np.zeros(1, dtype=np.intp), np.array([p.shape[0]]))
    if not np.isfinite(radius[0]):
        raise ValueError("the points are collinear: their best fit is a line (a circle of infinite radius)")
    return Circle(centre[0, 0], centre[0, 1], radius[0])
