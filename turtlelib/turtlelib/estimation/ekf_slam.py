"""EKF SLAM for a planar robot observing 2D point landmarks; the models and policies are passed in.

Structure
---------
:class:`EkfSlam` is the filter itself: predict, correct, add and remove landmarks, reset, load and give
maps, and its views. What varies is passed in or chosen by a parameter, one class each:

* the motion model (:mod:`turtlelib.motion.motion_models`): ``q' = f(q, u)``, ``G``, ``Q``;
* the measurement model (:mod:`turtlelib.estimation.measurement_models`; default the range-bearing LiDAR of
  the config), per filter and optionally per update (a second sensor): ``h``, its Jacobians, its inverse, the
  residual, the default noise, the usable range;
* the data association (:mod:`turtlelib.estimation.association_policies`): a policy (known ids with a gate, or
  gated tracks with tentative landmarks and a matcher: nearest neighbour, JCBB, or one passed in) plans each
  update from a read-only view of the filter;
* the linearisation (:mod:`turtlelib.estimation.linearization`): standard, FEJ, OC or invariant;
* the state and the records of its landmark slots (:class:`turtlelib.estimation.slam_state.SlamState`, which
  owns both).

State
-----
``x = [x, y, theta, m_0x, m_0y, ..., m_(n-1)x, m_(n-1)y]`` (map frame; m, m, rad, m...) with covariance
``P`` (N, N), ``N = 3 + 2n``, stored with spare capacity by
:class:`turtlelib.estimation.slam_state.SlamState`. The filter's slots hold confirmed and tentative landmarks;
the public views (:attr:`EkfSlam.state`,
:attr:`EkfSlam.covariance`, :attr:`EkfSlam.landmarks`, ...) show the pose and the confirmed landmarks only,
ordered by landmark id (dropping the tentative ones from ``x`` and ``P`` is their marginal).

Prediction (:meth:`EkfSlam.predict`, O(N))
-----------------------------------------
From an input ``u`` through the motion model (:mod:`turtlelib.motion.motion_models`: wheel increments,
odometry, unicycle or car-like)::

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
  :mod:`turtlelib.motion.motion_models`).
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
(:mod:`turtlelib.estimation.range_bearing`); one scan's observations are stacked into one update whose ``H``
touches only the pose and the observed landmarks (:meth:`SlamState.correct`). Landmarks seen for the first
time are initialised from the inverse observation model with their full cross-covariance
(:meth:`SlamState.append`).

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
:mod:`turtlelib.estimation.matching`), confirmed landmarks first: a tentative landmark only takes observations
that no confirmed landmark is compatible with, so a tentative duplicate next to a confirmed landmark
starves and expires. An unpaired observation starts a new tentative
landmark only if ``D2 > chi2_2^-1(gate_new)`` for every landmark, and is discarded otherwise. A tentative
landmark is confirmed once seen in ``confirm_count`` scans (its first sighting included; sightings at one
stamp count once, so copies of a scan confirm nothing) and is dropped
(marginalised out) if still unconfirmed ``tentative_timeout`` seconds after the scan that created it (scan
stamps in integer ns), so a single spurious detection never enters the map. Until it is confirmed, its
observations refine that landmark alone: the pose and the other landmarks are considered, as the Schmidt
update of localization considers the map (below), so a detection that never becomes a landmark never moves
the pose (an office's chair legs, tracked for a few scans, would otherwise steer it).

Localization (``mode = 'localization'``): a fixed map
-----------------------------------------------------
With a map loaded (:meth:`EkfSlam.load_map`, e.g. from :func:`turtlelib.mapping.landmark_map.load_map`) the
filter can localise against it without changing it. Matched observations update the pose only, by the
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
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..geometry.se2 import Transform2D, normalize_angle
from ..mapping.landmark_map import LandmarkMap
from ..motion.motion_models import MotionModel, composed_steps, finite_step
from ..util.timebase import NS_PER_S
from ..util.validation import (
    covariance,
    finite_real,
    in_range,
    integer,
    non_negative,
    one_of,
    positive,
    store,
)
from ..util.validation import landmark_ids as validated_landmark_ids
from .association_policies import (
    MATCHED,
    MATCHERS,
    NEW,
    REJECTED,
    UNMAPPED,
    AssociationPolicy,
    GatedTracks,
    KnownIds,
    Matcher,
    Plan,
    SlamView,
)
from .linearization import LINEARIZATIONS
from .measurement_models import MeasurementModel, RangeBearing, range_bearing_noise
from .slam_state import ROBOT_DIM, SlamState

MODES = ("mapping", "localization")


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
    * ``confirm_count`` (>= 1): sightings (in as many scans) that confirm a tentative landmark;
      ``tentative_timeout`` (s, > 0): how long after its first sighting a tentative landmark may stay
      unconfirmed.
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
        one_of("matcher", self.matcher, tuple(MATCHERS))
        one_of("linearization", self.linearization, tuple(LINEARIZATIONS))
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

    def measurement_model(self) -> RangeBearing:
        """The range-bearing model of these parameters: sensor mount, default noise, range limits."""
        return RangeBearing(
            self.T_body_sensor,
            self.range_std,
            self.bearing_std,
            self.range_std_per_m,
            self.min_range,
            self.max_range,
        )

    def measurement_covariance(self, count: int) -> NDArray[np.float64]:
        """``R = diag(range_std^2, bearing_std^2)`` (count, 2, 2): an observation's noise at range 0."""
        return range_bearing_noise(np.zeros(count), self.range_std, self.bearing_std)

    def observation_covariances(self, range_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """The default ``R`` (K, 2, 2) of observations at ranges ``range_m`` (K,):
        ``diag((range_std + range_std_per_m r)^2, bearing_std^2)``."""
        return range_bearing_noise(range_m, self.range_std, self.bearing_std, self.range_std_per_m)

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

    MATCHED = MATCHED  # joined an existing landmark (confirmed or tentative)
    NEW = NEW  # started a new landmark (tentative unless confirm_count == 1 or the association is known)
    REJECTED = REJECTED  # unused: outside [min_range, max_range], between the two gates, outbid for its
    # landmark, outside the known-association gate, or new while the map is full
    UNMAPPED = UNMAPPED  # would start a landmark, but the map is fixed (localization)


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

    @property
    def counts(self) -> dict[str, int]:
        """How many observations each status got, by lower-case status name."""
        tally = np.bincount(self.status, minlength=len(ObservationStatus))
        return {status.name.lower(): int(tally[status]) for status in ObservationStatus}


class CheckedObservations(NamedTuple):
    """One update's observations as :meth:`EkfSlam.checked_observations` validated them: ``z`` (K, 2), ``R``
    (K, 2, 2), ``ids`` (K,) for known association or None."""

    z: NDArray[np.float64]
    R: NDArray[np.float64]
    ids: NDArray[np.int64] | None


class EkfSlam:
    """EKF SLAM (see the module docstring for the maths): the filter itself, with its models and policies
    passed in.

    ``motion`` is the motion model (:class:`turtlelib.motion.motion_models.MotionModel`: its ``step`` gives
    ``q'``, ``G`` and ``Q`` for an input ``u``); ``T_map_body0`` the initial pose, with covariance from
    ``config.initial_pose_covariance()``; ``measurement`` the measurement model
    (:class:`turtlelib.estimation.measurement_models.MeasurementModel`; default:
    ``config.measurement_model()``, the range-bearing LiDAR), which an update may replace for one call (a
    second sensor); ``matcher`` the
    unknown association's matcher (:class:`turtlelib.estimation.association_policies.Matcher`; default:
    ``config.matcher``). The linearisation strategy is ``config.linearization``
    (:mod:`turtlelib.estimation.linearization`). A
    filter runs either with known association (:meth:`update_known`) or with unknown association
    (:meth:`update_unknown`), fixed by the first update until :meth:`reset`.
    """

    def __init__(
        self,
        config: SlamConfig,
        motion: MotionModel,
        T_map_body0: Transform2D | None = None,
        *,
        measurement: MeasurementModel | None = None,
        matcher: Matcher | None = None,
    ) -> None:
        self._config = config
        self._motion = motion
        self._measurement = config.measurement_model() if measurement is None else measurement
        self._linearization = LINEARIZATIONS[config.linearization](config.relinearize_gate)
        if matcher is None:
            matcher = MATCHERS[config.matcher](config.gate_associate, config.jcbb_max_nodes)
        timeout_ns = round(config.tentative_timeout * NS_PER_S)
        self._policies: dict[str, AssociationPolicy] = {
            "known": KnownIds(config.gate_known),
            "unknown": GatedTracks(
                matcher, config.gate_associate, config.gate_new, config.confirm_count, timeout_ns
            ),
        }
        self._localization = config.mode == "localization"
        # the viewpoints of correlated errors are recorded only when they are modelled
        self._independent_noise = config.independent_noise
        self.reset(Transform2D() if T_map_body0 is None else T_map_body0)

    @property
    def config(self) -> SlamConfig:
        return self._config

    @property
    def motion(self) -> MotionModel:
        return self._motion

    @property
    def measurement(self) -> MeasurementModel:
        """The default measurement model of the updates."""
        return self._measurement

    # --- the filter steps --------------------------------------------------------------------------------

    def predict(self, u: tuple) -> None:
        """Move the pose by the motion model's input ``u``; only the robot rows and columns of ``P`` change.

        ValueError (filter unchanged) for an input the model refuses (non-finite values, ...) or turns into
        a non-finite pose, Jacobian or noise (an overflowing step).
        """
        q_next, G, Q = finite_step(self._motion.step(self.pose, u))
        # P_qq' = G P_qq G^T + Q,  P_qm' = G P_qm
        self._state.predict(q_next, self._linearization.propagation_jacobian(self._state, G), Q)
        self._linearization.predicted(q_next)

    def predict_along(self, inputs: Sequence[tuple]) -> NDArray[np.float64]:
        """:meth:`predict` for each of the consecutive ``inputs`` as one composite prediction; returns the
        pose mean after each input (n, 3).

        The composite of steps ``(q_k, G_k, Q_k)`` is ``(q_n, G_n ... G_1, Q)`` with ``Q = sum_k (G_n ...
        G_(k+1)) Q_k (G_n ... G_(k+1))^T``: the n predictions, to rounding (one input: exactly
        :meth:`predict`). A :class:`~turtlelib.motion.motion_models.BatchMotionModel` gives it in vectorised
        O(n) work, any other model one ``step`` per input. With FEJ / OC the composite's propagation Jacobian
        gets the correction of one step, as after step 1 the mean is its own prior (exact for the arc
        Jacobians ``[[1, 0, -dy], [0, 1, dx], [0, 0, 1]]``, which compose by adding their displacements).
        ValueError (filter unchanged) as :meth:`predict` gives it for any of the inputs.
        """
        if len(inputs) == 0:
            return np.zeros((0, ROBOT_DIM))
        poses, G, Q = composed_steps(self._motion, self.pose, inputs)
        # a non-finite pose anywhere carries on to the last one (the poses accumulate)
        q_next, G, Q = finite_step((poses[-1].copy(), G, Q))
        # P_qq' = G P_qq G^T + Q,  P_qm' = G P_qm
        self._state.predict(q_next, self._linearization.propagation_jacobian(self._state, G), Q)
        self._linearization.predicted(q_next)
        return poses

    def propagated_pose_along(self, inputs: Iterable[tuple]) -> tuple[Transform2D, NDArray[np.float64]]:
        """The pose and its covariance (3, 3) that :meth:`predict` would give for each of the consecutive
        ``inputs`` in turn, one motion step each (none: the current pose), without changing the filter:
        ``q' = f(q, u)``, ``P_qq' = G P_qq G^T + Q``, O(1) per input, for publishing the pose between filter
        steps."""
        T_map_body = self.pose
        P_qq = self._state.pose_covariance.copy()
        for step, u in enumerate(inputs):
            q_next, G, Q = finite_step(self._motion.step(T_map_body, u))
            # the first step from the filter's pose as predict takes it; the later ones start at their prior
            G = self._linearization.propagation_jacobian(self._state, G) if step == 0 else G
            # P_qq' = G P_qq G^T + Q
            P_qq = G @ P_qq @ G.T + Q
            P_qq = 0.5 * (P_qq + P_qq.T)
            T_map_body = Transform2D(*q_next)
        return T_map_body, P_qq

    def update_known(
        self,
        ids: ArrayLike,
        z: ArrayLike,
        R: ArrayLike | None = None,
        measurement: MeasurementModel | None = None,
    ) -> Association:
        """Update with observations ``z`` (K, 2) (sensor frame; [range_m, bearing_rad] for the default model)
        of landmarks ``ids``.

        ``ids`` (K,) distinct integers >= 0 are the truth: an id never seen before starts a new (confirmed)
        landmark from its observation (in localization: is UNMAPPED); an observation of a mapped landmark
        outside the ``gate_known`` innovation gate is rejected. ``R`` (K, 2, 2) the observation noise
        (default from the measurement model); ``measurement`` the model of this update (default: the
        filter's).
        """
        return self.update(
            self.checked_observations(z, R, ids, measurement), stamp_ns=0, measurement=measurement
        )

    def update_unknown(
        self,
        z: ArrayLike,
        R: ArrayLike | None = None,
        *,
        stamp_ns: int,
        measurement: MeasurementModel | None = None,
    ) -> Association:
        """Associate and fuse one scan's observations ``z`` (K, 2) (sensor frame; [range_m, bearing_rad] for
        the default model), taken at ``stamp_ns`` (integer ns; the tentative timeout runs on these stamps).

        Call it once per scan, also with no observations (K = 0), so that tentative landmarks expire.
        ``R`` (K, 2, 2) the observation noise (default from the measurement model); ``measurement`` the
        model of this update (default: the filter's). In localization an observation that would start a
        landmark is UNMAPPED instead.
        """
        checked = self.checked_observations(z, R, measurement=measurement)
        return self.update(checked, stamp_ns=stamp_ns, measurement=measurement)

    def update(
        self, observations: CheckedObservations, *, stamp_ns: int, measurement: MeasurementModel | None = None
    ) -> Association:
        """:meth:`update_known` (``observations.ids`` given) or :meth:`update_unknown` (None) with
        observations that :meth:`checked_observations` validated for ``measurement`` (default: the filter's
        model), as it gave them: not validated again (for callers that queue observations). ValueError for
        anything else, or an association mode the filter does not run in."""
        if not isinstance(observations, CheckedObservations):
            raise ValueError("update takes what checked_observations gives (validated observations)")
        stamp_ns = integer("stamp_ns", stamp_ns)
        z, R, ids = observations
        mode = "unknown" if ids is None else "known"
        self._check_mode(mode)
        self._association = mode
        model = self._measurement if measurement is None else measurement
        policy = self._policies[mode]
        view = self.view(model)
        plan = policy.plan(view, z, R, ids)
        status, landmark_ids = plan.status, plan.landmark_ids
        # one stacked update with the matched observations, then the new landmarks from the updated pose
        nis, fused = self._fuse(model, plan, R[plan.rows])
        confirmed_ids = [policy.sighted(self._state.tracks, fused, stamp_ns)]
        births = plan.births
        if self._localization:
            status[births] = UNMAPPED
            births = births[:0]
        started: list[int] = []
        for b, k in enumerate(births.tolist()):
            if view.map_full or not policy.admits(view, z[k], R[k], started):
                continue
            landmark_id = self._state.tracks.next_id if plan.birth_ids is None else int(plan.birth_ids[b])
            started.append(self._add_landmark(model, landmark_id, z[k], R[k], plan.birth_confirmed, stamp_ns))
            landmark_ids[k], status[k] = landmark_id, NEW
            if plan.birth_confirmed and policy.tentative:
                confirmed_ids.append(landmark_ids[k : k + 1])
        # tentative landmarks the policy gives up are marginalised
        dropped_ids = [self._remove(slot) for slot in policy.expired(view, stamp_ns)]
        return Association(
            status,
            landmark_ids,
            np.concatenate(confirmed_ids) if len(confirmed_ids) > 1 else confirmed_ids[0],
            np.sort(np.array(dropped_ids, dtype=np.int64)) if dropped_ids else np.zeros(0, dtype=np.int64),
            nis,
            2 * len(fused),
        )

    def remove_landmark(self, landmark_id: int) -> None:
        """Marginalise landmark ``landmark_id`` (confirmed or tentative) out of the filter: its rows and
        columns of ``x`` and ``P`` deleted, its record forgotten (a tentative landmark's timeout does the
        same). O(N). ValueError if no landmark has that id."""
        slot = self._state.tracks.slot(int(landmark_id)) if isinstance(landmark_id, Integral) else None
        if slot is None:
            raise ValueError(f"no landmark with id {landmark_id!r}")
        self._remove(slot)

    def _remove(self, slot: int) -> int:
        """Marginalise landmark ``slot`` out; returns its id."""
        landmark_id = int(self._state.tracks.ids[slot])
        self._state.remove(slot)
        return landmark_id

    def update_pose(
        self, T_map_body: Transform2D, covariance: ArrayLike, gate: float = math.inf
    ) -> tuple[float, bool]:
        """Fuse a measurement of the pose itself (a second pose source: a scan registration, a GNSS-like
        fix): ``z = q + v``, ``v ~ N(0, covariance)`` (3, 3), so ``H = [I_3, 0]`` and::

            nu = [x_z - x, y_z - y, wrap(theta_z - theta)]

        (invariant coordinates: ``H T``, whose heading column is ``[-y, x, 1]``). In localization the
        landmarks are considered, not estimated (as :meth:`update` does). Returns the NIS
        ``nu^T S^-1 nu`` (3 dof) and whether the measurement was fused: not when the NIS is not below
        ``gate``. ValueError for a non-finite pose or a covariance that is not symmetric positive definite
        (the filter unchanged)."""
        R = np.asarray(covariance, dtype=np.float64)
        z = T_map_body.as_array()
        if R.shape != (ROBOT_DIM, ROBOT_DIM) or not (np.isfinite(R).all() and np.isfinite(z).all()):
            raise ValueError(
                f"a pose measurement needs a finite pose and a finite 3x3 covariance, got {R.shape}"
            )
        if not np.allclose(R, R.T) or np.linalg.eigvalsh(0.5 * (R + R.T))[0] <= 0.0:
            raise ValueError("the pose measurement's covariance must be symmetric positive definite")
        q = self._state.mean[:ROBOT_DIM]
        nu = z - q
        nu[2] = normalize_angle(z[2] - q[2])
        H = np.eye(ROBOT_DIM)
        if self._linearization.invariant:
            H[0, 2], H[1, 2] = -q[1], q[0]
        return self._state.correct_pose(H, nu, 0.5 * (R + R.T), self._localization, gate)

    def _fuse(
        self, model: MeasurementModel, plan: Plan, R: NDArray[np.float64]
    ) -> tuple[float, NDArray[np.int64]]:
        """The plan's observations (noise ``R`` (m, 2, 2)) in one stacked update; returns the joint NIS and
        the slots fused. Observations beyond the plan's gate are rejected (their status and id in the plan)
        and the others fused.

        Observations of tentative landmarks are fused first, into those landmarks alone (the pose and the
        other landmarks considered, :meth:`SlamState.correct` with ``observed_only``): a detection that never
        becomes a landmark never moves the pose. That update leaves the pose and the confirmed landmarks as
        they were, so the others' innovations and Jacobians still hold, and they follow in one stacked
        update (the sum of the two NIS is the joint NIS).

        With correlated errors each one's ``R`` is scaled by ``(1 + rho) / (1 - rho)`` for the sensor's
        distance from its landmark's last view (module docstring); the gate takes ``R`` itself."""
        if len(plan.slots) == 0:
            return 0.0, plan.slots
        tentative = ~self._state.tracks.confirmed[plan.slots]
        if not tentative.any():  # the usual scan: every observation of a confirmed landmark
            return self._fuse_rows(model, plan, R, None, observed_only=False)
        nis_tentative, fused_tentative = self._fuse_rows(model, plan, R, tentative.nonzero()[0], True)
        nis, fused = self._fuse_rows(model, plan, R, (~tentative).nonzero()[0], False)
        return nis_tentative + nis, np.concatenate([fused_tentative, fused])

    def _fuse_rows(
        self,
        model: MeasurementModel,
        plan: Plan,
        R: NDArray[np.float64],
        subset: NDArray[np.int64] | None,
        observed_only: bool,
    ) -> tuple[float, NDArray[np.int64]]:
        """:meth:`_fuse` of the plan's fusions ``subset`` (None: all), all of the pose and the map or (with
        ``observed_only``) into their landmarks alone."""
        slots, H_robot, H_landmark, nu, rows = plan.slots, plan.H_robot, plan.H_landmark, plan.nu, plan.rows
        if subset is not None:
            slots, H_robot, H_landmark = slots[subset], H_robot[subset], H_landmark[subset]
            nu, rows, R = nu[subset], rows[subset], R[subset]
        if len(slots) == 0:
            return 0.0, slots
        R_fused = R
        if not self._independent_noise:
            sensor_xy = model.sensor_xy(self._state.mean)
            moved_m = np.linalg.norm(sensor_xy - self._state.tracks.last_view_xy[slots], axis=1)
            R_fused = R * self._config.fusion_scale(moved_m)[:, None, None]
        consider, only = self._localization, {"observed_only": observed_only}
        nis, outside = self._state.correct(
            slots, H_robot, H_landmark, nu, R_fused, consider, plan.gate, R, **only
        )
        if outside.any():
            plan.status[rows[outside]], plan.landmark_ids[rows[outside]] = REJECTED, -1
            inside = ~outside
            slots, H_robot, H_landmark, nu = slots[inside], H_robot[inside], H_landmark[inside], nu[inside]
            nis, _ = self._state.correct(slots, H_robot, H_landmark, nu, R_fused[inside], consider, **only)
        if not self._independent_noise:
            self._state.tracks.viewed(slots, sensor_xy)
        self._linearization.fused(self._state, slots)
        return nis, slots

    def _add_landmark(
        self,
        model: MeasurementModel,
        landmark_id: int,
        z: NDArray[np.float64],
        R: NDArray[np.float64],
        confirmed: bool,
        stamp_ns: int,
    ) -> int:
        """Initialise a landmark from one observation by the inverse model (see :meth:`SlamState.append`),
        first seen at ``stamp_ns``; returns its slot."""
        p_map, G_robot, G_z = model.inverse(self._state.mean[:ROBOT_DIM], z[None, :])
        slot = self._state.append(p_map[0], G_robot[0], G_z[0], R, landmark_id, stamp_ns, confirmed)
        self._linearization.added(self._state, np.array([slot]))
        if not self._independent_noise:
            # the sensor position of this first view: the landmark's estimate carries its error
            self._state.tracks.viewed(np.array([slot]), model.sensor_xy(self._state.mean))
        return slot

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
        pose, covariance = _initial_pose(self._config, T_map_body, pose_covariance)
        if keep_map:
            self._state.reset_robot(pose, covariance, keep_map=True)
        else:
            self._state = SlamState(pose, covariance, invariant=self._linearization.invariant)
            self._association: str | None = None
        self._linearization.start(self._state)

    def load_map(
        self,
        landmark_map: LandmarkMap,
        T_map_body: Transform2D | None = None,
        pose_covariance: ArrayLike | None = None,
    ) -> None:
        """Restart with the map ``landmark_map`` (:class:`turtlelib.mapping.landmark_map.LandmarkMap`), from
        pose ``T_map_body`` (default identity) with ``pose_covariance`` (3, 3) (default from the config), as
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
        pose, covariance = _initial_pose(self._config, T_map_body, pose_covariance)
        state = SlamState(
            pose, covariance, capacity_landmarks=max(16, n), invariant=self._linearization.invariant
        )
        slots = state.append_independent(landmark_map.xy, landmark_map.covariance, landmark_map.ids)
        self._linearization.start(state)
        self._linearization.added(state, slots)
        self._state = state
        self._association = None

    def landmark_map(
        self, frame_id: str, stamp_ns: int, parameters: dict[str, bool | int | float | str] | None = None
    ) -> LandmarkMap:
        """The confirmed landmarks as a :class:`turtlelib.mapping.landmark_map.LandmarkMap` in ``frame_id`` at
        ``stamp_ns``: ids ascending (:attr:`landmark_ids`), positions (:attr:`landmarks`) and their joint
        covariance (2n, 2n) from ``P``, cross-covariances included; ``parameters`` (default none) for the
        record. ValueError for an invalid frame, stamp or parameters.
        """
        tracks = self._state.tracks
        slots = tracks.slots_by_id(confirmed=True)
        indices = (ROBOT_DIM + 2 * slots[:, None] + np.arange(2)).ravel()
        return LandmarkMap(
            frame_id=frame_id,
            stamp_ns=stamp_ns,
            ids=tracks.ids[slots],
            xy=self._state.landmark_positions()[slots],
            covariance=self._state.covariance[np.ix_(indices, indices)],
            parameters={} if parameters is None else parameters,
        )

    # --- estimates ---------------------------------------------------------------------------------------

    def view(self, measurement: MeasurementModel | None = None) -> SlamView:
        """The filter as data association sees it (read-only, live), through ``measurement`` (default: the
        filter's model); landmarks by slot."""
        model = self._measurement if measurement is None else measurement
        return SlamView(self._state, self._linearization, model, self._config.max_landmarks)

    def predicted_landmarks(self) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """The confirmed landmarks as the filter's measurement model predicts them now: ids (n,) ascending,
        ``z_hat = h(x)`` (n, 2) and its covariance ``H P H^T`` (n, 2, 2) (pose and landmark uncertainty,
        without the observation noise)."""
        tracks = self._state.tracks
        slots = tracks.slots_by_id(confirmed=True)
        z_hat, covariance = self.view().predicted(slots)
        return tracks.ids[slots], z_hat, covariance

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
        tracks = self._state.tracks
        return tracks.ids[tracks.slots_by_id(confirmed=True)]

    @property
    def landmarks(self) -> NDArray[np.float64]:
        """Map positions (n, 2) (m) of the confirmed landmarks."""
        return self._state.landmark_positions()[self._state.tracks.slots_by_id(confirmed=True)]

    @property
    def landmark_covariances(self) -> NDArray[np.float64]:
        """Marginal covariances (n, 2, 2) (m^2) of the confirmed landmarks."""
        return self._state.landmark_blocks(self._state.tracks.slots_by_id(confirmed=True))

    @property
    def state(self) -> NDArray[np.float64]:
        """``x`` (N,) = ``[x, y, theta, m_0x, m_0y, ...]`` over the confirmed landmarks."""
        return self._state.mean[_confirmed_indices(self._state)]

    @property
    def covariance(self) -> NDArray[np.float64]:
        """``P`` (N, N), a copy, over the pose and the confirmed landmarks (the layout of :attr:`state`)."""
        indices = _confirmed_indices(self._state)
        return self._state.covariance[np.ix_(indices, indices)]

    @property
    def map_full(self) -> bool:
        """Whether the map (confirmed and tentative landmarks) holds ``max_landmarks``: no landmark is added
        until one is dropped."""
        return self._state.n_landmarks >= self._config.max_landmarks

    @property
    def tentative_ids(self) -> NDArray[np.int64]:
        """Ids of the tentative (unconfirmed) landmarks, ascending."""
        tracks = self._state.tracks
        return tracks.ids[tracks.slots_by_id(confirmed=False)]

    @property
    def tentative_landmarks(self) -> NDArray[np.float64]:
        """Map positions (t, 2) of the tentative landmarks, in the order of :attr:`tentative_ids`."""
        return self._state.landmark_positions()[self._state.tracks.slots_by_id(confirmed=False)]

    def landmark_estimate(self, landmark_id: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Position (2,) and covariance (2, 2) of confirmed landmark ``landmark_id``.

        ValueError if no confirmed landmark has that id.
        """
        tracks = self._state.tracks
        slot = tracks.slot(int(landmark_id)) if isinstance(landmark_id, Integral) else None
        if slot is None or not tracks.confirmed[slot]:
            raise ValueError(f"no confirmed landmark with id {landmark_id!r}")
        first = ROBOT_DIM + 2 * slot
        return (
            self._state.mean[first : first + 2].copy(),
            self._state.landmark_blocks(np.array([slot]))[0],
        )

    # --- helpers -----------------------------------------------------------------------------------------

    def checked_observations(
        self,
        z: ArrayLike,
        R: ArrayLike | None = None,
        ids: ArrayLike | None = None,
        measurement: MeasurementModel | None = None,
    ) -> CheckedObservations:
        """What the updates take, validated (for :meth:`update`): ``z`` (K, 2) finite and taken by the
        measurement model (``measurement``, default the filter's; range > 0 for range-bearing), ``R``
        (K, 2, 2) symmetric positive definite (default from the model) and, if given, ``ids`` (K,) distinct
        integers >= 0. Observations with ``ids`` are for :meth:`update_known`, without for
        :meth:`update_unknown`: they must fit the filter's association mode.

        ValueError otherwise. For callers that queue observations and must refuse bad ones at once.
        """
        self._check_mode("unknown" if ids is None else "known")
        landmark_ids = None if ids is None else validated_landmark_ids("landmark ids", ids)
        model = self._measurement if measurement is None else measurement
        z, R = _observations(model, z, R)
        if len(z) > self._config.max_observations:
            raise ValueError(
                f"{len(z)} observations in one update, more than max_observations = "
                f"{self._config.max_observations}"
            )
        if landmark_ids is not None and len(landmark_ids) != len(z):
            raise ValueError(f"{len(landmark_ids)} ids for {len(z)} observations")
        return CheckedObservations(z, R, landmark_ids)

    def _check_mode(self, mode: str) -> None:
        """ValueError unless the filter may run with ``mode`` association (the first update fixes it)."""
        if self._association not in (None, mode):
            raise ValueError(f"this filter runs with {self._association} association; reset() to switch")


def _initial_pose(
    config: SlamConfig, T_map_body: Transform2D | None, pose_covariance: ArrayLike | None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The validated pose (3,) (default identity) and its covariance (3, 3) (default from ``config``)."""
    T_map_body = Transform2D() if T_map_body is None else T_map_body
    if not isinstance(T_map_body, Transform2D):
        raise ValueError(f"T_map_body must be a Transform2D, got {type(T_map_body).__name__}")
    if pose_covariance is None:
        return T_map_body.as_array(), config.initial_pose_covariance()
    return T_map_body.as_array(), covariance("pose covariance", pose_covariance, (3, 3), definite=False)


def _confirmed_indices(state: SlamState) -> NDArray[np.int64]:
    """State indices of the pose and the confirmed landmarks (in id order)."""
    first = ROBOT_DIM + 2 * state.tracks.slots_by_id(confirmed=True)
    return np.concatenate([np.arange(ROBOT_DIM), (first[:, None] + np.arange(2)).ravel()])


def _observations(
    model: MeasurementModel, z: ArrayLike, R: ArrayLike | None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Validated ``z`` (K, 2) with finite values the model takes, and ``R`` (K, 2, 2) symmetric PD (default:
    the model's)."""
    z = np.array(z, dtype=np.float64)
    if z.size == 0:
        z = z.reshape(0, 2)
    if z.ndim != 2 or z.shape[1] != 2:
        raise ValueError(f"observations must have shape (K, 2), got {z.shape}")
    if not np.isfinite(z).all():
        raise ValueError("observations must be finite")
    model.check(z)
    if R is None:
        return z, model.noise(z)
    return z, covariance("R", R, (len(z), 2, 2), definite=True)
