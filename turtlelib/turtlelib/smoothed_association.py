"""Association decisions revised by the smoother: what a causal filter had to decide at once, decided again
with the whole run (unknown association).

After each smoothing (:class:`turtlelib.smoother.Smoother`) of the current labelling:

1. **Merge duplicates.** Two landmarks ``a``, ``b`` that no pose observed together (one scan never sees one
   landmark twice) are one landmark when their difference is compatible with zero under the smoothed joint
   covariance::

       D^2 = (m_a - m_b)^T (S_aa + S_bb - S_ab - S_ba)^-1 (m_a - m_b) < chi2_2^-1(merge_gate)

   Pairs are merged greedily by increasing ``D^2``, each landmark once per round; ``b``'s observations are
   relabelled ``a`` (the smaller id is kept).
2. **Remove unsupported landmarks.** A landmark with fewer than ``min_support`` observations that the
   robust kernel keeps as inliers (weight >= 1/2: within ``kernel_width`` sigma) is removed with its
   observations.
3. **Outliers** stay in the problem, down-weighted by the kernel (their weights are in the result).

A change is smoothed again from the last optimum, until nothing changes (or ``max_rounds``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.special import chdtri

from .measurement_models import MeasurementModel
from .smoother import SmoothedRun, Smoother
from .smoothing_problem import SmoothingProblem
from .validation import in_range, integer, store


@dataclass(frozen=True)
class RevisionConfig:
    """``merge_gate`` the chi2 probability of the merge and cluster tests, ``inlier_gate`` that under which
    an observation's squared Mahalanobis distance makes it an inlier (both in (0, 1)); ``min_support`` the
    inlier observations a landmark needs (>= 1); ``max_rounds`` smoothings at most (>= 1)."""

    merge_gate: float = 0.999
    inlier_gate: float = 0.99
    min_support: int = 3
    max_rounds: int = 20

    def __post_init__(self) -> None:
        store(
            self,
            ("merge_gate", "inlier_gate"),
            partial(in_range, low=0.0, high=1.0, open_low=True, open_high=True),
        )
        store(self, ("min_support", "max_rounds"), partial(integer, minimum=1))


@dataclass(frozen=True)
class Revision:
    """The smoothed run of the revised labelling (``problem``), the merges ``(kept id, merged id)`` in
    order, the ids removed, the ids of the landmarks made from outliers, and how many observations ended
    as outliers (weight < 1/2)."""

    run: SmoothedRun
    problem: SmoothingProblem
    merged: list[tuple[int, int]]
    removed: NDArray[np.int64]
    created: list[int]
    outliers: int


def revise_associations(
    smoother: Smoother,
    problem: SmoothingProblem,
    poses: NDArray[np.float64],
    landmark_ids: NDArray[np.int64],
    landmarks: NDArray[np.float64],
    rescale: Callable[[SmoothingProblem], NDArray[np.float64]],
    config: RevisionConfig | None = None,
) -> Revision:
    """Smooth, merge, remove, smooth again (module docstring) from the warm start ``poses``, ``landmarks`` of
    ``landmark_ids``. ``rescale(problem)`` gives the observations' ``noise_scale`` (K,) of a problem's
    labelling (correlated errors depend on which views belong together)."""
    config = RevisionConfig() if config is None else config
    landmark_ids = np.asarray(landmark_ids, dtype=np.int64)
    merged: list[tuple[int, int]] = []
    removed: list[int] = []
    created: list[int] = []
    # new landmarks get ids above every id of the run
    next_id = int(landmark_ids.max(initial=-1)) + 1
    for round_ in range(config.max_rounds):
        run = smoother.solve(problem, poses, landmark_ids, landmarks, near_optimum=round_ > 0)
        poses, landmarks = run.poses, run.landmarks
        pairs = compatible_pairs(run, problem, config.merge_gate)
        if pairs:
            labels = problem.observation_landmark.copy()
            for kept, gone in pairs:
                labels[labels == gone] = kept
            keep = ~np.isin(landmark_ids, [gone for _, gone in pairs])
            landmark_ids, landmarks = landmark_ids[keep], landmarks[keep]
            problem = _relabelled(replace(problem, observation_landmark=labels), rescale)
            merged += pairs
            continue
        inliers = run.mahalanobis2 < chdtri(2, 1.0 - config.inlier_gate)
        slot = np.searchsorted(landmark_ids, problem.observation_landmark)
        support = np.bincount(slot[inliers], minlength=len(landmark_ids))
        weak = support < config.min_support
        if not weak.any():
            clusters = outlier_clusters(run, problem, smoother.measurement, config)
            if not clusters:
                return Revision(
                    run, problem, merged, np.array(removed, dtype=np.int64), created, int((~inliers).sum())
                )
            labels = problem.observation_landmark.copy()
            for members, xy in clusters:
                labels[members] = next_id
                landmark_ids, landmarks = np.r_[landmark_ids, next_id], np.vstack([landmarks, xy])
                created.append(next_id)
                next_id += 1
            problem = _relabelled(replace(problem, observation_landmark=labels), rescale)
            continue
        removed += landmark_ids[weak].tolist()
        kept_obs = ~weak[slot]
        landmark_ids, landmarks = landmark_ids[~weak], landmarks[~weak]
        problem = _relabelled(
            replace(
                problem,
                observation_pose=problem.observation_pose[kept_obs],
                observation_landmark=problem.observation_landmark[kept_obs],
                z=problem.z[kept_obs],
                R=problem.R[kept_obs],
                noise_scale=problem.noise_scale[kept_obs],
            ),
            rescale,
        )
    run = smoother.solve(problem, poses, landmark_ids, landmarks, near_optimum=True)
    outliers = int((run.mahalanobis2 >= chdtri(2, 1.0 - config.inlier_gate)).sum())
    return Revision(run, problem, merged, np.array(removed, dtype=np.int64), created, outliers)


def compatible_pairs(run: SmoothedRun, problem: SmoothingProblem, merge_gate: float) -> list[tuple[int, int]]:
    """The landmark pairs to merge (module docstring, step 1) as ``(kept id, merged id)``."""
    n = len(run.landmark_ids)
    if n < 2:
        return []
    a, b = np.triu_indices(n, k=1)
    # never merge two landmarks seen from one pose
    slot = np.searchsorted(run.landmark_ids, problem.observation_landmark)
    seen = sparse.csr_matrix(
        (np.ones(len(slot)), (problem.observation_pose, slot)), shape=(problem.n_poses, n)
    )
    together = (seen.T @ seen).toarray() > 0
    candidates = ~together[a, b]
    a, b = a[candidates], b[candidates]
    S = run.landmark_covariance.reshape(n, 2, n, 2)
    # C = S_aa + S_bb - S_ab - S_ba
    C = S[a, :, a, :] + S[b, :, b, :] - S[a, :, b, :] - S[b, :, a, :]
    d = run.landmarks[a] - run.landmarks[b]
    D2 = np.einsum("ki,ki->k", d, np.linalg.solve(C, d[:, :, None])[:, :, 0])
    close = D2 < chdtri(2, 1.0 - merge_gate)
    pairs, used = [], set()
    for k in np.flatnonzero(close)[np.argsort(D2[close])]:
        if a[k] in used or b[k] in used:
            continue
        used.update((a[k], b[k]))
        ids = sorted((int(run.landmark_ids[a[k]]), int(run.landmark_ids[b[k]])))
        pairs.append((ids[0], ids[1]))
    return pairs


def outlier_clusters(
    run: SmoothedRun, problem: SmoothingProblem, measurement: MeasurementModel, config: RevisionConfig
) -> list[tuple[NDArray[np.int64], NDArray[np.float64]]]:
    """New landmarks from outlier observations (module docstring, step 3): ``(members (k,), xy (2,))``.

    Each outlier ``j`` is placed at ``p_j = g(q_k, z_j)`` with ``C_j = G_z R_j G_z^T``; two outliers from
    different poses agree when ``(p_i - p_j)^T (C_i + C_j)^-1 (p_i - p_j) < chi2_2^-1(merge_gate)``. The
    outlier that agrees with the most others makes a cluster with them (the nearest one per pose) if they
    are ``min_support`` together, placed at their information-weighted mean, and kept only if it is
    incompatible with every landmark (else its views were mere outliers of that landmark); repeated over
    the outliers left."""
    is_outlier = run.mahalanobis2 >= chdtri(2, 1.0 - config.inlier_gate)
    if is_outlier.sum() < config.min_support:
        return []
    all_points, all_covariances = _observed_points(run, problem, measurement)
    outliers = np.flatnonzero(is_outlier)
    points, covariances = all_points[outliers], all_covariances[outliers]
    # each landmark's precision relative to the poses: that of its inliers' points (its marginal holds the
    # whole map's uncertainty in the start's frame, which a comparison within the run does not see)
    slot = np.searchsorted(run.landmark_ids, problem.observation_landmark)
    local_information = np.zeros((len(run.landmark_ids), 2, 2))
    np.add.at(local_information, slot[~is_outlier], np.linalg.inv(all_covariances[~is_outlier]))
    local_information += 1e-12 * np.eye(2)
    gate = chdtri(2, 1.0 - config.merge_gate)
    d = points[:, None, :] - points[None, :, :]
    D2 = np.einsum(
        "abi,abi->ab", d, np.linalg.solve(covariances[:, None] + covariances[None, :], d[..., None])[..., 0]
    )
    pose = problem.observation_pose[outliers]
    agree = (D2 < gate) & (pose[:, None] != pose[None, :])
    information = np.linalg.inv(covariances)
    clusters, free = [], np.ones(len(outliers), dtype=bool)
    while True:
        counts = (agree & free[None, :]).sum(axis=1) * free
        seed = int(np.argmax(counts))
        if counts[seed] + 1 < config.min_support:
            return clusters
        near = np.flatnonzero(agree[seed] & free)
        # the nearest view per pose, the seed's own pose excluded
        near = near[np.argsort(D2[seed, near])]
        _, first = np.unique(pose[near], return_index=True)
        members = np.r_[seed, near[first]]
        free[members] = False
        if len(members) < config.min_support:
            continue
        # information-weighted mean: (sum C_j^-1)^-1 sum C_j^-1 p_j
        total = information[members].sum(axis=0)
        xy = np.linalg.solve(total, np.einsum("kij,kj->i", information[members], points[members]))
        gap = run.landmarks - xy
        C = np.linalg.inv(local_information) + np.linalg.inv(total)
        D2_landmarks = np.einsum("ki,ki->k", gap, np.linalg.solve(C, gap[:, :, None])[:, :, 0])
        if np.all(D2_landmarks >= gate):
            clusters.append((outliers[members], xy))


def _observed_points(
    run: SmoothedRun, problem: SmoothingProblem, measurement: MeasurementModel
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Every observation's map point ``p_j = g(q_k, z_j)`` (K, 2) from the smoothed poses and its covariance
    ``G_z R_j G_z^T`` (K, 2, 2), through the relative model: ``g(q, z) = p + R(theta) g(0, z)`` and
    ``G_z(q) = R(theta) G_z(0)``."""
    q = run.poses[problem.observation_pose]
    p_body, _, G_z0 = measurement.inverse(np.zeros(3), problem.z)
    c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
    R = np.stack([np.column_stack([c, -s]), np.column_stack([s, c])], axis=1)
    G_z = R @ G_z0
    points = q[:, :2] + np.einsum("kij,kj->ki", R, p_body)
    return points, G_z @ problem.observation_covariance @ np.swapaxes(G_z, 1, 2)


def _relabelled(
    problem: SmoothingProblem, rescale: Callable[[SmoothingProblem], NDArray[np.float64]]
) -> SmoothingProblem:
    """``problem`` with the noise scales of its (new) labelling."""
    return replace(problem, noise_scale=rescale(problem))
