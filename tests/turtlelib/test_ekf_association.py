"""turtlelib.estimation.matching: chi2 gates, batched 2x2 Mahalanobis distances, nearest neighbour and JCBB.

JCBB is checked against brute-force enumeration of every hypothesis on small random problems.
"""

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from turtlelib.estimation.matching import (
    chi2_gate,
    joint_compatibility,
    mahalanobis_2d,
    mahalanobis_lower_bound,
    nearest_neighbour,
)


@pytest.mark.parametrize("prob", [0.5, 0.95, 0.99, 0.9999])
@pytest.mark.parametrize("dof", [1, 2, 6, 20])
def test_chi2_gate_is_the_quantile(prob, dof):
    assert chi2_gate(prob, dof) == pytest.approx(chi2.ppf(prob, dof), rel=1e-10)


def test_chi2_gate_two_dof_closed_form():
    # chi2 with 2 dof: P(X <= x) = 1 - exp(-x/2)
    assert chi2_gate(0.99, 2) == pytest.approx(-2.0 * math.log(0.01), rel=1e-12)


def test_mahalanobis_hand_case_and_batch():
    S = np.array([[4.0, 0.0], [0.0, 1.0]])
    d2, log_det = mahalanobis_2d(np.array([2.0, 1.0]), S)
    assert d2 == pytest.approx(2.0)
    assert log_det == pytest.approx(math.log(4.0))
    rng = np.random.default_rng(0)
    A = rng.normal(size=(5, 3, 2, 2))
    S = A @ A.transpose(0, 1, 3, 2) + 0.1 * np.eye(2)
    nu = rng.normal(size=(5, 3, 2))
    d2, log_det = mahalanobis_2d(nu, S)
    expected = np.einsum("...i,...i->...", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    np.testing.assert_allclose(d2, expected, rtol=1e-12)
    np.testing.assert_allclose(log_det, np.linalg.slogdet(S)[1], rtol=1e-12)


def test_mahalanobis_lower_bound_hand_case():
    # P = diag(1, 4), H = I, R = 0: S = P, and an innovation along one axis gives D2 itself
    H = np.eye(2)[None]
    std = np.array([[1.0, 2.0]])
    R = np.zeros((2, 2, 2))
    nu = np.array([[[2.0, 0.0]], [[0.0, 2.0]]])
    np.testing.assert_allclose(mahalanobis_lower_bound(nu, R, H, std), [[4.0], [1.0]], rtol=1e-15)
    # H = [1, 1] in both rows, perfectly correlated worst case: (1 + 2)^2 + R_ii = 9 + 1
    bound = mahalanobis_lower_bound(np.array([[[3.0, 1.0]]]), np.eye(2)[None], np.ones((1, 2, 2)), std)
    np.testing.assert_allclose(bound, [[0.9]], rtol=1e-15)


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    correlation=st.floats(0.0, 1.0),
    d=st.integers(1, 6),
    n_obs=st.integers(1, 4),
    n_landmarks=st.integers(1, 5),
)
def test_mahalanobis_lower_bound_never_exceeds_d2(seed, correlation, d, n_obs, n_landmarks):
    rng = np.random.default_rng(seed)
    # P_j: a mix of a rank-one (perfectly correlated) and a random full-rank covariance, scales apart
    scale = 10.0 ** rng.uniform(-3, 2, size=(n_landmarks, d))
    u = rng.normal(size=(n_landmarks, d, 1))
    A = rng.normal(size=(n_landmarks, d, d))
    P = correlation * (u @ u.transpose(0, 2, 1)) + (1.0 - correlation) * (A @ A.transpose(0, 2, 1))
    P = scale[:, :, None] * P * scale[:, None, :] + 1e-12 * np.eye(d)
    H = rng.normal(size=(n_landmarks, 2, d)) * 10.0 ** rng.uniform(-2, 2, size=(n_landmarks, 2, 1))
    B = rng.normal(size=(n_obs, 2, 2))
    R = 0.01 * (B @ B.transpose(0, 2, 1)) + 1e-4 * np.eye(2)
    nu = rng.normal(size=(n_obs, n_landmarks, 2)) * 10.0 ** rng.uniform(-2, 2, size=(n_obs, n_landmarks, 1))
    std = np.sqrt(np.diagonal(P, axis1=1, axis2=2))
    d2, _ = mahalanobis_2d(nu, (H @ P @ H.transpose(0, 2, 1))[None] + R[:, None])
    assert np.all(mahalanobis_lower_bound(nu, R, H, std) <= d2 * (1.0 + 1e-9))


# --- nearest neighbour -------------------------------------------------------------------------------------


def test_nearest_neighbour_resolves_conflicts_by_cost():
    cost = np.array([[1.0, 2.0, 9.0], [0.5, 3.0, 9.0], [0.2, 9.0, 9.0]])
    compatible = np.array([[True, True, False], [True, True, False], [False, False, False]])
    # observation 1 takes landmark 0 (0.5 < 1.0); observation 0 falls back on landmark 1;
    # observation 2 is compatible with nothing
    np.testing.assert_array_equal(nearest_neighbour(cost, compatible), [1, 0, -1])


def test_nearest_neighbour_leaves_the_loser_unmatched_without_alternative():
    cost = np.array([[1.0], [0.5]])
    np.testing.assert_array_equal(nearest_neighbour(cost, np.ones((2, 1), dtype=bool)), [-1, 0])


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 5), st.integers(1, 5), st.integers(0, 2**32 - 1))
def test_nearest_neighbour_is_the_greedy_pass_over_every_compatible_pair(count, n, seed):
    # costs on a coarse grid (ties, resolved row by row) and a random compatibility, wide or tall
    rng = np.random.default_rng(seed)
    cost = rng.integers(0, 4, (count, n)).astype(float)
    compatible = rng.random((count, n)) < 0.6
    expected, taken = [-1] * count, set()
    for _, k, j in sorted((cost[k, j], k, j) for k, j in zip(*compatible.nonzero(), strict=True)):
        if expected[k] < 0 and j not in taken:
            expected[k] = j
            taken.add(j)
    np.testing.assert_array_equal(nearest_neighbour(cost, compatible), expected)


def test_nearest_neighbour_empty():
    assert nearest_neighbour(np.zeros((0, 4)), np.zeros((0, 4), dtype=bool)).shape == (0,)
    np.testing.assert_array_equal(nearest_neighbour(np.zeros((2, 0)), np.zeros((2, 0), dtype=bool)), [-1, -1])


# --- JCBB --------------------------------------------------------------------------------------------------


def individual(nu, Sigma, R):
    c = nu.shape[1]
    blocks = np.stack([Sigma[2 * j : 2 * j + 2, 2 * j : 2 * j + 2] for j in range(c)])
    d2, _ = mahalanobis_2d(nu, blocks[None] + R[:, None])
    return d2


def joint_d2(pairs, nu, Sigma, R):
    rows = np.concatenate([[2 * j, 2 * j + 1] for _, j in pairs])
    S = Sigma[np.ix_(rows, rows)].copy()
    for i, (k, _) in enumerate(pairs):
        S[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] += R[k]
    v = np.concatenate([nu[k, j] for k, j in pairs])
    return float(v @ np.linalg.solve(S, v))


def brute_force(nu, compatible, Sigma, R, prob):
    """Every hypothesis: (most pairings, smallest joint D2) among the jointly compatible ones."""
    n_obs = nu.shape[0]
    options = [[-1, *np.flatnonzero(compatible[k])] for k in range(n_obs)]
    best = (0, 0.0)
    for choice in itertools.product(*options):
        used = [j for j in choice if j >= 0]
        if len(set(used)) != len(used) or not used:
            continue
        pairs = [(k, j) for k, j in enumerate(choice) if j >= 0]
        d2 = joint_d2(pairs, nu, Sigma, R)
        if d2 >= chi2.ppf(prob, 2 * len(pairs)):
            continue
        if len(pairs) > best[0] or (len(pairs) == best[0] and d2 < best[1]):
            best = (len(pairs), d2)
    return best


@pytest.mark.parametrize("seed", range(25))
def test_jcbb_finds_the_brute_force_optimum(seed):
    rng = np.random.default_rng(seed)
    n_obs, n_cand = int(rng.integers(1, 5)), int(rng.integers(1, 5))
    # candidates close together with a strong common (robot) component, so gates overlap
    common = rng.normal(size=(2, 3)) * 0.3
    A = np.concatenate([common + rng.normal(size=(2, 3)) * 0.05 for _ in range(n_cand)])
    Sigma = A @ A.T + 0.01 * np.eye(2 * n_cand)
    z_hat = rng.normal(size=(n_cand, 2)) * 0.3
    z = rng.normal(size=(n_obs, 2)) * 0.3
    R = np.stack([np.diag(rng.uniform(0.005, 0.02, 2)) for _ in range(n_obs)])
    nu = z[:, None, :] - z_hat[None, :, :]
    prob = 0.99
    compatible = individual(nu, Sigma, R) < chi2.ppf(prob, 2)

    match = joint_compatibility(nu, compatible, Sigma, R, prob, max_nodes=100_000)
    pairs = [(k, int(j)) for k, j in enumerate(match) if j >= 0]
    assert len({j for _, j in pairs}) == len(pairs)
    assert all(compatible[k, j] for k, j in pairs)
    best_pairings, best_d2 = brute_force(nu, compatible, Sigma, R, prob)
    assert len(pairs) == best_pairings
    if pairs:
        assert joint_d2(pairs, nu, Sigma, R) == pytest.approx(best_d2, rel=1e-9)


def test_jcbb_explains_a_common_shift_that_fools_nearest_neighbour():
    # two landmarks 1 m apart in range; both observations are shifted by +0.6 m, as after a robot error
    # that the predicted-observation covariance knows is common to both (variance 0.25 m^2 in common)
    z_hat = np.array([[1.0, 0.0], [2.0, 0.0]])
    z = np.array([[1.6, 0.0], [2.6, 0.0]])
    common, own = 0.25, 0.002
    Sigma = np.array(
        [
            [common + own, 0.0, common, 0.0],
            [0.0, own, 0.0, 0.0],
            [common, 0.0, common + own, 0.0],
            [0.0, 0.0, 0.0, own],
        ]
    )
    R = np.tile(np.diag([1e-3, 1e-3]), (2, 1, 1))
    nu = z[:, None, :] - z_hat[None, :, :]
    d2 = individual(nu, Sigma, R)
    compatible = d2 < chi2.ppf(0.99, 2)
    # nearest neighbour pairs observation 0 with landmark 1 (0.4 m away) and loses observation 1
    blocks = np.stack([Sigma[:2, :2], Sigma[2:, 2:]])
    _, log_det = mahalanobis_2d(nu, blocks[None] + R[:, None])
    np.testing.assert_array_equal(nearest_neighbour(d2 + log_det, compatible), [1, -1])
    # the joint hypothesis sees one common shift
    np.testing.assert_array_equal(joint_compatibility(nu, compatible, Sigma, R, 0.99, 1000), [0, 1])


def test_jcbb_without_compatible_pairs_pairs_nothing():
    nu = np.ones((3, 2, 2))
    R = np.tile(np.eye(2), (3, 1, 1))
    match = joint_compatibility(nu, np.zeros((3, 2), dtype=bool), np.eye(4), R, 0.99, 10)
    np.testing.assert_array_equal(match, [-1, -1, -1])


def test_jcbb_node_budget_still_returns_a_valid_hypothesis():
    rng = np.random.default_rng(4)
    n = 6
    Sigma = 0.5 * np.ones((2 * n, 2 * n)) + 0.1 * np.eye(2 * n)
    R = np.tile(0.05 * np.eye(2), (n, 1, 1))
    nu = rng.normal(size=(n, n, 2)) * 0.1
    compatible = np.ones((n, n), dtype=bool)
    match = joint_compatibility(nu, compatible, Sigma, R, 0.99, max_nodes=3)
    pairs = [(k, int(j)) for k, j in enumerate(match) if j >= 0]
    assert 1 <= len(pairs) <= 3
    assert len({j for _, j in pairs}) == len(pairs)
    assert joint_d2(pairs, nu, Sigma, R) < chi2.ppf(0.99, 2 * len(pairs))


def test_jcbb_rejects_individually_compatible_pairings_that_disagree_jointly():
    # one candidate per observation, as in most scans; the predictions share a strong common (robot)
    # error, so shifts in opposite directions cannot both be right: only one pairing survives
    z_hat = np.array([[1.0, 0.0], [2.0, 0.0]])
    common, own = 0.04, 0.0005
    Sigma = np.array(
        [
            [common + own, 0.0, common, 0.0],
            [0.0, own, 0.0, 0.0],
            [common, 0.0, common + own, 0.0],
            [0.0, 0.0, 0.0, own],
        ]
    )
    R = np.tile(np.diag([1e-4, 1e-4]), (2, 1, 1))
    for shifts, expected_pairs in [((0.3, 0.3), 2), ((0.3, -0.3), 1)]:
        z = z_hat + np.array([[shifts[0], 0.0], [shifts[1], 0.0]])
        nu = z[:, None, :] - z_hat[None, :, :]
        compatible = individual(nu, Sigma, R) < chi2.ppf(0.99, 2)
        np.testing.assert_array_equal(compatible, np.eye(2, dtype=bool))
        match = joint_compatibility(nu, compatible, Sigma, R, 0.99, 1000)
        pairs = [(k, int(j)) for k, j in enumerate(match) if j >= 0]
        assert len(pairs) == expected_pairs
        assert all(k == j for k, j in pairs)
        assert brute_force(nu, compatible, Sigma, R, 0.99)[0] == expected_pairs
