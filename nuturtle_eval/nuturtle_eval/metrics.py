"""Accuracy and consistency metrics of one simulation + SLAM run: pure numpy/scipy, no ROS.

Frames
------
Every pose series handed to these functions is in the simulator's world frame ``nusim/world``: the SLAM
``map`` frame *is* that frame because SLAM starts at the true initial pose, and wheel odometry's ``odom``
frame starts at the identity on the true initial pose ``T_world_start``, so its poses are mapped with
``T_world_body = T_world_start @ T_odom_body`` (:func:`odom_in_world`).

Series
------
A :class:`PoseSeries` holds stamps ``t_s`` (N,) (s, strictly increasing) and poses ``poses`` (N, 3)
``[x, y, theta]`` (m, m, rad). The ground truth is interpolated at an estimate's stamps (linear in x, y
and in the unwrapped heading), so estimates published at any rate are compared with the truth at the
same instant.

Metrics
-------
* pose error ``e = [x_hat - x, y_hat - y, wrap(theta_hat - theta)]``; final position error ``|e_xy|`` and
  heading error ``|e_theta|`` at the estimate's last stamp;
* ATE RMSE ``sqrt(mean |e_xy|^2)`` over the whole run (no re-alignment: the frames are tied by the start),
  and the same after the rigid motion that best fits the estimated positions to the truth's
  (:func:`align_se2`: what evo's ``evo_ape --align`` reports for a planar run);
* relative pose error over pairs of truth poses 1 to 10 m of the true path apart, translation (m) and
  rotation (deg), for SLAM and for the odometry (:mod:`nuturtle_eval.relative_error`);
* landmarks: mapped landmarks ``m_hat`` (K, 2) are associated one-to-one with the true centres ``m``
  (M, 2) by the Hungarian algorithm on Euclidean distance, keeping pairs closer than a gate; a mapped
  landmark without a partner within the gate is *spurious*, a mapped landmark whose nearest true
  centre is another one's partner a *duplicate*; RMSE ``sqrt(mean |m_hat_i - m_j|^2)`` over the pairs.
  Without the true centres (a recording of another world) the mapped landmarks are counted, never judged:
  the true, in range, paired, unmapped, duplicate and spurious counts are None and the RMSE NaN;
* pose NEES ``eps_k = e_k^T P_k^-1 e_k`` (3 dof) per estimate with covariance ``P_k``, judged against the
  two-sided 95% chi2 interval for one run (``turtlelib.estimation.consistency``); estimates whose covariance
  is singular (the exactly known start, before the robot moves) are left out; with none left (a run that
  ended before the robot moved) the NEES figures are NaN (null in metrics.json).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from turtlelib import Transform2D, normalize_angles
from turtlelib.estimation.consistency import chi2_bounds, nees

from .relative_error import relative_pose_error

POSE_DOF = 3
# Covariances with a smallest eigenvalue at or below this (m^2 or rad^2: a 1 micrometre / microradian
# standard deviation) are treated as singular: their NEES is undefined
MIN_EIGENVALUE = 1e-12
NEES_BAND_PROB = 0.95


@dataclass(frozen=True)
class PoseSeries:
    """Stamped planar poses: ``t_s`` (N,) strictly increasing (s), ``poses`` (N, 3) ``[x, y, theta]``."""

    t_s: NDArray[np.float64]
    poses: NDArray[np.float64]

    def __post_init__(self) -> None:
        t_s = np.asarray(self.t_s, dtype=np.float64).reshape(-1)
        poses = np.asarray(self.poses, dtype=np.float64).reshape(-1, 3)
        if t_s.size != poses.shape[0]:
            raise ValueError(f"{t_s.size} stamps but {poses.shape[0]} poses")
        if not (np.all(np.isfinite(t_s)) and np.all(np.isfinite(poses))):
            raise ValueError("stamps and poses must be finite")
        if np.any(np.diff(t_s) <= 0.0):
            raise ValueError("stamps must be strictly increasing")
        object.__setattr__(self, "t_s", t_s)
        object.__setattr__(self, "poses", poses)

    def __len__(self) -> int:
        return int(self.t_s.size)

    @property
    def xy(self) -> NDArray[np.float64]:
        return self.poses[:, :2]

    def within(self, t0_s: float, t1_s: float) -> NDArray[np.bool_]:
        """Mask of the samples with ``t0_s <= t <= t1_s``."""
        return (self.t_s >= t0_s) & (self.t_s <= t1_s)

    def interpolate(self, t_query_s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Poses (M, 3) at ``t_query_s`` (M,), all within ``[t_s[0], t_s[-1]]`` (ValueError otherwise).

        x, y: linear interpolation; theta: linear in the unwrapped heading, wrapped back to (-pi, pi].
        """
        t_query_s = np.asarray(t_query_s, dtype=np.float64).reshape(-1)
        if len(self) == 0 or np.any(t_query_s < self.t_s[0]) or np.any(t_query_s > self.t_s[-1]):
            raise ValueError("query stamps must lie within the series")
        theta_unwrapped = np.unwrap(self.poses[:, 2])
        return np.column_stack(
            [
                np.interp(t_query_s, self.t_s, self.poses[:, 0]),
                np.interp(t_query_s, self.t_s, self.poses[:, 1]),
                normalize_angles(np.interp(t_query_s, self.t_s, theta_unwrapped)),
            ]
        )


def odom_in_world(odom: PoseSeries, T_world_odom: Transform2D) -> PoseSeries:
    """Odometry poses in the world: ``T_world_body = T_world_odom @ T_odom_body`` for each sample (the demo's
    odom frame starts on the true start pose: ``T_world_odom = T_world_start``)."""
    poses = np.array([(T_world_odom @ Transform2D(*pose)).as_array() for pose in odom.poses])
    return PoseSeries(odom.t_s, poses.reshape(-1, 3))


def align_se2(source_xy: NDArray[np.float64], target_xy: NDArray[np.float64]) -> Transform2D:
    """The rigid motion ``T`` (no scale) minimising ``sum_i |T p_i - q_i|^2`` for point pairs ``source_xy``
    (N, 2) -> ``target_xy`` (N, 2), N >= 2 (Kabsch / Umeyama in the plane).

    With centroids ``p_bar``, ``q_bar`` and centred points: ``theta = atan2(sum p x q, sum p . q)``
    (cross and dot products of the pairs), ``t = q_bar - R(theta) p_bar``.
    """
    p = np.asarray(source_xy, dtype=np.float64).reshape(-1, 2)
    q = np.asarray(target_xy, dtype=np.float64).reshape(-1, 2)
    if p.shape != q.shape or p.shape[0] < 2:
        raise ValueError(f"need two equal (N >= 2, 2) point sets, got {p.shape} and {q.shape}")
    p_bar, q_bar = p.mean(axis=0), q.mean(axis=0)
    a, b = p - p_bar, q - q_bar
    # theta = atan2(sum a x b, sum a . b)
    theta = math.atan2(float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])), float(np.sum(a * b)))
    c, s = math.cos(theta), math.sin(theta)
    # t = q_bar - R p_bar
    return Transform2D(
        q_bar[0] - (c * p_bar[0] - s * p_bar[1]), q_bar[1] - (s * p_bar[0] + c * p_bar[1]), theta
    )


def pose_errors(estimate: PoseSeries, truth: PoseSeries) -> NDArray[np.float64]:
    """``e_k = [x_hat - x, y_hat - y, wrap(theta_hat - theta)]`` (K, 3) at the estimate's stamps that
    the truth covers (estimates outside the truth's time span are left out)."""
    covered = estimate.within(truth.t_s[0], truth.t_s[-1])
    true_poses = truth.interpolate(estimate.t_s[covered])
    e = estimate.poses[covered] - true_poses
    e[:, 2] = normalize_angles(e[:, 2])
    return e


def ate_rmse(errors: NDArray[np.float64]) -> float:
    """``sqrt(mean_k (e_x^2 + e_y^2))`` of pose errors (K, 3) (m); ValueError when empty."""
    if errors.shape[0] == 0:
        raise ValueError("no pose errors")
    return float(np.sqrt(np.mean(np.sum(errors[:, :2] ** 2, axis=1))))


def ate_rmse_aligned(estimate: PoseSeries, truth: PoseSeries) -> float:
    """``sqrt(mean_k |T p_hat_k - p_k|^2)`` (m) at the estimate's stamps the truth covers, ``p_k`` the
    truth interpolated there and ``T`` the rigid motion that best fits the estimated positions to them
    (:func:`align_se2`); NaN with fewer than two such stamps."""
    covered = estimate.within(truth.t_s[0], truth.t_s[-1])
    if np.count_nonzero(covered) < 2:
        return math.nan
    estimate_xy, truth_xy = estimate.xy[covered], truth.interpolate(estimate.t_s[covered])[:, :2]
    aligned_xy = align_se2(estimate_xy, truth_xy) @ estimate_xy
    return float(np.sqrt(np.mean(np.sum((aligned_xy - truth_xy) ** 2, axis=1))))


@dataclass(frozen=True)
class LandmarkAssociation:
    """One-to-one pairs ``(mapped[i], true[j])`` closer than the gate, and the leftovers.

    ``mapped_index``, ``true_index`` (P,) the pairs; ``distance_m`` (P,) their distances;
    ``spurious`` mapped landmarks with no true centre within the gate; ``duplicates`` unpaired mapped
    landmarks whose nearest true centre (within the gate) is already paired: a cylinder mapped twice.
    """

    mapped_index: NDArray[np.intp]
    true_index: NDArray[np.intp]
    distance_m: NDArray[np.float64]
    spurious: NDArray[np.intp]
    duplicates: NDArray[np.intp]

    @property
    def rmse_m(self) -> float:
        """``sqrt(mean distance^2)`` over the pairs (NaN when there is none)."""
        return float(np.sqrt(np.mean(self.distance_m**2))) if self.distance_m.size else float("nan")


def associate_landmarks(
    mapped_xy: NDArray[np.float64], true_xy: NDArray[np.float64], gate_m: float
) -> LandmarkAssociation:
    """Hungarian assignment of mapped (K, 2) to true (M, 2) landmark centres on distance, gated at
    ``gate_m`` (> 0): pairs farther apart than the gate are dropped (see :class:`LandmarkAssociation`)."""
    if not gate_m > 0.0:
        raise ValueError(f"gate_m must be > 0, got {gate_m!r}")
    mapped_xy = np.asarray(mapped_xy, dtype=np.float64).reshape(-1, 2)
    true_xy = np.asarray(true_xy, dtype=np.float64).reshape(-1, 2)
    # D_ij = |m_hat_i - m_j|
    D = np.linalg.norm(mapped_xy[:, None, :] - true_xy[None, :, :], axis=2)
    # pairs beyond the gate must never be preferred to leaving both unpaired: cost them out of reach
    cost = np.where(D <= gate_m, D, 1e6 + D)
    rows, cols = linear_sum_assignment(cost) if D.size else (np.zeros(0, int), np.zeros(0, int))
    keep = D[rows, cols] <= gate_m
    rows, cols = rows[keep], cols[keep]
    unpaired = np.setdiff1d(np.arange(mapped_xy.shape[0]), rows)
    near = D[unpaired].min(axis=1) <= gate_m if true_xy.shape[0] else np.zeros(unpaired.size, bool)
    return LandmarkAssociation(
        mapped_index=rows.astype(np.intp),
        true_index=cols.astype(np.intp),
        distance_m=D[rows, cols],
        spurious=unpaired[~near].astype(np.intp),
        duplicates=unpaired[near].astype(np.intp),
    )


# Path points checked for sight at a time (memory: chunk x M x M x 2 floats)
SIGHT_CHUNK = 1024


def landmarks_within_range(
    true_xy: NDArray[np.float64],
    path_xy: NDArray[np.float64],
    range_m: float | NDArray[np.float64],
    radii_m: NDArray[np.float64] | None = None,
) -> NDArray[np.bool_]:
    """Mask (M,) of the true landmarks that came within ``range_m`` (one for all, or (M,) per landmark) of
    some point of the path (N, 2), in sight there when the cylinders' ``radii_m`` (M,) are given.

    Landmark ``j`` is in sight from ``p`` unless the segment from ``p`` to its centre ``c_j`` passes through
    another cylinder ``i``: with ``v = c_j - p`` and ``s = clip((c_i - p).v / v.v, 0, 1)``, the segment's
    nearest point to ``c_i`` is ``p + s v``, and it blocks when ``|p + s v - c_i| < r_i`` (a cylinder fully
    hidden behind another along the row of a grid, never seen however close it comes)."""
    true_xy = np.asarray(true_xy, dtype=np.float64).reshape(-1, 2)
    path_xy = np.asarray(path_xy, dtype=np.float64).reshape(-1, 2)
    radii = None if radii_m is None else np.asarray(radii_m, dtype=np.float64).reshape(-1)
    seen = np.zeros(true_xy.shape[0], dtype=bool)
    for start in range(0, path_xy.shape[0], SIGHT_CHUNK):
        seen |= _seen_from(true_xy, path_xy[start : start + SIGHT_CHUNK], range_m, radii)
    return seen


def _seen_from(
    true_xy: NDArray[np.float64],
    path_xy: NDArray[np.float64],
    range_m: float | NDArray[np.float64],
    radii_m: NDArray[np.float64] | None,
) -> NDArray[np.bool_]:
    """:func:`landmarks_within_range` for a piece of the path."""
    # v[k, j] = c_j - p_k, (N, M, 2)
    v = true_xy[None, :, :] - path_xy[:, None, :]
    within = np.linalg.norm(v, axis=2) <= range_m
    if radii_m is not None:
        vv = np.maximum(np.einsum("kjd,kjd->kj", v, v), 1e-300)
        # s[k, j, i] = clip((c_i - p_k) . v_kj / v_kj . v_kj, 0, 1)
        s = np.clip(np.einsum("kid,kjd->kji", v, v) / vv[:, :, None], 0.0, 1.0)
        # the segment's nearest point to c_i, from c_i: s v_kj - (c_i - p_k)
        gap = s[..., None] * v[:, :, None, :] - v[:, None, :, :]
        blocked = np.linalg.norm(gap, axis=3) < radii_m[None, None, :]
        blocked[:, np.arange(true_xy.shape[0]), np.arange(true_xy.shape[0])] = False
        within &= ~np.any(blocked, axis=2)
    return np.any(within, axis=0)


def pose_nees(errors: NDArray[np.float64], covariances: NDArray[np.float64]) -> NDArray[np.float64]:
    """``eps_k = e_k^T P_k^-1 e_k`` (K,) for errors (K, d) and covariances (K, d, d).

    A sample whose covariance is not positive definite (smallest eigenvalue <= ``MIN_EIGENVALUE``, e.g.
    the exactly known start pose before the robot moves) or unknown (NaN: a smoothed pose) has no NEES: NaN.
    """
    known = ~np.isnan(covariances).any(axis=(1, 2))
    result = np.full(errors.shape[0], np.nan)
    if known.any():
        result[known] = nees(errors[known], covariances[known], atol=MIN_EIGENVALUE)
    return result


def nees_band(prob: float = NEES_BAND_PROB) -> tuple[float, float]:
    """The two-sided ``prob`` interval of a single run's 3-dof pose NEES."""
    return chi2_bounds(POSE_DOF, 1, prob)


@dataclass(frozen=True)
class RunMetrics:
    """The figures of one run (metrics.json); units in the names, counts are landmarks. The landmark counts
    but ``landmarks_mapped`` are None when the true landmarks are unknown (nothing to judge the map by)."""

    final_position_error_odom_m: float
    final_position_error_slam_m: float
    final_heading_error_odom_rad: float
    final_heading_error_slam_rad: float
    ate_rmse_odom_m: float
    ate_rmse_slam_m: float
    ate_rmse_aligned_odom_m: float
    ate_rmse_aligned_slam_m: float
    rpe_translation_odom_m: float
    rpe_rotation_odom_deg: float
    rpe_translation_slam_m: float
    rpe_rotation_slam_deg: float
    rpe_pairs: int
    landmarks_true: int | None
    landmarks_in_range: int | None
    landmarks_mapped: int
    landmarks_paired: int | None
    landmarks_in_range_unmapped: int | None
    landmarks_duplicate: int | None
    landmarks_spurious: int | None
    landmark_rmse_m: float
    nees_pose_mean: float
    nees_pose_median: float
    nees_pose_within_95_fraction: float
    nees_pose_band_95: tuple[float, float]
    sim_seconds: float
    wall_seconds: float

    def as_dict(self) -> dict:
        values = asdict(self)
        values["nees_pose_band_95"] = list(self.nees_pose_band_95)
        return values


@dataclass(frozen=True)
class RunData:
    """What a run produced, in the world frame (see the module docstring).

    ``truth``, ``odom``, ``slam`` pose series; ``slam_covariances`` (K, 3, 3) the (x, y, theta) covariance
    of each SLAM pose; ``mapped_xy`` (n, 2) the final map; ``true_xy`` (M, 2) the true cylinder centres
    (None: unknown, the map is then not judged);
    ``sensor_range_m`` the range within which a cylinder counts as seen (one for all, or (M,) per cylinder),
    in sight of the path when ``true_radii_m`` (M,) are given (:func:`landmarks_within_range`);
    ``gate_m`` the association gate.
    """

    truth: PoseSeries
    odom: PoseSeries
    slam: PoseSeries
    slam_covariances: NDArray[np.float64]
    mapped_xy: NDArray[np.float64]
    true_xy: NDArray[np.float64] | None
    sensor_range_m: float | NDArray[np.float64]
    gate_m: float
    true_radii_m: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        covariances = np.asarray(self.slam_covariances, dtype=np.float64).reshape(-1, 3, 3)
        if covariances.shape[0] != len(self.slam):
            raise ValueError(f"{len(self.slam)} SLAM poses but {covariances.shape[0]} covariances")
        object.__setattr__(self, "slam_covariances", covariances)


def landmark_figures(data: RunData) -> dict[str, int | float | None]:
    """The map judged against the true landmarks (module docstring): the :class:`RunMetrics` landmark
    counts but ``landmarks_mapped``, and ``landmark_rmse_m``; None counts and a NaN RMSE without them."""
    if data.true_xy is None:
        counts = ("true", "in_range", "paired", "in_range_unmapped", "duplicate", "spurious")
        return {**{f"landmarks_{count}": None for count in counts}, "landmark_rmse_m": math.nan}
    association = associate_landmarks(data.mapped_xy, data.true_xy, data.gate_m)
    in_range = landmarks_within_range(data.true_xy, data.truth.xy, data.sensor_range_m, data.true_radii_m)
    paired = np.zeros(in_range.size, dtype=bool)
    paired[association.true_index] = True
    return {
        "landmarks_true": int(in_range.size),
        "landmarks_in_range": int(np.count_nonzero(in_range)),
        "landmarks_paired": int(association.true_index.size),
        "landmarks_in_range_unmapped": int(np.count_nonzero(in_range & ~paired)),
        "landmarks_duplicate": int(association.duplicates.size),
        "landmarks_spurious": int(association.spurious.size),
        "landmark_rmse_m": association.rmse_m,
    }


def evaluate_run(data: RunData, sim_seconds: float, wall_seconds: float) -> RunMetrics:
    """All metrics of a run (module docstring); ValueError when an estimate never overlaps the truth."""
    e_odom = pose_errors(data.odom, data.truth)
    slam_covered = data.slam.within(data.truth.t_s[0], data.truth.t_s[-1])
    e_slam = pose_errors(data.slam, data.truth)
    if e_odom.shape[0] == 0 or e_slam.shape[0] == 0:
        raise ValueError("the estimates do not overlap the ground truth in time")
    eps = pose_nees(e_slam, data.slam_covariances[slam_covered])
    eps = eps[np.isfinite(eps)]
    low, high = nees_band()
    rpe_odom, rpe_slam = (
        relative_pose_error(data.odom, data.truth),
        relative_pose_error(data.slam, data.truth),
    )
    return RunMetrics(
        final_position_error_odom_m=float(np.hypot(*e_odom[-1, :2])),
        final_position_error_slam_m=float(np.hypot(*e_slam[-1, :2])),
        final_heading_error_odom_rad=float(abs(e_odom[-1, 2])),
        final_heading_error_slam_rad=float(abs(e_slam[-1, 2])),
        ate_rmse_odom_m=ate_rmse(e_odom),
        ate_rmse_slam_m=ate_rmse(e_slam),
        ate_rmse_aligned_odom_m=ate_rmse_aligned(data.odom, data.truth),
        ate_rmse_aligned_slam_m=ate_rmse_aligned(data.slam, data.truth),
        rpe_translation_odom_m=rpe_odom.translation_m,
        rpe_rotation_odom_deg=rpe_odom.rotation_deg,
        rpe_translation_slam_m=rpe_slam.translation_m,
        rpe_rotation_slam_deg=rpe_slam.rotation_deg,
        rpe_pairs=rpe_slam.pairs,
        landmarks_mapped=int(np.asarray(data.mapped_xy).reshape(-1, 2).shape[0]),
        **landmark_figures(data),
        # NaN when no pose had a positive definite covariance (the robot never moved from its known start)
        nees_pose_mean=float(np.mean(eps)) if eps.size else math.nan,
        nees_pose_median=float(np.median(eps)) if eps.size else math.nan,
        nees_pose_within_95_fraction=float(np.mean((eps >= low) & (eps <= high))) if eps.size else math.nan,
        nees_pose_band_95=(low, high),
        sim_seconds=float(sim_seconds),
        wall_seconds=float(wall_seconds),
    )
