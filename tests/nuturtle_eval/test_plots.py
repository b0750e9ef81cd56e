"""nuturtle_eval.plots: the ellipse geometry, and that each figure renders to a PNG."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from nuturtle_eval.metrics import PoseSeries
from nuturtle_eval.plots import ellipse_points, plot_covariance, plot_errors, plot_trajectory
from turtlelib import arena_walls

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@settings(max_examples=50)
@given(st.integers(0, 2**32 - 1), st.floats(0.5, 3.0))
def test_ellipse_points_lie_on_the_n_sigma_contour(seed, n_sigma):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(2, 2))
    C = A @ A.T + 1e-3 * np.eye(2)
    center = rng.normal(size=2)
    points = ellipse_points(center, C, n_sigma)
    d = points - center
    # (p - c)^T C^-1 (p - c) = n^2
    q = np.einsum("ki,ki->k", d, np.linalg.solve(C, d.T).T)
    np.testing.assert_allclose(q, n_sigma**2, rtol=1e-9)


def _series(t, phase):
    return PoseSeries(t, np.column_stack([np.cos(t + phase), np.sin(t + phase), t + phase]))


def test_figures_render(tmp_path):
    t = np.linspace(0.0, 6.0, 50)
    truth, odom, slam = _series(t, 0.0), _series(t, 0.05), _series(t, 0.01)
    circles = np.array([[1.2, 0.3, 0.038], [-1.0, 0.8, 0.038]])
    mapped = circles[:, :2] + 0.01
    covariances = np.array([np.diag([1e-4, 4e-4]), [[2e-4, 1e-4], [1e-4, 2e-4]]])
    plot_trajectory(
        tmp_path / "trajectory.png", truth, odom, slam, circles, mapped, covariances, arena_walls(5.0, 5.0)
    )
    errors = slam.poses - truth.poses
    plot_errors(tmp_path / "errors.png", t, errors, np.full((t.size, 3), 0.02))
    A = np.random.default_rng(0).normal(size=(7, 7))
    plot_covariance(tmp_path / "covariance.png", A @ A.T + np.eye(7))
    for name in ("trajectory.png", "errors.png", "covariance.png"):
        data = (tmp_path / name).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 10_000, name
