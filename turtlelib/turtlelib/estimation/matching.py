"""Data association of range-bearing observations with map landmarks: chi2 gates, NN and JCBB.

Notation: ``K`` observations ``z_k`` with noise ``R_k``, ``n`` landmarks (or candidates) with predicted
observations ``z_hat_j`` and predicted-observation covariances ``Sigma_j = H_j P H_j^T``. The innovation
of pairing ``(k, j)`` is ``nu_kj = z_k - z_hat_j`` with covariance ``S_kj = Sigma_j + R_k`` and squared
Mahalanobis distance ``D2_kj = nu_kj^T S_kj^-1 nu_kj``, chi2-distributed with 2 dof when the pairing is
right.

* Individual compatibility: ``D2_kj < chi2_2^-1(gate_prob)``.
* Nearest neighbour (:func:`nearest_neighbour`): each observation joins its most likely compatible
  landmark, i.e. the smallest ``D2_kj + ln det S_kj`` (-2 log-likelihood up to a constant), resolved
  greedily over the scan so that no landmark takes two observations.
* Joint compatibility branch and bound (:func:`joint_compatibility`, Neira & Tardos 2001): the
  hypothesis ``H = {(k, j_k)}`` with the most pairings whose joint innovation passes
  ``D2_H = nu_H^T S_H^-1 nu_H < chi2_{2|H|}^-1(gate_prob)``, ties broken by the smaller ``D2_H``; ``S_H``
  includes the cross-covariances of the predicted observations through the robot and the map.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.lapack import dpotrf, dtrtrs
from scipy.special import chdtri


def chi2_gate(prob: float, dof: int | NDArray[np.int64]) -> float | NDArray[np.float64]:
    """The chi2 quantile ``x`` with ``P(chi2_dof <= x) = prob``."""
    return chdtri(dof, 1.0 - prob)


def gate_2d(prob: float) -> float:
    """``chi2_2^-1(prob)``, the gate of one 2-vector's ``D2``; infinite for ``prob = 1`` (no gate)."""
    return float(chi2_gate(prob, 2)) if prob < 1.0 else math.inf


def mahalanobis_2d(
    nu: NDArray[np.float64], S: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(D2 = nu^T S^-1 nu, ln det S)`` for stacks of 2-vectors ``nu`` (..., 2) and 2x2 ``S`` (..., 2, 2) of
    one shape.

    Closed-form 2x2 inverse, vectorised: ``S^-1 = [[S11, -S01], [-S10, S00]] / det S``.
    """
    d2, det = _d2_det(nu, S)
    return d2, np.log(det)


def mahalanobis_d2(nu: NDArray[np.float64], S: NDArray[np.float64]) -> NDArray[np.float64]:
    """``D2 = nu^T S^-1 nu`` of :func:`mahalanobis_2d` alone (the gates need no ``ln det S``)."""
    return _d2_det(nu, S)[0]


def _d2_det(
    nu: NDArray[np.float64], S: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(D2, det S)`` (...,) of :func:`mahalanobis_2d`."""
    stack = nu.shape[:-1]
    if len(stack) > 1:  # a stack of stacks (gating's (K, n)) flattened: every entry one strided run below
        d2, det = _d2_det(nu.reshape(-1, 2), S.reshape(-1, 2, 2))
        return d2.reshape(stack), det.reshape(stack)
    S00, S01, S10, S11 = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
    det = S00 * S11 - S01 * S10
    a, b = nu[..., 0], nu[..., 1]
    # D2 = (a^2 S11 - a b (S01 + S10) + b^2 S00) / det
    d2 = (a * a * S11 - a * b * (S01 + S10) + b * b * S00) / det
    return d2, det


def mahalanobis_lower_bound(
    nu: NDArray[np.float64], R: NDArray[np.float64], H: NDArray[np.float64], std: NDArray[np.float64]
) -> NDArray[np.float64]:
    """A lower bound (K, n) of ``D2_kj = nu_kj^T S_kj^-1 nu_kj``, ``S_kj = H_j P_j H_j^T + R_k``, that needs
    only the standard deviations ``sigma_j = sqrt(diag P_j)``, not the covariances of ``P_j``::

        (H_j P_j H_j^T)_ii <= (sum_l |H_j,il| sigma_j,l)^2     (|P_lm| <= sigma_l sigma_m)
        D2_kj >= nu_kj,i^2 / S_kj,ii   for i = 1, 2             (the marginal of one component)

    ``nu`` (K, n, 2), ``R`` (K, 2, 2), ``H`` (n, 2, d), ``std`` (n, d). O(K n d), for discarding the landmarks
    no observation can come near before their ``S`` is formed.
    """
    spread = np.einsum("nid,nd->ni", np.abs(H), std)
    # S_ii upper bound (K, n, 2)
    S_ii = (spread * spread)[None] + np.diagonal(R, axis1=1, axis2=2)[:, None, :]
    return (nu * nu / S_ii).max(axis=2)


def nearest_neighbour(cost: NDArray[np.float64], compatible: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Greedy most-likely assignment: (K,) landmark index per observation, -1 where none is left.

    ``cost`` (K, n) is ``D2 + ln det S``; pairs are taken in increasing cost among ``compatible`` (K, n)
    ones, each observation and each landmark at most once.
    """
    count, n = cost.shape
    match = [-1] * count
    # the compatible pairs by flat index k n + j, row by row
    pairs = compatible.ravel().nonzero()[0]
    order = cost.ravel()[pairs].argsort(kind="stable")
    taken: set[int] = set()
    most = min(count, n)  # pairs that can be taken
    # the pairs in increasing cost, as Python ints, until no observation or no landmark is left
    for pair in pairs[order].tolist():
        k, j = divmod(pair, n)
        if match[k] < 0 and j not in taken:
            match[k] = j
            taken.add(j)
            if len(taken) == most:
                break
    return np.array(match, dtype=np.int64)


def joint_compatibility(
    nu: NDArray[np.float64],
    compatible: NDArray[np.bool_],
    Sigma: NDArray[np.float64],
    R: NDArray[np.float64],
    gate_prob: float,
    max_nodes: int,
) -> NDArray[np.int64]:
    """JCBB over one scan: (K,) candidate index per observation, -1 for unpaired.

    ``nu`` (K, c, 2) innovations of every observation against every candidate landmark, ``compatible``
    (K, c) the individually compatible pairs (only these are tried), ``Sigma`` (2c, 2c) the joint
    covariance of the candidates' predicted observations, ``R`` (K, 2, 2). The search visits at most
    ``max_nodes`` pairings and returns the best hypothesis found.

    Each extension by a pair ``(k, j)`` grows the Cholesky factor of ``S_H`` by one block::

        S_H+ = [[S_H, B], [B^T, D]],  L_H+ = [[L_H, 0], [C^T, E]],  C = L_H^-1 B,  E E^T = D - C^T C
        w_H+ = [w_H, E^-1 (nu_kj - C^T w_H)],  D2_H+ = |w_H+|^2
    """
    n_obs, n_candidates = compatible.shape
    gates = chi2_gate(gate_prob, 2 * np.arange(1, n_obs + 1))
    # individual D2 of every pair, to try the most compatible candidate first
    rows = 2 * np.arange(n_candidates)[:, None] + np.arange(2)
    Sigma_j = Sigma[rows[:, :, None], rows[:, None, :]]
    d2, _ = mahalanobis_2d(nu, Sigma_j[None] + R[:, None])
    # only observations with candidates take part, those with fewer first: the tree narrows early
    counts = np.count_nonzero(compatible, axis=1)
    order = np.flatnonzero(counts)[np.argsort(counts[counts > 0], kind="stable")]
    candidates = []
    for k in order:
        pairable = np.flatnonzero(compatible[k])
        candidates.append(pairable[np.argsort(d2[k, pairable], kind="stable")])
    match = np.full(n_obs, -1, dtype=np.int64)
    if len(order) == 0:
        return match
    # the usual scan: one candidate per observation, all different; then the hypothesis pairing them all
    # is the only one with that many pairings, and it is the answer if it is jointly compatible
    only = [int(c[0]) for c in candidates if len(c) == 1]
    if len(only) == len(order) and len(set(only)) == len(only):
        if _joint_d2(nu, Sigma, R, order, only) < gates[len(order) - 1]:
            match[order] = only
            return match
    search = _JcbbSearch(nu, Sigma, R, gates, order, candidates, max_nodes)
    search.extend(0, [], [], np.zeros((0, 0)), np.zeros(0))
    for k, j in search.best_pairs:
        match[k] = j
    return match


def _joint_d2(
    nu: NDArray[np.float64],
    Sigma: NDArray[np.float64],
    R: NDArray[np.float64],
    observations: NDArray[np.int64],
    landmarks: list[int],
) -> float:
    """``D2_H = nu_H^T S_H^-1 nu_H`` of the hypothesis pairing ``observations[i]`` with ``landmarks[i]``."""
    size = len(landmarks)
    rows = (2 * np.asarray(landmarks)[:, None] + np.arange(2)).ravel()
    # S_H = Sigma[H, H] + blockdiag(R_k)
    S = Sigma[rows[:, None], rows[None, :]]
    diagonal = np.arange(size)
    S.reshape(size, 2, size, 2)[diagonal, :, diagonal, :] += R[observations]
    L, info = dpotrf(S, lower=1, clean=1, overwrite_a=1)
    if info != 0:
        return math.inf
    w = dtrtrs(L, nu[observations, landmarks].ravel(), lower=1)[0]
    return float(w @ w)


class _JcbbSearch:
    """Depth-first branch and bound state of :func:`joint_compatibility`."""

    def __init__(
        self,
        nu: NDArray[np.float64],
        Sigma: NDArray[np.float64],
        R: NDArray[np.float64],
        gates: NDArray[np.float64],
        order: NDArray[np.int64],
        candidates: list[NDArray[np.int64]],
        max_nodes: int,
    ) -> None:
        """Observations are visited in ``order``; ``candidates[depth]`` are those of ``order[depth]``."""
        self.nu, self.Sigma, self.R, self.gates = nu, Sigma, R, gates
        self.order, self.candidates = order, candidates
        self.nodes_left = max_nodes
        self.best_pairs: list[tuple[int, int]] = []
        self.best_d2 = math.inf

    def extend(
        self,
        depth: int,
        pairs: list[tuple[int, int]],
        used: list[int],
        L: NDArray[np.float64],
        w: NDArray[np.float64],
    ) -> None:
        """Extend hypothesis ``pairs`` (landmarks ``used``, Cholesky factor ``L`` of ``S_H``, whitened
        innovation ``w``) over the observations from ``depth`` on, keeping the best one found."""
        n_obs = len(self.order)
        d2 = float(w @ w)
        # bound: pairing every remaining observation cannot beat the best hypothesis (more pairings, or as
        # many with a smaller D2; D2 never decreases as pairs are added)
        most = len(pairs) + n_obs - depth
        best = len(self.best_pairs)
        if most < best or (most == best and d2 >= self.best_d2):
            return
        if depth == n_obs:
            self.best_pairs, self.best_d2 = list(pairs), d2
            return
        k = int(self.order[depth])
        for j in self.candidates[depth]:
            j = int(j)
            if j in used or self.nodes_left <= 0:
                continue
            self.nodes_left -= 1
            grown = self._grow(k, j, used, L, w)
            if grown is not None:
                self.extend(depth + 1, [*pairs, (k, j)], [*used, j], *grown)
        # the star branch: observation k unpaired
        self.extend(depth + 1, pairs, used, L, w)

    def _grow(
        self, k: int, j: int, used: list[int], L: NDArray[np.float64], w: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
        """``(L_H+, w_H+)`` for the hypothesis extended by ``(k, j)``, or None if not jointly compatible."""
        size = L.shape[0]
        rows = (2 * np.asarray(used, dtype=np.int64)[:, None] + np.arange(2)).ravel()
        cols = slice(2 * j, 2 * j + 2)
        # B = Cov(nu_H, nu_kj) = Sigma[H, j];  D = Sigma[j, j] + R_k
        B = self.Sigma[rows, cols]
        D = self.Sigma[cols, cols] + self.R[k]
        # C = L^-1 B  (forward substitution on the lower-triangular L)
        C = dtrtrs(L, B, lower=1)[0] if size else np.zeros((0, 2))
        # E E^T = D - C^T C (2x2 Cholesky in closed form)
        schur = D - C.T @ C
        e00 = schur[0, 0]
        if e00 <= 0.0:
            return None
        e00 = math.sqrt(e00)
        e10 = schur[1, 0] / e00
        e11_sq = schur[1, 1] - e10 * e10
        if e11_sq <= 0.0:
            return None
        e11 = math.sqrt(e11_sq)
        # w_new = E^-1 (nu_kj - C^T w)
        v = self.nu[k, j] - C.T @ w
        w0 = v[0] / e00
        w1 = (v[1] - e10 * w0) / e11
        d2 = float(w @ w) + w0 * w0 + w1 * w1
        if d2 >= self.gates[size // 2]:
            return None
        L_new = np.zeros((size + 2, size + 2))
        L_new[:size, :size] = L
        L_new[size:, :size] = C.T
        L_new[size:, size:] = [[e00, 0.0], [e10, e11]]
        return L_new, np.concatenate([w, [w0, w1]])
