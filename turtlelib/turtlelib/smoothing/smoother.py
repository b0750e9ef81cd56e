"""A full smoother over an EKF SLAM run: every pose and landmark re-estimated at once by sparse nonlinear
least squares (the factors: :mod:`turtlelib.smoothing.smoothing_problem`).

Cost
----
With each factor's residual whitened, ``e = L^-1 r`` for ``S = L L^T``, and ``s_j = |e_j|^2`` an
observation's squared Mahalanobis distance::

    F(x) = 1/2 |e_prior|^2 + 1/2 sum_k |e_motion,k|^2 + 1/2 sum_j rho(s_j),   rho(s) = c^2 ln(1 + s / c^2)

the Cauchy kernel with width ``c`` (``kernel_width``, whitened units) on the observations: an observation
``c`` sigma off keeps half its weight, a gross outlier (a wrong association) costs only logarithmically. The
prior and the motion factors are the filter's Gaussian models, kept quadratic.

Solver
------
Levenberg-Marquardt with the kernel by iteratively reweighted least squares: at ``x``, with the observation
weights ``w_j = rho'(s_j) = 1 / (1 + s_j / c^2)`` and ``W`` their block diagonal (1 for the other factors)::

    (J^T W J + lambda D) dx = -J^T W e,     D = diag(J^T W J)

``J`` (M, N) is sparse (a motion factor touches two poses, an observation one pose and one landmark), so
``J^T W J`` is too; it is factorised by SuperLU (:func:`scipy.sparse.linalg.splu`) with a minimum-degree
ordering of its symmetric pattern (:mod:`turtlelib.smoothing.sparse_least_squares`, with the damping
schedule and the stopping rule). ``x <- x (+) dx`` adds, with headings wrapped. It starts
without the kernel (plain Gauss-Newton least squares) from the warm start - the filter's estimates, whose
early poses may be far from the smoothed ones - and turns the kernel on from that optimum, so that a
distant warm start does not mark good observations as outliers.

Covariance
----------
The Laplace approximation at the optimum, ``Sigma = (J^T W J)^-1`` (the weights of the outliers as
found): the joint block of the last pose and the landmarks is solved from the factorisation for their
``3 + 2n`` unit columns, never by an inverse. Pose 0's prior fixes the gauge (the map frame), so
``J^T W J`` is positive definite.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property, partial

import numpy as np
from numpy.typing import NDArray
from scipy import sparse

from ..estimation.measurement_models import MeasurementModel
from ..geometry.se2 import normalize_angle, normalize_angles
from ..util.validation import integer, positive, store
from .smoothing_problem import SmoothingProblem
from .sparse_least_squares import (
    factorise,
    levenberg_marquardt,
    relative_pose_residuals,
    sparse_blocks,
    whitening,
)

# right-hand sides per solve when the landmark covariance is recovered from the factorisation
_COLUMNS_PER_SOLVE = 64


@dataclass(frozen=True)
class SmootherConfig:
    """``kernel_width`` the Cauchy kernel's ``c`` (whitened units; 1 was chosen on MRCLAM Dataset 7 robot 1,
    whose camera errors have heavy tails: docs/real_data.md, "Smoother"); ``max_iterations`` linearisations
    per stage; ``tolerance`` the relative cost decrease that ends it."""

    kernel_width: float = 1.0
    max_iterations: int = 50
    tolerance: float = 1e-4

    def __post_init__(self) -> None:
        store(self, ("kernel_width", "tolerance"), positive)
        store(self, ("max_iterations",), partial(integer, minimum=1))


@dataclass(frozen=True)
class SmoothedRun:
    """The optimum: ``poses`` (P, 3) ``T_map_body`` at the problem's stamps; ``landmark_ids`` (n,),
    ``landmarks`` (n, 2); ``weights`` (K,) the kernel's weight of each observation at the optimum (1: an
    inlier, small: an outlier) and ``mahalanobis2`` (K,) its squared Mahalanobis distance
    ``s = r^T R^-1 r`` there; the final cost ``F`` and the linearisations used; ``information`` the
    (N, N) ``J^T W J`` there, whose inverse blocks are the covariances (module docstring), solved when
    asked for (:meth:`covariance`, :attr:`final_covariance`)."""

    poses: NDArray[np.float64]
    landmark_ids: NDArray[np.int64]
    landmarks: NDArray[np.float64]
    weights: NDArray[np.float64]
    mahalanobis2: NDArray[np.float64]
    cost: float
    iterations: int
    information: sparse.csc_matrix = field(repr=False, compare=False)

    def covariance(self, variables: NDArray[np.int64]) -> NDArray[np.float64]:
        """The block of ``(J^T W J)^-1`` of ``variables`` (k,) (indices into ``[poses (3P), landmarks
        (2n)]``), (k, k), by columns from one factorisation."""
        covariance = np.empty((len(variables), len(variables)))
        for first in range(0, len(variables), _COLUMNS_PER_SOLVE):
            columns = np.arange(first, min(first + _COLUMNS_PER_SOLVE, len(variables)))
            rhs = np.zeros((self.information.shape[0], len(columns)))
            rhs[variables[columns], np.arange(len(columns))] = 1.0
            covariance[:, columns] = self._factor.solve(rhs)[variables]
        return 0.5 * (covariance + covariance.T)

    def landmark_variables(self, slots: NDArray[np.int64]) -> NDArray[np.int64]:
        """The variable indices ``[m_s0x, m_s0y, m_s1x, ...]`` (2k,) of the landmarks at ``slots`` (k,)."""
        return (3 * len(self.poses) + 2 * np.asarray(slots)[:, None] + np.arange(2)).ravel()

    @cached_property
    def final_covariance(self) -> NDArray[np.float64]:
        """(3 + 2n, 3 + 2n) the joint covariance of the last pose and the landmarks, laid out as the
        filter's state ``[x, y, theta, m_0x, m_0y, ...]``."""
        last_pose = 3 * len(self.poses) - 3 + np.arange(3)
        return self.covariance(np.r_[last_pose, self.landmark_variables(np.arange(len(self.landmark_ids)))])

    @property
    def landmark_covariance(self) -> NDArray[np.float64]:
        """(2n, 2n) the landmarks' joint covariance."""
        return self.final_covariance[3:, 3:]

    @property
    def landmark_covariances(self) -> NDArray[np.float64]:
        """(n, 2, 2) the marginal covariance of each landmark."""
        n = len(self.landmark_ids)
        blocks = self.landmark_covariance.reshape(n, 2, n, 2)
        return blocks[np.arange(n), :, np.arange(n), :]

    @cached_property
    def _factor(self):
        return factorise(self.information)


class Smoother:
    """Sparse Levenberg-Marquardt over a :class:`SmoothingProblem` (module docstring), with the measurement
    model ``measurement`` (the filter's: ``h``, its Jacobians and its residual) passed in."""

    def __init__(self, measurement: MeasurementModel, config: SmootherConfig | None = None) -> None:
        self._measurement = measurement
        self._config = SmootherConfig() if config is None else config

    @property
    def config(self) -> SmootherConfig:
        return self._config

    @property
    def measurement(self) -> MeasurementModel:
        return self._measurement

    def solve(
        self,
        problem: SmoothingProblem,
        poses: NDArray[np.float64],
        landmark_ids: NDArray[np.int64],
        landmarks: NDArray[np.float64],
        *,
        near_optimum: bool = False,
    ) -> SmoothedRun:
        """The optimum from the warm start ``poses`` (P, 3) and ``landmarks`` (n, 2) of ``landmark_ids`` (n,)
        (every observed id among them); ``near_optimum`` (a warm start that is a previous optimum of a
        slightly changed problem) skips the least-squares stage. ValueError for a warm start that does not
        fit the problem."""
        poses = np.array(poses, dtype=np.float64)
        landmarks = np.array(landmarks, dtype=np.float64).reshape(-1, 2)
        landmark_ids = np.asarray(landmark_ids, dtype=np.int64)
        if poses.shape != (problem.n_poses, 3) or len(landmark_ids) != len(landmarks):
            raise ValueError("the warm start must hold one pose per stamp and one position per landmark id")
        order = np.argsort(landmark_ids)
        slot = order[
            np.searchsorted(landmark_ids[order], problem.observation_landmark).clip(0, len(order) - 1)
        ]
        if len(slot) and not np.array_equal(landmark_ids[slot], problem.observation_landmark):
            raise ValueError("every observed landmark id must be in the warm start")
        system = _System(problem, self._measurement, slot, len(landmark_ids))
        x = np.concatenate([poses.ravel(), landmarks.ravel()])
        iterations = 0
        widths = (self._config.kernel_width,) if near_optimum else (np.inf, self._config.kernel_width)
        for width in widths:
            x, lin, used = levenberg_marquardt(
                partial(system.linearise, width=width),
                system.retract,
                x,
                self._config.max_iterations,
                self._config.tolerance,
            )
            iterations += used
        return SmoothedRun(
            poses=x[: system.n_pose_vars].reshape(-1, 3),
            landmark_ids=landmark_ids,
            landmarks=x[system.n_pose_vars :].reshape(-1, 2),
            weights=lin.weights,
            mahalanobis2=lin.mahalanobis2,
            cost=lin.cost,
            iterations=iterations,
            information=(lin.J.T @ lin.J).tocsc(),
        )


@dataclass(frozen=True)
class _Linearisation:
    """At ``x``: the reweighted whitened residuals ``e`` (M,) and Jacobian ``J`` (M, N) (sparse), the
    observations' weights and squared Mahalanobis distances (K,), and the robust cost ``F``."""

    e: NDArray[np.float64]
    J: sparse.csr_matrix
    weights: NDArray[np.float64]
    mahalanobis2: NDArray[np.float64]
    cost: float


class _System:
    """The problem's residuals and Jacobians at any ``x = [poses (3P), landmarks (2n)]``."""

    def __init__(
        self, problem: SmoothingProblem, measurement: MeasurementModel, slot: NDArray, n: int
    ) -> None:
        self.problem = problem
        self.measurement = measurement
        self.n_pose_vars = 3 * problem.n_poses
        self.n_vars = self.n_pose_vars + 2 * n
        # whitening L^-1 of every factor's covariance S = L L^T
        self.U_prior = whitening(problem.prior_covariance[None])[0]
        self.U_motion = whitening(problem.motion_covariance)
        self.U_loop = whitening(problem.loop_covariance)
        self.U_obs = whitening(problem.observation_covariance)
        self.slot = slot
        n_motion = problem.n_poses - 1
        self.motion_row0 = 3
        self.loop_row0 = 3 + 3 * n_motion
        self.obs_row0 = self.loop_row0 + 3 * len(problem.loop_pose)
        self.n_rows = self.obs_row0 + 2 * len(problem.z)

    def linearise(self, x: NDArray[np.float64], width: float) -> _Linearisation:
        problem = self.problem
        q = x[: self.n_pose_vars].reshape(-1, 3)
        m = x[self.n_pose_vars :].reshape(-1, 2)
        # dense blocks (values, first row, first column) of the sparse Jacobian
        blocks = []
        # start prior: r = q_0 (-) q0_bar, dr/dq_0 = I
        r_prior = _pose_difference(q[0], problem.prior_mean)
        e_prior = self.U_prior @ r_prior
        blocks.append((self.U_prior[None], np.array([0]), np.array([0])))

        # motion: r = (q_k^-1 q_(k+1)) (-) delta_k (sparse_least_squares.relative_pose_residuals)
        q0, q1 = q[:-1], q[1:]
        r_motion, A, B = relative_pose_residuals(q0, q1, problem.motion_delta)
        e_motion = np.einsum("kij,kj->ki", self.U_motion, r_motion)
        motion_rows = self.motion_row0 + 3 * np.arange(len(q0))
        blocks.append((self.U_motion @ A, motion_rows, 3 * np.arange(len(q0))))
        blocks.append((self.U_motion @ B, motion_rows, 3 * np.arange(1, len(q0) + 1)))

        # loops: r = (q_a^-1 q_b) (-) Z, the motion factor's form between any two poses
        a, b = problem.loop_pose.T
        r_loop, A_loop, B_loop = relative_pose_residuals(q[a], q[b], problem.loop_delta)
        e_loop = np.einsum("kij,kj->ki", self.U_loop, r_loop)
        loop_rows = self.loop_row0 + 3 * np.arange(len(a))
        blocks.append((self.U_loop @ A_loop, loop_rows, 3 * a))
        blocks.append((self.U_loop @ B_loop, loop_rows, 3 * b))

        # observations: r = z (-) h(q, m), dr/dq = -dh/dq, dr/dm = -dh/dm, all at once through the relative
        # model: h(q, m) = h(0, p) with p = R(theta)^T (m - p_body) the landmark in the body frame, so
        # dh/dm = H_0 R^T, dh/dp_body = -H_0 R^T, dh/dtheta = H_0 dp/dtheta = H_0 (-J p) = H_0 [p_y, -p_x]
        q_obs = q[problem.observation_pose]
        cos_obs, sin_obs = np.cos(q_obs[:, 2]), np.sin(q_obs[:, 2])
        R_t = np.empty((len(q_obs), 2, 2))
        R_t[:, 0, 0], R_t[:, 0, 1], R_t[:, 1, 0], R_t[:, 1, 1] = cos_obs, sin_obs, -sin_obs, cos_obs
        p_body = np.einsum("kij,kj->ki", R_t, m[self.slot] - q_obs[:, :2])
        z_hat, _, H_0 = self.measurement.predict(np.zeros(3), p_body)
        r_obs = self.measurement.residual(problem.z, z_hat)
        H_m = H_0 @ R_t
        H_q = np.empty((len(q_obs), 2, 3))
        H_q[:, :, :2] = -H_m
        H_q[:, :, 2] = np.einsum("kij,kj->ki", H_0, np.column_stack([p_body[:, 1], -p_body[:, 0]]))
        e_obs = np.einsum("kij,kj->ki", self.U_obs, r_obs)
        s_obs = np.einsum("ki,ki->k", e_obs, e_obs)
        # IRLS: rows scaled by sqrt(w), w = rho'(s) = 1 / (1 + s / c^2)
        K = len(problem.z)
        weights = np.ones(K) if np.isinf(width) else 1.0 / (1.0 + s_obs / width**2)
        root_w = np.sqrt(weights)[:, None]
        obs_rows = self.obs_row0 + 2 * np.arange(K)
        blocks.append((-(self.U_obs @ H_q) * root_w[:, :, None], obs_rows, 3 * problem.observation_pose))
        blocks.append((-(self.U_obs @ H_m) * root_w[:, :, None], obs_rows, self.n_pose_vars + 2 * self.slot))

        e = np.concatenate([e_prior, e_motion.ravel(), e_loop.ravel(), (e_obs * root_w).ravel()])
        J = sparse_blocks(blocks, (self.n_rows, self.n_vars))
        robust = np.sum(s_obs) if np.isinf(width) else width**2 * np.sum(np.log1p(s_obs / width**2))
        cost = 0.5 * (e_prior @ e_prior + np.sum(e_motion * e_motion) + np.sum(e_loop * e_loop) + robust)
        return _Linearisation(e, J, weights, s_obs, float(cost))

    def retract(self, x: NDArray[np.float64], step: NDArray[np.float64]) -> NDArray[np.float64]:
        """``x (+) dx``: added, with the headings wrapped."""
        moved = x + step
        moved[2 : self.n_pose_vars : 3] = normalize_angles(moved[2 : self.n_pose_vars : 3])
        return moved


def _pose_difference(q: NDArray[np.float64], q_ref: NDArray[np.float64]) -> NDArray[np.float64]:
    """``q (-) q_ref``: componentwise, the heading wrapped."""
    r = q - q_ref
    r[2] = normalize_angle(r[2])
    return r
