"""Association decisions revised by the smoother: what a causal filter had to decide at once, decided again
with the whole run (unknown association).

Every observation of the run is in one pool, labelled with a landmark id or unassigned (-1: what the filter
rejected, or gave to a tentative landmark it dropped). After each smoothing of the labelled observations
(:class:`turtlelib.smoothing.smoother.Smoother`), the first of these steps that changes something is taken,
and the run smoothed again from its last optimum, until none does (or ``max_rounds``):

1. **Merge duplicates.** Two landmarks ``a``, ``b`` that no pose observed together (one scan never sees one
   landmark twice) are one landmark when their difference is compatible with zero under the smoothed joint
   covariance::

       D^2 = (m_a - m_b)^T (S_aa + S_bb - S_ab - S_ba)^-1 (m_a - m_b) < chi2_2^-1(merge_gate)

   Pairs are merged greedily by increasing ``D^2``, each landmark once per round; ``b``'s observations are
   relabelled ``a`` (the smaller id is kept).
2. **Remove unsupported landmarks.** A landmark with fewer than ``min_support`` inlier observations
   (squared Mahalanobis distance ``s < chi2_2^-1(inlier_gate)``) is removed; its observations return to
   the pool.
3. **Adopt unassigned observations.** Each is placed in the map from its smoothed pose,
   ``p_j = g(q_k, z_j)`` with ``C_j = G_z R_j G_z^T``, and joins the landmark ``i`` for which
   ``(p_j - m_i)^T (C_j + L_i^-1)^-1 (p_j - m_i) < chi2_2^-1(merge_gate)`` if that landmark is the only
   one, and was not seen from that pose. ``L_i`` is the information of landmark ``i``'s inlier points (its
   precision relative to the poses: its marginal covariance also holds the uncertainty of the whole map
   in the start's frame, which a comparison within the run does not see).
4. **New landmarks from what no landmark explains** (the outliers of the labelled observations, once steps
   1-3 change nothing; an unassigned observation only ever joins a landmark, step 3): two of them
   from different poses agree when ``(p_a - p_b)^T (C_a + C_b)^-1 (p_a - p_b) < chi2_2^-1(merge_gate)``; the
   one that agrees with the most others makes a landmark with them (the nearest per pose) if they are
   ``min_support`` together, at their information-weighted mean, kept only if no landmark is compatible
   with it (else they were that landmark's outliers); repeated over those left.

Outliers that no step moves stay where they are, down-weighted by the robust kernel.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.special import chdtri

from ..estimation.measurement_models import MeasurementModel
from ..util.validation import in_range, integer, positive, store
from .smoother import SmoothedRun, Smoother
from .smoothing_problem import SmoothingProblem


@dataclass(frozen=True)
class RevisionConfig:
    """``merge_gate`` the chi2 probability of the merge and cluster tests, ``inlier_gate`` that under which
    an observation's squared Mahalanobis distance makes it an inlier (both in (0, 1)); ``min_support`` the
    inlier observations a landmark needs (>= 1); ``max_rounds`` smoothings at most (>= 1);
    ``merge_radius_m`` (m, > 0) the distance beyond which two landmarks are not tested for a merge (how far
    one landmark's duplicates can lie apart; it keeps the covariance solves to nearby pairs)."""

    merge_gate: float = 0.999
    inlier_gate: float = 0.99
    min_support: int = 3
    max_rounds: int = 10
    merge_radius_m: float = 2.0

    def __post_init__(self) -> None:
        store(
            self,
            ("merge_gate", "inlier_gate"),
            partial(in_range, low=0.0, high=1.0, open_low=True, open_high=True),
        )
        store(self, ("min_support", "max_rounds"), partial(integer, minimum=1))
        store(self, ("merge_radius_m",), positive)


@dataclass(frozen=True)
class Revision:
    """The smoothed run of the revised labelling (``problem``: the labelled observations), the merges
    ``(kept id, merged id)`` in order, the ids removed and created, how many observations were adopted,
    how many of ``problem``'s ended as outliers and how many stayed unassigned."""

    run: SmoothedRun
    problem: SmoothingProblem
    merged: list[tuple[int, int]]
    removed: list[int]
    created: list[int]
    adopted: int
    outliers: int
    unassigned: int


@dataclass(frozen=True)
class Unassigned:
    """Observations without a landmark: made from pose ``observation_pose`` (U,) (indices), ``z`` (U, 2) with
    noise ``R`` (U, 2, 2)."""

    observation_pose: NDArray[np.int64]
    z: NDArray[np.float64]
    R: NDArray[np.float64]


class _Pool:
    """Every observation (the problem's, then the unassigned ones) with its label (-1: unassigned)."""

    def __init__(self, problem: SmoothingProblem, unassigned: Unassigned | None) -> None:
        extra = (
            Unassigned(np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 2, 2)))
            if unassigned is None
            else unassigned
        )
        self.base = problem
        self.pose = np.r_[problem.observation_pose, extra.observation_pose].astype(np.int64)
        self.z = np.vstack([problem.z, extra.z])
        self.R = np.concatenate([problem.R, extra.R])
        self.label = np.r_[problem.observation_landmark, np.full(len(extra.z), -1)].astype(np.int64)

    def problem(self, rescale: Callable[[SmoothingProblem], NDArray[np.float64]]) -> SmoothingProblem:
        """The labelled observations as the base problem's factors, with the noise scales of the labels."""
        rows = self.labelled_rows
        problem = replace(
            self.base,
            observation_pose=self.pose[rows],
            observation_landmark=self.label[rows],
            z=self.z[rows],
            R=self.R[rows],
            noise_scale=np.ones(len(rows)),
        )
        return replace(problem, noise_scale=rescale(problem))

    @property
    def labelled_rows(self) -> NDArray[np.int64]:
        return np.flatnonzero(self.label >= 0)


def revise_associations(
    smoother: Smoother,
    problem: SmoothingProblem,
    poses: NDArray[np.float64],
    landmark_ids: NDArray[np.int64],
    landmarks: NDArray[np.float64],
    rescale: Callable[[SmoothingProblem], NDArray[np.float64]],
    config: RevisionConfig | None = None,
    unassigned: Unassigned | None = None,
) -> Revision:
    """The revision of the module docstring from the warm start ``poses``, ``landmarks`` of ``landmark_ids``
    (ascending) for the labelled observations of ``problem`` and the ``unassigned`` ones.
    ``rescale(problem)`` gives the observations' ``noise_scale`` (K,) of a problem's labelling (correlated
    errors depend on which views belong together)."""
    config = RevisionConfig() if config is None else config
    landmark_ids = np.asarray(landmark_ids, dtype=np.int64)
    pool = _Pool(problem, unassigned)
    merged: list[tuple[int, int]] = []
    removed: list[int] = []
    created: list[int] = []
    adopted = 0
    # new landmarks get ids above every id of the run
    next_id = int(landmark_ids.max(initial=-1)) + 1
    inlier_limit = chdtri(2, 1.0 - config.inlier_gate)
    problem = pool.problem(rescale)
    for round_ in range(config.max_rounds):
        run = smoother.solve(problem, poses, landmark_ids, landmarks, near_optimum=round_ > 0)
        poses, landmarks = run.poses, run.landmarks
        rows = pool.labelled_rows
        pairs = compatible_pairs(run, problem, config)
        if pairs:
            for kept, gone in pairs:
                pool.label[pool.label == gone] = kept
            keep = ~np.isin(landmark_ids, [gone for _, gone in pairs])
            landmark_ids, landmarks = landmark_ids[keep], landmarks[keep]
            merged += pairs
            problem = pool.problem(rescale)
            continue
        inliers = run.mahalanobis2 < inlier_limit
        slot = np.searchsorted(landmark_ids, problem.observation_landmark)
        weak = np.bincount(slot[inliers], minlength=len(landmark_ids)) < config.min_support
        points, covariances = _observed_points(run.poses, pool, smoother.measurement)
        local_covariance = _local_covariances(run, slot, inliers, covariances[rows])
        # from the same optimum: the weak landmarks' observations return to the pool and the pool's
        # observations join the other landmarks; once neither changes anything, the outliers left make
        # new landmarks
        joined, joined_ids = adoptable(
            run, pool, points, covariances, local_covariance, config.merge_gate, allowed=~weak
        )
        clusters = []
        if not (weak.any() or len(joined)):
            clusters = new_landmarks(run, pool, points, covariances, local_covariance, rows[~inliers], config)
            if not clusters:
                break
        removed += landmark_ids[weak].tolist()
        pool.label[rows[weak[slot]]] = -1
        landmark_ids, landmarks = landmark_ids[~weak], landmarks[~weak]
        pool.label[joined] = joined_ids
        adopted += len(joined)
        for members, xy in clusters:
            pool.label[members] = next_id
            landmark_ids, landmarks = np.r_[landmark_ids, next_id], np.vstack([landmarks, xy])
            created.append(next_id)
            next_id += 1
        problem = pool.problem(rescale)
    else:
        run = smoother.solve(problem, poses, landmark_ids, landmarks, near_optimum=True)
    outliers = int((run.mahalanobis2 >= inlier_limit).sum())
    return Revision(run, problem, merged, removed, created, adopted, outliers, int((pool.label < 0).sum()))


def compatible_pairs(
    run: SmoothedRun, problem: SmoothingProblem, config: RevisionConfig
) -> list[tuple[int, int]]:
    """The landmark pairs to merge (module docstring, step 1) as ``(kept id, merged id)``; only pairs
    closer than ``merge_radius_m`` are tested (their joint covariance is solved for, no other)."""
    n = len(run.landmark_ids)
    if n < 2:
        return []
    a, b = np.triu_indices(n, k=1)
    near = np.linalg.norm(run.landmarks[a] - run.landmarks[b], axis=1) < config.merge_radius_m
    a, b = a[near], b[near]
    # never merge two landmarks seen from one pose
    slot = np.searchsorted(run.landmark_ids, problem.observation_landmark)
    seen = sparse.csr_matrix(
        (np.ones(len(slot)), (problem.observation_pose, slot)), shape=(problem.n_poses, n)
    )
    together = (seen.T @ seen).toarray() > 0
    apart = ~together[a, b]
    a, b = a[apart], b[apart]
    if not len(a):
        return []
    involved = np.unique(np.r_[a, b])
    S = run.covariance(run.landmark_variables(involved)).reshape(len(involved), 2, len(involved), 2)
    ia, ib = np.searchsorted(involved, a), np.searchsorted(involved, b)
    # C = S_aa + S_bb - S_ab - S_ba
    C = S[ia, :, ia, :] + S[ib, :, ib, :] - S[ia, :, ib, :] - S[ib, :, ia, :]
    d = run.landmarks[a] - run.landmarks[b]
    D2 = np.einsum("ki,ki->k", d, np.linalg.solve(C, d[:, :, None])[:, :, 0])
    close = D2 < chdtri(2, 1.0 - config.merge_gate)
    pairs, used = [], set()
    for k in np.flatnonzero(close)[np.argsort(D2[close])]:
        if a[k] in used or b[k] in used:
            continue
        used.update((a[k], b[k]))
        ids = sorted((int(run.landmark_ids[a[k]]), int(run.landmark_ids[b[k]])))
        pairs.append((ids[0], ids[1]))
    return pairs


def adoptable(
    run: SmoothedRun,
    pool: _Pool,
    points: NDArray[np.float64],
    covariances: NDArray[np.float64],
    local_covariance: NDArray[np.float64],
    gate_probability: float,
    allowed: NDArray[np.bool_],
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The unassigned observations that one landmark alone explains (module docstring, step 3), among the
    ``allowed`` (n,) landmarks: their pool rows and those landmarks' ids."""
    free = np.flatnonzero(pool.label < 0)
    n = len(run.landmark_ids)
    if not len(free) or not n:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    gate = chdtri(2, 1.0 - gate_probability)
    labelled = pool.label >= 0
    seen = set(zip(pool.pose[labelled].tolist(), pool.label[labelled].tolist(), strict=True))
    rows, ids = [], []
    for chunk in np.array_split(free, max(1, len(free) * n // 200_000)):
        gap = points[chunk, None, :] - run.landmarks[None, :, :]
        C = covariances[chunk, None] + local_covariance[None, :]
        D2 = np.einsum("kni,kni->kn", gap, np.linalg.solve(C, gap[..., None])[..., 0])
        compatible = D2 < gate
        single = (compatible.sum(axis=1) == 1) & compatible[:, allowed].any(axis=1)
        for row, slot in zip(chunk[single], np.argmax(compatible[single], axis=1), strict=True):
            key = (int(pool.pose[row]), int(run.landmark_ids[slot]))
            if key not in seen:
                seen.add(key)
                rows.append(row)
                ids.append(key[1])
    return np.array(rows, dtype=np.int64), np.array(ids, dtype=np.int64)


def new_landmarks(
    run: SmoothedRun,
    pool: _Pool,
    points: NDArray[np.float64],
    covariances: NDArray[np.float64],
    local_covariance: NDArray[np.float64],
    candidates: NDArray[np.int64],
    config: RevisionConfig,
) -> list[tuple[NDArray[np.int64], NDArray[np.float64]]]:
    """New landmarks from the ``candidates`` (pool rows no landmark explains; module docstring, step 4):
    ``(member rows (k,), xy (2,))`` each."""
    if len(candidates) < config.min_support:
        return []
    points, covariances = points[candidates], covariances[candidates]
    gate = chdtri(2, 1.0 - config.merge_gate)
    d = points[:, None, :] - points[None, :, :]
    D2 = np.einsum(
        "abi,abi->ab", d, np.linalg.solve(covariances[:, None] + covariances[None, :], d[..., None])[..., 0]
    )
    pose = pool.pose[candidates]
    agree = (D2 < gate) & (pose[:, None] != pose[None, :])
    information = np.linalg.inv(covariances)
    clusters, free = [], np.ones(len(candidates), dtype=bool)
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
        C = local_covariance + np.linalg.inv(total)
        D2_landmarks = np.einsum("ki,ki->k", gap, np.linalg.solve(C, gap[:, :, None])[:, :, 0])
        if np.all(D2_landmarks >= gate):
            clusters.append((candidates[members], xy))


def _local_covariances(
    run: SmoothedRun, slot: NDArray[np.int64], inliers: NDArray[np.bool_], covariances: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``L_i^-1`` (n, 2, 2): the inverse of the summed information of each landmark's inlier points
    (``covariances`` (K, 2, 2) of the problem's observations, ``slot`` their landmarks' indices)."""
    information = np.zeros((len(run.landmark_ids), 2, 2))
    np.add.at(information, slot[inliers], np.linalg.inv(covariances[inliers]))
    return np.linalg.inv(information + 1e-12 * np.eye(2))


def _observed_points(
    poses: NDArray[np.float64], pool: _Pool, measurement: MeasurementModel
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Every pool observation's map point ``p_j = g(q_k, z_j)`` (N, 2) from the ``poses`` (P, 3) and its
    covariance ``G_z R_j G_z^T`` (N, 2, 2), through the relative model: ``g(q, z) = p + R(theta) g(0, z)``,
    ``G_z(q) = R(theta) G_z(0)``."""
    q = poses[pool.pose]
    p_body, _, G_z0 = measurement.inverse(np.zeros(3), pool.z)
    c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
    R = np.stack([np.column_stack([c, -s]), np.column_stack([s, c])], axis=1)
    G_z = R @ G_z0
    points = q[:, :2] + np.einsum("kij,kj->ki", R, p_body)
    return points, G_z @ pool.R @ np.swapaxes(G_z, 1, 2)
