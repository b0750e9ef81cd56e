"""Rigid alignment of a scan's detections with a landmark map, for relocalization.

Detections ``p_k`` (K, 2) in the body frame, landmarks ``m_j`` (M, 2) in the map frame; a pose
``T = T_map_body = (R(theta), t)`` *explains* detection ``k`` when ``|T p_k - m_j| < radius`` for some ``j``.

* :func:`align_to_map` (unknown association): every pair of detections at least ``2 radius`` apart against
  every pair of landmarks as far apart (to within ``2 radius``) proposes the pose that lays the one on the
  other::

      theta = atan2(m_b - m_a) - atan2(p_j - p_i),   t = (m_a + m_b) / 2 - R(theta) (p_i + p_j) / 2

  proposals outside the search (``max_turn_rad``, ``max_offset_m`` of a prior pose) are dropped, the one
  explaining the most detections wins (ties: the nearest to the prior), and is refined by the least-squares
  fit of the pairs it explains.
* :func:`align_known` (known association): the ids give the pairs; the alignment is their fit.
* :func:`rigid_fit`: the least-squares rigid fit (2D Procrustes) of ``n >= 2`` pairs about their centroids
  ``c`` (body) and ``c'`` (map)::

      theta = atan2(sum_k a_k x b_k, sum_k a_k . b_k),  a_k = p_k - c,  b_k = m_k - c',  t = c' - R(theta) c

  with covariance, for a per-axis variance ``s^2`` of each pair (at least the fit's mean squared
  residual)::

      Var(theta) = s^2 / sum_k |a_k|^2
      Cov(t) = s^2 / n I + l l^T Var(theta),   Cov(t, theta) = l Var(theta),   l = -J R(theta) c

  (``J`` the quarter turn: ``l`` is the body origin's lever arm about the centroid).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..geometry.se2 import Transform2D, normalize_angle, normalize_angles

# a proposal's detections and landmarks are the nearest this many (bounds the O(H K M) scoring)
_MAX_DETECTIONS = 12
_MAX_LANDMARKS = 40


class Search(NamedTuple):
    """Where and how an alignment is searched: within ``max_offset_m`` (m) and ``max_turn_rad`` (rad) of
    ``T_prior``; a detection is explained within ``radius_m`` (m) of a landmark; ``variance_m2`` (m^2) is
    the per-axis variance of one pair, for the fit's covariance."""

    T_prior: Transform2D
    max_offset_m: float
    max_turn_rad: float
    radius_m: float
    variance_m2: float

    def admits(self, T: Transform2D) -> bool:
        """Whether ``T`` lies within the search."""
        turn = abs(normalize_angle(T.theta - self.T_prior.theta))
        return turn <= self.max_turn_rad and float(
            np.linalg.norm(T.translation - self.T_prior.translation)
        ) <= (self.max_offset_m)


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
    distance = np.linalg.norm((T_map_body @ p_body)[:, None, :] - landmarks[None, :, :], axis=2)
    nearest = distance.argmin(axis=1)
    inside = (distance[np.arange(len(p_body)), nearest] < radius_m).nonzero()[0]
    return np.stack((inside, nearest[inside]), axis=1).astype(np.int64)


def rigid_fit(
    p_body: NDArray[np.float64], p_map: NDArray[np.float64], variance_m2: float
) -> tuple[Transform2D, NDArray[np.float64]]:
    """The least-squares ``T`` with ``T p_body ~ p_map`` (n >= 2 pairs) and its covariance (module
    docstring), for a combined per-axis variance ``variance_m2`` (at least the mean squared residual)."""
    c_body, c_map = p_body.mean(axis=0), p_map.mean(axis=0)
    a, b = p_body - c_body, p_map - c_map
    # theta = atan2(sum a x b, sum a . b)
    theta = math.atan2(float((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum()), float((a * b).sum()))
    Rc = Transform2D(0.0, 0.0, theta) @ c_body
    # t = c' - R c
    T = Transform2D(float(c_map[0] - Rc[0]), float(c_map[1] - Rc[1]), theta)
    residual = p_map - T @ p_body
    s2 = max(variance_m2, float((residual**2).sum(axis=1).mean()) / 2.0)
    n = len(p_body)
    var_theta = s2 / max(float((a**2).sum()), 1e-12)
    # l = -J R c: the body origin's lever arm about the centroid
    lever = np.array([Rc[1], -Rc[0]])
    covariance = np.zeros((3, 3))
    covariance[:2, :2] = s2 / n * np.eye(2) + np.outer(lever, lever) * var_theta
    covariance[:2, 2] = covariance[2, :2] = lever * var_theta
    covariance[2, 2] = var_theta
    return T, covariance


def align_to_map(
    p_body: NDArray[np.float64], landmarks: NDArray[np.float64], search: Search
) -> Alignment | None:
    """The pose laying the most detections ``p_body`` (K, 2, body frame) on ``landmarks`` (M, 2, map frame)
    within ``search`` (module docstring); None without a proposal explaining two detections."""
    T_prior, max_offset_m, max_turn_rad, radius_m, variance_m2 = search
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
    R, t, theta, turn, offset = R[within], t[within], theta[within], turn[within], offset[within]
    _, d2 = _nearest(p, m, R, t)
    count = (d2 < radius_m * radius_m).sum(axis=1)
    # most detections explained; among those the proposal nearest the prior
    closeness = (offset / max(max_offset_m, 1e-9)) ** 2 + (turn / max(max_turn_rad, 1e-9)) ** 2
    best = int(np.lexsort((closeness, -count))[0])
    T_fit = Transform2D(float(t[best, 0]), float(t[best, 1]), float(theta[best]))
    # refine twice: the pairs the pose explains, their fit, the pairs the fit explains, their fit
    for _ in range(2):
        pairs = explained(T_fit, p, m, radius_m)
        if len(pairs) < 2:
            return None
        T_fit, covariance = rigid_fit(p[pairs[:, 0]], m[pairs[:, 1]], variance_m2)
    return Alignment(
        T_fit, covariance, np.stack((nearest_detections[pairs[:, 0]], near[pairs[:, 1]]), axis=1)
    )


def align_known(
    ids: NDArray[np.int64],
    landmark_ids: NDArray[np.int64],
    p_body: NDArray[np.float64],
    landmarks: NDArray[np.float64],
    search: Search,
) -> tuple[int, Alignment | None]:
    """Known association: how many detections ``search.T_prior`` explains (each within ``radius_m`` of its
    own landmark: ``ids`` (K,) among ``landmark_ids`` (M,)), and the rigid fit of all mapped pairs if it
    lies within the search and explains two of them."""
    column = {int(landmark_id): j for j, landmark_id in enumerate(landmark_ids)}
    pairs = np.array([(k, column[int(i)]) for k, i in enumerate(ids) if int(i) in column], dtype=np.int64)
    if len(pairs) < 2:
        return 0, None

    def inside(T: Transform2D) -> NDArray[np.bool_]:
        return np.linalg.norm(T @ p_body[pairs[:, 0]] - landmarks[pairs[:, 1]], axis=1) < search.radius_m

    n_prior = int(inside(search.T_prior).sum())
    T_fit, covariance = rigid_fit(p_body[pairs[:, 0]], landmarks[pairs[:, 1]], search.variance_m2)
    fitted = pairs[inside(T_fit)]
    if not search.admits(T_fit) or len(fitted) < 2:
        return n_prior, None
    return n_prior, Alignment(T_fit, covariance, fitted)
