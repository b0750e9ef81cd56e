"""The Gaussian state of EKF SLAM: mean and covariance of the robot pose and 2D point landmarks.

Layout
------
::

    x = [x, y, theta, m_0x, m_0y, m_1x, m_1y, ..., m_(n-1)x, m_(n-1)y],   N = 3 + 2 n

(m, m, rad, then landmark positions in m, all in the map frame); landmark slot ``i`` occupies indices
``3 + 2i`` and ``4 + 2i``; ``P`` is the (N, N) covariance. The arrays are allocated with spare capacity
(``P`` is stored as the leading block of a larger C-ordered square) so that adding landmarks reallocates
only when the capacity (grown by an eighth at a time) is exhausted; removing landmarks shrinks it back once
it is more than twice what the remaining ones would grow to (the full update's cost follows the capacity,
so a flood of landmarks that are then dropped, such as expired tentative ones, must not leave it at its
peak).

``P`` is kept by its upper triangle (with the diagonal; the robot rows, ``P_qq`` included, are kept whole):
the filter steps write only that triangle, and every read of covariance entries takes ``P_ij`` for
``i > j`` from ``P_ji``. The lower triangle is filled in (copied, bitwise) only when the whole ``P`` is read
(:attr:`SlamState.covariance`), so that a run of predictions and updates that reads only the pose and a
few blocks never pays the O(N^2) copy.

Invariant coordinates (``invariant=True``: the right-invariant EKF)
------------------------------------------------------------------
The right-invariant EKF (Barrau & Bonnabel, "An EKF-SLAM algorithm with consistency properties", 2015)
treats pose and landmarks as one element of the group SE_(n+1)(2), ``chi = (R(theta), p, m_0, ...)``, and
its error as a left perturbation of the estimate, ``chi = exp(xi) chi_hat``, to first order::

    theta = theta_hat + xi_theta
    p = p_hat + xi_theta J p_hat + xi_p
    m_i = m_i_hat + xi_theta J m_i_hat + xi_i

with ``J = [[0, -1], [1, 0]]``: ``x - x_hat = T(x_hat) xi``, ``T = I + c e_theta^T`` and
``c = [J p; 0; J m_0; J m_1; ...]``. ``P`` is then stored as the covariance of ``xi``. Its point: a global
rotation and translation of pose and map is ``xi_theta = eps``, ``xi_p = xi_i = t``, the same directions at
every estimate, so no choice of linearisation point can give the filter information along them. What
changes, all inside this class:

* :meth:`predict` takes the model's ``G`` and ``Q`` (standard coordinates) and applies
  ``A = T_q(q')^-1 G T_q(q)`` (the identity for every arc model, whose ``G`` translates by the step's
  displacement) and the noise ``xi' = xi + B w``, ``B = [T_q(q')^-1; -J m_0 e_theta^T; ...]`` (the heading
  noise turns the robot against every landmark): ``P_qq += C Q C^T`` at once and, deferred like ``G``,
  ``P_qm += -(C Q e_theta) c_m^T``, ``P_mm += Q_theta,theta c_m c_m^T`` (``C = T_q(q')^-1``).
* :meth:`correct` takes ``H`` in invariant coordinates (``H T``) and moves the mean by the group
  exponential: ``theta += xi_theta``, each point ``<- R(xi_theta) point + V(xi_theta) xi_point``.
* :meth:`append` takes the inverse model's ``G_robot`` in standard coordinates and uses ``G_robot T_q - J m
  e_theta^T``; :meth:`append_independent` and :meth:`reset_robot` say "independent" in standard
  coordinates (the conversion is a rank-2 change of ``P``, O(N^2)).
* The views :attr:`covariance`, :attr:`pose_covariance` and :meth:`landmark_blocks` give standard
  coordinates (``T P T^T``); :meth:`pose_landmark_blocks` and :meth:`observation_covariance`, which the
  filter combines with its Jacobians, give the stored ones.

Cost per operation (``m = 2k`` stacked observation rows)
--------------------------------------------------------
* :meth:`predict` is O(1): it updates the pose and ``P_qq`` and defers the cross-covariance ``P_qm <- G P_qm``
  by accumulating the product of the steps' ``G`` (3 x 3), applied to the robot rows (O(N)) when anything
  else is read or changed. A run of predictions between two updates costs one pass over the robot rows
  (invariant: and one rank-one pass over ``P``'s upper triangle, O(N^2), for the heading noise).
* :meth:`correct` uses that ``H`` is non-zero only in the robot columns and the observed landmarks'
  columns: it gathers those ``3 + m`` rows of ``P`` (O(N m)), forms ``S`` (m x m), and applies one
  symmetric rank-m downdate of ``P``'s upper triangle in place by BLAS ``dsyrk`` (O(N^2 m)); never an
  N x N temporary, product or inverse.
* :meth:`correct` with ``consider_landmarks`` (the Schmidt update of a fixed map) changes only the robot
  rows and columns: O(N m).
* :meth:`append` / :meth:`remove` of a landmark: O(N) (swap-remove; the last slot moves);
  :meth:`append_independent` of ``k`` landmarks at once: O(N k) (one reallocation at most).

Every read sees ``P`` exactly (bitwise) symmetric: each off-diagonal pair ``P_ij``, ``P_ji`` is computed
once and copied.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.blas import dsyrk
from scipy.linalg.lapack import dpotrf, dtrtrs

from ..geometry.se2 import normalize_angle
from .landmark_tracks import LandmarkTracks, Sightings
from .matching import mahalanobis_d2

ROBOT_DIM = 3
LANDMARK_DIM = 2
HEADING = 2  # index of theta in x
MIRROR_BLOCK = 256  # rows per block when copying the upper triangle of P into the lower one (measured)
_STRICT_LOWER = np.tri(MIRROR_BLOCK, k=-1, dtype=bool)  # strictly-lower mask of a diagonal block
J = np.array([[0.0, -1.0], [1.0, 0.0]])  # the derivative of a rotation: d/dphi R(phi) = J R(phi)
_ROBOT_INDICES = np.arange(ROBOT_DIM)
_LANDMARK_OFFSETS = ROBOT_DIM + np.arange(LANDMARK_DIM)  # the state indices of slot 0


class SlamState:
    """Mean and covariance of ``[robot pose, landmark slots]`` (see the module docstring)."""

    def __init__(
        self,
        pose: NDArray[np.float64],
        pose_covariance: NDArray[np.float64],
        capacity_landmarks: int = 16,
        invariant: bool = False,
    ) -> None:
        """``pose`` (3,) with ``pose_covariance`` (3, 3) (standard coordinates) and no landmark; ``invariant``
        stores ``P`` in the right-invariant coordinates (module docstring). The slots' records
        (:attr:`tracks`) are appended and removed with the slots."""
        self._invariant = invariant
        capacity = ROBOT_DIM + LANDMARK_DIM * capacity_landmarks
        self._mean = np.zeros(capacity)
        self._cov = np.zeros((capacity, capacity))
        self._n = 0
        # whether the lower triangle of P (below the robot block) holds the upper one's values
        self._lower_filled = True
        # the product of the Jacobians G of the predictions not yet applied to P_qm (None: none pending)
        self._pending_G: NDArray[np.float64] | None = None
        # invariant: the heading noise not yet applied to P_qm (-b c_m^T) and P_mm (s c_m c_m^T)
        self._pending_b = np.zeros(ROBOT_DIM)
        self._pending_s = 0.0
        self.reset_robot(pose, pose_covariance, keep_map=False)

    # --- views -------------------------------------------------------------------------------------------

    @property
    def n_landmarks(self) -> int:
        return self._n

    @property
    def capacity_landmarks(self) -> int:
        """Landmark slots the storage holds without reallocating (>= :attr:`n_landmarks`)."""
        return (self._cov.shape[0] - ROBOT_DIM) // LANDMARK_DIM

    @property
    def tracks(self) -> LandmarkTracks:
        """The records of the landmark slots (row ``i`` is slot ``i``); this state appends and removes
        their rows."""
        return self._tracks

    @property
    def dim(self) -> int:
        """``N = 3 + 2 n``."""
        return ROBOT_DIM + LANDMARK_DIM * self._n

    @property
    def mean(self) -> NDArray[np.float64]:
        """``x`` (N,), a view into the filter's storage (read it, do not write it)."""
        return self._mean[: self.dim]

    @property
    def covariance(self) -> NDArray[np.float64]:
        """``P`` (N, N) in standard coordinates: a view into the filter's storage (read it, do not write it),
        valid until the next filter step (invariant: a copy, ``T P T^T``); filling in its lower triangle
        costs O(N^2) after a step."""
        P = self._full_storage()
        if self._invariant:
            P = P.copy()
            _change_coordinates(P, self._rotation_column(), 1.0)
        return P

    @property
    def pose_covariance(self) -> NDArray[np.float64]:
        """``P_qq`` (3, 3) in standard coordinates, a view (read it, do not write it; invariant: a copy,
        ``T_q P_qq T_q^T``)."""
        P_qq = self._cov[:ROBOT_DIM, :ROBOT_DIM]
        if not self._invariant:
            return P_qq
        T_q = _pose_coordinates(self._mean, 1.0)
        return T_q @ P_qq @ T_q.T

    def landmark_positions(self) -> NDArray[np.float64]:
        """``[m_i]`` (n, 2), a view."""
        return self._mean[ROBOT_DIM : self.dim].reshape(self._n, LANDMARK_DIM)

    def landmark_blocks(self, slots: NDArray[np.int64] | None = None) -> NDArray[np.float64]:
        """The marginal covariances ``P_(m_i m_i)`` (k, 2, 2) of ``slots`` (default all) in standard
        coordinates, gathered in O(k). Invariant: with ``c_i = J m_i``, ``P_(m_i m_i) + c_i P_(theta m_i) +
        P_(m_i theta) c_i^T + P_(theta theta) c_i c_i^T``."""
        slots = np.arange(self._n) if slots is None else np.asarray(slots)
        blocks = self._stored_landmark_blocks(slots)
        if self._invariant:
            columns = (ROBOT_DIM + LANDMARK_DIM * slots)[:, None] + np.arange(LANDMARK_DIM)
            c = self._mean[columns] @ J.T
            P_theta_m = self._cov[HEADING][columns]
            cross = c[:, :, None] * P_theta_m[:, None, :]
            blocks += cross + cross.transpose(0, 2, 1)
            blocks += self._cov[HEADING, HEADING] * c[:, :, None] * c[:, None, :]
        return blocks

    def _stored_landmark_blocks(self, slots: NDArray[np.int64]) -> NDArray[np.float64]:
        """The stored ``P_(m_i m_i)`` (k, 2, 2) of ``slots``."""
        if self._invariant:  # the deferred heading noise reaches P_mm
            self._apply_pending()
        first = ROBOT_DIM + LANDMARK_DIM * slots
        # [[P_xx, P_xy], [P_xy, P_yy]] from the upper triangle, by flat index into the C-ordered storage
        flat = self._cov.ravel()
        diagonal = first * (self._cov.shape[0] + 1)
        blocks = np.empty((len(slots), LANDMARK_DIM, LANDMARK_DIM))
        blocks[:, 0, 0] = flat[diagonal]
        blocks[:, 0, 1] = blocks[:, 1, 0] = flat[diagonal + 1]
        blocks[:, 1, 1] = flat[diagonal + self._cov.shape[0] + 1]
        return blocks

    def stored_std(self) -> NDArray[np.float64]:
        """``sqrt(diag P)`` (N,) in the stored coordinates (as :meth:`pose_landmark_blocks`), O(N)."""
        self._apply_pending()
        return np.sqrt(np.diagonal(self._cov)[: self.dim])

    def pose_landmark_blocks(self, slots: NDArray[np.int64] | None = None) -> NDArray[np.float64]:
        """Joint covariances (k, 5, 5) of ``[x, y, theta, m_ix, m_iy]`` for ``slots`` (default all), O(k), in
        the stored coordinates (for the filter's Jacobians)."""
        self._apply_pending()
        # every entry from the upper triangle, P_ab at flat index min(a, b) * capacity + max(a, b) for the
        # state indices [0, 1, 2, 3 + 2i, 4 + 2i] of slot i, in one gather
        flat = _pose_landmark_block_indices(self._cov.shape[0])
        return self._cov.ravel()[flat[: self._n] if slots is None else flat[slots]]

    # --- the filter steps --------------------------------------------------------------------------------

    def predict(self, pose: NDArray[np.float64], G: NDArray[np.float64], Q: NDArray[np.float64]) -> None:
        """Robot motion ``q <- f(q, u)`` with Jacobian ``G = df/dq`` (3, 3) and process noise ``Q`` (3, 3),
        both in standard coordinates (invariant: converted as the module docstring says; ValueError for
        a ``G`` whose heading row is not ``[0, 0, 1]``, which would turn the map's coordinates too)."""
        dim = self.dim
        P = self._cov
        if self._invariant:
            if not np.array_equal(G[HEADING], [0.0, 0.0, 1.0]):
                raise ValueError("the invariant filter needs motion models whose heading step is pose-free")
            # A = T_q(q')^-1 G T_q(q),  C = T_q(q')^-1
            C = _pose_coordinates(pose, -1.0)
            G = C @ G @ _pose_coordinates(self._mean, 1.0)
            if dim > ROBOT_DIM:
                # deferred, with b = C Q e_theta: P_qm <- A (G_p P_qm - b_p c_m^T) - b c_m^T, so
                # b_p <- A b_p + b;  P_mm += Q_theta,theta c_m c_m^T
                self._pending_b = G @ self._pending_b + C @ Q[:, HEADING]
                self._pending_s += Q[HEADING, HEADING]
            Q = C @ Q @ C.T
        # P_qq <- G P_qq G^T + Q
        P_qq = G @ P[:ROBOT_DIM, :ROBOT_DIM] @ G.T + Q
        P[:ROBOT_DIM, :ROBOT_DIM] = 0.5 * (P_qq + P_qq.T)
        # P_qm <- G P_qm, deferred: G_pending <- G G_pending
        if dim > ROBOT_DIM:
            self._pending_G = G.copy() if self._pending_G is None else G @ self._pending_G
        self._mean[:ROBOT_DIM] = pose

    def observation_covariance(
        self, slots: NDArray[np.int64], H_robot: NDArray[np.float64], H_landmark: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """``H P H^T`` (2k, 2k) for observations of ``slots`` (k,) with Jacobians (k, 2, 3) and (k, 2, 2)."""
        self._apply_pending()
        cols, H = self._compressed_jacobian(slots, H_robot, H_landmark)
        return H @ self._blocks(cols) @ H.T

    def correct(
        self,
        slots: NDArray[np.int64],
        H_robot: NDArray[np.float64],
        H_landmark: NDArray[np.float64],
        nu: NDArray[np.float64],
        R: NDArray[np.float64],
        consider_landmarks: bool = False,
        gate: float = math.inf,
        R_gate: NDArray[np.float64] | None = None,
        observed_only: bool = False,
    ) -> tuple[float, NDArray[np.bool_]]:
        """EKF update with ``k`` observations of distinct ``slots``; returns the joint NIS ``nu^T S^-1 nu``
        and ``outside`` (k,), the observations beyond ``gate``.

        ``H_robot`` (k, 2, 3), ``H_landmark`` (k, 2, 2), innovations ``nu`` (k, 2) (already wrapped) and
        noise ``R`` (k, 2, 2). With a finite ``gate``, each observation alone must have
        ``D2_i = nu_i^T S_i^-1 nu_i < gate``, ``S_i = H_i P H_i^T + R_gate_i`` (default ``R``; the diagonal
        blocks of the stacked ``H P H^T``): if one does not, nothing changes and the NIS is 0.

        With ``S = L L^T`` (Cholesky) and ``W = L^-1 H P`` (m, N)::

            x <- x + K nu = x + W^T (L^-1 nu)
            P <- P - K S K^T = P - W^T W

        ``P - W^T W`` is the Joseph form ``(I - K H) P (I - K H)^T + K R K^T`` for the optimal gain
        ``K = P H^T S^-1 = W^T L^-1``, written as one symmetric rank-m downdate: what is removed is
        exactly the information the observations add, ``P+ = (P^-1 + H^T R^-1 H)^-1``.

        The downdate is computed on the upper triangle only, the one ``P`` is kept by (a general
        ``dgemm`` would round ``P_ij`` and ``P_ji`` differently, ~1e-19 apart):

        ``triu(P) <- triu(P - W^T W)`` by BLAS ``dsyrk`` (m flops per entry of ``P``, half of ``dgemm``),
        in place on the F-contiguous transpose of the whole C-ordered storage (its lower triangle is the
        upper one of ``P``). f2py would copy any non-contiguous view, so the call spans the full capacity;
        the spare columns of ``W_pad`` are zero and leave the spare storage unchanged.

        ``consider_landmarks=True``: the Schmidt-Kalman (consider-state) update, for a fixed map: the
        landmarks are "considered" (their uncertainty enters ``S`` and the robot's gain) but never
        estimated (Schmidt, "Application of state-space methods to navigation problems", 1966; the
        consider Kalman filter, e.g. Woodbury & Junkins, 2010). The gain is the optimal ``K`` with its
        landmark rows set to zero, ``K_s = [K_r; 0]``, ``K_r = (P H^T)_r S^-1 = W_r^T L^-1`` (``W_r``,
        ``W_m``: the robot and landmark columns of ``W``), applied in the Joseph form
        ``P <- (I - K_s H) P (I - K_s H)^T + K_s R K_s^T`` (valid for any gain), which is, block by block::

            x_r <- x_r + K_r nu = x_r + W_r^T (L^-1 nu),        x_m unchanged
            P_rr <- P_rr - K_r S K_r^T = P_rr - W_r^T W_r
            P_rm <- P_rm - K_r (H P)_m = P_rm - W_r^T W_m,      P_mr = P_rm^T
            P_mm unchanged (bit for bit)

        Only the robot rows and columns change, O(N m) (no ``dsyrk``); the robot rows are written, and
        ``P_rr`` takes its upper triangle into its lower one.

        ``observed_only=True``: the observed landmarks alone are estimated, the pose and every other
        landmark considered (the same Schmidt update with the roles turned: tentative landmarks, whose
        observations must never move the pose). With ``W_o`` the columns of ``W`` of the observed
        landmarks' indices ``o``, ``K_s = [0; K_o; 0]``, ``K_o = W_o^T L^-1``::

            x_o <- x_o + W_o^T (L^-1 nu),      x_r, other x_m unchanged
            P_o. <- P_o. - W_o^T W,            P_.o = P_o.^T, the rest unchanged (bit for bit)

        O(N m) (no ``dsyrk``). In invariant coordinates the gain is the one above in standard coordinates
        (the best estimate of the landmarks themselves, not of their error relative to a rotation):
        ``K_o = (W_o + W_theta c_o^T)^T L^-1 = G^T L^-1`` with ``c_o = J m_o``, so ``xi`` is zero but on
        ``o``, whose exponential moves those landmarks by ``xi_o = G^T (L^-1 nu)`` alone, and
        ``P_o. <- P_o. - G^T W`` with ``(G - W_o)^T G`` added to ``P_oo`` (the Joseph form of that gain).
        """
        dim, k = self.dim, len(slots)
        outside = np.zeros(k, dtype=bool)
        if k == 0:
            return 0.0, outside
        self._apply_pending()
        m = LANDMARK_DIM * k
        # the full update's dsyrk spans the storage's capacity (step 1); the consider updates only dim
        width = dim if consider_landmarks or observed_only else self._cov.shape[0]
        cols, H = self._compressed_jacobian(slots, H_robot, H_landmark)
        # right-hand sides [H P, 0, nu] (m, width + 1); H P = (P H^T)^T needs only the rows `cols` of P
        rhs = np.zeros((m, width + 1), order="F")
        np.matmul(H, self._rows(cols), out=rhs[:, :dim])
        rhs[:, width] = nu.reshape(m)
        # S = H P H^T + R; S is C-contiguous: its diagonal blocks by flat index
        S = rhs[:, cols] @ H.T
        diagonal_blocks = _diagonal_block_indices(k)
        S_flat = S.ravel()
        S_ii = S_flat[diagonal_blocks] + R
        if gate < math.inf:
            # D2_i = nu_i^T S_i^-1 nu_i, S_i = (H P H^T)_ii + R_gate_i
            d2 = mahalanobis_d2(nu, S_ii if R_gate is None else S_flat[diagonal_blocks] + R_gate)
            outside = ~(d2 < gate)
            if outside.any():
                return 0.0, outside
        # add R_i to the diagonal block i
        S_flat[diagonal_blocks] = S_ii
        if observed_only:
            return self._observed_update(S, rhs, cols[ROBOT_DIM:]), outside
        return self._kalman_update(S, rhs, dim, width, consider_landmarks), outside

    def correct_pose(
        self,
        H_robot: NDArray[np.float64],
        nu: NDArray[np.float64],
        R: NDArray[np.float64],
        consider_landmarks: bool = False,
        gate: float = math.inf,
    ) -> tuple[float, bool]:
        """EKF update with ``m`` observations of the robot pose alone (``H`` non-zero only in the robot
        columns, in the stored coordinates): ``H_robot`` (m, 3), innovation ``nu`` (m,) (already wrapped),
        noise ``R`` (m, m). Returns the NIS ``nu^T S^-1 nu`` and whether it was fused: with a finite
        ``gate``, nothing changes when the NIS is not below it.

        ``S = H P_qq H^T + R`` and the update of :meth:`correct` (``x += W^T w``, ``P -= W^T W``; the
        Schmidt update with ``consider_landmarks``): O(N^2 m), or O(N m) considered."""
        m = len(nu)
        self._apply_pending()
        dim = self.dim
        width = dim if consider_landmarks else self._cov.shape[0]
        rhs = np.zeros((m, width + 1), order="F")
        # H P = H P[:3, :]
        np.matmul(H_robot, self._rows(_ROBOT_INDICES), out=rhs[:, :dim])
        rhs[:, width] = nu
        # S = H P_qq H^T + R
        S = np.ascontiguousarray(rhs[:, :ROBOT_DIM] @ H_robot.T + R)
        if gate < math.inf:
            nis = float(nu @ np.linalg.solve(S, nu))
            if not nis < gate:
                return nis, False
        return self._kalman_update(S, rhs, dim, width, consider_landmarks), True

    def _kalman_update(
        self, S: NDArray[np.float64], rhs: NDArray[np.float64], dim: int, width: int, consider_landmarks: bool
    ) -> float:
        """The update of :meth:`correct` from ``S`` (m, m) and ``rhs = [H P, 0, nu]`` (m, width + 1,
        F-ordered; ``width``: the storage's capacity, or ``dim`` = N when ``consider_landmarks``); returns
        the NIS."""
        L, info = dpotrf(S, lower=1, clean=1, overwrite_a=1)
        if info != 0:
            raise np.linalg.LinAlgError("the innovation covariance S is not positive definite")
        # [W, 0, w] = L^-1 [H P, 0, nu]: W (m, N) padded with zeros to the width, w (m,)
        solved, info = dtrtrs(L, rhs, lower=1, overwrite_b=1)
        W_pad, w = solved[:, :width], solved[:, width]
        W = W_pad[:, :dim]
        if consider_landmarks:
            self._consider_update(W, w)
            return float(w @ w)
        if self._invariant:
            # x <- exp(W^T w) x on SE_(n+1)(2)
            self._retract(W.T @ w)
        else:
            # x <- x + W^T w, with the heading kept in (-pi, pi]
            self._mean[:dim] += W.T @ w
            self._mean[HEADING] = normalize_angle(self._mean[HEADING])
        # triu(P) <- triu(P - W^T W) (W_pad = 0 on the spare columns)
        self._rank_update(W_pad, -1.0)
        # the robot block is kept whole: its upper triangle into its lower one
        self._fill_robot_block()
        return float(w @ w)

    def _observed_update(
        self, S: NDArray[np.float64], rhs: NDArray[np.float64], observed: NDArray[np.int64]
    ) -> float:
        """The update of :meth:`correct` with ``observed_only``: only the state indices ``observed`` (m,)
        are estimated, from ``S`` (m, m) and ``rhs = [H P, nu]`` (m, N + 1); returns the NIS."""
        dim = self.dim
        L, info = dpotrf(S, lower=1, clean=1, overwrite_a=1)
        if info != 0:
            raise np.linalg.LinAlgError("the innovation covariance S is not positive definite")
        # [W, w] = L^-1 [H P, nu]
        solved, info = dtrtrs(L, rhs, lower=1, overwrite_b=1)
        W, w = solved[:, :dim], solved[:, dim]
        W_o = W[:, observed]
        # G = W_o (+ W_theta c_o^T in invariant coordinates)
        G = W_o + np.outer(W[:, HEADING], self._rotation_column()[observed]) if self._invariant else W_o
        # x_o <- x_o + G^T w
        self._mean[observed] += G.T @ w
        # P_o. <- P_o. - G^T W (+ (G - W_o)^T G on P_oo), its own block symmetrised so that row and column
        # agree bit for bit
        rows = self._rows(observed) - G.T @ W
        block = rows[:, observed] + (G - W_o).T @ G if self._invariant else rows[:, observed]
        rows[:, observed] = 0.5 * (block + block.T)
        self._cov[observed, :dim] = rows
        self._cov[:dim, observed] = rows.T
        return float(w @ w)

    def _retract(self, xi: NDArray[np.float64]) -> None:
        """``x <- exp(xi) x`` (N,) on SE_(n+1)(2): ``theta += phi`` and every point (the pose's position and
        the landmarks) ``<- R(phi) point + V(phi) xi_point`` with ``phi = xi_theta`` and
        ``V(phi) = [[sin(phi), cos(phi) - 1], [1 - cos(phi), sin(phi)]] / phi`` (the identity at 0)."""
        dim = self.dim
        phi = xi[HEADING]
        c, s = np.cos(phi), np.sin(phi)
        # sin(phi) / phi and (1 - cos(phi)) / phi = 2 sin(phi / 2)^2 / phi, by their series near 0
        if abs(phi) < 1e-4:
            a, b = 1.0 - phi * phi / 6.0, 0.5 * phi
        else:
            a, b = s / phi, 2.0 * math.sin(0.5 * phi) ** 2 / phi
        points = np.delete(self._mean[:dim], HEADING).reshape(-1, 2)
        steps = np.delete(xi, HEADING).reshape(-1, 2)
        moved = points @ np.array([[c, s], [-s, c]]) + steps @ np.array([[a, b], [-b, a]])
        self._mean[HEADING] = normalize_angle(self._mean[HEADING] + phi)
        self._mean[:2] = moved[0]
        self._mean[ROBOT_DIM:dim] = moved[1:].ravel()

    def _consider_update(self, W: NDArray[np.float64], w: NDArray[np.float64]) -> None:
        """The Schmidt update of :meth:`correct` from ``W = L^-1 H P`` (m, N) and ``w = L^-1 nu`` (m,)."""
        dim = self.dim
        W_r = W[:, :ROBOT_DIM]
        # x_r <- x_r + W_r^T w
        self._mean[:ROBOT_DIM] += W_r.T @ w
        self._mean[HEADING] = normalize_angle(self._mean[HEADING])
        # [P_rr, P_rm] <- [P_rr, P_rm] - W_r^T [W_r, W_m]
        P = self._cov
        P[:ROBOT_DIM, :dim] -= W_r.T @ W
        # P_rr: upper triangle into the lower one (P_mr = P_rm^T is in the lower triangle)
        self._fill_robot_block()
        self._lower_filled = False

    def append(
        self,
        p_map: NDArray[np.float64],
        G_robot: NDArray[np.float64],
        G_z: NDArray[np.float64],
        R: NDArray[np.float64],
        landmark_id: int | None = None,
        stamp_ns: int = 0,
        confirmed: bool = True,
    ) -> int:
        """Add a landmark ``m = g(q, z)`` (2,) from the inverse observation model; returns its slot.

        Its record: ``landmark_id`` (default: the tracks' ``next_id``), first seen at ``stamp_ns``,
        ``confirmed`` or tentative, with the evidence of this first sighting (the robot's position,
        ``m`` and ``G_z R G_z^T``: :class:`turtlelib.estimation.landmark_tracks.Sightings`).
        ``G_robot = dg/dq`` (2, 3), ``G_z = dg/dz`` (2, 2), ``R`` (2, 2) the observation noise::

            P_mx = G_robot P_qx              (cross-covariance with the pose and every landmark)
            P_mm = G_robot P_qq G_robot^T + G_z R G_z^T

        ``G_robot`` in standard coordinates; invariant: ``G_robot T_q - J m e_theta^T`` is used.
        """
        self._apply_pending()
        if self._invariant:
            G_robot = G_robot @ _pose_coordinates(self._mean, 1.0)
            G_robot[:, HEADING] -= J @ p_map
        self._reserve(self._n + 1)
        dim = self.dim
        new = slice(dim, dim + LANDMARK_DIM)
        P = self._cov
        # P_xm = (G_robot P_qx)^T  (the robot rows P_qx are whole; P_mx is in the lower triangle)
        P[:dim, new] = (G_robot @ P[:ROBOT_DIM, :dim]).T
        # P_mm = G_robot P_qq G_robot^T + G_z R G_z^T
        P_mm = G_robot @ P[:ROBOT_DIM, :ROBOT_DIM] @ G_robot.T + G_z @ R @ G_z.T
        P[new, new] = 0.5 * (P_mm + P_mm.T)
        self._lower_filled = False
        self._mean[new] = p_map
        landmark_id = self._tracks.next_id if landmark_id is None else landmark_id
        # the first sighting's evidence: the robot's position, m, and Sigma = G_z R G_z^T
        sighting = Sightings(self._mean[None, :2].copy(), p_map[None], (G_z @ R @ G_z.T)[None])
        self._tracks.append(np.array([landmark_id]), stamp_ns, confirmed, sighting)
        self._n += 1
        return self._n - 1

    def append_independent(
        self,
        xy: NDArray[np.float64],
        covariance: NDArray[np.float64],
        landmark_ids: NDArray[np.int64] | None = None,
    ) -> NDArray[np.int64]:
        """Add ``k`` confirmed landmarks ``landmark_ids`` (k,) (distinct, none held; default the next ``k``
        free ids) at ``xy`` (k, 2) with joint covariance ``covariance`` (2k, 2k) (symmetric), independent
        of the pose and the landmarks already held (zero cross-covariance); returns their slots (k,).
        ``P <- blockdiag(P, covariance)``, one reallocation at most (invariant: in standard coordinates,
        O(N^2))."""
        if self._invariant:
            self._change_storage_coordinates(to_standard=True)
        k = len(xy)
        self._apply_pending()
        self._reserve(self._n + k)
        dim = self.dim
        new = slice(dim, dim + LANDMARK_DIM * k)
        P = self._cov
        P[:dim, new] = 0.0
        P[new, new] = covariance
        self._lower_filled = False
        self._mean[new] = np.reshape(xy, LANDMARK_DIM * k)
        if landmark_ids is None:
            landmark_ids = self._tracks.next_id + np.arange(k)
        self._tracks.append(np.asarray(landmark_ids, dtype=np.int64), 0, True)
        self._n += k
        if self._invariant:
            self._change_storage_coordinates(to_standard=False)
        return np.arange(self._n - k, self._n)

    def remove(self, slot: int) -> int | None:
        """Marginalise landmark ``slot`` out (delete its rows and columns, and its record); O(N).

        The last slot (and its record) moves into the freed one: returns its old index, or None if ``slot``
        was last.
        """
        self._apply_pending()
        last = self._n - 1
        dim = self.dim
        moved = None
        if slot != last:
            P = self._cov
            t0 = ROBOT_DIM + LANDMARK_DIM * slot
            target = slice(t0, t0 + LANDMARK_DIM)
            source = np.arange(dim - LANDMARK_DIM, dim)
            # the source rows, whole, go to the target's place in the upper triangle: its column above the
            # target's block, its row to the right of it (up to the new N), and the source's own block
            rows = self._rows(source)
            P[:t0, target] = rows[:, :t0].T
            P[target, t0 + LANDMARK_DIM : dim - LANDMARK_DIM] = rows[
                :, t0 + LANDMARK_DIM : dim - LANDMARK_DIM
            ]
            P[target, target] = rows[:, source]
            self._lower_filled = False
            self._mean[target] = self._mean[source]
            moved = last
        self._tracks.remove(slot)
        self._n -= 1
        if self.capacity_landmarks > 2 * _grown(self._n):
            self._reallocate(_grown(self._n))
        return moved

    def reset_robot(
        self, pose: NDArray[np.float64], pose_covariance: NDArray[np.float64], keep_map: bool
    ) -> None:
        """New pose mean and covariance, independent of the map (in standard coordinates; invariant: O(N^2));
        ``keep_map=False`` also empties it."""
        if not keep_map:
            self._n = 0
            self._tracks = LandmarkTracks((len(self._mean) - ROBOT_DIM) // LANDMARK_DIM)
        if self._invariant:
            self._change_storage_coordinates(to_standard=True)
        self._pending_G = None
        dim = self.dim
        self._cov[:ROBOT_DIM, :dim] = 0.0
        self._cov[:dim, :ROBOT_DIM] = 0.0
        self._cov[:ROBOT_DIM, :ROBOT_DIM] = 0.5 * (pose_covariance + pose_covariance.T)
        self._mean[:ROBOT_DIM] = pose
        if self._invariant:
            self._change_storage_coordinates(to_standard=False)

    def _change_storage_coordinates(self, to_standard: bool) -> None:
        """``P <- T P T^T`` (``to_standard``) or ``P <- T^-1 P T^-T`` at the current mean, O(N^2)."""
        _change_coordinates(self._full_storage(), self._rotation_column(), 1.0 if to_standard else -1.0)

    # --- helpers -----------------------------------------------------------------------------------------

    def _apply_pending(self) -> None:
        """``P_qm <- G_pending P_qm`` for the deferred predictions (``P_mq = P_qm^T`` is in the lower
        triangle); invariant: then ``P_qm -= b c_m^T`` and ``triu(P_mm) += s c_m c_m^T``."""
        if self._pending_G is None:
            return
        dim = self.dim
        P = self._cov
        P[:ROBOT_DIM, ROBOT_DIM:dim] = self._pending_G @ P[:ROBOT_DIM, ROBOT_DIM:dim]
        self._pending_G = None
        self._lower_filled = False
        if not self._invariant:
            return
        c = self._rotation_column(capacity=True)
        P[:ROBOT_DIM, ROBOT_DIM:dim] -= np.outer(self._pending_b, c[ROBOT_DIM:dim])
        c[:ROBOT_DIM] = 0.0
        # triu(P_mm) += s c_m c_m^T (none without heading noise)
        if self._pending_s > 0.0:
            self._rank_update(c[None, :], self._pending_s)
        self._pending_b = np.zeros(ROBOT_DIM)
        self._pending_s = 0.0

    def _rank_update(self, W_pad: NDArray[np.float64], alpha: float) -> None:
        """``triu(P) <- triu(P + alpha W^T W)`` for ``W_pad`` (m, capacity) (zero on the spare columns), in
        place by BLAS ``dsyrk`` on the lower triangle of the storage's F-contiguous transpose (capacity x
        capacity, so f2py passes it without a copy)."""
        storage_T = self._cov.T
        updated = dsyrk(alpha, W_pad, beta=1.0, c=storage_T, trans=1, lower=1, overwrite_c=1)
        if updated is not storage_T:  # f2py worked on a copy (never for this float64 Fortran array)
            storage_T[...] = updated
        self._lower_filled = False

    def _rotation_column(self, capacity: bool = False) -> NDArray[np.float64]:
        """``c = [J p; 0; J m_0; ...]`` (N,) (``capacity``: padded with zeros to the storage's size), the
        standard-coordinate change of a unit rotation about the origin of every point."""
        dim = self.dim
        c = np.zeros(self._cov.shape[0] if capacity else dim)
        x = self._mean
        # J [x, y] = [-y, x] for the pose's position and every landmark
        c[0], c[1] = -x[1], x[0]
        c[ROBOT_DIM:dim:2] = -x[ROBOT_DIM + 1 : dim : 2]
        c[ROBOT_DIM + 1 : dim : 2] = x[ROBOT_DIM:dim:2]
        return c

    def _full_storage(self) -> NDArray[np.float64]:
        """The stored ``P`` (N, N), a view, with its lower triangle filled in."""
        dim = self.dim
        self._apply_pending()
        if not self._lower_filled:
            _mirror_upper_triangle(self._cov, dim)
            self._lower_filled = True
        return self._cov[:dim, :dim]

    def _fill_robot_block(self) -> None:
        """``tril(P_qq, -1) <- triu(P_qq, 1)^T``."""
        P = self._cov
        P[1, 0], P[2, 0], P[2, 1] = P[0, 1], P[0, 2], P[1, 2]

    def _rows(self, indices: NDArray[np.int64]) -> NDArray[np.float64]:
        """The rows ``P[indices, :N]`` (r, N), each whole: ``P_ij`` from ``P_ji`` where ``j < i``. O(N r)."""
        self._apply_pending()
        dim = self.dim
        rows = self._cov[indices, :dim]
        if not self._lower_filled:
            below = np.arange(dim) < indices[:, None]
            np.copyto(rows, self._cov[:dim, indices].T, where=below)
        return rows

    def _blocks(self, indices: NDArray[np.int64]) -> NDArray[np.float64]:
        """The square blocks ``P[i, i]`` (..., r, r) for the index arrays ``i`` of ``indices`` (..., r), each
        entry taken from the upper triangle."""
        blocks = self._cov[indices[..., :, None], indices[..., None, :]]
        below = indices[..., :, None] > indices[..., None, :]
        np.copyto(blocks, np.swapaxes(blocks, -1, -2).copy(), where=below)
        return blocks

    def _compressed_jacobian(
        self, slots: NDArray[np.int64], H_robot: NDArray[np.float64], H_landmark: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """The state indices ``cols`` (3 + 2k,) that ``H`` touches and ``H`` restricted to them (2k, 3 + 2k).

        Block row ``i`` has ``H_robot[i]`` in the pose columns and ``H_landmark[i]`` in columns
        ``3 + 2i, 4 + 2i``, which are slot ``slots[i]``'s state indices.
        """
        k = len(slots)
        m = LANDMARK_DIM * k
        # [0, 1, 2, 3 + 2 s_0, 4 + 2 s_0, ...]
        cols = np.concatenate((_ROBOT_INDICES, (LANDMARK_DIM * slots[:, None] + _LANDMARK_OFFSETS).ravel()))
        H = np.zeros((m, ROBOT_DIM + m))
        H[:, :ROBOT_DIM] = H_robot.reshape(m, ROBOT_DIM)
        H.ravel()[_landmark_block_indices(k)] = H_landmark
        return cols, H

    def _reserve(self, n_landmarks: int) -> None:
        """Grow the storage (by at least an eighth) so that ``n_landmarks`` slots fit."""
        if n_landmarks > self.capacity_landmarks:
            self._reallocate(_grown(n_landmarks))

    def _reallocate(self, capacity_landmarks: int) -> None:
        """Storage for ``capacity_landmarks`` (>= n) slots, holding the current mean and ``P`` block."""
        capacity = ROBOT_DIM + LANDMARK_DIM * capacity_landmarks
        dim = self.dim
        mean = np.zeros(capacity)
        mean[:dim] = self._mean[:dim]
        cov = np.zeros((capacity, capacity))
        cov[:dim, :dim] = self._cov[:dim, :dim]
        self._mean, self._cov = mean, cov


@functools.lru_cache(maxsize=128)
def _landmark_block_indices(k: int) -> NDArray[np.int64]:
    """Flat indices (k, 2, 2) into a C-ordered (2k, 3 + 2k) ``H`` of its block-diagonal landmark part:
    ``H[2i + a, 3 + 2i + b]`` for block ``i`` (read-only, one array per ``k``)."""
    width = ROBOT_DIM + LANDMARK_DIM * k
    block = LANDMARK_DIM * np.arange(k)[:, None, None]
    flat = (block + np.arange(LANDMARK_DIM)[:, None]) * width + ROBOT_DIM + block + np.arange(LANDMARK_DIM)
    flat.flags.writeable = False
    return flat


@functools.lru_cache(maxsize=16)
def _pose_landmark_block_indices(capacity: int) -> NDArray[np.int64]:
    """Flat indices (c, 5, 5) into the C-ordered (capacity, capacity) storage of the upper-triangle entries
    ``P_ab`` of ``[x, y, theta, m_ix, m_iy]`` for every slot ``i < c`` of the capacity: ``base + 2i step``
    (``base`` those of slot 0; ``step`` 0 between robot indices, 1 between a robot and a landmark index,
    ``capacity + 1`` between landmark indices). Read-only, one table per capacity."""
    indices = np.arange(ROBOT_DIM + LANDMARK_DIM)
    rows, columns = indices[:, None], indices[None, :]
    base = np.minimum(rows, columns) * capacity + np.maximum(rows, columns)
    landmark = indices >= ROBOT_DIM
    step = np.where(
        landmark[:, None] & landmark[None, :], capacity + 1, landmark[:, None] | landmark[None, :]
    )
    slots = np.arange((capacity - ROBOT_DIM) // LANDMARK_DIM)
    flat = base + LANDMARK_DIM * slots[:, None, None] * step
    flat.flags.writeable = False
    return flat


@functools.lru_cache(maxsize=128)
def _diagonal_block_indices(k: int) -> NDArray[np.int64]:
    """Flat indices (k, 2, 2) into a C-ordered (2k, 2k) matrix of its 2 x 2 diagonal blocks: ``[2i + a,
    2i + b]`` for block ``i`` (read-only, one array per ``k``)."""
    m = LANDMARK_DIM * k
    rows = LANDMARK_DIM * np.arange(k)[:, None, None] + np.arange(LANDMARK_DIM)[:, None]
    flat = rows * m + LANDMARK_DIM * np.arange(k)[:, None, None] + np.arange(LANDMARK_DIM)
    flat.flags.writeable = False
    return flat


def _grown(n_landmarks: int) -> int:
    """The capacity (landmark slots) a storage grows to for ``n_landmarks``: an eighth more, at least 8."""
    return n_landmarks + max(8, n_landmarks // 8)


def _mirror_upper_triangle(P: NDArray[np.float64], dim: int) -> None:
    """``tril(P, -1) <- triu(P, 1)^T`` on the leading ``dim x dim`` block of ``P``, in place, O(dim^2).

    Row blocks ``[i0, i1)`` of ``MIRROR_BLOCK`` rows: the block column under the diagonal block is the
    transposed block row to its right, written as ``MIRROR_BLOCK``-wide row segments while the block row
    is read column by column (each cache line on either side is loaded once), and the diagonal block
    copies its own transpose through a strictly-lower mask (numpy buffers the overlapping source).
    """
    for i0 in range(0, dim, MIRROR_BLOCK):
        i1 = min(i0 + MIRROR_BLOCK, dim)
        diagonal = P[i0:i1, i0:i1]
        np.copyto(diagonal, diagonal.T, where=_STRICT_LOWER[: i1 - i0, : i1 - i0])
        # P[i1:N, i0:i1] = P[i0:i1, i1:N]^T
        P[i1:dim, i0:i1] = P[i0:i1, i1:dim].T


def _pose_coordinates(pose: NDArray[np.float64], sign: float) -> NDArray[np.float64]:
    """``T_q = [[I_2, J p], [0, 1]]`` (3, 3) at ``pose`` (sign 1) or its inverse ``[[I_2, -J p], [0, 1]]``
    (sign -1): standard from invariant pose coordinates, ``dq = T_q xi_q``."""
    T_q = np.eye(ROBOT_DIM)
    T_q[0, HEADING], T_q[1, HEADING] = -sign * pose[1], sign * pose[0]
    return T_q


def _change_coordinates(P: NDArray[np.float64], c: NDArray[np.float64], sign: float) -> None:
    """``P <- (I + sign c e_theta^T) P (I + sign c e_theta^T)^T`` on the full (N, N) ``P`` in place, for ``c``
    (N,) with ``c_theta = 0`` (so the inverse is the other sign): with ``u = P e_theta``,
    ``P + sign (c u^T + u c^T) + P_theta,theta c c^T``, O(N^2)."""
    u = P[:, HEADING].copy()
    P += sign * (np.outer(c, u) + np.outer(u, c)) + P[HEADING, HEADING] * np.outer(c, c)
