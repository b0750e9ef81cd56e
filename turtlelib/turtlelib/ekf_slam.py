"""EKF SLAM for a differential-drive robot with a range-bearing landmark sensor.

State
-----
``x = [x, y, theta, m_0x, m_0y, ..., m_(n-1)x, m_(n-1)y]`` (map frame; m, m, rad, m...) with covariance
``P`` (N, N), ``N = 3 + 2n``, stored with spare capacity by :class:`turtlelib.slam_state.SlamState`. The
filter's slots hold confirmed and tentative landmarks; the public views (:attr:`EkfSlam.state`,
:attr:`EkfSlam.covariance`, :attr:`EkfSlam.landmarks`, ...) show the pose and the confirmed landmarks only,
ordered by landmark id (dropping the tentative ones from ``x`` and ``P`` is their marginal).

Prediction (:meth:`EkfSlam.predict`, O(N))
-----------------------------------------
From the wheel increments ``dphi = [dphi_left, dphi_right]`` (rad) through ``DiffDrive``::

    q' = f(q, dphi) = q (+) exp([F dphi])                    (the exact arc)
    P_qq' = G P_qq G^T + Q(dphi),  P_qm' = G P_qm,  G = df/dq

``Q`` propagates random-walk wheel slip ``N(0, wheel_noise^2 |dphi|)`` through the kinematics along the arc
(:mod:`turtlelib.wheel_noise`), so the result does not depend on how often prediction runs.

Update (:meth:`EkfSlam.update_known`, :meth:`EkfSlam.update_unknown`, O(N^2) per observation)
----------------------------------------------------------------------------------------------
Observation ``z = [range_m, bearing_rad]`` of a landmark from the sensor at ``T_body_sensor``
(:mod:`turtlelib.range_bearing`); one scan's observations are stacked into one update whose ``H`` touches
only the pose and the observed landmarks (:meth:`SlamState.correct`). Landmarks seen for the first time are
initialised from the inverse observation model with their full cross-covariance (:meth:`SlamState.append`).

Unknown association (:meth:`EkfSlam.update_unknown`)
----------------------------------------------------
Every observation is gated against every landmark (vectorised 2x2 innovation covariances, O(n) each)
with ``D2 < chi2_2^-1(gate_associate)``; compatible observations join a landmark by nearest neighbour or
by JCBB (``matcher``, :mod:`turtlelib.association`), confirmed landmarks first: a tentative landmark
only takes observations that no confirmed landmark is compatible with, so a tentative duplicate next to
a confirmed landmark starves and expires. An unpaired observation starts a new tentative
landmark only if ``D2 > chi2_2^-1(gate_new)`` for every landmark, and is discarded otherwise. A tentative
landmark is confirmed once seen ``confirm_count`` times (its first sighting included) and is dropped
(marginalised out) if still unconfirmed ``tentative_timeout`` scans after the scan that created it, so a
single spurious detection never enters the map.

Bad input (non-finite values, non-positive range, an invalid noise covariance, invalid or duplicate
landmark ids) raises ValueError and leaves the filter unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from functools import partial
from numbers import Integral

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .association import chi2_gate, joint_compatibility, mahalanobis_2d, nearest_neighbour
from .geometry import Transform2D
from .kinematics import DiffDrive
from .landmark_tracks import LandmarkTracks
from .range_bearing import landmarks_from_observations, predict_observations, residual
from .slam_state import ROBOT_DIM, SlamState
from .validation import finite_real, in_range, integer, non_negative, one_of, positive, store
from .wheel_noise import wheel_slip_covariance

MATCHERS = ("nn", "jcbb")


@dataclass(frozen=True)
class SlamConfig:
    """Parameters of :class:`EkfSlam`; the field names are the slam node's ROS parameters.

    * ``wheel_noise`` (sqrt(rad), >= 0): slip of each wheel is ``N(0, wheel_noise^2 |dphi|)`` over an
      increment ``dphi`` (variance per rad of wheel travel), see :mod:`turtlelib.wheel_noise`.
    * ``range_std`` (m), ``bearing_std`` (rad), > 0: default observation noise ``R = diag(range_std^2,
      bearing_std^2)`` when an update is given no ``R``.
    * ``sensor_x``, ``sensor_y`` (m), ``sensor_theta`` (rad): ``T_body_sensor``, the sensor mounting in the
      body frame (default: at the body origin; the robot's description says where it is).
    * ``matcher``: how unknown association pairs observations with landmarks, ``'nn'`` (nearest neighbour)
      or ``'jcbb'`` (joint compatibility branch and bound).
    * ``gate_associate`` < ``gate_new``, both in (0, 1): chi2 probabilities (2 dof) of the association gate
      and of the gate beyond which an observation may start a new landmark.
    * ``confirm_count`` (>= 1): sightings that confirm a tentative landmark; ``tentative_timeout`` (scans,
      >= 1 and >= confirm_count - 1): how long a tentative landmark may stay unconfirmed.
    * ``max_range`` (m, > 0): observations farther than this are rejected.
    * ``initial_xy_std`` (m), ``initial_theta_std`` (rad), >= 0: initial pose standard deviations.
    * ``jcbb_max_nodes`` (>= 1): bound on the pairings JCBB tries per scan.

    Invalid values raise ValueError.
    """

    wheel_noise: float = 0.05
    range_std: float = 0.02
    bearing_std: float = 0.02
    sensor_x: float = 0.0
    sensor_y: float = 0.0
    sensor_theta: float = 0.0
    matcher: str = "nn"
    gate_associate: float = 0.99
    gate_new: float = 0.9999
    confirm_count: int = 5
    tentative_timeout: int = 10
    max_range: float = 3.5
    initial_xy_std: float = 0.0
    initial_theta_std: float = 0.0
    jcbb_max_nodes: int = 10_000

    def __post_init__(self) -> None:
        store(self, ("sensor_x", "sensor_y", "sensor_theta"), finite_real)
        store(self, ("wheel_noise", "initial_xy_std", "initial_theta_std"), non_negative)
        store(self, ("range_std", "bearing_std", "max_range"), positive)
        one_of("matcher", self.matcher, MATCHERS)
        probability = partial(in_range, low=0.0, high=1.0, open_low=True, open_high=True)
        store(self, ("gate_associate", "gate_new"), probability)
        if not self.gate_associate < self.gate_new:
            raise ValueError(f"need gate_associate < gate_new, got {self.gate_associate}, {self.gate_new}")
        counts = ("confirm_count", "tentative_timeout", "jcbb_max_nodes")
        store(self, counts, partial(integer, minimum=1))
        if self.tentative_timeout < self.confirm_count - 1:
            raise ValueError(
                f"tentative_timeout ({self.tentative_timeout}) must leave room for confirm_count "
                f"({self.confirm_count}) sightings, one per scan"
            )

    @property
    def T_body_sensor(self) -> Transform2D:
        return Transform2D(self.sensor_x, self.sensor_y, self.sensor_theta)

    def measurement_covariance(self, count: int) -> NDArray[np.float64]:
        """``count`` copies (count, 2, 2) of the default ``R = diag(range_std^2, bearing_std^2)``."""
        return np.broadcast_to(np.diag([self.range_std**2, self.bearing_std**2]), (count, 2, 2)).copy()

    def initial_pose_covariance(self) -> NDArray[np.float64]:
        """``diag(initial_xy_std^2, initial_xy_std^2, initial_theta_std^2)`` (3, 3)."""
        return np.diag([self.initial_xy_std**2, self.initial_xy_std**2, self.initial_theta_std**2])


class ObservationStatus(IntEnum):
    """What an update did with one observation."""

    MATCHED = 0  # joined an existing landmark (confirmed or tentative)
    NEW = 1  # started a new landmark (tentative unless confirm_count == 1 or the association is known)
    REJECTED = 2  # unused: beyond max_range, or between the two gates, or outbid for its landmark


# the status values as plain integers, for filling int8 arrays
_MATCHED = int(ObservationStatus.MATCHED)
_NEW = int(ObservationStatus.NEW)
_REJECTED = int(ObservationStatus.REJECTED)


@dataclass(frozen=True)
class Association:
    """The outcome of one update, per observation and for the map.

    ``status`` (K,) ``ObservationStatus`` values, ``landmark_ids`` (K,) the landmark each observation
    joined or started (-1 when rejected), ``confirmed_ids`` / ``dropped_ids`` the tentative landmarks this
    update confirmed / dropped, ``nis`` the joint NIS of the matched observations with ``nis_dof`` dof
    (0 and 0 without matches; gated observations make it biased low under unknown association).
    """

    status: NDArray[np.int8]
    landmark_ids: NDArray[np.int64]
    confirmed_ids: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    dropped_ids: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    nis: float = 0.0
    nis_dof: int = 0


class EkfSlam:
    """EKF SLAM (see the module docstring for the maths).

    ``T_map_body0`` is the initial pose, with covariance from ``config.initial_pose_covariance()``. A
    filter runs either with known association (:meth:`update_known`) or with unknown association
    (:meth:`update_unknown`), fixed by the first update until :meth:`reset`.
    """

    def __init__(
        self, config: SlamConfig, diff_drive: DiffDrive, T_map_body0: Transform2D | None = None
    ) -> None:
        self._config = config
        self._drive = diff_drive
        self._T_body_sensor = config.T_body_sensor
        self._default_R = config.measurement_covariance(1)
        self._gate_associate = float(chi2_gate(config.gate_associate, 2))
        self._gate_new = float(chi2_gate(config.gate_new, 2))
        self.reset(Transform2D() if T_map_body0 is None else T_map_body0)

    # --- the filter steps --------------------------------------------------------------------------------

    def predict(self, dphi_left: float, dphi_right: float) -> None:
        """Move the pose by wheel increments (rad); only the robot rows and columns of ``P`` change.

        ValueError (filter unchanged) for non-finite increments.
        """
        q_next, G, Q = self._motion(self.pose, dphi_left, dphi_right)
        # P_qq' = G P_qq G^T + Q,  P_qm' = G P_qm
        self._state.predict(q_next, G, Q)

    def propagated_pose(self, dphi_left: float, dphi_right: float) -> tuple[Transform2D, NDArray[np.float64]]:
        """The pose and its covariance (3, 3) :meth:`predict` would give, without changing the filter.

        ``q' = f(q, dphi)``, ``P_qq' = G P_qq G^T + Q``: O(1), for publishing the pose between filter steps.
        """
        return self.propagated_pose_along([(dphi_left, dphi_right)])

    def propagated_pose_along(self, increments: ArrayLike) -> tuple[Transform2D, NDArray[np.float64]]:
        """As :meth:`propagated_pose` for consecutive increments ``[[dphi_left, dphi_right], ...]`` (S, 2)
        (rad), one motion step each (the arcs of S sample intervals); S = 0 gives the current pose."""
        steps = np.asarray(increments, dtype=np.float64).reshape(-1, 2)
        T_map_body = self.pose
        P_qq = self._state.covariance[:ROBOT_DIM, :ROBOT_DIM].copy()
        for dphi_left, dphi_right in steps.tolist():
            q_next, G, Q = self._motion(T_map_body, dphi_left, dphi_right)
            # P_qq' = G P_qq G^T + Q
            P_qq = G @ P_qq @ G.T + Q
            P_qq = 0.5 * (P_qq + P_qq.T)
            T_map_body = Transform2D(*q_next)
        return T_map_body, P_qq

    def _motion(
        self, T_map_body: Transform2D, dphi_left: float, dphi_right: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The motion model: the new pose ``q'`` (3,), its Jacobian ``G = dq'/dq`` and the noise ``Q``
        (3, 3)."""
        # q' = q (+) exp([F dphi])  (DiffDrive.step raises ValueError for non-finite increments)
        q_next = self._drive.step(T_map_body, dphi_left, dphi_right).as_array()
        # G = dq'/dq = [[1, 0, -dy], [0, 1, dx], [0, 0, 1]] (DiffDrive.step_jacobians' G_pose) with
        # [dx, dy] = [x', y'] - [x, y]
        G = np.eye(3)
        G[0, 2] = -(q_next[1] - T_map_body.y)
        G[1, 2] = q_next[0] - T_map_body.x
        Q = wheel_slip_covariance(
            self._drive, T_map_body.theta, dphi_left, dphi_right, self._config.wheel_noise
        )
        return q_next, G, Q

    def update_known(self, ids: ArrayLike, z: ArrayLike, R: ArrayLike | None = None) -> Association:
        """Update with observations ``z`` (K, 2) [range_m, bearing_rad] (sensor frame) of landmarks ``ids``.

        ``ids`` (K,) distinct integers >= 0 are the truth: an id never seen before starts a new (confirmed)
        landmark from its observation. ``R`` (K, 2, 2) the observation noise (default from the config).
        """
        z, R, landmark_ids = self.checked_observations(z, R, ids)
        self._enter_mode("known")

        in_range = z[:, 0] <= self._config.max_range
        slot_of = [self._tracks.slot(i) for i in landmark_ids.tolist()]
        known = np.array([slot is not None for slot in slot_of], dtype=bool)
        matched = np.flatnonzero(in_range & known)
        slots = np.array([slot_of[k] for k in matched], dtype=np.int64)
        # one stacked update with the landmarks seen before, then the new ones from the updated pose
        nis = self._correct(slots, z[matched], R[matched])
        for k in np.flatnonzero(in_range & ~known):
            self._add_landmark(int(landmark_ids[k]), z[k], R[k], confirmed=True)

        status = np.full(len(z), _REJECTED, dtype=np.int8)
        status[in_range] = np.where(known[in_range], _MATCHED, _NEW)
        return Association(status, np.where(in_range, landmark_ids, -1), nis=nis, nis_dof=2 * len(matched))

    def update_unknown(self, z: ArrayLike, R: ArrayLike | None = None) -> Association:
        """Associate and fuse one scan's observations ``z`` (K, 2) [range_m, bearing_rad] (sensor frame).

        Call it once per scan, also with no observations (K = 0): the tentative timeout counts these calls.
        ``R`` (K, 2, 2) the observation noise (default from the config).
        """
        z, R, _ = self.checked_observations(z, R)
        self._enter_mode("unknown")
        self._scan += 1
        usable = (z[:, 0] <= self._config.max_range).nonzero()[0]
        z_usable, R_usable = (z, R) if len(usable) == len(z) else (z[usable], R[usable])
        landmark_ids = np.full(len(z), -1, dtype=np.int64)
        status = np.full(len(z), _REJECTED, dtype=np.int8)

        # gate every usable observation against every landmark, associate, fuse the matched ones at once
        match = np.full(len(usable), -1, dtype=np.int64)
        far_from_all = np.ones(len(usable), dtype=bool)
        nis = 0.0
        if self._state.n_landmarks and len(usable):
            nu, d2, log_det, H_robot, H_landmark = self._gate(z_usable, R_usable)
            match = self._associate(nu, d2, log_det, R_usable, H_robot, H_landmark)
            far_from_all = (d2 > self._gate_new).all(axis=1)
            rows = (match >= 0).nonzero()[0]
            slots = match[rows]
            landmark_ids[usable[rows]] = self._tracks.ids[slots]
            status[usable[rows]] = _MATCHED
            nis = self._state.correct(
                slots, H_robot[slots], H_landmark[slots], nu[rows, slots], R_usable[rows]
            )
            confirmed_ids = [self._tracks.sighted(slots, self._config.confirm_count)]
        else:
            slots, confirmed_ids = match[:0], []

        # new (tentative) landmarks from the observations incompatible with every landmark
        started: list[int] = []
        for k in usable[(match < 0) & far_from_all]:
            if self._start_landmark(z[k], R[k], started):
                landmark_ids[k] = self._next_id - 1
                status[k] = _NEW
                if self._config.confirm_count == 1:
                    confirmed_ids.append(landmark_ids[k : k + 1])

        # tentative landmarks still unconfirmed after tentative_timeout scans are marginalised out
        dropped_ids = []
        for slot in self._tracks.expired(self._scan, self._config.tentative_timeout):
            dropped_ids.append(int(self._tracks.ids[slot]))
            self._tracks.remove(slot)
            self._state.remove(slot)
        return Association(
            status,
            landmark_ids,
            np.concatenate([np.zeros(0, dtype=np.int64), *confirmed_ids]),
            np.sort(np.array(dropped_ids, dtype=np.int64)),
            nis,
            2 * len(slots),
        )

    def reset(
        self,
        T_map_body: Transform2D | None = None,
        pose_covariance: ArrayLike | None = None,
        keep_map: bool = False,
    ) -> None:
        """Restart from pose ``T_map_body`` (default identity) with ``pose_covariance`` (3, 3) (default
        from the config).

        ``keep_map=False`` empties the map and forgets the association mode; ``keep_map=True`` keeps the
        landmarks with their covariance and makes the new pose independent of them (zero cross-covariance).
        """
        T_map_body = Transform2D() if T_map_body is None else T_map_body
        if not isinstance(T_map_body, Transform2D):
            raise ValueError(f"T_map_body must be a Transform2D, got {type(T_map_body).__name__}")
        if pose_covariance is None:
            covariance = self._config.initial_pose_covariance()
        else:
            covariance = _pose_covariance(pose_covariance)
        if keep_map:
            self._state.reset_robot(T_map_body.as_array(), covariance, keep_map=True)
            return
        self._state = SlamState(T_map_body.as_array(), covariance)
        self._tracks = LandmarkTracks()
        self._next_id = 0
        self._scan = 0
        self._mode: str | None = None

    # --- estimates ---------------------------------------------------------------------------------------

    @property
    def pose(self) -> Transform2D:
        """``T_map_body``, the pose mean."""
        x, y, theta = self._state.mean[:ROBOT_DIM]
        return Transform2D(x, y, theta)

    @property
    def pose_covariance(self) -> NDArray[np.float64]:
        """``P_qq`` (3, 3) of ``[x, y, theta]`` (m^2, m^2, rad^2)."""
        return self._state.covariance[:ROBOT_DIM, :ROBOT_DIM].copy()

    @property
    def landmark_ids(self) -> NDArray[np.int64]:
        """Ids (n,) of the confirmed landmarks, ascending; the order of every landmark view."""
        return self._tracks.ids[self._tracks.slots_by_id(confirmed=True)]

    @property
    def landmarks(self) -> NDArray[np.float64]:
        """Map positions (n, 2) (m) of the confirmed landmarks."""
        return self._state.landmark_positions()[self._tracks.slots_by_id(confirmed=True)]

    @property
    def landmark_covariances(self) -> NDArray[np.float64]:
        """Marginal covariances (n, 2, 2) (m^2) of the confirmed landmarks."""
        return self._state.landmark_blocks(self._tracks.slots_by_id(confirmed=True))

    @property
    def state(self) -> NDArray[np.float64]:
        """``x`` (N,) = ``[x, y, theta, m_0x, m_0y, ...]`` over the confirmed landmarks."""
        return self._state.mean[self._confirmed_indices()]

    @property
    def covariance(self) -> NDArray[np.float64]:
        """``P`` (N, N), a copy, over the pose and the confirmed landmarks (the layout of :attr:`state`)."""
        indices = self._confirmed_indices()
        return self._state.covariance[np.ix_(indices, indices)]

    @property
    def tentative_ids(self) -> NDArray[np.int64]:
        """Ids of the tentative (unconfirmed) landmarks, ascending."""
        return self._tracks.ids[self._tracks.slots_by_id(confirmed=False)]

    @property
    def tentative_landmarks(self) -> NDArray[np.float64]:
        """Map positions (t, 2) of the tentative landmarks, in the order of :attr:`tentative_ids`."""
        return self._state.landmark_positions()[self._tracks.slots_by_id(confirmed=False)]

    def landmark_estimate(self, landmark_id: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Position (2,) and covariance (2, 2) of confirmed landmark ``landmark_id``.

        ValueError if no confirmed landmark has that id.
        """
        slot = self._tracks.slot(int(landmark_id)) if isinstance(landmark_id, Integral) else None
        if slot is None or not self._tracks.confirmed[slot]:
            raise ValueError(f"no confirmed landmark with id {landmark_id!r}")
        first = ROBOT_DIM + 2 * slot
        return (
            self._state.mean[first : first + 2].copy(),
            self._state.covariance[first : first + 2, first : first + 2].copy(),
        )

    # --- helpers -----------------------------------------------------------------------------------------

    def checked_observations(
        self, z: ArrayLike, R: ArrayLike | None = None, ids: ArrayLike | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64] | None]:
        """What the updates take, validated: ``z`` (K, 2) finite with range > 0, ``R`` (K, 2, 2) symmetric
        positive definite (default from the config) and, if given, ``ids`` (K,) distinct integers >= 0.
        Observations with ``ids`` are for :meth:`update_known`, without for :meth:`update_unknown`: they
        must fit the filter's association mode.

        ValueError otherwise. For callers that queue observations and must refuse bad ones at once.
        """
        mode = "unknown" if ids is None else "known"
        if self._mode not in (None, mode):
            raise ValueError(f"this filter runs with {self._mode} association; reset() to switch")
        landmark_ids = None if ids is None else _landmark_ids(ids)
        z, R = self._observations(z, R)
        if landmark_ids is not None and len(landmark_ids) != len(z):
            raise ValueError(f"{len(landmark_ids)} ids for {len(z)} observations")
        return z, R, landmark_ids

    def _observations(
        self, z: ArrayLike, R: ArrayLike | None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Validated ``z`` (K, 2) with finite values and range > 0, and ``R`` (K, 2, 2) symmetric PD."""
        z = np.array(z, dtype=np.float64)
        if z.size == 0:
            z = z.reshape(0, 2)
        if z.ndim != 2 or z.shape[1] != 2:
            raise ValueError(f"observations must have shape (K, 2), got {z.shape}")
        if not np.isfinite(z).all():
            raise ValueError("observations must be finite")
        if not (z[:, 0] > 0.0).all():
            raise ValueError("observed ranges must be > 0")
        if R is None:
            return z, np.repeat(self._default_R, len(z), axis=0)
        R = np.array(R, dtype=np.float64)
        if R.shape != (len(z), 2, 2):
            raise ValueError(f"R must have shape ({len(z)}, 2, 2), got {R.shape}")
        if not np.isfinite(R).all():
            raise ValueError("R must be finite")
        scale = np.abs(R).max(initial=0.0)
        if np.any(np.abs(R[:, 0, 1] - R[:, 1, 0]) > 1e-12 * scale):
            raise ValueError("R must be symmetric")
        det = R[:, 0, 0] * R[:, 1, 1] - R[:, 0, 1] * R[:, 1, 0]
        if not ((R[:, 0, 0] > 0.0).all() and (R[:, 1, 1] > 0.0).all() and (det > 0.0).all()):
            raise ValueError("R must be positive definite (positive variances)")
        return z, R

    def _enter_mode(self, mode: str) -> None:
        if self._mode not in (None, mode):
            raise ValueError(f"this filter runs with {self._mode} association; reset() to switch")
        self._mode = mode

    def _gate(
        self, z: NDArray[np.float64], R: NDArray[np.float64], slots: NDArray[np.int64] | None = None
    ) -> tuple[NDArray[np.float64], ...]:
        """Observations ``z`` (K, 2) against landmark ``slots`` (k,) (default all), O(K k).

        Returns innovations ``nu_kj`` (K, k, 2), ``D2_kj`` and ``ln det S_kj`` (K, k) with
        ``S_kj = H_j P H_j^T + R_k``, and the Jacobians ``H_robot`` (k, 2, 3), ``H_landmark`` (k, 2, 2).
        """
        positions = self._state.landmark_positions()
        if slots is not None:
            positions = positions[slots]
        z_hat, H_robot, H_landmark = predict_observations(
            self._state.mean[:ROBOT_DIM], positions, self._T_body_sensor
        )
        # nu_kj = z_k - z_hat_j,  S_kj = H_j P H_j^T + R_k
        nu = residual(z[:, None, :], z_hat[None, :, :])
        S = self._predicted_covariances(H_robot, H_landmark, slots)[None] + R[:, None]
        d2, log_det = mahalanobis_2d(nu, S)
        return nu, d2, log_det, H_robot, H_landmark

    def _predicted_covariances(
        self, H_robot: NDArray[np.float64], H_landmark: NDArray[np.float64], slots: NDArray[np.int64] | None
    ) -> NDArray[np.float64]:
        """``Sigma_j = H_j P H_j^T`` (k, 2, 2) for ``slots`` (default all), O(k): ``H_j`` is non-zero only on
        the pose and landmark j, so ``Sigma_j = J_j P_(q m_j) J_j^T`` with ``J_j = [H_robot_j, H_landmark_j]``
        and ``P_(q m_j)`` the 5x5 joint covariance of the pose and landmark j.
        """
        J = np.concatenate([H_robot, H_landmark], axis=2)
        return J @ self._state.pose_landmark_blocks(slots) @ J.transpose(0, 2, 1)

    def _associate(
        self,
        nu: NDArray[np.float64],
        d2: NDArray[np.float64],
        log_det: NDArray[np.float64],
        R: NDArray[np.float64],
        H_robot: NDArray[np.float64],
        H_landmark: NDArray[np.float64],
    ) -> NDArray[np.int64]:
        """The slot (or -1) for each observation: confirmed landmarks first; tentative landmarks only take
        observations that no confirmed landmark is compatible with."""
        compatible = d2 < self._gate_associate
        confirmed = self._tracks.confirmed
        with_confirmed = compatible & confirmed
        match = self._pair(nu, d2, log_det, with_confirmed, R, H_robot, H_landmark)
        unexplained = ~with_confirmed.any(axis=1)
        if unexplained.any() and not confirmed.all():
            to_tentative = compatible & ~confirmed & unexplained[:, None]
            tentative_match = self._pair(nu, d2, log_det, to_tentative, R, H_robot, H_landmark)
            match = np.where(unexplained, tentative_match, match)
        return match

    def _pair(
        self,
        nu: NDArray[np.float64],
        d2: NDArray[np.float64],
        log_det: NDArray[np.float64],
        compatible: NDArray[np.bool_],
        R: NDArray[np.float64],
        H_robot: NDArray[np.float64],
        H_landmark: NDArray[np.float64],
    ) -> NDArray[np.int64]:
        """Observations to ``compatible`` slots by nearest neighbour or JCBB (the ``matcher`` option)."""
        if self._config.matcher == "nn":
            # most likely: the smallest -2 log N(nu; 0, S) = D2 + ln det S (+ const)
            return nearest_neighbour(d2 + log_det, compatible)
        candidates = compatible.any(axis=0).nonzero()[0]
        if len(candidates) == 0:
            return np.full(len(nu), -1, dtype=np.int64)
        joint = self._state.observation_covariance(candidates, H_robot[candidates], H_landmark[candidates])
        match = joint_compatibility(
            nu[:, candidates],
            compatible[:, candidates],
            joint,
            R,
            self._config.gate_associate,
            self._config.jcbb_max_nodes,
        )
        return np.where(match >= 0, candidates[match], -1)

    def _correct(self, slots: NDArray[np.int64], z: NDArray[np.float64], R: NDArray[np.float64]) -> float:
        """One stacked update with observations ``z`` of ``slots``; returns the joint NIS."""
        z_hat, H_robot, H_landmark = predict_observations(
            self._state.mean[:ROBOT_DIM], self._state.landmark_positions()[slots], self._T_body_sensor
        )
        return self._state.correct(slots, H_robot, H_landmark, residual(z, z_hat), R)

    def _add_landmark(
        self, landmark_id: int, z: NDArray[np.float64], R: NDArray[np.float64], confirmed: bool
    ) -> int:
        """Initialise a landmark from one observation by the inverse model (see :meth:`SlamState.append`);
        returns its slot."""
        p_map, G_robot, G_z = landmarks_from_observations(
            self._state.mean[:ROBOT_DIM], z[None, :], self._T_body_sensor
        )
        slot = self._state.append(p_map[0], G_robot[0], G_z[0], R)
        self._tracks.append(landmark_id, self._scan, confirmed)
        return slot

    def _start_landmark(self, z: NDArray[np.float64], R: NDArray[np.float64], started: list[int]) -> bool:
        """Start a landmark (id ``_next_id``) from an observation ``z`` (2,) that no landmark explains, unless
        it lies within gate_new of one this scan has ``started`` (slots) already: one object gives one
        detection per scan. Returns whether it did (and appends the new slot to ``started``)."""
        if started:
            _, d2, _, _, _ = self._gate(z[None], R[None], np.array(started))
            if np.any(d2 <= self._gate_new):
                return False
        confirmed = self._config.confirm_count == 1
        started.append(self._add_landmark(self._next_id, z, R, confirmed=confirmed))
        self._next_id += 1
        return True

    def _confirmed_indices(self) -> NDArray[np.int64]:
        """State indices of the pose and the confirmed landmarks (in id order)."""
        first = ROBOT_DIM + 2 * self._tracks.slots_by_id(confirmed=True)
        return np.concatenate([np.arange(ROBOT_DIM), (first[:, None] + np.arange(2)).ravel()])


def _landmark_ids(ids: ArrayLike) -> NDArray[np.int64]:
    """Validated landmark ids: (K,) distinct integers >= 0."""
    array = np.asarray(ids)
    if array.size == 0:
        return np.zeros(0, dtype=np.int64)
    if array.ndim != 1 or not np.issubdtype(array.dtype, np.integer):
        raise ValueError(f"landmark ids must be a 1-D integer array, got {array.dtype} {array.shape}")
    if np.any(array < 0):
        raise ValueError("landmark ids must be >= 0")
    if len(set(array.tolist())) != len(array):
        raise ValueError("landmark ids must be distinct within one update")
    return array.astype(np.int64)


def _pose_covariance(covariance: ArrayLike) -> NDArray[np.float64]:
    """A validated (3, 3) finite, symmetric, positive semi-definite pose covariance."""
    P = np.array(covariance, dtype=np.float64)
    if P.shape != (3, 3) or not np.all(np.isfinite(P)):
        raise ValueError(f"pose covariance must be a finite (3, 3) array, got shape {P.shape}")
    scale = np.abs(P).max()
    if not np.allclose(P, P.T, rtol=0.0, atol=1e-12 * scale):
        raise ValueError("pose covariance must be symmetric")
    if np.linalg.eigvalsh(P).min() < -1e-12 * scale:
        raise ValueError("pose covariance must be positive semi-definite (no negative variances)")
    return 0.5 * (P + P.T)
