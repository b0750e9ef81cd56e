"""Motion the LiDAR contradicts (wheel slip, bumps): detect it, report it, relocalize against the map.

Why
---
The motion models take the wheels' word with a noise proportional to their travel. A slip event (the wheels
report a turn the body does not make) or a bump (the robot pushes against an obstacle, its wheels spinning)
breaks that model: the pose moves on by motion that never happened, far outside its covariance. Then every
observation of a mapped landmark lands outside the association gates, the filter dead-reckons on the wrong
pose, starts landmarks beside the true ones and never finds its way back.

Evidence (per scan, ``K`` detections ``p_k`` in the body frame, ``m_j`` the confirmed landmarks)
---------------------------------------------------------------------------------------------------
* ``n(T)``, the detections a pose ``T = T_map_body`` explains: those with ``|T p_k - m_j| < match_radius``
  for some ``j``. ``n(T_hat)`` for the filter's pose ``T_hat``.
* The best rigid alignment ``T*`` of the detections with the map (:func:`align_to_map`): every pair of
  detections at least ``min_pair_separation`` apart against every pair of landmarks as far apart (to within
  ``2 match_radius``) proposes the pose that lays the one on the other::

      theta = atan2(m_b - m_a) - atan2(p_j - p_i),   t = (m_a + m_b) / 2 - R(theta) (p_i + p_j) / 2

  the proposal explaining the most detections wins (ties: the nearest to ``T_hat``), and is refined by the
  least-squares rigid fit of its pairs (2D Procrustes).
* Slip and bumps only ever make the wheels report motion the body does not make, so ``T*`` is searched
  within what the wheels reported since the last scan the map confirmed (``T_good``): a heading within
  ``|theta_hat - theta_good| + margin_rad`` of ``theta_hat`` and a position within
  ``|p_hat - p_good| (1 + that heading bound) + margin_m`` of ``p_hat``. A repetitive world (a grid of
  cylinders) has other alignments further away; these are never candidates while the map confirms the scans.

A scan *contradicts the motion* when ``T*`` explains at least ``min_matches`` detections and at least two
more than ``T_hat``, and ``T*`` is outside ``T_hat``'s uncertainty: ``d^T (P_rr + Sigma*)^-1 d >
chi2_3^-1(0.999)`` for ``d = [t* - t_hat, theta* (-) theta_hat]``.

Recovery
--------
A contradicting scan is held (not fused: its detections would start landmarks beside the true ones); when
``confirm_scans`` scans in a row contradict the motion with the same correction ``T_hat^-1 T*`` (to within
``2 match_radius`` and ``0.1 rad``), the filter is relocalized at ``T*`` with the fit's covariance and no
correlation with the map (:meth:`EkfSlam.reset` with ``keep_map``), and the scan is fused from there. The
fit's covariance, for ``n`` pairs of combined per-axis variance ``s^2`` (the observations' and the landmarks'
position variance, at least the fit's mean squared residual) about the detections' centroid ``c``::

    Var(theta) = s^2 / sum_k |p_k - c|^2
    Cov(t) = s^2 / n I + a a^T Var(theta),   Cov(t, theta) = a Var(theta)

with ``a = -J R(theta*) c`` (``J`` the 90 degree rotation): the body origin's lever arm about the centroid.

Report (:attr:`SlipRecovery.status`): ``ok``; ``warn`` while a scan is held and for ``report_s`` after a
relocalization, naming the cause from the correction (a heading the wheels invented: "wheel slip"; the body
short of where the wheels put it: "bump or stall"); ``error`` when relocalizations follow each other (three
within ``report_s``): the wheels keep slipping or the robot is stuck.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import partial
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from .data_association import REJECTED
from .ekf_slam import Association, CheckedObservations, EkfSlam
from .geometry import Transform2D, normalize_angle, normalize_angles
from .timebase import NS_PER_S
from .validation import integer, non_negative, positive, store

# chi2_3^-1(0.999): a correction outside this is not the filter's own uncertainty
_SIGNIFICANT_D2 = float(chi2.ppf(0.999, 3))
# consecutive held scans propose the same correction to within 2 match radii and this (rad)
_SAME_CORRECTION_RAD = 0.1
# a proposal's detections and landmarks are the nearest this many (bounds the O(H K M) scoring)
_MAX_DETECTIONS = 12
_MAX_LANDMARKS = 40
# relocalizations within report_s that make the status an error (the wheels keep slipping: stuck)
_REPEATS_FOR_ERROR = 3


@dataclass(frozen=True)
class SlipRecoveryConfig:
    """``slip_recovery`` (bool): detect and recover (else the filter runs as it is);
    ``slip_min_matches`` (int >= 2): detections an alignment with the map must explain;
    ``slip_match_radius`` (m, > 0): how near a mapped landmark a detection must fall to be explained;
    ``slip_confirm_scans`` (int >= 1): scans in a row that must contradict the motion the same way;
    ``slip_margin_m`` (m, >= 0), ``slip_margin_rad`` (rad, >= 0): how far the search reaches beyond the
    motion reported since the last confirmed scan; ``slip_report_s`` (s, > 0): how long a relocalization
    stays in the status. Invalid values raise ValueError."""

    slip_recovery: bool = True
    slip_min_matches: int = 2
    slip_match_radius: float = 0.1
    slip_confirm_scans: int = 2
    slip_margin_m: float = 0.15
    slip_margin_rad: float = 0.15
    slip_report_s: float = 5.0

    def __post_init__(self) -> None:
        if not isinstance(self.slip_recovery, bool):
            raise ValueError(f"slip_recovery must be a bool, got {self.slip_recovery!r}")
        store(self, ("slip_min_matches",), partial(integer, minimum=2))
        store(self, ("slip_confirm_scans",), partial(integer, minimum=1))
        store(self, ("slip_match_radius", "slip_report_s"), positive)
        store(self, ("slip_margin_m", "slip_margin_rad"), non_negative)


class Alignment(NamedTuple):
    """A rigid alignment of detections with the map: the pose ``T_map_body``, its covariance (3, 3) over
    ``[x, y, theta]``, and the pairs (n, 2) ``[detection index, landmark index]`` it explains."""

    T_map_body: Transform2D
    covariance: NDArray[np.float64]
    pairs: NDArray[np.int64]


def _rotations(theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """``R(theta)`` (H, 2, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack((np.stack((c, -s), -1), np.stack((s, c), -1)), -2)


def _nearest(
    p_body: NDArray[np.float64],
    landmarks: NDArray[np.float64],
    R: NDArray[np.float64],
    t: NDArray[np.float64],
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """For poses ``(R (H, 2, 2), t (H, 2))``: each detection's nearest landmark (H, K), squared distance."""
    # p_map = R p + t  (H, K, 2)
    p_map = np.einsum("hij,kj->hki", R, p_body) + t[:, None, :]
    d2 = ((p_map[:, :, None, :] - landmarks[None, None, :, :]) ** 2).sum(-1)
    nearest = d2.argmin(axis=2)
    return nearest, np.take_along_axis(d2, nearest[..., None], axis=2)[..., 0]


def explained(
    T_map_body: Transform2D, p_body: NDArray[np.float64], landmarks: NDArray[np.float64], radius_m: float
) -> NDArray[np.int64]:
    """``[detection, landmark]`` pairs (n, 2): detections ``p_body`` (K, 2) that ``T_map_body`` puts within
    ``radius_m`` of a landmark (``landmarks`` (M, 2), map frame), each with its nearest one."""
    if len(p_body) == 0 or len(landmarks) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    R = _rotations(np.array([T_map_body.theta]))
    nearest, d2 = _nearest(p_body, landmarks, R, T_map_body.translation[None, :])
    inside = (d2[0] < radius_m * radius_m).nonzero()[0]
    return np.stack((inside, nearest[0, inside]), axis=1).astype(np.int64)


def _rigid_fit(
    p_body: NDArray[np.float64], p_map: NDArray[np.float64], variance_m2: float
) -> tuple[Transform2D, NDArray[np.float64]]:
    """The least-squares ``T`` with ``T p_body ~ p_map`` (n >= 2 pairs) and its covariance (module
    docstring), for a combined per-axis variance ``variance_m2`` (at least the mean squared residual)."""
    c_body, c_map = p_body.mean(axis=0), p_map.mean(axis=0)
    a, b = p_body - c_body, p_map - c_map
    # theta = atan2(sum a x b, sum a . b)
    theta = math.atan2(float((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum()), float((a * b).sum()))
    R = _rotations(np.array([theta]))[0]
    t = c_map - R @ c_body
    residual = p_map - (p_body @ R.T + t)
    s2 = max(variance_m2, float((residual**2).sum(axis=1).mean()) / 2.0)
    n = len(p_body)
    var_theta = s2 / max(float((a**2).sum()), 1e-12)
    # a = -J R c: the body origin's lever arm about the centroid
    Rc = R @ c_body
    lever = np.array([Rc[1], -Rc[0]])
    covariance = np.zeros((3, 3))
    covariance[:2, :2] = s2 / n * np.eye(2) + np.outer(lever, lever) * var_theta
    covariance[:2, 2] = covariance[2, :2] = lever * var_theta
    covariance[2, 2] = var_theta
    return Transform2D(float(t[0]), float(t[1]), theta), covariance


def align_to_map(
    p_body: NDArray[np.float64],
    landmarks: NDArray[np.float64],
    T_prior: Transform2D,
    max_offset_m: float,
    max_turn_rad: float,
    radius_m: float,
    variance_m2: float,
) -> Alignment | None:
    """The pose laying the most detections ``p_body`` (K, 2, body frame) on ``landmarks`` (M, 2, map frame),
    within ``max_offset_m`` and ``max_turn_rad`` of ``T_prior`` (module docstring); None without a
    proposal explaining two detections. ``radius_m``: how near a landmark an explained detection falls;
    ``variance_m2``: the per-axis variance of one pair, for the covariance."""
    min_pair_m = 2.0 * radius_m
    if len(p_body) < 2 or len(landmarks) < 2:
        return None
    p_prior = T_prior.translation
    reach = float(np.linalg.norm(p_body, axis=1).max()) + max_offset_m + radius_m
    near = (np.linalg.norm(landmarks - p_prior, axis=1) <= reach).nonzero()[0]
    near = near[np.argsort(np.linalg.norm(landmarks[near] - p_prior, axis=1))][:_MAX_LANDMARKS]
    if len(near) < 2:
        return None
    nearest_detections = np.argsort(np.linalg.norm(p_body, axis=1))[:_MAX_DETECTIONS]
    p, m = p_body[nearest_detections], landmarks[near]
    i, j = np.triu_indices(len(p), 1)
    a, b = np.nonzero(~np.eye(len(m), dtype=bool))
    d_p = np.linalg.norm(p[j] - p[i], axis=1)
    d_m = np.linalg.norm(m[b] - m[a], axis=1)
    # pairs of detection pairs and landmark pairs of one length
    u, v = np.nonzero((np.abs(d_p[:, None] - d_m[None, :]) < 2.0 * radius_m) & (d_p[:, None] >= min_pair_m))
    if len(u) == 0:
        return None
    i, j, a, b = i[u], j[u], a[v], b[v]
    dp, dm = p[j] - p[i], m[b] - m[a]
    theta = np.arctan2(dm[:, 1], dm[:, 0]) - np.arctan2(dp[:, 1], dp[:, 0])
    R = _rotations(theta)
    # t = (m_a + m_b) / 2 - R (p_i + p_j) / 2
    t = 0.5 * (m[a] + m[b]) - 0.5 * np.einsum("hij,hj->hi", R, p[i] + p[j])
    turn = np.abs(normalize_angles(theta - T_prior.theta))
    offset = np.linalg.norm(t - p_prior, axis=1)
    within = (turn <= max_turn_rad) & (offset <= max_offset_m)
    if not within.any():
        return None
    R, t, turn, offset = R[within], t[within], turn[within], offset[within]
    _, d2 = _nearest(p, m, R, t)
    count = (d2 < radius_m * radius_m).sum(axis=1)
    # most detections explained; among those the proposal nearest the prior
    closeness = (offset / max(max_offset_m, 1e-9)) ** 2 + (turn / max(max_turn_rad, 1e-9)) ** 2
    best = int(np.lexsort((closeness, -count))[0])
    T_best = Transform2D(
        float(t[best, 0]), float(t[best, 1]), float(math.atan2(R[best, 1, 0], R[best, 0, 0]))
    )
    pairs = explained(T_best, p, m, radius_m)
    if len(pairs) < 2:
        return None
    T_fit, covariance = _rigid_fit(p[pairs[:, 0]], m[pairs[:, 1]], variance_m2)
    pairs = explained(T_fit, p, m, radius_m)
    if len(pairs) < 2:
        return None
    T_fit, covariance = _rigid_fit(p[pairs[:, 0]], m[pairs[:, 1]], variance_m2)
    return Alignment(
        T_fit, covariance, np.stack((nearest_detections[pairs[:, 0]], near[pairs[:, 1]]), axis=1)
    )


def _align_known(
    ids: NDArray[np.int64],
    landmark_ids: NDArray[np.int64],
    p_body: NDArray[np.float64],
    landmarks: NDArray[np.float64],
    T_prior: Transform2D,
    max_offset_m: float,
    max_turn_rad: float,
    radius_m: float,
    variance_m2: float,
) -> tuple[int, Alignment | None]:
    """Known association: the detections the prior explains (each within ``radius_m`` of its own landmark
    ``ids`` (K,) among ``landmark_ids`` (M,)), and the rigid fit of all mapped pairs if within the search and
    explaining two of them (:func:`align_to_map` for its arguments)."""
    column = {int(landmark_id): j for j, landmark_id in enumerate(landmark_ids)}
    pairs = np.array([(k, column[int(i)]) for k, i in enumerate(ids) if int(i) in column], dtype=np.int64)
    if len(pairs) < 2:
        return 0, None

    def inside(T: Transform2D) -> NDArray[np.bool_]:
        return np.linalg.norm(T @ p_body[pairs[:, 0]] - landmarks[pairs[:, 1]], axis=1) < radius_m

    n_prior = int(inside(T_prior).sum())
    T_fit, covariance = _rigid_fit(p_body[pairs[:, 0]], landmarks[pairs[:, 1]], variance_m2)
    turn = abs(normalize_angle(T_fit.theta - T_prior.theta))
    offset = float(np.linalg.norm(T_fit.translation - T_prior.translation))
    fitted = pairs[inside(T_fit)]
    if turn > max_turn_rad or offset > max_offset_m or len(fitted) < 2:
        return n_prior, None
    return n_prior, Alignment(T_fit, covariance, fitted)


@dataclass(frozen=True)
class SlipEvent:
    """One relocalization: at ``stamp_ns``, the correction ``T_hat^-1 T*`` (body frame of the filter's
    pose) and its cause (``"wheel slip"`` or ``"bump or stall"``)."""

    stamp_ns: int
    correction: Transform2D
    cause: str


@dataclass
class _Held:
    """The scans held in a row and the correction they agree on."""

    count: int
    correction: Transform2D


@dataclass
class SlipStatus:
    """What :class:`SlipRecovery` reports: ``level`` (``"ok"``, ``"warn"``, ``"error"``), ``message``,
    and the totals ``held`` (scans not fused) and ``relocalized``."""

    level: str = "ok"
    message: str = "the LiDAR agrees with the motion"
    held: int = 0
    relocalized: int = 0
    events: list[SlipEvent] = field(default_factory=list)


class SlipRecovery:
    """Updates an :class:`EkfSlam` with one scan's observations as :meth:`EkfSlam.update` does, unless the
    scan contradicts the motion (module docstring): then it is held, and the filter relocalized once
    ``slip_confirm_scans`` agree. With known association the pairs are the ids' (the alignment is their
    least-squares fit). Switched off (``slip_recovery`` false) it is :meth:`EkfSlam.update`."""

    def __init__(self, config: SlipRecoveryConfig | None = None) -> None:
        self.config = SlipRecoveryConfig() if config is None else config
        self._T_good: Transform2D | None = None
        self._held: _Held | None = None
        self._status = SlipStatus()
        self._now_ns = 0

    @property
    def status(self) -> SlipStatus:
        """The report at the newest scan's time (module docstring)."""
        return self._status

    def update(self, slam: EkfSlam, observations: CheckedObservations, *, stamp_ns: int) -> Association:
        """Fuse, hold or relocalize then fuse one scan taken at ``stamp_ns`` (ns) (class docstring)."""
        self._now_ns = stamp_ns
        if not self.config.slip_recovery:
            return slam.update(observations, stamp_ns=stamp_ns)
        if self._T_good is None:
            self._T_good = slam.pose
        alignment = self._contradiction(slam, observations)
        if alignment is None:
            self._held = None
        else:
            correction = slam.pose.inverse() @ alignment.T_map_body
            if self._held is not None and self._agree(self._held.correction, correction):
                self._held = _Held(self._held.count + 1, correction)
            else:
                self._held = _Held(1, correction)
            if self._held.count < self.config.slip_confirm_scans:
                self._status.held += 1
                self._report()
                count = len(observations.z)
                return Association(
                    np.full(count, REJECTED, dtype=np.int8), np.full(count, -1, dtype=np.int64)
                )
            self._relocalize(slam, alignment, correction, stamp_ns)
        association = slam.update(observations, stamp_ns=stamp_ns)
        if association.counts["matched"] >= min(2, len(observations.z)) > 0:
            self._T_good = slam.pose
        self._report()
        return association

    def forget(self, T_map_body: Transform2D) -> None:
        """Start over from a pose set from outside (a reset, an initial pose): nothing held, the search
        bounded by the motion from ``T_map_body``."""
        self._T_good, self._held = T_map_body, None

    # --- helpers -----------------------------------------------------------------------------------------

    def _contradiction(self, slam: EkfSlam, observations: CheckedObservations) -> Alignment | None:
        """The alignment ``T*`` if this scan contradicts the motion (module docstring), else None."""
        config = self.config
        z, R, ids = observations
        model = slam.measurement
        usable = model.usable(z)
        if usable.sum() < config.slip_min_matches or len(slam.landmark_ids) < 2:
            return None
        # the detections in the body frame and their position covariance G_z R G_z^T
        p_body, _, G_z = model.inverse(np.zeros(3), z[usable])
        position_cov = np.einsum("kij,kjl,kml->kim", G_z, R[usable], G_z)
        landmark_var = float(np.trace(slam.landmark_covariances, axis1=1, axis2=2).mean()) / 2.0
        variance = float(np.trace(position_cov, axis1=1, axis2=2).mean()) / 2.0 + landmark_var
        T_hat = slam.pose
        T_good = self._T_good if self._T_good is not None else T_hat
        max_turn = abs(normalize_angle(T_hat.theta - T_good.theta)) + config.slip_margin_rad
        travel = float(np.linalg.norm(T_hat.translation - T_good.translation))
        max_offset = travel * (1.0 + max_turn) + config.slip_margin_m
        search = (p_body, slam.landmarks, T_hat, max_offset, max_turn, config.slip_match_radius, variance)
        if ids is None:
            n_hat = len(explained(T_hat, p_body, slam.landmarks, config.slip_match_radius))
            alignment = align_to_map(*search) if len(p_body) - n_hat >= 2 else None
        else:
            n_hat, alignment = _align_known(ids[usable], slam.landmark_ids, *search)
        if alignment is None or len(alignment.pairs) < max(config.slip_min_matches, n_hat + 2):
            return None
        d = alignment.T_map_body.as_array() - T_hat.as_array()
        d[2] = normalize_angle(d[2])
        S = slam.pose_covariance + alignment.covariance
        if float(d @ np.linalg.solve(S, d)) <= _SIGNIFICANT_D2:
            return None
        return alignment

    def _agree(self, a: Transform2D, b: Transform2D) -> bool:
        return (
            float(np.linalg.norm(a.translation - b.translation)) < 2.0 * self.config.slip_match_radius
            and abs(normalize_angle(a.theta - b.theta)) < _SAME_CORRECTION_RAD
        )

    def _relocalize(
        self, slam: EkfSlam, alignment: Alignment, correction: Transform2D, stamp_ns: int
    ) -> None:
        """``T*`` with the fit's covariance, independent of the map; the event recorded with its cause."""
        motion = (self._T_good or slam.pose).inverse() @ slam.pose
        slam.reset(alignment.T_map_body, alignment.covariance, keep_map=True)
        self._T_good, self._held = alignment.T_map_body, None
        # the body short of where the wheels put it: the correction runs back along the reported motion
        backwards = float(correction.translation @ motion.translation) < 0.0
        cause = "bump or stall" if backwards and abs(correction.theta) < 0.1 else "wheel slip"
        self._status.relocalized += 1
        self._status.events.append(SlipEvent(stamp_ns, correction, cause))

    def _report(self) -> None:
        """The status at ``_now_ns``: recent relocalizations and a held scan."""
        status, config = self._status, self.config
        since = self._now_ns - round(config.slip_report_s * NS_PER_S)
        recent = [event for event in status.events if event.stamp_ns >= since]
        del status.events[: len(status.events) - len(recent)]
        if len(recent) >= _REPEATS_FOR_ERROR:
            status.level = "error"
            causes = sorted({event.cause for event in recent})
            status.message = (
                f"{len(recent)} relocalizations in {config.slip_report_s:g} s ({', '.join(causes)}): the "
                "wheels keep reporting motion the LiDAR does not see (slipping, or the robot is stuck)"
            )
        elif recent:
            event = recent[-1]
            c = event.correction
            status.level = "warn"
            status.message = (
                f"{event.cause}: the wheels reported motion the LiDAR did not see; relocalized against the "
                f"map by {np.hypot(c.x, c.y):.3f} m, {c.theta:+.3f} rad"
            )
        elif self._held is not None:
            status.level = "warn"
            c = self._held.correction
            status.message = (
                f"the LiDAR contradicts the motion (slip or bump?): scan held, the map says the pose is off "
                f"by {np.hypot(c.x, c.y):.3f} m, {c.theta:+.3f} rad"
            )
        else:
            status.level, status.message = "ok", SlipStatus.message
