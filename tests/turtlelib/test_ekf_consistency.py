"""turtlelib.estimation.consistency: NEES, NIS and the chi2 bounds of their averages."""

import math

import numpy as np
import pytest
from scipy.stats import chi2

from turtlelib.estimation.consistency import chi2_bounds, nees, nis


def test_nees_hand_cases():
    assert nees([1.0, 2.0], np.diag([1.0, 4.0])) == pytest.approx(2.0)
    # correlated: P = [[2, 1], [1, 2]], P^-1 = [[2, -1], [-1, 2]] / 3, e = [1, 1] -> 2/3
    assert nees([1.0, 1.0], [[2.0, 1.0], [1.0, 2.0]]) == pytest.approx(2.0 / 3.0)
    assert nis([3.0], [[9.0]]) == pytest.approx(1.0)


def test_nees_is_batched():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(4, 3, 3))
    P = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(3)
    e = rng.normal(size=(4, 3))
    expected = [e[i] @ np.linalg.solve(P[i], e[i]) for i in range(4)]
    np.testing.assert_allclose(nees(e, P), expected, rtol=1e-12)


def test_nees_of_gaussian_errors_is_chi2():
    # errors drawn from N(0, P) give NEES with mean d and variance 2 d
    rng = np.random.default_rng(1)
    P = np.array([[2.0, 0.5, 0.1], [0.5, 1.0, -0.2], [0.1, -0.2, 0.5]])
    e = rng.multivariate_normal(np.zeros(3), P, 20_000)
    values = nees(e, np.broadcast_to(P, (20_000, 3, 3)))
    assert values.mean() == pytest.approx(3.0, abs=0.06)
    assert values.var() == pytest.approx(6.0, rel=0.06)


@pytest.mark.parametrize(
    "error, covariance",
    [
        ([1.0, 2.0], np.eye(3)),  # shapes disagree
        ([1.0, math.nan], np.eye(2)),
        ([1.0, 2.0], [[1.0, 0.0], [0.0, math.inf]]),
        ([1.0, 2.0], [[1.0, 0.5], [0.0, 1.0]]),  # not symmetric
        ([1.0, 2.0], [[1.0, 0.0], [0.0, -1.0]]),  # a negative variance
        ([1.0, 2.0], [[1.0, 2.0], [2.0, 1.0]]),  # indefinite
    ],
)
def test_nees_rejects_bad_input(error, covariance):
    with pytest.raises(ValueError):
        nees(error, covariance)


def test_a_singular_covariance_has_no_nees():
    # the exactly known start (P = 0) and a rank-deficient P are skipped as NaN, the others computed
    assert math.isnan(nees([0.0, 0.0, 0.0], np.zeros((3, 3))))
    assert math.isnan(nees([1.0, 2.0], [[1.0, 1.0], [1.0, 1.0]]))
    values = nees([[1.0, 0.0], [2.0, 0.0]], [np.zeros((2, 2)), np.eye(2)])
    assert math.isnan(values[0]) and values[1] == pytest.approx(4.0)


@pytest.mark.parametrize("dof, n_runs, prob", [(3, 50, 0.95), (2, 1, 0.95), (2, 100, 0.99), (6, 10, 0.9)])
def test_chi2_bounds_match_scipy(dof, n_runs, prob):
    low, high = chi2_bounds(dof, n_runs, prob)
    tail = (1.0 - prob) / 2.0
    assert low == pytest.approx(chi2.ppf(tail, dof * n_runs) / n_runs, rel=1e-9)
    assert high == pytest.approx(chi2.ppf(1.0 - tail, dof * n_runs) / n_runs, rel=1e-9)
    assert low < dof < high


def test_chi2_bounds_for_the_pose_over_50_runs():
    # the classic band of Bar-Shalom et al.: 3 dof, 50 runs, 95 % -> about [2.36, 3.72]
    low, high = chi2_bounds(3, 50)
    assert low == pytest.approx(2.36, abs=0.01)
    assert high == pytest.approx(3.72, abs=0.01)


@pytest.mark.parametrize(
    "dof, n_runs, prob",
    [(0, 10, 0.95), (3, 0, 0.95), (3, 10, 0.0), (3, 10, 1.0), (2.5, 10, 0.95), (True, 10, 0.95)],
)
def test_chi2_bounds_reject_bad_arguments(dof, n_runs, prob):
    with pytest.raises(ValueError):
        chi2_bounds(dof, n_runs, prob)


def test_an_absolute_floor_makes_tiny_variances_singular():
    P = np.diag([1e-11, 1.0])  # above the relative floor (1e-12 of the largest)
    assert nees([1e-6, 1.0], P) == pytest.approx(1.1)  # (1e-6)^2 / 1e-11 + 1
    assert math.isnan(nees([1e-6, 1.0], P, atol=1e-10))
