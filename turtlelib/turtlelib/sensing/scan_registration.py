"""Registration of a 2D LiDAR scan to a local map of recent scans, seeded and regularised by a motion prior.

Model
-----
A scan gives points ``p_i`` (body frame, m), thinned to one per ``voxel_m`` cell. The local map holds points
``q_j`` (map frame) with the covariance ``C_j`` of the neighbours around each (a wall is long along itself
and thin across; a corner or a post is round). With the body pose ``x = [x, y, theta]`` (``T_map_body``,
perturbed additively in the map frame), point ``i`` against its nearest map point ``j`` has the residual::

    d_i(x) = R(theta) p_i + t - q_j

    C_j = lambda_t t t^T + lambda_n n n^T                       (lambda_n <= lambda_t)
    Omega_j = n n^T / (lambda_n + sigma^2)                      on a line: lambda_n < 0.1 lambda_t
    Omega_j = (C_j + sigma^2 I)^-1                              elsewhere
    Omega_j = 0                                                 fewer than 3 neighbours within r

a point-to-distribution residual (as generalised ICP, Segal, Haehnel & Thrun 2009, with the map's side
only): on a wall a point-to-line distance with the LiDAR's noise ``sigma`` (``point_std_m``) and nothing
along it (a point could match anywhere on the line, so a corridor says nothing about its length), a post or
a corner constraining both directions. The motion input (wheels, odometry) gives the prior ``x_p`` with
covariance ``P_p`` (Kinematic-ICP's idea, Guadagnino et al. 2024: a wheeled robot's odometry is the prior
of its LiDAR odometry). The registration minimises::

    F(x) = sum_i rho(m_i^2) + r_p^T P_p^-1 r_p,   m_i^2 = d_i^T Omega_j d_i,   r_p = x - x_p (wrapped)

with the Geman-McClure kernel ``rho(m^2) = c^2 m^2 / (c^2 + m^2)`` (``c = kernel`` in units of sigma:
people walking by and furniture that moved weigh almost nothing), by iteratively reweighted Gauss-Newton,
the correspondences found again at each iteration within ``max_correspondence_m``::

    w_i = rho'(m_i^2) = (c^2 / (c^2 + m_i^2))^2
    J_i = [I_2, S R(theta) p_i],   S = [[0, -1], [1, 0]]                       (2 x 3)
    (sum_i w_i J_i^T Omega_j J_i + P_p^-1) delta = -(sum_i w_i J_i^T Omega_j d_i + P_p^-1 r_p)

The map's spread is first widened (``sigma`` times 4, then 2, then 1: a coarse-to-fine schedule, so that a
prior some decimetres off at long range still pulls in) and the final stage is at the LiDAR's noise.

Result
------
With ``H_s = sum_i w_i J_i^T Omega_j J_i`` (the scan's information at the solution) and the reduced
chi-square ``s = max(1, sum_i w_i m_i^2 / (n - 3))`` (a scan noisier than ``sigma`` widens the result,
never narrows it)::

    Sigma = (H_s / s + P_p^-1)^-1

is the covariance of the registered pose given the local map (the map's own pose is the condition: what the
map's frame is relative to the world is the estimator's business, not the matcher's). The scan's weakest
direction is the eigenvector of the smallest eigenvalue of ``D^-1 (H_s / s) D^-1``, ``D = diag(1, 1, L)``
(heading scaled by ``L = 1 m``): ``weakest_std_m = lambda_min^-1/2`` is the standard deviation the scan alone
leaves along it (a long corridor constrains its length by its ends only: large). A registration is
``degenerate`` when that exceeds ``degenerate_std_m``: the prior then holds that direction, as ``Sigma``
says.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ..geometry.se2 import Transform2D, normalize_angle
from ..util.validation import covariance, finite_array, integer, positive, store

# the map's spread widened by these factors of sigma, then the LiDAR's own (coarse to fine)
_STAGES = (4.0, 2.0, 1.0)
# Gauss-Newton has converged when a step moves less than this (m, rad: 0.1 mm at 3.5 m)
_STEP_TOL = (1e-4, 3e-5)
# heading scale of the weakest-direction measure (m per rad)
_HEADING_SCALE_M = 1.0
# neighbours of a map point that give its local covariance C_j
_NEIGHBOURS = 16
# a map point lies on a line when its neighbours' spread across is below this fraction of the spread along
_LINEAR_RATIO = 0.1
# a map point with fewer neighbours (itself included) constrains nothing
_MIN_NEIGHBOURS = 3


@dataclass(frozen=True)
class RegistrationConfig:
    """Scan registration (module docstring); every value > 0 (ValueError otherwise).

    * ``voxel_m`` (m): scans and the local map keep one point (the centroid) per cell of this size;
    * ``point_std_m`` (m): ``sigma``, the LiDAR's range noise across a surface;
    * ``kernel``: ``c`` of the Geman-McClure kernel, in units of sigma;
    * ``max_correspondence_m`` (m): a scan point further than this from every map point is left out;
    * ``neighbour_radius_m`` (m): the neighbours within this distance give a map point's covariance;
    * ``max_iterations`` (int >= 1): Gauss-Newton iterations per stage at most;
    * ``min_points`` (int >= 3): fewer matched points than this, and there is no registration;
    * ``degenerate_std_m`` (m): a scan whose weakest direction is less constrained than this is degenerate.
    """

    voxel_m: float = 0.05
    point_std_m: float = 0.03
    kernel: float = 3.0
    max_correspondence_m: float = 1.0
    neighbour_radius_m: float = 0.3
    max_iterations: int = 10
    min_points: int = 20
    degenerate_std_m: float = 0.1

    def __post_init__(self) -> None:
        store(
            self,
            (
                "voxel_m",
                "point_std_m",
                "kernel",
                "max_correspondence_m",
                "neighbour_radius_m",
                "degenerate_std_m",
            ),
            positive,
        )
        store(self, ("max_iterations",), partial(integer, minimum=1))
        store(self, ("min_points",), partial(integer, minimum=3))


def voxel_centroids(p: NDArray[np.float64], voxel_m: float) -> NDArray[np.float64]:
    """The centroid of the points ``p`` (n, 2) in each occupied ``voxel_m`` square cell, (m, 2)."""
    if len(p) == 0:
        return np.zeros((0, 2))
    keys = np.floor(p / voxel_m).astype(np.int64)
    # one integer per cell (cells within 2^31 of the origin: 100,000 km at 5 cm)
    key = (keys[:, 0] << 32) + (keys[:, 1] & 0xFFFFFFFF)
    _, cell, counts = np.unique(key, return_inverse=True, return_counts=True)
    sums = np.column_stack([np.bincount(cell, p[:, 0], len(counts)), np.bincount(cell, p[:, 1], len(counts))])
    return sums / counts[:, None]


class LocalMap:
    """Map points ``q`` (m, 2) in the map frame with their information ``Omega`` at each stage's widened
    spread, and a k-d tree to find the nearest (module docstring)."""

    def __init__(self, q_map: NDArray[np.float64], config: RegistrationConfig) -> None:
        """``omega[stage]`` (m, 3): each point's information ``[a, b, c]`` of ``[[a, b], [b, c]]`` at the
        stage's widened spread."""
        self.q_map = finite_array("map points", q_map, (len(q_map), 2))
        self.tree = cKDTree(self.q_map)
        C, count = self._spread(config.neighbour_radius_m)
        # C = lambda_t t t^T + lambda_n n n^T,  lambda_n <= lambda_t
        lam, vec = np.linalg.eigh(C)
        n, t = vec[:, :, 0], vec[:, :, 1]
        # along a line, nothing: its points could match anywhere on it
        along = np.where(lam[:, 0] < _LINEAR_RATIO * lam[:, 1], 0.0, 1.0)
        # a point with fewer than _MIN_NEIGHBOURS around it (a far beam's lone return) has no shape
        alone = count < _MIN_NEIGHBOURS
        nn, tt = np.einsum("ni,nj->nij", n, n), np.einsum("ni,nj->nij", t, t)
        nn[alone], tt[alone] = 0.0, 0.0
        self.omega = []
        for factor in _STAGES:
            var = (factor * config.point_std_m) ** 2
            # Omega_j = n n^T / (lambda_n + sigma^2) + [not a line] t t^T / (lambda_t + sigma^2)
            omega = nn / (lam[:, 0] + var)[:, None, None] + tt * (along / (lam[:, 1] + var))[:, None, None]
            # the three entries [a, b, c] of each symmetric [[a, b], [b, c]] (m, 3)
            self.omega.append(np.column_stack([omega[:, 0, 0], omega[:, 0, 1], omega[:, 1, 1]]))

    def __len__(self) -> int:
        return len(self.q_map)

    def _spread(self, radius_m: float) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """``(C_j (m, 2, 2), count (m,))``: the covariance of each point's neighbours within ``radius_m``
        (itself included; at most ``_NEIGHBOURS``) and how many neighbours each has."""
        k = min(_NEIGHBOURS, len(self.q_map))
        distance, index = self.tree.query(self.q_map, k=k, distance_upper_bound=radius_m)
        index = np.atleast_2d(index.reshape(len(self.q_map), k))
        found = np.isfinite(distance.reshape(len(self.q_map), k))
        neighbours = self.q_map[np.where(found, index, 0)]
        count = found.sum(axis=1)
        mean = (neighbours * found[..., None]).sum(axis=1) / count[:, None]
        centred = (neighbours - mean[:, None, :]) * found[..., None]
        C = np.einsum("nki,nkj->nij", centred, centred) / count[:, None, None]
        return C, count


@dataclass(frozen=True)
class Registration:
    """A registration's result: ``T_map_body``, its covariance ``Sigma`` (3, 3, additive ``[x, y, theta]``
    in the map frame), the scan's own information ``H_scan`` (3, 3, already divided by ``s``), ``matched``
    (points that found a map point), ``weakest_std_m``, ``degenerate`` and ``prior_nis``, the Mahalanobis
    distance squared of the result from the prior (``r_p^T P_p^-1 r_p``: chi-square with 3 degrees of
    freedom if the prior is right)."""

    T_map_body: Transform2D
    Sigma: NDArray[np.float64]
    H_scan: NDArray[np.float64]
    matched: int
    weakest_std_m: float
    degenerate: bool
    prior_nis: float


def _prior_residual(x: NDArray[np.float64], x_prior: NDArray[np.float64]) -> NDArray[np.float64]:
    """``r_p = x - x_p`` with the heading residual wrapped to (-pi, pi]."""
    r = x - x_prior
    r[2] = normalize_angle(float(r[2]))
    return r


def register(
    p_body: NDArray[np.float64],
    local_map: LocalMap,
    T_prior: Transform2D,
    P_prior: NDArray[np.float64],
    config: RegistrationConfig,
) -> Registration | None:
    """The pose of the scan points ``p_body`` (n, 2, body frame, already thinned) in ``local_map``, from the
    prior ``T_prior`` with covariance ``P_prior`` (3, 3, positive definite), or None when fewer than
    ``min_points`` points find a map point (module docstring)."""
    P_prior = covariance("prior covariance", P_prior, (3, 3), definite=True)
    P_prior_inv = np.linalg.inv(P_prior)
    x_prior = T_prior.as_array()
    x = x_prior.copy()
    c2 = config.kernel**2
    for stage, omega_all in enumerate(local_map.omega):
        max_distance = config.max_correspondence_m if stage == 0 else config.max_correspondence_m / 2**stage
        for _ in range(config.max_iterations):
            step = _gauss_newton(p_body, local_map, omega_all, x, x_prior, P_prior_inv, c2, max_distance)
            if step is None:
                return None
            delta, *_ = step
            x += delta
            if np.hypot(delta[0], delta[1]) < _STEP_TOL[0] and abs(delta[2]) < _STEP_TOL[1]:
                break
    final = _gauss_newton(
        p_body, local_map, local_map.omega[-1], x, x_prior, P_prior_inv, c2, config.max_correspondence_m / 4
    )
    if final is None:
        return None
    _, H, chi2, matched = final
    # s = max(1, chi2 / (n - 3)): a scan noisier than sigma widens the result
    s = max(1.0, chi2 / max(matched - 3, 1))
    H_scan = H / s
    # Sigma = (H_s / s + P_p^-1)^-1
    Sigma = np.linalg.inv(H_scan + P_prior_inv)
    Sigma = 0.5 * (Sigma + Sigma.T)
    D_inv = np.diag([1.0, 1.0, 1.0 / _HEADING_SCALE_M])
    lambda_min = float(np.linalg.eigvalsh(D_inv @ H_scan @ D_inv)[0])
    weakest_std_m = math.inf if lambda_min <= 0.0 else lambda_min**-0.5
    r_p = _prior_residual(x, x_prior)
    return Registration(
        T_map_body=Transform2D(float(x[0]), float(x[1]), normalize_angle(float(x[2]))),
        Sigma=Sigma,
        H_scan=H_scan,
        matched=matched,
        weakest_std_m=weakest_std_m,
        degenerate=weakest_std_m > config.degenerate_std_m,
        prior_nis=float(r_p @ P_prior_inv @ r_p),
    )


def _gauss_newton(
    p_body: NDArray[np.float64],
    local_map: LocalMap,
    omega_all: NDArray[np.float64],
    x: NDArray[np.float64],
    x_prior: NDArray[np.float64],
    P_prior_inv: NDArray[np.float64],
    c2: float,
    max_distance: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], float, int] | None:
    """One reweighted Gauss-Newton step from ``x``: ``(delta, H_s, chi2 = sum w m^2, matched)``, or None
    with fewer than 3 matched points (module docstring)."""
    c, s = math.cos(x[2]), math.sin(x[2])
    # R(theta) p_i
    p_rot = p_body @ np.array([[c, s], [-s, c]])
    p_map = p_rot + x[:2]
    distance, j = local_map.tree.query(p_map, distance_upper_bound=max_distance)
    found = np.isfinite(distance)
    matched = int(found.sum())
    if matched < 3:
        return None
    j = j[found]
    # d_i = R p_i + t - q_j;  Omega_j = [[a, b], [b, c]] as its three entries (n, 3)
    dx, dy = (p_map[found] - local_map.q_map[j]).T
    a, b, c = omega_all[j].T
    # Omega d, m^2 = d^T Omega d
    od_x, od_y = a * dx + b * dy, b * dx + c * dy
    m2 = dx * od_x + dy * od_y
    # w_i = (c^2 / (c^2 + m_i^2))^2
    w = (c2 / (c2 + m2)) ** 2
    # J_i = [I_2, S R p_i],  S R p = [-(R p)_y, (R p)_x]
    jx, jy = -p_rot[found, 1], p_rot[found, 0]
    oj_x, oj_y = a * jx + b * jy, b * jx + c * jy
    # H = sum w J^T Omega J,  g = sum w J^T Omega d
    H = np.array(
        [
            [w @ a, w @ b, w @ oj_x],
            [w @ b, w @ c, w @ oj_y],
            [w @ oj_x, w @ oj_y, w @ (jx * oj_x + jy * oj_y)],
        ]
    )
    g = np.array([w @ od_x, w @ od_y, w @ (jx * od_x + jy * od_y)])
    r_p = _prior_residual(x, x_prior)
    # (H_s + P_p^-1) delta = -(g + P_p^-1 r_p)
    delta = np.linalg.solve(H + P_prior_inv, -(g + P_prior_inv @ r_p))
    return delta, H, float(w @ m2), matched
