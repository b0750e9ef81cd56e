"""EKF SLAM for a planar robot with a range-bearing landmark sensor; the motion model is passed in.

State
-----
``x = [x, y, theta, m_0x, m_0y, ..., m_(n-1)x, m_(n-1)y]`` (map frame; m, m, rad, m...) with covariance
``P`` (N, N), ``N = 3 + 2n``, stored with spare capacity by :class:`turtlelib.slam_state.SlamState`. The
filter's slots hold confirmed and tentative landmarks; the public views (:attr:`EkfSlam.state`,
:attr:`EkfSlam.covariance`, :attr:`EkfSlam.landmarks`, ...) show the pose and the confirmed landmarks only,
ordered by landmark id (dropping the tentative ones from ``x`` and ``P`` is their marginal).

Prediction (:meth:`EkfSlam.predict`, O(N))
-----------------------------------------
From an input ``u`` through the motion model (:mod:`turtlelib.motion_models`: wheel increments, odometry,
unicycle or car-like)::

    q' = f(q, u),   P_qq' = G P_qq G^T + Q(u),  P_qm' = G P_qm,  G = df/dq

The models' ``Q`` is integrated along the step's arc, so the result does not depend on how often
prediction runs.

Consistency: observability-constrained Jacobians (``linearization = 'fej'`` or ``'oc'``)
-----------------------------------------------------------------------------------------
The standard EKF evaluates ``G`` and ``H`` at the newest estimates. Then the linearised system no longer
has the unobservable directions of the true one (a global translation and rotation of pose and map), the
filter gains spurious information about the global heading, and its covariance becomes overconfident
(Huang, Mourikis & Roumeliotis, "Analysis and improvement of the consistency of extended Kalman filter
based SLAM", ICRA 2008). The unobservable directions are, with ``J = [[0, -1], [1, 0]]``, the columns of::

    N = [[I_2, J p], [0, 1], [I_2, J m_0], [I_2, J m_1], ...]     (a translation, a rotation about 0)

and the remedies choose Jacobians for which ``G_k N_k = N_(k+1)`` and ``H_k N_k = 0`` (so no observation
carries information along ``N``), with ``p`` the pose prior ``q_(k|k-1)`` (the pose of the last prediction,
before any update at this time) and ``m_i`` each landmark's first estimate (its value when it was
initialised):

* both: ``G`` at the motion from the last prior, ``G = [[1, 0, -dy], [0, 1, dx], [0, 0, 1]]`` with
  ``[dx, dy] = p_(k+1|k) - p_(k|k-1)``, i.e. the model's ``G`` plus ``J (p_(k|k) - p_(k|k-1))`` in its
  heading column. Exact for models that compose the pose with a displacement (every model of
  :mod:`turtlelib.motion_models`).
* ``'fej'`` (first-estimates Jacobian EKF): ``H`` evaluated at ``p`` and the landmarks' first estimates.
* ``'oc'`` (observability-constrained EKF, Huang et al., IJRR 2010): ``H`` at the newest estimates,
  projected onto the closest (Frobenius) Jacobian with ``H N = 0``: per observation of landmark ``i``,
  on its pose and landmark columns, ``H* = H (I_5 - N_i (N_i^T N_i)^-1 N_i^T)`` with
  ``N_i = [[I_2, J p], [0, 1], [I_2, J m_i]]``. It stays close to the standard Jacobian when the first
  estimates were poor (where FEJ can diverge).

The innovations still use the newest estimates; only the Jacobians (so ``P``) change. Then the global
heading variance never drops below its value when the first landmark was seen: relative observations
cannot tell where the whole map points.

Both are only as good as the first estimates: a landmark initialised from a pose that was far off
(a long stretch of poor odometry) keeps a wrong linearisation point. With ``relinearize_gate < 1`` a
landmark's first estimate is replaced by its current estimate ``m`` once
``(m - m_first)^T P_mm^-1 (m - m_first) > chi2_2^-1(relinearize_gate)`` after an update (the first
estimate is statistically incompatible with what the map now says). Each such reset lets a little of the
spurious information back in, once, in exchange for Jacobians at a sound point.

Consistency without first estimates: the right-invariant EKF (``linearization = 'invariant'``)
--------------------------------------------------------------------------------------------
Barrau & Bonnabel ("An EKF-SLAM algorithm with consistency properties", 2015) take pose and landmarks as one
element of the group SE_(n+1)(2) and the error as ``chi = exp(xi) chi_hat``; :class:`SlamState` then keeps
``P`` as the covariance of ``xi`` (its module docstring has the coordinates). In those coordinates the
unobservable directions are constant, ``N_xi = [e_theta, translation of the pose and every landmark]``,
whatever the estimate, and the Jacobians are taken at the newest estimates:

* ``H_xi = H T``, ``T = I + c e_theta^T``, ``c = [J p; 0; J m_0; ...]``: its heading column
  ``H_theta + H_p J p + H_m J m`` is zero for a range-bearing observation (it does not change when pose and
  landmark turn together), so ``H_xi N_xi = 0`` at every estimate: no observation can inform the global
  heading, with no first estimate to go stale;
* an arc motion step is the identity on ``xi``; its noise also turns the robot against every landmark
  (``P_qm``, ``P_mm`` gain rank-one terms, applied once per run of predictions);
* the update moves the mean by the group exponential (every point turned by ``xi_theta`` and shifted).

So the global heading variance never drops below its value when the first landmark was seen (as with
FEJ / OC), while the local accuracy is that of Jacobians at the newest estimates (unlike FEJ / OC after a
long stretch of dead reckoning). Localization keeps ``'standard'``: there the fixed map holds the frame.

Update (:meth:`EkfSlam.update_known`, :meth:`EkfSlam.update_unknown`, O(N^2) per observation)
----------------------------------------------------------------------------------------------
Observation ``z = [range_m, bearing_rad]`` of a landmark from the sensor at ``T_body_sensor``
(:mod:`turtlelib.range_bearing`); one scan's observations are stacked into one update whose ``H`` touches
only the pose and the observed landmarks (:meth:`SlamState.correct`). Landmarks seen for the first time are
initialised from the inverse observation model with their full cross-covariance (:meth:`SlamState.append`).

Known association gates every observation of a mapped landmark too: one with
``D2 = nu^T S^-1 nu >= chi2_2^-1(gate_known)`` (a wrong id, a reflection) is rejected rather than fused,
so a single bad observation cannot corrupt the map (``gate_known = 1`` fuses everything).

Correlated observation errors (``noise_correlation``, ``noise_correlation_length``)
-------------------------------------------------------------------------------------
A real detector's error depends on the viewpoint: the same landmark seen again from (nearly) the same
place gives (nearly) the same error, so repeated views carry much less information than independent ones
(on MRCLAM the range errors of successive sightings correlate at 0.9 when the robot has not moved, 0.4
after 0.2 m, none beyond a metre). Fused as independent, they make the map and the pose overconfident.
The filter models the error of landmark ``i``'s observations as a first-order (AR(1)) sequence over the
sensor's path: two views ``d`` apart correlate as ``rho(d) = c exp(-d / l)`` (``c`` =
``noise_correlation``, ``l`` = ``noise_correlation_length``; ``c < 1`` leaves an independent part). ``n``
views with correlation ``rho`` carry the information of ``n (1 - rho) / (1 + rho)`` independent ones
(that of the mean of an AR(1) sequence), so each observation is fused with::

    R_fused = R (1 + rho(d)) / (1 - rho(d)),   d = |p_sensor - p_sensor at landmark i's last view|

(the landmark's initialisation counts as a view). Gating uses ``R`` itself: one observation's innovation
is distributed with ``S = H P H^T + R`` whatever came before it. ``c = 0`` or ``l = 0`` is the independent
model.

Unknown association (:meth:`EkfSlam.update_unknown`)
----------------------------------------------------
Every observation is gated against every landmark (vectorised 2x2 innovation covariances, O(n) each;
landmarks that a lower bound of ``D2`` from the standard deviations of ``P`` puts beyond ``gate_new`` of
every observation are left out before their ``S`` is formed) with ``D2 < chi2_2^-1(gate_associate)``;
compatible observations join a landmark by nearest neighbour or by JCBB (``matcher``,
:mod:`turtlelib.association`), confirmed landmarks first: a tentative landmark only takes observations
that no confirmed landmark is compatible with, so a tentative duplicate next to a confirmed landmark
starves and expires. An unpaired observation starts a new tentative
landmark only if ``D2 > chi2_2^-1(gate_new)`` for every landmark, and is discarded otherwise. A tentative
landmark is confirmed once seen ``confirm_count`` times (its first sighting included) and is dropped
(marginalised out) if still unconfirmed ``tentative_timeout`` seconds after the scan that created it (scan
stamps in integer ns), so a single spurious detection never enters the map.

Localization (``mode = 'localization'``): a fixed map
-----------------------------------------------------
With a map loaded (:meth:`EkfSlam.load_map`, e.g. from :func:`turtlelib.slam_map.load_map`) the filter
can localise against it without changing it. Matched observations update the pose only, by the
Schmidt-Kalman (consider-state) update (Schmidt 1966; the consider Kalman filter): the landmarks'
uncertainty and their correlation with the pose still enter the innovation covariance ``S`` and the pose's
gain, but the landmarks are never estimated. With ``K = P H^T S^-1`` the optimal gain of the stacked update
and ``K_r`` its robot rows, the gain is ``K_s = [K_r; 0]`` in the Joseph form
``P' = (I - K_s H) P (I - K_s H)^T + K_s R K_s^T``::

    x_r' = x_r + K_r nu,              x_m' = x_m
    P_rr' = P_rr - K_r S K_r^T,       P_rm' = P_rm - K_r (H P)_m,       P_mm' = P_mm

so the map's means and covariance stay exactly (bit for bit) as loaded, and ``P`` stays positive
semi-definite (the Joseph form is, for any gain). Observations that would start a landmark (known
association: an id not in the map; unknown association: unpaired and beyond ``gate_new`` of every
landmark) get :attr:`ObservationStatus.UNMAPPED` and change nothing; tentative landmarks never appear.

Bad input (non-finite values, non-positive range, an invalid noise covariance, invalid or duplicate
landmark ids, more than ``max_observations`` in one update, a motion step the model turns into non-finite
values) raises ValueError and leaves the filter unchanged. Implausible observations (nearer than
``min_range``, farther than ``max_range``, outside the innovation gates) are rejected one by one, and the
map never grows past ``max_landmarks``: what matters is the memory and time of ``P``, ``O(n^2)``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from functools import partial
from numbers import Integral

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .association import (
    chi2_gate,
    joint_compatibility,
    mahalanobis_2d,
    mahalanobis_lower_bound,
    nearest_neighbour,
)
from .geometry import Transform2D
from .landmark_tracks import LandmarkTracks
from .motion_models import BatchMotionModel, MotionModel
from .range_bearing import landmarks_from_observations, predict_observations, residual
from .slam_map import LandmarkMap
from .slam_state import HEADING, ROBOT_DIM, J, SlamState
from .timebase import NS_PER_S
from .validation import finite_real, in_range, integer, non_negative, one_of, positive, store

MATCHERS = ("nn", "jcbb")
MODES = ("mapping", "localization")
LINEARIZATIONS = ("standard", "fej", "oc", "invariant")


@dataclass(frozen=True)
class SlamConfig:
    """Parameters of :class:`EkfSlam`; the field names are the slam node's ROS parameters.

    * ``range_std`` (m), ``bearing_std`` (rad), > 0: default observation noise ``R = diag(sigma_r^2,
      bearing_std^2)`` when an update is given no ``R``, with ``sigma_r = range_std + range_std_per_m r``
      for an observed range ``r``; ``range_std_per_m`` (m/m, >= 0, default 0): the part of the range noise
      that grows with the range (a camera's range from apparent size; 0 for a LiDAR).
    * ``noise_correlation`` in [0, 1) and ``noise_correlation_length`` (m, >= 0), default 0 (independent
      errors): the observation errors of one landmark seen from two sensor positions ``d`` apart correlate
      as ``rho = noise_correlation exp(-d / noise_correlation_length)``; each fused observation's ``R`` is
      scaled by ``(1 + rho) / (1 - rho)`` (module docstring, "Correlated observation errors").
    * ``sensor_x``, ``sensor_y`` (m), ``sensor_theta`` (rad): ``T_body_sensor``, the sensor mounting in the
      body frame (default: at the body origin; the robot's description says where it is).
    * ``matcher``: how unknown association pairs observations with landmarks, ``'nn'`` (nearest neighbour)
      or ``'jcbb'`` (joint compatibility branch and bound).
    * ``gate_associate`` < ``gate_new``, both in (0, 1): chi2 probabilities (2 dof) of the association gate
      and of the gate beyond which an observation may start a new landmark.
    * ``gate_known`` in (0, 1]: chi2 probability (2 dof) of the innovation gate of known association
      (1: no gate).
    * ``linearization``: ``'standard'`` (Jacobians at the newest estimates), ``'fej'`` (first-estimates
      Jacobians), ``'oc'`` (observability-constrained Jacobians) or ``'invariant'`` (the right-invariant
      EKF, mapping only): the consistency remedies of the module docstring; ``relinearize_gate`` in
      (0, 1]: chi2 probability (2 dof) beyond which fej / oc reset a landmark's first estimate to its current
      one (1: never).
    * ``confirm_count`` (>= 1): sightings that confirm a tentative landmark; ``tentative_timeout`` (s, > 0):
      how long after its first sighting a tentative landmark may stay unconfirmed.
    * ``min_range`` (m, >= 0) < ``max_range`` (m): observations nearer or farther than these are rejected
      (the sensor's range_min and range_max: nothing real is seen outside them).
    * ``max_landmarks`` (>= 1): the map's size bound; observations that would start a landmark beyond it
      are rejected (:attr:`EkfSlam.map_full`).
    * ``max_observations`` (>= 1): the most observations one update takes; more raise ValueError (no real
      scan holds that many landmarks: a flood, not a scan).
    * ``initial_xy_std`` (m), ``initial_theta_std`` (rad), >= 0: initial pose standard deviations.
    * ``jcbb_max_nodes`` (>= 1): bound on the pairings JCBB tries per scan.
    * ``mode``: ``'mapping'`` (SLAM: the map grows and every update refines it) or ``'localization'``
      (the map is fixed, e.g. loaded by :meth:`EkfSlam.load_map`: updates move the pose only, by the
      Schmidt-Kalman update of the module docstring, and no landmark is ever added; observations that
      would start one are :attr:`ObservationStatus.UNMAPPED`).

    Invalid values raise ValueError.
    """

    range_std: float = 0.02
    bearing_std: float = 0.02
    range_std_per_m: float = 0.0
    noise_correlation: float = 0.0
    noise_correlation_length: float = 0.0
    sensor_x: float = 0.0
    sensor_y: float = 0.0
    sensor_theta: float = 0.0
    matcher: str = "nn"
    gate_associate: float = 0.99
    gate_new: float = 0.9999
    gate_known: float = 0.9999
    linearization: str = "standard"
    relinearize_gate: float = 1.0
    confirm_count: int = 5
    tentative_timeout: float = 2.0
    min_range: float = 0.12
    max_range: float = 3.5
    max_landmarks: int = 1000
    max_observations: int = 100
    initial_xy_std: float = 0.0
    initial_theta_std: float = 0.0
    jcbb_max_nodes: int = 10_000
    mode: str = "mapping"

    def __post_init__(self) -> None:
        store(self, ("sensor_x", "sensor_y", "sensor_theta"), finite_real)
        store(
            self,
            (
                "initial_xy_std",
                "initial_theta_std",
                "min_range",
                "range_std_per_m",
                "noise_correlation_length",
            ),
            non_negative,
        )
        store(self, ("noise_correlation",), partial(in_range, low=0.0, high=1.0, open_high=True))
        store(self, ("range_std", "bearing_std", "max_range", "tentative_timeout"), positive)
        one_of("matcher", self.matcher, MATCHERS)
        one_of("linearization", self.linearization, LINEARIZATIONS)
        one_of("mode", self.mode, MODES)
        probability = partial(in_range, low=0.0, high=1.0, open_low=True, open_high=True)
        store(self, ("gate_associate", "gate_new"), probability)
        store(self, ("gate_known", "relinearize_gate"), partial(in_range, low=0.0, high=1.0, open_low=True))
        if not self.gate_associate < self.gate_new:
            raise ValueError(f"need gate_associate < gate_new, got {self.gate_associate}, {self.gate_new}")
        store(
            self,
            ("confirm_count", "jcbb_max_nodes", "max_landmarks", "max_observations"),
            partial(integer, minimum=1),
        )
        if not self.min_range < self.max_range:
            raise ValueError(f"need min_range < max_range, got {self.min_range}, {self.max_range}")
        if self.mode == "localization" and self.linearization == "invariant":
            raise ValueError(
                "linearization 'invariant' is for mapping: in localization the fixed map holds the frame "
                "(use 'standard')"
            )

    @property
    def T_body_sensor(self) -> Transform2D:
        return Transform2D(self.sensor_x, self.sensor_y, self.sensor_theta)

    def measurement_covariance(self, count: int) -> NDArray[np.float64]:
        """``R = diag(range_std^2, bearing_std^2)`` (count, 2, 2): an observation's noise at range 0."""
        return np.broadcast_to(np.diag([self.range_std**2, self.bearing_std**2]), (count, 2, 2)).copy()

    def observation_covariances(self, range_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """The default ``R`` (K, 2, 2) of observations at ranges ``range_m`` (K,):
        ``diag((range_std + range_std_per_m r)^2, bearing_std^2)``."""
        R = self.measurement_covariance(len(range_m))
        if self.range_std_per_m > 0.0:
            R[:, 0, 0] = (self.range_std + self.range_std_per_m * np.asarray(range_m)) ** 2
        return R

    @property
    def independent_noise(self) -> bool:
        """Whether observation errors are taken as independent (``noise_correlation`` or its length 0)."""
        return self.noise_correlation == 0.0 or self.noise_correlation_length == 0.0

    def fusion_scale(self, moved_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(1 + rho) / (1 - rho)`` (k,), ``rho = noise_correlation exp(-d / noise_correlation_length)``, for
        observations whose landmark was last viewed from ``moved_m`` (k,) away (inf: never); 1 with
        independent errors."""
        moved_m = np.asarray(moved_m, dtype=np.float64)
        if self.independent_noise:
            return np.ones(moved_m.shape)
        rho = self.noise_correlation * np.exp(-moved_m / self.noise_correlation_length)
        return (1.0 + rho) / (1.0 - rho)

    def initial_pose_covariance(self) -> NDArray[np.float64]:
        """``diag(initial_xy_std^2, initial_xy_std^2, initial_theta_std^2)`` (3, 3)."""
        return np.diag([self.initial_xy_std**2, self.initial_xy_std**2, self.initial_theta_std**2])


class ObservationStatus(IntEnum):
    """What an update did with one observation."""

    MATCHED = 0  # joined an existing landmark (confirmed or tentative)
    NEW = 1  # started a new landmark (tentative unless confirm_count == 1 or the association is known)
    REJECTED = 2  # unused: outside [min_range, max_range], between the two gates, outbid for its landmark,
    # outside the known-association gate, or new while the map is full
    UNMAPPED = 3  # would start a landmark, but the map is fixed (localization)


# the status values as plain integers, for filling int8 arrays
_MATCHED = int(ObservationStatus.MATCHED)
_NEW = int(ObservationStatus.NEW)
_REJECTED = int(ObservationStatus.REJECTED)
_UNMAPPED = int(ObservationStatus.UNMAPPED)


@dataclass(frozen=True)
class Association:
    """The outcome of one update, per observation and for the map.

    ``status`` (K,) ``ObservationStatus`` values, ``landmark_ids`` (K,) the landmark each observation
    joined or started (-1 when rejected or unmapped), ``confirmed_ids`` / ``dropped_ids`` the tentative
    landmarks this update confirmed / dropped, ``nis`` the joint NIS of the matched observations with
    ``nis_dof`` dof (0 and 0 without matches; gated observations make it biased low under unknown
    association).
    """

    status: NDArray[np.int8]
    landmark_ids: NDArray[np.int64]
    confirmed_ids: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    dropped_ids: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    nis: float = 0.0
    nis_dof: int = 0


class EkfSlam:
    """EKF SLAM (see the module docstring for the maths).

    ``motion`` is the motion model (:class:`turtlelib.motion_models.MotionModel`: its ``step`` gives
    ``q'``, ``G`` and ``Q`` for an input ``u``); ``T_map_body0`` the initial pose, with covariance from
    ``config.initial_pose_covariance()``. A filter runs either with known association
    (:meth:`update_known`) or with unknown association (:meth:`update_unknown`), fixed by the first update
    until :meth:`reset`.
    """

    def __init__(
        self, config: SlamConfig, motion: MotionModel, T_map_body0: Transform2D | None = None
    ) -> None:
        self._config = config
        self._motion = motion
        self._constrained = config.linearization in ("fej", "oc")
        self._invariant = config.linearization == "invariant"
        self._T_body_sensor = config.T_body_sensor
        self._gate_associate = float(chi2_gate(config.gate_associate, 2))
        self._gate_new = float(chi2_gate(config.gate_new, 2))
        self._gate_known = _gate_or_inf(config.gate_known)
        self._relinearize = _gate_or_inf(config.relinearize_gate) if self._constrained else np.inf
        self._timeout_ns = round(config.tentative_timeout * NS_PER_S)
        self._localization = config.mode == "localization"
        self.reset(Transform2D() if T_map_body0 is None else T_map_body0)

    @property
    def config(self) -> SlamConfig:
        return self._config

    @property
    def motion(self) -> MotionModel:
        return self._motion

    # --- the filter steps --------------------------------------------------------------------------------

    def predict(self, u: tuple) -> None:
        """Move the pose by the motion model's input ``u``; only the robot rows and columns of ``P`` change.

        ValueError (filter unchanged) for an input the model refuses (non-finite values, ...) or turns into
        a non-finite pose, Jacobian or noise (an overflowing step).
        """
        q_next, G, Q = _finite_step(self._motion.step(self.pose, u))
        # P_qq' = G P_qq G^T + Q,  P_qm' = G P_qm
        self._state.predict(q_next, self._propagation_jacobian(G), Q)
        self._pose_prior = q_next.copy()

    def predict_along(self, inputs: Sequence[tuple]) -> NDArray[np.float64]:
        """:meth:`predict` for each of the consecutive ``inputs`` as one composite prediction; returns the
        pose mean after each input (n, 3).

        The composite of steps ``(q_k, G_k, Q_k)`` is ``(q_n, G_n ... G_1, Q)`` with ``Q = sum_k (G_n ...
        G_(k+1)) Q_k (G_n ... G_(k+1))^T``: the n predictions, to rounding (one input: exactly
        :meth:`predict`). A :class:`~turtlelib.motion_models.BatchMotionModel` gives it in vectorised O(n)
        work, any other model one ``step`` per input. With FEJ / OC the composite's propagation Jacobian
        gets the correction of one step, as after step 1 the mean is its own prior (exact for the arc
        Jacobians ``[[1, 0, -dy], [0, 1, dx], [0, 0, 1]]``, which compose by adding their displacements).
        ValueError (filter unchanged) as :meth:`predict` gives it for any of the inputs.
        """
        if len(inputs) == 0:
            return np.zeros((0, ROBOT_DIM))
        if isinstance(self._motion, BatchMotionModel):
            poses, G, Q = self._motion.steps(self.pose, inputs)
        else:
            poses, G, Q = _composed_steps(self._motion, self.pose, inputs)
        # a non-finite pose anywhere carries on to the last one (the poses accumulate)
        q_next, G, Q = _finite_step((poses[-1].copy(), G, Q))
        # P_qq' = G P_qq G^T + Q,  P_qm' = G P_qm
        self._state.predict(q_next, self._propagation_jacobian(G), Q)
        self._pose_prior = q_next.copy()
        return poses

    def propagated_pose(self, u: tuple) -> tuple[Transform2D, NDArray[np.float64]]:
        """The pose and its covariance (3, 3) :meth:`predict` would give for input ``u``, without changing the
        filter: ``q' = f(q, u)``, ``P_qq' = G P_qq G^T + Q``, O(1), for publishing the pose between filter
        steps."""
        return self.propagated_pose_along([u])

    def propagated_pose_along(self, inputs: Iterable[tuple]) -> tuple[Transform2D, NDArray[np.float64]]:
        """As :meth:`propagated_pose` for consecutive inputs, one motion step each; none gives the current
        pose."""
        T_map_body = self.pose
        P_qq = self._state.pose_covariance.copy()
        for step, u in enumerate(inputs):
            q_next, G, Q = _finite_step(self._motion.step(T_map_body, u))
            # the first step from the filter's pose as predict takes it; the later ones start at their prior
            G = self._propagation_jacobian(G) if step == 0 else G
            # P_qq' = G P_qq G^T + Q
            P_qq = G @ P_qq @ G.T + Q
            P_qq = 0.5 * (P_qq + P_qq.T)
            T_map_body = Transform2D(*q_next)
        return T_map_body, P_qq

    def _propagation_jacobian(self, G: NDArray[np.float64]) -> NDArray[np.float64]:
        """The model's ``G``, or with FEJ / OC ``G + J (p_(k|k) - p_(k|k-1))`` in its heading column: ``G`` at
        ``p_(k+1|k) - p_(k|k-1)`` (module docstring)."""
        if not self._constrained:
            return G
        G = G.copy()
        G[0, 2] -= self._state.mean[1] - self._pose_prior[1]
        G[1, 2] += self._state.mean[0] - self._pose_prior[0]
        return G

    def update_known(self, ids: ArrayLike, z: ArrayLike, R: ArrayLike | None = None) -> Association:
        """Update with observations ``z`` (K, 2) [range_m, bearing_rad] (sensor frame) of landmarks ``ids``.

        ``ids`` (K,) distinct integers >= 0 are the truth: an id never seen before starts a new (confirmed)
        landmark from its observation (in localization: is UNMAPPED); an observation of a mapped landmark
        outside the ``gate_known`` innovation gate is rejected. ``R`` (K, 2, 2) the observation noise
        (default from the config).
        """
        z, R, landmark_ids = self.checked_observations(z, R, ids)
        self._enter_mode("known")

        in_range = self._in_range(z)
        slot_of = [self._tracks.slot(i) for i in landmark_ids.tolist()]
        known = np.array([slot is not None for slot in slot_of], dtype=bool)
        seen_before = np.flatnonzero(in_range & known)
        slots = np.array([slot_of[k] for k in seen_before], dtype=np.int64)
        # D2 = nu^T S^-1 nu of each observation against its landmark; fuse those inside the gate
        nu, d2, H_robot, H_landmark = self._innovations(slots, z[seen_before], R[seen_before])
        inside = d2 < self._gate_known
        matched = seen_before[inside]
        # one stacked update with the landmarks seen before, then the new ones from the updated pose
        sensor_xy, R_fused = self._fusion_noise(slots[inside], R[matched])
        nis = self._state.correct(
            slots[inside], H_robot[inside], H_landmark[inside], nu[inside], R_fused, self._localization
        )
        self._tracks.viewed(slots[inside], sensor_xy)
        self._relinearize_first_estimates(slots[inside])
        status = np.full(len(z), _REJECTED, dtype=np.int8)
        status[matched] = _MATCHED
        if self._localization:
            status[in_range & ~known] = _UNMAPPED
            return Association(
                status, np.where(status == _MATCHED, landmark_ids, -1), nis=nis, nis_dof=2 * len(matched)
            )
        for k in np.flatnonzero(in_range & ~known):
            if self.map_full:
                break
            self._add_landmark(int(landmark_ids[k]), z[k], R[k], confirmed=True, stamp_ns=0)
            status[k] = _NEW
        used = status != _REJECTED
        return Association(status, np.where(used, landmark_ids, -1), nis=nis, nis_dof=2 * len(matched))

    def update_unknown(self, z: ArrayLike, R: ArrayLike | None = None, *, stamp_ns: int) -> Association:
        """Associate and fuse one scan's observations ``z`` (K, 2) [range_m, bearing_rad] (sensor frame),
        taken at ``stamp_ns`` (integer ns; the tentative timeout runs on these stamps).

        Call it once per scan, also with no observations (K = 0), so that tentative landmarks expire.
        ``R`` (K, 2, 2) the observation noise (default from the config). In localization an observation
        that would start a landmark is UNMAPPED instead.
        """
        stamp_ns = integer("stamp_ns", stamp_ns)
        z, R, _ = self.checked_observations(z, R)
        self._enter_mode("unknown")
        usable = self._in_range(z).nonzero()[0]
        z_usable, R_usable = (z, R) if len(usable) == len(z) else (z[usable], R[usable])
        landmark_ids = np.full(len(z), -1, dtype=np.int64)
        status = np.full(len(z), _REJECTED, dtype=np.int8)

        # gate every usable observation against the landmarks near it, associate, fuse the matched ones
        match = np.full(len(usable), -1, dtype=np.int64)
        far_from_all = np.ones(len(usable), dtype=bool)
        nis = 0.0
        if self._state.n_landmarks and len(usable):
            near, nu, d2, log_det, H_robot, H_landmark = self._gate_near(z_usable, R_usable)
            match = self._associate(nu, d2, log_det, R_usable, H_robot, H_landmark, near)
            far_from_all = (d2 > self._gate_new).all(axis=1)
            rows = (match >= 0).nonzero()[0]
            columns = match[rows]
            slots = near[columns]
            landmark_ids[usable[rows]] = self._tracks.ids[slots]
            status[usable[rows]] = _MATCHED
            sensor_xy, R_fused = self._fusion_noise(slots, R_usable[rows])
            nis = self._state.correct(
                slots, H_robot[columns], H_landmark[columns], nu[rows, columns], R_fused, self._localization
            )
            self._tracks.viewed(slots, sensor_xy)
            self._relinearize_first_estimates(slots)
            confirmed_ids = [self._tracks.sighted(slots, self._config.confirm_count)]
        else:
            slots, confirmed_ids = match[:0], []

        # new (tentative) landmarks from the observations incompatible with every landmark
        started: list[int] = []
        unexplained = usable[(match < 0) & far_from_all]
        if self._localization:
            status[unexplained] = _UNMAPPED
            unexplained = unexplained[:0]
        for k in unexplained:
            if self._start_landmark(z[k], R[k], started, stamp_ns):
                landmark_ids[k] = self._next_id - 1
                status[k] = _NEW
                if self._config.confirm_count == 1:
                    confirmed_ids.append(landmark_ids[k : k + 1])

        # tentative landmarks still unconfirmed tentative_timeout after their first sighting are marginalised
        dropped_ids = []
        for slot in self._tracks.expired(stamp_ns, self._timeout_ns):
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
        landmarks with their covariance and makes the new pose independent of them (zero cross-covariance):
        a relocalization, also after :meth:`load_map` and in localization.
        """
        pose, covariance = self._initial_pose(T_map_body, pose_covariance)
        # the pose prior q_(k|k-1) of the first-estimates Jacobians
        self._pose_prior = pose.copy()
        if keep_map:
            self._state.reset_robot(pose, covariance, keep_map=True)
            return
        self._state = SlamState(pose, covariance, invariant=self._invariant)
        self._tracks = LandmarkTracks()
        self._next_id = 0
        self._association: str | None = None

    def load_map(
        self,
        landmark_map: LandmarkMap,
        T_map_body: Transform2D | None = None,
        pose_covariance: ArrayLike | None = None,
    ) -> None:
        """Restart with the map ``landmark_map`` (:class:`turtlelib.slam_map.LandmarkMap`), from pose
        ``T_map_body`` (default identity) with ``pose_covariance`` (3, 3) (default from the config), as
        :meth:`reset` does.

        ``x = [pose, m_i in the map's order]``, ``P = blockdiag(P_qq, P_mm)`` (the pose independent of the
        map; the map's joint covariance as it is). Every landmark is confirmed with its id, its first
        estimate (for ``fej`` / ``oc``) its position; the next new landmark gets ``max(ids) + 1`` (0 for an
        empty map); the association mode is free (known association then observes the map's ids). O(n^2).
        :meth:`landmark_map` then gives the same map bit for bit (reordered by id if its ids were not
        ascending).

        ValueError (filter unchanged) for more than ``max_landmarks`` landmarks, or an invalid pose.
        """
        if not isinstance(landmark_map, LandmarkMap):
            raise ValueError(f"landmark_map must be a LandmarkMap, got {type(landmark_map).__name__}")
        n = landmark_map.n_landmarks
        if n > self._config.max_landmarks:
            raise ValueError(
                f"the map holds {n} landmarks, more than max_landmarks = {self._config.max_landmarks}"
            )
        pose, covariance = self._initial_pose(T_map_body, pose_covariance)
        state = SlamState(pose, covariance, capacity_landmarks=max(16, n), invariant=self._invariant)
        state.append_independent(landmark_map.xy, landmark_map.covariance)
        tracks = LandmarkTracks(max(16, n))
        tracks.append_many(landmark_map.ids, 0, True, landmark_map.xy)
        self._state, self._tracks = state, tracks
        self._pose_prior = pose.copy()
        self._next_id = int(landmark_map.ids.max()) + 1 if n else 0
        self._association = None

    def landmark_map(
        self, frame_id: str, stamp_ns: int, parameters: dict[str, bool | int | float | str] | None = None
    ) -> LandmarkMap:
        """The confirmed landmarks as a :class:`turtlelib.slam_map.LandmarkMap` in ``frame_id`` at
        ``stamp_ns``: ids ascending (:attr:`landmark_ids`), positions (:attr:`landmarks`) and their joint
        covariance (2n, 2n) from ``P``, cross-covariances included; ``parameters`` (default none) for the
        record. ValueError for an invalid frame, stamp or parameters.
        """
        slots = self._tracks.slots_by_id(confirmed=True)
        indices = (ROBOT_DIM + 2 * slots[:, None] + np.arange(2)).ravel()
        return LandmarkMap(
            frame_id=frame_id,
            stamp_ns=stamp_ns,
            ids=self._tracks.ids[slots],
            xy=self._state.landmark_positions()[slots],
            covariance=self._state.covariance[np.ix_(indices, indices)],
            parameters={} if parameters is None else parameters,
        )

    def _initial_pose(
        self, T_map_body: Transform2D | None, pose_covariance: ArrayLike | None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The validated pose (3,) (default identity) and its covariance (3, 3) (default from the config)."""
        T_map_body = Transform2D() if T_map_body is None else T_map_body
        if not isinstance(T_map_body, Transform2D):
            raise ValueError(f"T_map_body must be a Transform2D, got {type(T_map_body).__name__}")
        if pose_covariance is None:
            return T_map_body.as_array(), self._config.initial_pose_covariance()
        return T_map_body.as_array(), _pose_covariance(pose_covariance)

    # --- estimates ---------------------------------------------------------------------------------------

    @property
    def pose(self) -> Transform2D:
        """``T_map_body``, the pose mean."""
        x, y, theta = self._state.mean[:ROBOT_DIM]
        return Transform2D(x, y, theta)

    @property
    def pose_covariance(self) -> NDArray[np.float64]:
        """``P_qq`` (3, 3) of ``[x, y, theta]`` (m^2, m^2, rad^2)."""
        return self._state.pose_covariance.copy()

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
    def map_full(self) -> bool:
        """Whether the map (confirmed and tentative landmarks) holds ``max_landmarks``: no landmark is added
        until one is dropped."""
        return self._state.n_landmarks >= self._config.max_landmarks

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
            self._state.landmark_blocks(np.array([slot]))[0],
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
        if self._association not in (None, mode):
            raise ValueError(f"this filter runs with {self._association} association; reset() to switch")
        landmark_ids = None if ids is None else _landmark_ids(ids)
        z, R = self._observations(z, R)
        if len(z) > self._config.max_observations:
            raise ValueError(
                f"{len(z)} observations in one update, more than max_observations = "
                f"{self._config.max_observations}"
            )
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
            return z, self._config.observation_covariances(z[:, 0])
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

    def _in_range(self, z: NDArray[np.float64]) -> NDArray[np.bool_]:
        """``min_range <= range <= max_range`` per observation (K,)."""
        return (z[:, 0] >= self._config.min_range) & (z[:, 0] <= self._config.max_range)

    def _enter_mode(self, mode: str) -> None:
        if self._association not in (None, mode):
            raise ValueError(f"this filter runs with {self._association} association; reset() to switch")
        self._association = mode

    def _gate(
        self, z: NDArray[np.float64], R: NDArray[np.float64], slots: NDArray[np.int64]
    ) -> tuple[NDArray[np.float64], ...]:
        """Observations ``z`` (K, 2) against landmark ``slots`` (k,), O(K k).

        Returns innovations ``nu_kj`` (K, k, 2), ``D2_kj`` and ``ln det S_kj`` (K, k) with
        ``S_kj = H_j P H_j^T + R_k``, and the Jacobians ``H_robot`` (k, 2, 3), ``H_landmark`` (k, 2, 2).
        """
        z_hat, H_robot, H_landmark = self._predicted_observations(slots)
        # nu_kj = z_k - z_hat_j
        nu = residual(z[:, None, :], z_hat[None, :, :])
        return self._distances(nu, R, H_robot, H_landmark, slots)

    def _distances(
        self,
        nu: NDArray[np.float64],
        R: NDArray[np.float64],
        H_robot: NDArray[np.float64],
        H_landmark: NDArray[np.float64],
        slots: NDArray[np.int64],
    ) -> tuple[NDArray[np.float64], ...]:
        """:meth:`_gate`'s result from the innovations ``nu`` (K, k, 2) and Jacobians of ``slots`` (k,)."""
        # S_kj = H_j P H_j^T + R_k
        S = self._predicted_covariances(H_robot, H_landmark, slots)[None] + R[:, None]
        d2, log_det = mahalanobis_2d(nu, S)
        return nu, d2, log_det, H_robot, H_landmark

    def _gate_near(self, z: NDArray[np.float64], R: NDArray[np.float64]) -> tuple[NDArray, ...]:
        """:meth:`_gate` of observations ``z`` (K, 2) against the landmark slots ``near`` (k,) (ascending)
        that may come within ``gate_new`` of one of them; returns ``(near, nu, D2, ln det S, H_robot,
        H_landmark)``. The others are left out before their ``S`` is formed, by a lower bound of their
        ``D2`` from the standard deviations of ``P`` (:func:`~turtlelib.association.mahalanobis_lower_bound`):
        every landmark left out has ``D2 > gate_new`` for every observation, so it could neither be
        associated nor keep an observation from starting a landmark. O(K n), with ``S`` for ``k`` only.
        """
        z_hat, H_robot, H_landmark = self._predicted_observations(np.arange(self._state.n_landmarks))
        nu = residual(z[:, None, :], z_hat[None, :, :])
        std = self._state.stored_std()
        std_robot = np.broadcast_to(std[:ROBOT_DIM], (len(z_hat), ROBOT_DIM))
        std_pose_landmark = np.concatenate([std_robot, std[ROBOT_DIM:].reshape(-1, 2)], axis=1)
        bound = mahalanobis_lower_bound(
            nu, R, np.concatenate([H_robot, H_landmark], axis=2), std_pose_landmark
        )
        # margin: D2 and its bound are computed differently, to rounding
        near = (bound <= self._gate_new * (1.0 + 1e-6)).any(axis=0).nonzero()[0]
        return (near, *self._distances(nu[:, near], R, H_robot[near], H_landmark[near], near))

    def _predicted_covariances(
        self, H_robot: NDArray[np.float64], H_landmark: NDArray[np.float64], slots: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        """``Sigma_j = H_j P H_j^T`` (k, 2, 2) for ``slots`` (k,), O(k): ``H_j`` is non-zero only on
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
        slots: NDArray[np.int64],
    ) -> NDArray[np.int64]:
        """The column of ``d2`` (K, k) (or -1) for each observation, the columns being landmark ``slots``
        (k,): confirmed landmarks first; tentative landmarks only take observations that no confirmed
        landmark is compatible with."""
        compatible = d2 < self._gate_associate
        confirmed = self._tracks.confirmed[slots]
        with_confirmed = compatible & confirmed
        match = self._pair(nu, d2, log_det, with_confirmed, R, H_robot, H_landmark, slots)
        unexplained = ~with_confirmed.any(axis=1)
        if unexplained.any() and not confirmed.all():
            to_tentative = compatible & ~confirmed & unexplained[:, None]
            tentative_match = self._pair(nu, d2, log_det, to_tentative, R, H_robot, H_landmark, slots)
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
        slots: NDArray[np.int64],
    ) -> NDArray[np.int64]:
        """Observations to ``compatible`` columns (landmark ``slots``) by nearest neighbour or JCBB (the
        ``matcher`` option)."""
        if self._config.matcher == "nn":
            # most likely: the smallest -2 log N(nu; 0, S) = D2 + ln det S (+ const)
            return nearest_neighbour(d2 + log_det, compatible)
        candidates = compatible.any(axis=0).nonzero()[0]
        if len(candidates) == 0:
            return np.full(len(nu), -1, dtype=np.int64)
        joint = self._state.observation_covariance(
            slots[candidates], H_robot[candidates], H_landmark[candidates]
        )
        match = joint_compatibility(
            nu[:, candidates],
            compatible[:, candidates],
            joint,
            R,
            self._config.gate_associate,
            self._config.jcbb_max_nodes,
        )
        return np.where(match >= 0, candidates[match], -1)

    def _predicted_observations(
        self, slots: NDArray[np.int64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``z_hat`` (k, 2) of landmark ``slots`` from the newest estimates and the Jacobians ``H_robot``
        (k, 2, 3), ``H_landmark`` (k, 2, 2) of the configured ``linearization`` (module docstring)."""
        pose = self._state.mean[:ROBOT_DIM]
        landmarks = self._state.landmark_positions()[slots]
        z_hat, H_robot, H_landmark = predict_observations(pose, landmarks, self._T_body_sensor)
        if self._config.linearization == "fej":
            _, H_robot, H_landmark = predict_observations(
                self._pose_prior, self._tracks.first_xy[slots], self._T_body_sensor
            )
        elif self._config.linearization == "oc":
            H_robot, H_landmark = _observability_constrained(
                H_robot, H_landmark, self._pose_prior, self._tracks.first_xy[slots]
            )
        elif self._invariant:
            # H T: the heading column gains H_p J p + H_m J m (zero for range-bearing, to rounding)
            H_robot[:, :, HEADING] += H_robot[:, :, :2] @ (J @ pose[:2]) + np.einsum(
                "kij,kj->ki", H_landmark, landmarks @ J.T
            )
        return z_hat, H_robot, H_landmark

    def _innovations(
        self, slots: NDArray[np.int64], z: NDArray[np.float64], R: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], ...]:
        """Observations ``z`` (k, 2) of ``slots`` (k,): innovations ``nu`` (k, 2), ``D2 = nu^T S^-1 nu`` (k,)
        with ``S = H P H^T + R`` of each one alone, and the Jacobians ``H_robot``, ``H_landmark``."""
        z_hat, H_robot, H_landmark = self._predicted_observations(slots)
        nu = residual(z, z_hat)
        d2, _ = mahalanobis_2d(nu, self._predicted_covariances(H_robot, H_landmark, slots) + R)
        return nu, d2, H_robot, H_landmark

    def _fusion_noise(
        self, slots: NDArray[np.int64], R: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The sensor's map position (2,) now and the noise ``R`` (k, 2, 2) of observations of ``slots`` (k,)
        as they are fused: scaled by ``(1 + rho) / (1 - rho)`` for the distance from each one's last view
        (module docstring)."""
        sensor_xy = self._sensor_xy()
        if self._config.independent_noise:
            return sensor_xy, R
        moved_m = np.linalg.norm(sensor_xy - self._tracks.last_view_xy[slots], axis=1)
        return sensor_xy, R * self._config.fusion_scale(moved_m)[:, None, None]

    def _relinearize_first_estimates(self, slots: NDArray[np.int64]) -> None:
        """Reset the first estimates of ``slots`` that lie beyond ``relinearize_gate`` of the current ones."""
        if self._relinearize == np.inf or len(slots) == 0:
            return
        current = self._state.landmark_positions()[slots]
        # D2 = (m - m_first)^T P_mm^-1 (m - m_first)
        d2, _ = mahalanobis_2d(current - self._tracks.first_xy[slots], self._state.landmark_blocks(slots))
        far = d2 > self._relinearize
        self._tracks.relinearize(slots[far], current[far])

    def _add_landmark(
        self, landmark_id: int, z: NDArray[np.float64], R: NDArray[np.float64], confirmed: bool, stamp_ns: int
    ) -> int:
        """Initialise a landmark from one observation by the inverse model (see :meth:`SlamState.append`),
        first seen at ``stamp_ns``; returns its slot."""
        p_map, G_robot, G_z = landmarks_from_observations(
            self._state.mean[:ROBOT_DIM], z[None, :], self._T_body_sensor
        )
        slot = self._state.append(p_map[0], G_robot[0], G_z[0], R)
        self._tracks.append(landmark_id, stamp_ns, confirmed, p_map[0])
        # the sensor position of this first view: the landmark's estimate carries its error
        self._tracks.viewed(np.array([slot]), self._sensor_xy())
        return slot

    def _sensor_xy(self) -> NDArray[np.float64]:
        """The sensor's map position (2,) at the pose mean: ``p + R(theta) [sensor_x, sensor_y]``."""
        x, y, theta = self._state.mean[:ROBOT_DIM]
        c, s = math.cos(theta), math.sin(theta)
        sx, sy = self._T_body_sensor.x, self._T_body_sensor.y
        return np.array([x + c * sx - s * sy, y + s * sx + c * sy])

    def _start_landmark(
        self, z: NDArray[np.float64], R: NDArray[np.float64], started: list[int], stamp_ns: int
    ) -> bool:
        """Start a landmark (id ``_next_id``) from an observation ``z`` (2,) that no landmark explains, unless
        it lies within gate_new of one this scan has ``started`` (slots) already: one object gives one
        detection per scan, or the map is full. Returns whether it did (and appends the new slot to
        ``started``)."""
        if self.map_full:
            return False
        if started:
            _, d2, _, _, _ = self._gate(z[None], R[None], np.array(started))
            if np.any(d2 <= self._gate_new):
                return False
        confirmed = self._config.confirm_count == 1
        started.append(self._add_landmark(self._next_id, z, R, confirmed=confirmed, stamp_ns=stamp_ns))
        self._next_id += 1
        return True

    def _confirmed_indices(self) -> NDArray[np.int64]:
        """State indices of the pose and the confirmed landmarks (in id order)."""
        first = ROBOT_DIM + 2 * self._tracks.slots_by_id(confirmed=True)
        return np.concatenate([np.arange(ROBOT_DIM), (first[:, None] + np.arange(2)).ravel()])


def _finite_step(
    step: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """A motion model's ``(q', G, Q)``, checked finite: ValueError otherwise (a step so large it overflows
    would make ``P`` NaN for good)."""
    q_next, G, Q = step
    if not (np.isfinite(q_next).all() and np.isfinite(G).all() and np.isfinite(Q).all()):
        raise ValueError("the motion step gives a non-finite pose, Jacobian or noise (an implausible input)")
    return step


def _composed_steps(
    motion: MotionModel, T_map_body: Transform2D, inputs: Sequence[tuple]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(poses (n, 3), G, Q)`` of consecutive ``inputs``, one ``motion.step`` each (see
    :meth:`EkfSlam.predict_along`)."""
    poses = np.empty((len(inputs), ROBOT_DIM))
    G, Q = np.eye(ROBOT_DIM), np.zeros((ROBOT_DIM, ROBOT_DIM))
    for k, u in enumerate(inputs):
        q_k, G_k, Q_k = _finite_step(motion.step(T_map_body, u))
        # G <- G_k G,  Q <- G_k Q G_k^T + Q_k
        G, Q = G_k @ G, G_k @ Q @ G_k.T + Q_k
        poses[k] = q_k
        T_map_body = Transform2D(*q_k)
    return poses, G, Q


def _gate_or_inf(prob: float) -> float:
    """``chi2_2^-1(prob)``, infinite for ``prob = 1``."""
    return float(chi2_gate(prob, 2)) if prob < 1.0 else np.inf


def _observability_constrained(
    H_robot: NDArray[np.float64],
    H_landmark: NDArray[np.float64],
    pose: NDArray[np.float64],
    landmarks_xy: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The OC-EKF Jacobians (k, 2, 3), (k, 2, 2): ``H* = H (I - N (N^T N)^-1 N^T)`` per observation with
    ``N = [[I_2, J p], [0, 1], [I_2, J m]]`` (5, 3), ``p`` the pose's position and ``m`` (k, 2) the
    landmarks' (module docstring).

    The projector in closed form: ``N``'s columns orthogonalised are ``n_x = [1, 0, 0, 1, 0]``,
    ``n_y = [0, 1, 0, 0, 1]`` (``|n|^2 = 2``) and, with ``d = m - p``,
    ``n_theta = [d_y / 2, -d_x / 2, 1, -d_y / 2, d_x / 2]`` (``|n_theta|^2 = 1 + |d|^2 / 2``), so::

        H* = H - (H n_x) n_x^T / 2 - (H n_y) n_y^T / 2 - (H n_theta) n_theta^T / |n_theta|^2
    """
    H = np.concatenate([H_robot, H_landmark], axis=2)
    d = landmarks_xy - pose[:2]
    half = 0.5 * d
    n_theta = np.zeros((len(d), 5))
    n_theta[:, 0], n_theta[:, 1], n_theta[:, 2] = half[:, 1], -half[:, 0], 1.0
    n_theta[:, 3], n_theta[:, 4] = -half[:, 1], half[:, 0]
    # (H n_x) / 2 and (H n_y) / 2 (k, 2): the mean of the pose's and the landmark's x (y) columns
    mean_x = 0.5 * (H[:, :, 0] + H[:, :, 3])
    mean_y = 0.5 * (H[:, :, 1] + H[:, :, 4])
    H_theta = np.einsum("kij,kj->ki", H, n_theta) / (1.0 + 0.5 * np.einsum("ki,ki->k", d, d))[:, None]
    H = H - H_theta[:, :, None] * n_theta[:, None, :]
    H[:, :, 0] -= mean_x
    H[:, :, 3] -= mean_x
    H[:, :, 1] -= mean_y
    H[:, :, 4] -= mean_y
    return H[:, :, :ROBOT_DIM], H[:, :, ROBOT_DIM:]


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
