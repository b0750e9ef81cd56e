"""Metrics of a dataset run against its reference: Vicon poses and landmarks (MRCLAM) or GPS (Victoria Park).

Trajectory
----------
The estimate ``T_map_body`` after every scan (stamps ``t_k``) is compared with the reference at ``t_k``:

* MRCLAM: the Vicon pose interpolated at ``t_k`` (the filter starts on the Vicon pose, so its map frame
  is the Vicon frame); error ``e_k = [x_hat - x, y_hat - y, wrap(theta_hat - theta)]`` with the filter's
  ``P_k`` (3 dof);
* Victoria Park: the GPS antenna sits at the laser, so the compared point is the laser's,
  ``p_k = p_body + R(theta) [a, b]`` with covariance ``J P_k J^T``, ``J = [I_2, [-r_y, r_x]^T]``
  (``r = R(theta) [a, b]``), interpolated linearly at each GPS fix (outliers removed,
  :func:`~nuturtle_eval.datasets.victoria.gps_outliers`); 2 dof. The GPS's own metre-level error counts
  as filter error here, so this NEES is biased high.

``ate_rmse_m = sqrt(mean |e_xy|^2)``; ``ate_rmse_aligned_m`` the same after the rigid SE(2) motion that
best fits the estimated positions to the reference (:func:`~nuturtle_eval.metrics.align_se2`), which
removes the unobservable global frame. NEES ``e^T P^-1 e`` per sample, its mean and the fraction inside the
two-sided 95 % chi2 interval of one sample.

Victoria Park's published protocol (``--protocol published``) adds the literature's score,
``ate_rmse_published_m = sqrt(mean_k |p_k - g_j(k)|^2)`` over the estimates ``k`` that have a fix ``g_j(k)``
within 25 ms of their stamp (:func:`pair_with_fixes`): no interpolation and no alignment.

Map (MRCLAM)
------------
Known association pairs each mapped landmark with the true one of its id. Unknown association first
moves the map by the trajectory alignment, then pairs mapped and true landmarks one-to-one (Hungarian,
gated at ``gate_m``, :func:`~nuturtle_eval.metrics.associate_landmarks`): a true landmark is *mapped once*
when paired and no other mapped landmark has it as its nearest (within the gate); *merged* when unpaired
while its nearest mapped landmark (within the gate) is paired to another true one (two landmarks mapped as
one); a mapped landmark is *spurious* with no true one within the gate and a *duplicate* when unpaired
next to a paired one. ``landmark_rmse_m`` over the pairs in the map frame, ``landmark_rmse_aligned_m``
after the rigid motion that best fits the paired map to the truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from turtlelib import Transform2D, normalize_angles
from turtlelib.estimation.consistency import chi2_bounds
from turtlelib.util.validation import one_of

from ..metrics import align_se2, associate_landmarks, pose_nees
from .experiment import Experiment, ExperimentResult
from .mrclam import MrclamRecording
from .setups import PROTOCOLS, interpolate_poses, laser_points
from .victoria import VictoriaRecording, gps_outliers

NEES_PROB = 0.95
LANDMARK_GATE_M = 0.5
# the published protocol scores the estimates that have a GPS fix within 25 ms of their stamp
PUBLISHED_PAIRING_NS = 25_000_000


@dataclass(frozen=True)
class Evaluation:
    """What the figures and metrics.json need: evaluation stamps ``t_s`` (s since the run's start),
    ``errors`` (S, d) of the estimate against the reference with the filter's ``sigmas`` (S, d) and
    ``error_labels``; ``nees`` (S,) with ``nees_dof``; the reference track
    ``reference_track`` (R, 2) and the estimate's track ``estimate_track`` (E, 2); the map (in the map frame)
    and the true landmarks (or None); ``T_align`` the rigid motion that best fits the estimate to the
    reference and the position errors after it ``aligned_errors_m`` (S,); ``metrics``."""

    t_s: NDArray[np.float64]
    errors: NDArray[np.float64]
    sigmas: NDArray[np.float64]
    error_labels: tuple[str, ...]
    nees: NDArray[np.float64]
    nees_dof: int
    reference_label: str
    reference_track: NDArray[np.float64]
    estimate_track: NDArray[np.float64]
    landmarks: NDArray[np.float64]
    landmark_covariances: NDArray[np.float64]
    true_landmarks: NDArray[np.float64] | None
    T_align: Transform2D
    aligned_errors_m: NDArray[np.float64]
    metrics: dict


def _trajectory_metrics(
    estimate_xy: NDArray[np.float64], reference_xy: NDArray[np.float64], nees: NDArray[np.float64], dof: int
) -> tuple[dict, Transform2D, NDArray[np.float64]]:
    """ATE raw and after the best rigid alignment (returned, with the aligned errors (S,)), and the NEES
    statistics of one run."""
    error_m = np.linalg.norm(estimate_xy - reference_xy, axis=1)
    T_align = align_se2(estimate_xy, reference_xy)
    aligned_error_m = np.linalg.norm(T_align @ estimate_xy - reference_xy, axis=1)
    low, high = chi2_bounds(dof, 1, NEES_PROB)
    finite = nees[np.isfinite(nees)]
    return (
        {
            "ate_rmse_m": float(np.sqrt(np.mean(error_m**2))),
            "ate_rmse_aligned_m": float(np.sqrt(np.mean(aligned_error_m**2))),
            "ate_max_m": float(error_m.max()),
            "alignment_rotation_rad": T_align.theta,
            "nees_pose_mean": float(np.mean(finite)) if finite.size else float("nan"),
            "nees_pose_median": float(np.median(finite)) if finite.size else float("nan"),
            "nees_pose_within_95_fraction": float(np.mean((finite >= low) & (finite <= high)))
            if finite.size
            else float("nan"),
            "nees_dof": dof,
            "nees_band_95": [low, high],
            "evaluated_samples": int(len(error_m)),
        },
        T_align,
        aligned_error_m,
    )


def _timing_metrics(experiment: Experiment, result: ExperimentResult) -> dict:
    duration_s = (experiment.motion_t_ns[-1] - experiment.motion_t_ns[0]) * 1e-9
    return {
        "duration_s": float(duration_s),
        "scans": int(len(experiment.scans)),
        "scans_applied": int(len(result.t_ns)),
        "observations": result.status_counts,
        "cpu_seconds": result.cpu_seconds,
        "update_ms_median": float(np.median(result.update_ms)) if result.update_ms.size else float("nan"),
        "update_ms_p99": float(np.percentile(result.update_ms, 99))
        if result.update_ms.size
        else float("nan"),
    }


def _landmark_metrics(
    result: ExperimentResult, recording: MrclamRecording, known: bool, T_align: Transform2D, gate_m: float
) -> dict:
    true_xy = recording.landmark_xy
    mapped = result.landmarks
    if known:
        true_index = {int(s): i for i, s in enumerate(recording.landmark_subjects)}
        pairs = [(m, true_index[int(i)]) for m, i in enumerate(result.landmark_ids) if int(i) in true_index]
        mapped_index = np.array([m for m, _ in pairs], dtype=np.intp)
        paired_true = np.array([t for _, t in pairs], dtype=np.intp)
        spurious, duplicates, merged = len(mapped) - len(pairs), 0, 0
        mapped_once = len(pairs)
    else:
        moved = T_align @ mapped if len(mapped) else mapped
        association = associate_landmarks(moved, true_xy, gate_m)
        mapped_index, paired_true = association.mapped_index, association.true_index
        distance = np.linalg.norm(moved[:, None, :] - true_xy[None, :, :], axis=2)
        # a duplicate's nearest true landmark is mapped more than once
        doubled = {int(np.argmin(distance[d])) for d in association.duplicates}
        mapped_once = len(set(paired_true.tolist()) - doubled)
        unpaired_true = np.setdiff1d(np.arange(len(true_xy)), paired_true)
        merged = 0
        if len(mapped):
            paired_mapped = set(mapped_index.tolist())
            for t in unpaired_true:
                nearest = int(np.argmin(distance[:, t]))
                merged += int(distance[nearest, t] <= gate_m and nearest in paired_mapped)
        spurious, duplicates = len(association.spurious), len(association.duplicates)
    values = {
        "landmarks_true": int(len(true_xy)),
        "landmarks_mapped": int(len(mapped)),
        "landmarks_mapped_once": int(mapped_once),
        "landmarks_spurious": int(spurious),
        "landmarks_duplicate": int(duplicates),
        "landmarks_merged": int(merged),
        "landmark_gate_m": gate_m,
    }
    if len(mapped_index) >= 2:
        p, q = mapped[mapped_index], true_xy[paired_true]
        values["landmark_rmse_m"] = float(np.sqrt(np.mean(np.sum((p - q) ** 2, axis=1))))
        aligned = align_se2(p, q) @ p
        values["landmark_rmse_aligned_m"] = float(np.sqrt(np.mean(np.sum((aligned - q) ** 2, axis=1))))
        # map frame: the start ties it to the Vicon frame, and each marginal holds that frame's uncertainty
        values["landmark_nees_mean"] = float(
            np.mean(pose_nees(p - q, result.landmark_covariances[mapped_index]))
        )
    else:
        values["landmark_rmse_m"] = values["landmark_rmse_aligned_m"] = float("nan")
        values["landmark_nees_mean"] = float("nan")
    return values


def evaluate_mrclam(
    experiment: Experiment,
    result: ExperimentResult,
    recording: MrclamRecording,
    gate_m: float = LANDMARK_GATE_M,
) -> Evaluation:
    """MRCLAM against the Vicon poses and landmarks (module docstring)."""
    t0 = experiment.motion_t_ns[0]
    covered = (result.t_ns >= recording.truth_t_ns[0]) & (result.t_ns <= recording.truth_t_ns[-1])
    if not covered.any():
        raise ValueError("no estimate lies within the ground truth's time span")
    t_ns, poses, P = result.t_ns[covered], result.poses[covered], result.covariances[covered]
    truth = interpolate_poses(recording.truth_t_ns, recording.truth_poses, t_ns)
    errors = poses - truth
    errors[:, 2] = normalize_angles(errors[:, 2])
    nees = pose_nees(errors, P)
    metrics, T_align, aligned_errors_m = _trajectory_metrics(poses[:, :2], truth[:, :2], nees, 3)
    metrics.update(_landmark_metrics(result, recording, experiment.scans.ids is not None, T_align, gate_m))
    metrics.update(_timing_metrics(experiment, result))
    in_run = (recording.truth_t_ns >= t0) & (recording.truth_t_ns <= experiment.motion_t_ns[-1])
    return Evaluation(
        t_s=(t_ns - t0) * 1e-9,
        errors=errors,
        sigmas=np.sqrt(np.maximum(np.diagonal(P, axis1=1, axis2=2), 0.0)),
        error_labels=("x error (m)", "y error (m)", "heading error (rad)"),
        nees=nees,
        nees_dof=3,
        reference_label="Vicon ground truth",
        reference_track=recording.truth_poses[in_run, :2],
        estimate_track=result.track[:, :2],
        landmarks=result.landmarks,
        landmark_covariances=result.landmark_covariances,
        true_landmarks=recording.landmark_xy,
        T_align=T_align,
        aligned_errors_m=aligned_errors_m,
        metrics=metrics,
    )


def pair_with_fixes(
    t_ns: NDArray[np.int64], fix_t_ns: NDArray[np.int64], tolerance_ns: int
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """``(estimates, fixes)``: the indices of the estimates stamped ``t_ns`` (S,) that have a fix within
    ``tolerance_ns``, and of that fix, the nearest one ``j(k) = argmin_j |t_k - tau_j|`` (the earlier of
    two equally near), kept when ``|t_k - tau_j(k)| <= tolerance_ns``. One fix may serve two estimates.
    ``fix_t_ns`` (G,) increasing; ValueError otherwise, or for a negative tolerance."""
    t_ns, fix_t_ns = np.asarray(t_ns, dtype=np.int64), np.asarray(fix_t_ns, dtype=np.int64)
    if np.any(np.diff(fix_t_ns) <= 0):
        raise ValueError("fix_t_ns must be increasing")
    if tolerance_ns < 0:
        raise ValueError(f"tolerance_ns must be >= 0, got {tolerance_ns}")
    if fix_t_ns.size == 0:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    # the fixes on either side of each stamp (the first or last fix twice beyond the ends)
    after = np.searchsorted(fix_t_ns, t_ns)
    before, after = np.maximum(after - 1, 0), np.minimum(after, fix_t_ns.size - 1)
    earlier = np.abs(t_ns - fix_t_ns[before]) <= np.abs(fix_t_ns[after] - t_ns)
    nearest = np.where(earlier, before, after)
    estimates = np.flatnonzero(np.abs(t_ns - fix_t_ns[nearest]) <= tolerance_ns)
    return estimates, nearest[estimates]


def published_metrics(result: ExperimentResult, recording: VictoriaRecording) -> dict:
    """The published protocol's score: ``ate_rmse_published_m = sqrt(mean_k |p_k - g_j(k)|^2)`` over the
    ``published_fixes`` estimates with an (outlier-free) GPS fix ``g_j(k)`` within ``PUBLISHED_PAIRING_NS``
    of their stamp (:func:`pair_with_fixes`), ``p_k`` the laser point of the estimate itself (no
    interpolation, no alignment)."""
    points, _ = laser_points(result.poses)
    good = ~gps_outliers(recording.gps_t_ns, recording.gps_xy)
    estimates, fixes = pair_with_fixes(result.t_ns, recording.gps_t_ns[good], PUBLISHED_PAIRING_NS)
    error_m = np.linalg.norm(points[estimates] - recording.gps_xy[good][fixes], axis=1)
    return {
        "ate_rmse_published_m": float(np.sqrt(np.mean(error_m**2))) if error_m.size else float("nan"),
        "ate_max_published_m": float(error_m.max()) if error_m.size else float("nan"),
        "published_fixes": int(error_m.size),
        "published_pairing_s": PUBLISHED_PAIRING_NS * 1e-9,
    }


def evaluate_victoria(
    experiment: Experiment, result: ExperimentResult, recording: VictoriaRecording, protocol: str = "aligned"
) -> Evaluation:
    """Victoria Park's laser point against the GPS fixes (module docstring); with ``protocol``
    ``published`` also :func:`published_metrics`."""
    one_of("protocol", protocol, PROTOCOLS)
    t0 = experiment.motion_t_ns[0]
    points, point_covariances = laser_points(result.poses, result.covariances)
    track, _ = laser_points(result.track)
    good = ~gps_outliers(recording.gps_t_ns, recording.gps_xy)
    covered = good & (recording.gps_t_ns >= result.t_ns[0]) & (recording.gps_t_ns <= result.t_ns[-1])
    t_gps, gps = recording.gps_t_ns[covered], recording.gps_xy[covered]
    t_rel, t_est = (t_gps - t0) * 1e-9, (result.t_ns - t0) * 1e-9
    estimate = np.column_stack([np.interp(t_rel, t_est, points[:, i]) for i in range(2)])
    flat = point_covariances.reshape(-1, 4)
    covariance = np.column_stack([np.interp(t_rel, t_est, flat[:, i]) for i in range(4)]).reshape(-1, 2, 2)
    errors = estimate - gps
    nees = pose_nees(errors, covariance)
    metrics, T_align, aligned_errors_m = _trajectory_metrics(estimate, gps, nees, 2)
    metrics.update(
        {
            "gps_fixes_used": int(covered.sum()),
            "gps_outliers_removed": int((~good).sum()),
            "landmarks_true": None,
            "landmarks_mapped": int(len(result.landmarks)),
            "landmarks_spurious": None,
            "landmarks_merged": None,
            "landmark_rmse_m": None,
            "landmark_rmse_aligned_m": None,
            "landmark_nees_mean": None,
        }
    )
    if protocol == "published":
        metrics.update(published_metrics(result, recording))
    metrics.update(_timing_metrics(experiment, result))
    return Evaluation(
        t_s=t_rel,
        errors=errors,
        sigmas=np.sqrt(np.maximum(np.diagonal(covariance, axis1=1, axis2=2), 0.0)),
        error_labels=("East error (m)", "North error (m)"),
        nees=nees,
        nees_dof=2,
        reference_label="GPS (outliers removed)",
        reference_track=recording.gps_xy[good],
        estimate_track=track,
        landmarks=result.landmarks,
        landmark_covariances=result.landmark_covariances,
        true_landmarks=None,
        T_align=T_align,
        aligned_errors_m=aligned_errors_m,
        metrics=metrics,
    )
