"""The factors of a smoother over an EKF SLAM run, from the run's own models
(:mod:`turtlelib.smoothing.smoother`).

Unknowns: poses ``q_k = [x, y, theta]`` (``T_map_body``; m, m, rad) at stamps ``t_k`` (ns) - the run's start
and every scan - and landmarks ``m_i = [mx, my]`` (m, map frame). Each factor is a residual ``r`` with a
Gaussian covariance ``S``::

    start prior      r = q_0 (-) q0_bar                           S = P_0
    motion k         r = (q_k^-1 q_(k+1)) (-) delta_k             S = Q_k
    loop l           r = (q_a(l)^-1 q_b(l)) (-) Z_l               S = S_l
    observation j    r = z_j (-) h(q_k(j), m_i(j))                S = R_j

``(-)`` subtracts componentwise with the heading wrapped (for ``z``, the measurement model's residual).
``q_k^-1 q_(k+1)`` is the relative pose ``[R(theta_k)^T (p_(k+1) - p_k), theta_(k+1) - theta_k]``. A loop is
a measured relative pose ``Z_l`` between two poses far apart in the run (:class:`LoopEdge`: a revisit that
loop closure matched, :mod:`turtlelib.smoothing.loop_closure`), ``S_l`` in frame ``a``'s ``[x, y, theta]``.

``delta_k`` and ``Q_k`` are the motion model's composite step from the identity along the signal's pieces
between ``t_k`` and ``t_(k+1)`` (:func:`relative_motions`): exactly the prediction the filter made over that
interval, so ``Q_k`` is the covariance of the relative pose in frame ``k``'s ``[x, y, theta]``, from the same
motion model and noise. A robot standing still gives ``Q_k = 0``; ``min_motion_std`` floors it so that the
factor stays invertible.

Correlated observation errors (:class:`turtlelib.estimation.ekf_slam.SlamConfig`'s ``noise_correlation``) are
modelled as in the filter: each view of a landmark after its first has ``R`` scaled by ``(1 + rho(d)) / (1 -
rho(d))``, ``d`` the distance the sensor moved since the landmark's previous view (:func:`viewpoint_scales`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..geometry.se2 import Transform2D
from ..motion.motion_models import MotionModel, composed_steps
from ..motion.motion_signals import MotionSignal, Sample, signal_at, signal_pieces


@dataclass(frozen=True)
class SmoothingProblem:
    """The factors of a run (module docstring): ``pose_t_ns`` (P,) increasing pose stamps; the start prior
    ``prior_mean`` (3,) and ``prior_covariance`` (3, 3) on pose 0; ``motion_delta`` (P-1, 3) and
    ``motion_covariance`` (P-1, 3, 3) between consecutive poses; observations ``z`` (K, 2) with their own
    noise ``R`` (K, 2, 2), made from pose ``observation_pose`` (K,) (indices) of landmark
    ``observation_landmark`` (K,) (ids); each observation's factor has the covariance ``noise_scale R``
    (``noise_scale`` (K,), default ones: the viewpoint scale of correlated errors, which depends on the
    labelling); loops between poses ``loop_pose`` (L, 2) (indices ``a, b``), measured ``loop_delta`` (L, 3)
    with ``loop_covariance`` (L, 3, 3) (default: none). ValueError for inconsistent shapes."""

    pose_t_ns: NDArray[np.int64]
    prior_mean: NDArray[np.float64]
    prior_covariance: NDArray[np.float64]
    motion_delta: NDArray[np.float64]
    motion_covariance: NDArray[np.float64]
    observation_pose: NDArray[np.int64]
    observation_landmark: NDArray[np.int64]
    z: NDArray[np.float64]
    R: NDArray[np.float64]
    noise_scale: NDArray[np.float64] | None = None
    loop_pose: NDArray[np.int64] = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    loop_delta: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    loop_covariance: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3, 3)))

    def __post_init__(self) -> None:
        n_poses, n_obs, n_loops = len(self.pose_t_ns), len(self.z), len(self.loop_pose)
        if self.noise_scale is None:
            object.__setattr__(self, "noise_scale", np.ones(n_obs))
        if n_poses < 1 or np.any(np.diff(self.pose_t_ns) <= 0):
            raise ValueError("pose stamps must be at least one, strictly increasing")
        shapes = {
            "prior_mean": (self.prior_mean, (3,)),
            "prior_covariance": (self.prior_covariance, (3, 3)),
            "motion_delta": (self.motion_delta, (n_poses - 1, 3)),
            "motion_covariance": (self.motion_covariance, (n_poses - 1, 3, 3)),
            "observation_pose": (self.observation_pose, (n_obs,)),
            "observation_landmark": (self.observation_landmark, (n_obs,)),
            "z": (self.z, (n_obs, 2)),
            "R": (self.R, (n_obs, 2, 2)),
            "noise_scale": (self.noise_scale, (n_obs,)),
            "loop_pose": (self.loop_pose, (n_loops, 2)),
            "loop_delta": (self.loop_delta, (n_loops, 3)),
            "loop_covariance": (self.loop_covariance, (n_loops, 3, 3)),
        }
        for name, (value, shape) in shapes.items():
            if np.shape(value) != shape:
                raise ValueError(f"{name} must have shape {shape}, got {np.shape(value)}")
        if n_obs and not (0 <= self.observation_pose.min() and self.observation_pose.max() < n_poses):
            raise ValueError("observation_pose must index the poses")
        if n_loops and not (0 <= self.loop_pose.min() and self.loop_pose.max() < n_poses):
            raise ValueError("loop_pose must index the poses")
        if np.any(self.loop_pose[:, 0] == self.loop_pose[:, 1]):
            raise ValueError("a loop joins two distinct poses")

    @property
    def n_poses(self) -> int:
        return len(self.pose_t_ns)

    @property
    def observation_covariance(self) -> NDArray[np.float64]:
        """(K, 2, 2) ``noise_scale R``: each observation factor's covariance."""
        return self.R * self.noise_scale[:, None, None]


@dataclass(frozen=True)
class LoopEdge:
    """A loop: the measured relative pose ``Z = T(t_a)^-1 T(t_b)`` (``T_map_body`` at two stamps, ns) with its
    covariance ``S`` (3, 3, frame ``a``'s ``[x, y, theta]``)."""

    t_a_ns: int
    t_b_ns: int
    Z: Transform2D
    S: NDArray[np.float64]


def relative_motions(
    motion: MotionModel,
    signal: MotionSignal,
    times: Sequence[int],
    samples: Sequence[Sample],
    pose_t_ns: NDArray[np.int64],
    min_motion_std: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(delta (P-1, 3), Q (P-1, 3, 3))``: the motion between consecutive ``pose_t_ns`` (within
    ``[times[0], times[-1]]``), the motion model composed from the identity along the signal's pieces
    (:func:`turtlelib.motion.motion_signals.signal_pieces`, as :class:`turtlelib.SlamTimeline` predicts), with
    ``Q + min_motion_std^2 I`` (m^2, m^2, rad^2) so that a robot standing still keeps an invertible factor."""
    n = len(pose_t_ns) - 1
    delta, Q = np.zeros((n, 3)), np.empty((n, 3, 3))
    floor = min_motion_std**2 * np.eye(3)
    t_from = int(pose_t_ns[0])
    s_from = signal_at(signal, times, samples, t_from)
    for k in range(n):
        t_to = int(pose_t_ns[k + 1])
        pieces = signal_pieces(signal, times, samples, t_from, s_from, t_to)
        inputs = [u for _, _, u in pieces if u is not None]
        Q[k] = floor
        if inputs:
            poses, _, Q_k = composed_steps(motion, Transform2D(), inputs)
            delta[k], Q[k] = poses[-1], Q_k + floor
        t_from, s_from = t_to, pieces[-1][1]
    return delta, Q


def viewpoint_scales(
    sensor_xy: NDArray[np.float64],
    observation_pose: NDArray[np.int64],
    observation_landmark: NDArray[np.int64],
    fusion_scale: Callable[[NDArray[np.float64]], NDArray[np.float64]],
) -> NDArray[np.float64]:
    """(K,) the factor each observation's ``R`` is scaled by for errors correlated over the viewpoint: 1 for
    a landmark's first view (by pose index), else ``fusion_scale(d)`` (e.g.
    :meth:`turtlelib.estimation.ekf_slam.SlamConfig.fusion_scale`) with ``d`` (m) the distance between the
    sensor positions ``sensor_xy`` (P, 2) of this view and the landmark's previous one."""
    order = np.lexsort((observation_pose, observation_landmark))
    landmark, pose = observation_landmark[order], observation_pose[order]
    scales = np.ones(len(order))
    again = np.r_[False, landmark[1:] == landmark[:-1]]
    moved_m = np.linalg.norm(sensor_xy[pose[1:]] - sensor_xy[pose[:-1]], axis=1)
    later = np.flatnonzero(again)
    scales[later] = fusion_scale(moved_m[later - 1])
    result = np.empty(len(order))
    result[order] = scales
    return result
