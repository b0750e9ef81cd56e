"""LiDAR odometry: each scan registered to a local map of recent scans, the motion input as its prior.

The motion input (wheel odometry, a recorded ``odom``) gives the pose ``T_odom_body(t_k)`` at each scan's
stamp ``t_k``. With ``T_k-1`` the previous scan's registered pose (frame ``lidar_odom``) and the input's
motion between the scans ``U_k = T_odom_body(t_k-1)^-1 T_odom_body(t_k)``, the prior of scan ``k`` and its
covariance given ``T_k-1`` are::

    T_prior = T_k-1 U_k,     P_prior = Q(T_k-1, log U_k, t_k - t_k-1) + P_floor

(``Q`` the motion input's :class:`~turtlelib.motion.motion_models.TwistNoise`; ``P_floor`` keeps a robot
that stands still from pinning the registration exactly; after steps on the input alone, ``Q`` is what
they accumulated since the last registered scan). After the input restarted (a gap in it, another
odometry frame, a clock that jumped: :meth:`LidarOdometry.forget_input`) its motion to the next scan is
taken only if a robot within its speed bounds could have made it in the time (``|U_xy| <= v_max dt +
s_m``, ``|U_theta| <= omega_max dt + s_rad``: a gap in an odometry that goes on in its frame), else the
prior is the previous scan's pose; either way widened by ``diag(s_m^2, s_m^2, s_rad^2)``
(``resume_std_m``, ``resume_std_rad``). The local map, which the robot has not left, is kept.

The scan is registered to the local map with that prior
(:func:`turtlelib.sensing.scan_registration.register`): ``T_k`` with covariance ``Sigma_k`` (given the map, so
given ``T_k-1``). Where registration has nothing to match (the first scan, too few points) the scan's pose is
the prior: the estimate is then the motion input's own. A scan that moved ``keyframe_distance_m`` or turned
``keyframe_angle_rad`` from the newest keyframe becomes one; the local map is the newest ``keyframes`` of
them, thinned to one point per ``voxel_m`` cell.

Each scan gives a sample of :class:`turtlelib.motion.motion_signals.MeasuredPoses` for the filter's
timeline: the pose ``T_k`` and the covariance of the motion since ``t_k-1`` (map frame, additive ``[x, y,
theta]``), so the filter predicts from scan to scan with the registered motion
(:class:`turtlelib.motion.motion_models.MeasuredMotion`) as independent increments. Scans registered to the
same local map are not independent: their errors are errors against the same anchor (the local map),
which moves only a little when a keyframe is added; summing each scan's ``Sigma_k`` as an increment would
grow the covariance with the number of scans while the error stays bounded wherever the scans constrain it.
The registered pose is ``Sigma_k (H_s z + P_prior^-1 (T_k-1 U_k))``: the scan's part errs against the map,
the prior's carries the previous scan's error ``e_k-1`` on. So the error against the map has the
covariance::

    C_k = Sigma_k + M C_k-1 M^T,     M = Sigma_k P_prior^-1

(where the scan pins a direction, ``M ~ 0`` there and ``C_k ~ Sigma_k``: bounded; along a degenerate one
``M ~ I`` and ``C_k ~ C_k-1 + P_prior``: the motion input's random walk). The map's own error ``B`` is what
its keyframes brought in. Where the scans pin the pose, the map is (to first order) the mean of its
keyframes, each put in at its registered pose: a keyframe added to a map of ``n`` moves the map by ``s``
of its error against it, ``s = 1 / (n + 1)`` while the map grows and, once each new keyframe drops the
oldest of ``K``, ``s = 2 / (K + 1)`` in the long run (the lasting shift an error ``e_k`` gives ``x_k =
mean(x_k-K .. x_k-1) + e_k`` is ``1 / sum_j (j / K)``). Where the prior decided the pose (``M``), the map
along that direction is the new keyframe alone, and takes all of its error. So with ``N = s (I - M) + M``
(``M`` the keyframe's own), the keyframe moves the map by ``N e`` and leaves ``(I - N) e`` as the error
against the new map::

    B <- B + N C_k N^T,     C_k <- (I - N) C_k (I - N)^T

A scan's error against the world then has the covariance ``B + C_k``, and the steps add up to its
envelope: with ``A`` their sum so far, a registered scan's increment is::

    Q_k = [B + C_k - A]_+,     A <- A + Q_k      ([.]_+: the positive semi-definite part)

so ``A >= B + C_k`` after each scan (the filter's pose covariance covers the newest error): in a room the
covariance grows by about ``s^2 C`` a keyframe instead of ``C``, along a corridor by the motion input's
random walk, as it should. ``A``, ``B`` and ``C`` are carried to each new pose (``G X G^T``, ``G`` the
right-composition Jacobian). A step on the motion input alone carries its whole motion covariance (and
adds it to ``A``, its ``M = I``; ``C`` is carried to the new pose, the next registration's prior covering
the motion).

The local map is itself made of registered scans: its error against the world, which no registration
against it can see, grows with the distance travelled by more than ``B`` holds where the scans are biased
(a wall seen at a glancing angle, glass, a LiDAR's range bias: errors that do not average out). Each
registered step of ``d_k`` metres adds ``d_k diag(q_xy, q_xy, q_theta)`` (``drift_m2_per_m``,
``drift_rad2_per_m``) for it; 0 where the scans are unbiased, as in a simulator.

Anchored increments (a keyframe graph's edges)
----------------------------------------------
While no scan comes (a LiDAR slower than the input, or scans kept only every half metre, as in recorded
logs), the input alone moves the pose on and its motion adds to ``A``: the filter's pose between the scans
is that uncertain. The next scan, registered, puts the pose back within ``B + C_k`` of the world, but a sum
cannot shrink, so ``A`` keeps the motion for good. Between two registered scans that is not their relative
pose's uncertainty: a keyframe graph built on the steps would take the input's noise for the registrations'
and bend the wrong edges when a loop closes. So each step also carries its *anchored* increment
``Sigma_anchored``, with its own sum ``A_a`` kept like ``A`` but for the steps without a scan, whose motion
is deferred (``D <- D + Q``, carried like the rest) rather than summed::

    registered:                        Q_a = [B + C_k - A_a]_+ (+ the drift since the last one),   D <- 0
    a scan that did not register:      Q_a = Q + D,  D <- 0          (the input's motion is the pose's)
    no scan:                           Q_a = 0,      D <- D + Q

(the registration's prior holds ``P_since``, so ``C_k`` carries the deferred motion where the scan leaves
the prior in charge), ``A_a <- A_a + Q_a``. Where every step has a scan, ``Sigma_anchored = Sigma``.
"""

from __future__ import annotations

import enum
import math
from collections import deque
from dataclasses import dataclass, field
from functools import partial

import numpy as np
from numpy.typing import NDArray

from ..geometry.se2 import Transform2D, normalize_angle, right_composition_jacobian
from ..motion.motion_models import TwistNoise, upper_triangle
from ..motion.motion_signals import Sample
from ..sensing.range_scan import RangeScan
from ..sensing.scan_registration import (
    LocalMap,
    Registration,
    RegistrationConfig,
    register,
    voxel_centroids,
)
from ..util.timebase import NS_PER_S
from ..util.validation import integer, non_negative, positive, store

# P_floor: (1 mm)^2 and (0.001 rad)^2
_PRIOR_FLOOR = np.diag([1e-6, 1e-6, 1e-6])


@dataclass(frozen=True)
class LidarOdometryConfig:
    """``keyframe_distance_m`` (m, > 0), ``keyframe_angle_rad`` (rad, > 0): how far a scan must be from the
    newest keyframe to become one; ``keyframes`` (int >= 1): keyframes in the local map; ``resume_std_m``
    (m, > 0), ``resume_std_rad`` (rad, > 0): the prior's standard deviations for the first scan after the
    motion input restarted; ``drift_m2_per_m`` (m^2/m), ``drift_rad2_per_m`` (rad^2/m), >= 0: the local
    maps' own drift per metre of a registered step (module docstring); ``registration``: the matcher's
    (:class:`RegistrationConfig`). ValueError for invalid values."""

    keyframe_distance_m: float = 0.2
    keyframe_angle_rad: float = 0.2
    keyframes: int = 20
    resume_std_m: float = 0.5
    resume_std_rad: float = 0.3
    drift_m2_per_m: float = 0.02**2
    drift_rad2_per_m: float = 0.01**2
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)

    def __post_init__(self) -> None:
        store(self, ("keyframe_distance_m", "keyframe_angle_rad", "resume_std_m", "resume_std_rad"), positive)
        store(self, ("keyframes",), partial(integer, minimum=1))
        store(self, ("drift_m2_per_m", "drift_rad2_per_m"), non_negative)
        if not isinstance(self.registration, RegistrationConfig):
            raise ValueError(f"registration must be a RegistrationConfig, got {self.registration!r}")


class Basis(enum.Enum):
    """What a scan's pose rests on: the scan registered (``REGISTERED``), registered but weak along a
    direction the prior then holds (``DEGENERATE``), or the motion input alone (``MOTION``: no map yet,
    too few points matched)."""

    REGISTERED = "registered"
    DEGENERATE = "degenerate"
    MOTION = "motion"


@dataclass(frozen=True)
class OdometryStep:
    """One scan's result: its stamp, its pose ``T_odom_body`` (frame ``lidar_odom``), the covariance
    ``Sigma`` (3, 3) the step adds to the pose's (module docstring: what the newest error against the
    keyframe exceeds of the steps since it, plus the map's drift over the step), what it rests on
    (``basis``), the registration (None for ``Basis.MOTION``), and ``Sigma_anchored`` (3, 3), the step's
    anchored increment (module docstring, "Anchored increments")."""

    t_ns: int
    T_odom_body: Transform2D
    Sigma: NDArray[np.float64]
    basis: Basis
    registration: Registration | None
    interval_ns: int
    Sigma_anchored: NDArray[np.float64]

    @property
    def sample(self) -> Sample:
        """This step as a :class:`~turtlelib.motion.motion_signals.MeasuredPoses` sample."""
        T = self.T_odom_body
        return T.x, T.y, T.theta, float(self.interval_ns), *upper_triangle(self.Sigma)


def scan_points(scan: RangeScan, T_body_lidar: Transform2D) -> NDArray[np.float64]:
    """The returns of ``scan`` as points in the body frame (n, 2): ``T_body_lidar rho_b [cos phi_b, sin
    phi_b]``."""
    valid = scan.returns()
    beams = np.flatnonzero(valid)
    phi = scan.angle_min + beams * scan.angle_increment
    rho = scan.ranges[valid]
    p_lidar = np.column_stack([rho * np.cos(phi), rho * np.sin(phi)])
    return T_body_lidar @ p_lidar


class LidarOdometry:
    """Scan-to-local-map odometry with the motion input as the prior (module docstring). ``noise`` is the
    motion input's; ``max_speed_mps`` and ``max_turn_rate_rad_s`` (> 0) bound the robot's motion."""

    def __init__(
        self,
        config: LidarOdometryConfig,
        noise: TwistNoise,
        max_speed_mps: float = math.inf,
        max_turn_rate_rad_s: float = math.inf,
    ) -> None:
        self.config = config
        self.noise = noise
        self._max_speed = (
            positive("max_speed_mps", max_speed_mps) if math.isfinite(max_speed_mps) else math.inf
        )
        self._max_turn = (
            positive("max_turn_rate_rad_s", max_turn_rate_rad_s)
            if math.isfinite(max_turn_rate_rad_s)
            else math.inf
        )
        self._input_restarted = False
        self._keyframes: deque[NDArray[np.float64]] = deque(maxlen=config.keyframes)
        self._keyframe_pose: Transform2D | None = None
        self._map: LocalMap | None = None
        self._last: tuple[int, Transform2D, Transform2D] | None = None
        # the covariance of the motion since the last registered scan (the next registration's prior)
        self._P_since = np.zeros((3, 3))
        # A: the steps' covariances summed; B: the local map's error covariance; C: the newest registered
        # scan's error covariance against the local map (all carried to the newest pose)
        self._A = np.zeros((3, 3))
        self._B = np.zeros((3, 3))
        self._C = np.zeros((3, 3))
        # A_a: the anchored increments summed; D: the motion of the steps without a scan since the last
        # registered one, deferred (module docstring, "Anchored increments")
        self._A_anchored = np.zeros((3, 3))
        self._deferred = np.zeros((3, 3))
        # the path (m) of those steps, whose drift the next registered one adds to its anchored increment
        self._deferred_m = 0.0
        # M of the newest step: how much of its pose the prior, not the scan, decided (I: the input alone)
        self._M = np.eye(3)

    def forget_input(self) -> None:
        """The motion input restarted: its motion to the next scan is taken only if plausible (module
        docstring); that scan's stamp may be any."""
        self._input_restarted = self._last is not None

    def step(
        self,
        t_ns: int,
        T_input_body: Transform2D,
        scan: RangeScan | None,
        T_body_lidar: Transform2D | None = None,
    ) -> OdometryStep:
        """Register the scan stamped ``t_ns`` (integer ns, after the previous one), taken by the LiDAR
        mounted at ``T_body_lidar``, at which the motion input's pose is ``T_input_body``; with no scan
        (``None``: the LiDAR is silent) the motion input alone moves the pose on to ``t_ns``. ValueError for
        a stamp not after the previous one's."""
        t_ns = integer("scan stamp (ns)", t_ns)
        points = np.zeros((0, 2))
        if scan is not None:
            mount = Transform2D() if T_body_lidar is None else T_body_lidar
            points = voxel_centroids(scan_points(scan, mount), self.config.registration.voxel_m)
        if self._last is None:
            # the first scan: frame lidar_odom starts as the input's own
            step = OdometryStep(t_ns, T_input_body, np.zeros((3, 3)), Basis.MOTION, None, 0, np.zeros((3, 3)))
        else:
            step = self._registered(t_ns, T_input_body, points)
        self._last = (t_ns, step.T_odom_body, T_input_body)
        self._keep(step.T_odom_body, points)
        return step

    def seed_map(
        self,
        t_ns: int,
        T_input_body: Transform2D,
        scan: RangeScan,
        T_body_lidar: Transform2D | None = None,
    ) -> bool:
        """A scan stamped ``t_ns`` at or before the newest step, while there is no local map yet (the
        motion input alone drove the pose on past the first scans, e.g. a LiDAR whose messages arrive
        later than the wheels'): it becomes the map's first keyframe at the pose of that stamp, the newest
        step's moved back by the input's own motion::

            T_odom_body(t) = T_last T_input_last^-1 T_input(t)

        and no step is made. False (nothing done) once a map exists, before any step, after the input
        restarted, or for a stamp after the newest step's (then :meth:`step` takes the scan)."""
        if self._map is not None or self._last is None or self._input_restarted or t_ns > self._last[0]:
            return False
        _, T_last, T_input_last = self._last
        mount = Transform2D() if T_body_lidar is None else T_body_lidar
        points = voxel_centroids(scan_points(scan, mount), self.config.registration.voxel_m)
        self._keep(T_last @ T_input_last.inverse() @ T_input_body, points)
        return self._map is not None

    def _registered(self, t_ns: int, T_input_body: Transform2D, points: NDArray[np.float64]) -> OdometryStep:
        t_prev, T_prev, T_input_prev = self._last
        if t_ns <= t_prev and not self._input_restarted:
            raise ValueError(f"scan stamp {t_ns} ns is not after the previous scan's, {t_prev} ns")
        # T_prior = T_k-1 U_k,  P_prior = Q(T_k-1, log U_k, dt) + P_floor
        U, dt_s = T_input_prev.inverse() @ T_input_body, (t_ns - t_prev) / NS_PER_S
        P_motion = np.zeros((3, 3))
        if self._input_restarted:
            config = self.config
            plausible = (
                dt_s > 0.0
                and math.hypot(U.x, U.y) <= self._max_speed * dt_s + config.resume_std_m
                and abs(U.theta) <= self._max_turn * dt_s + config.resume_std_rad
            )
            U = U if plausible else Transform2D()
            P_motion = np.diag([config.resume_std_m**2, config.resume_std_m**2, config.resume_std_rad**2])
            t_prev = min(t_prev, t_ns)
            self._input_restarted = False
        T_prior = T_prev @ U
        P_motion = P_motion + self.noise.covariance(T_prev, U.log(), max(dt_s, 0.0))
        # the uncertainty since the last registered scan (steps on the input alone in between):
        # P_acc' = G P_acc G^T + P_motion,  G = [[1, 0, -dy], [0, 1, dx], [0, 0, 1]]
        G = right_composition_jacobian(T_prev, T_prior)
        P_since = G @ self._P_since @ G.T + P_motion
        registration = None
        P_prior = P_since + _PRIOR_FLOOR
        if self._map is not None and len(points) >= self.config.registration.min_points:
            registration = register(points, self._map, T_prior, P_prior, self.config.registration)
        self._A, self._B, self._C, self._A_anchored, self._deferred = (
            G @ X @ G.T for X in (self._A, self._B, self._C, self._A_anchored, self._deferred)
        )
        if registration is None:
            self._M = np.eye(3)
            self._P_since = P_since
            self._A = self._A + P_motion
            if len(points):
                # a scan that did not register: Q_a = Q + D, D <- 0
                anchored, self._deferred = P_motion + self._deferred, np.zeros((3, 3))
                self._deferred_m = 0.0
            else:
                # no scan: Q_a = 0, D <- D + Q
                anchored, self._deferred = np.zeros((3, 3)), self._deferred + P_motion
                self._deferred_m += math.hypot(T_prior.x - T_prev.x, T_prior.y - T_prev.y)
            self._A_anchored = self._A_anchored + anchored
            return OdometryStep(t_ns, T_prior, P_motion, Basis.MOTION, None, t_ns - t_prev, anchored)
        self._P_since = np.zeros((3, 3))
        basis = Basis.DEGENERATE if registration.degenerate else Basis.REGISTERED
        # C_k = Sigma_k + M C_k-1 M^T,  M = Sigma_k P_prior^-1
        Sigma = registration.Sigma
        M = np.linalg.solve(P_prior, Sigma).T
        self._C = Sigma + M @ self._C @ M.T
        self._M = M
        # Q_k = [B + C_k - A]_+,  A <- A + Q_k;  Q_a = [B + C_k - A_a]_+,  A_a <- A_a + Q_a,  D <- 0
        Q = _positive_part(self._B + self._C - self._A)
        self._A = self._A + Q
        Q_anchored = _positive_part(self._B + self._C - self._A_anchored)
        self._A_anchored = self._A_anchored + Q_anchored
        # + d_k diag(q_xy, q_xy, q_theta): the local map's own drift over the step's d_k metres (the anchored
        # increment's over the path since the last registered scan: the deferred steps' too)
        d_m = math.hypot(registration.T_map_body.x - T_prev.x, registration.T_map_body.y - T_prev.y)
        q = self.config
        drift = np.diag([q.drift_m2_per_m, q.drift_m2_per_m, q.drift_rad2_per_m])
        anchored = Q_anchored + (d_m + self._deferred_m) * drift
        self._deferred, self._deferred_m = np.zeros((3, 3)), 0.0
        return OdometryStep(
            t_ns, registration.T_map_body, Q + d_m * drift, basis, registration, t_ns - t_prev, anchored
        )

    def _is_keyframe(self, T_odom_body: Transform2D) -> bool:
        """True when a scan at ``T_odom_body`` moved or turned far enough from the newest keyframe."""
        if self._keyframe_pose is None:
            return True
        moved = self._keyframe_pose.inverse() @ T_odom_body
        far = math.hypot(moved.x, moved.y) >= self.config.keyframe_distance_m
        return far or abs(normalize_angle(moved.theta)) >= self.config.keyframe_angle_rad

    def _keep(self, T_odom_body: Transform2D, points: NDArray[np.float64]) -> None:
        """Make the scan a keyframe if it moved or turned far enough from the newest one."""
        if len(points) == 0 or not self._is_keyframe(T_odom_body):
            return
        self._keyframe_pose = T_odom_body
        n = len(self._keyframes)
        if n:
            # N = s (I - M) + M: B <- B + N C N^T,  C <- (I - N) C (I - N)^T
            s = 2.0 / (n + 1) if n == self._keyframes.maxlen else 1.0 / (n + 1)
            N = s * (np.eye(3) - self._M) + self._M
            self._B = self._B + N @ self._C @ N.T
            self._C = (np.eye(3) - N) @ self._C @ (np.eye(3) - N).T
        self._keyframes.append(T_odom_body @ points)
        q_map = voxel_centroids(np.concatenate(list(self._keyframes)), self.config.registration.voxel_m)
        self._map = LocalMap(q_map, self.config.registration) if len(q_map) >= 3 else None


def _positive_part(M: NDArray[np.float64]) -> NDArray[np.float64]:
    """``[M]_+ = V max(Lambda, 0) V^T`` for the symmetric part of ``M = V Lambda V^T``."""
    eigenvalues, V = np.linalg.eigh(0.5 * (M + M.T))
    return (V * np.maximum(eigenvalues, 0.0)) @ V.T
