"""nuturtle_eval.plots: the ellipse geometry, that each figure renders to a PNG with its legend below the
data, the grid's key and the errors' time axis."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nuturtle_eval.metrics import PoseSeries
from nuturtle_eval.plots import (
    ellipse_points,
    plot_covariance,
    plot_errors,
    plot_grid,
    plot_slam_errors,
    plot_trajectory,
)
from turtlelib import Transform2D, arena_walls
from turtlelib.mapping.grid_map_file import FREE_PIXEL, OCCUPIED_PIXEL, UNKNOWN_PIXEL
from turtlelib.mapping.occupancy_grid import GridMap

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


def _grid():
    """A 4 m x 4 m grid at 0.05 m, origin (-2, -2): free inside, walls on the border, unknown in a corner."""
    occupancy = np.zeros((80, 80), dtype=np.int8)
    occupancy[[0, -1], :] = occupancy[:, [0, -1]] = 100
    occupancy[:20, :20] = -1
    return GridMap(occupancy, 0.05, Transform2D(-2.0, -2.0, 0.0))


def _legend_clear_of(figure, axes, points_xy):
    """The figure's one legend lies outside ``axes`` and off every point (data coordinates), in display
    coordinates of the drawn figure."""
    figure.draw_without_rendering()
    (legend,) = figure.legends
    box = legend.get_window_extent()
    assert not box.overlaps(axes.get_window_extent())
    assert not any(box.contains(*point) for point in axes.transData.transform(points_xy))
    return legend


def test_figures_render_with_their_legend_clear_of_the_landmarks(tmp_path):
    t = np.linspace(0.0, 6.0, 50)
    truth, odom, slam = _series(t, 0.0), _series(t, 0.05), _series(t, 0.01)
    # a cylinder in each corner of the arena: where a legend inside the axes would sit
    corners = np.array([[2.3, 2.3], [-2.3, 2.3], [2.3, -2.3], [-2.3, -2.3]])
    circles = np.column_stack([np.vstack([corners, [[1.2, 0.3]]]), np.full(5, 0.038)])
    mapped = circles[:, :2] + 0.01
    covariances = np.array([np.diag([1e-4, 4e-4])] * 4 + [[[2e-4, 1e-4], [1e-4, 2e-4]]])
    figure = plot_trajectory(
        tmp_path / "trajectory.png", truth, odom, slam, circles, mapped, covariances, arena_walls(5.0, 5.0)
    )
    _legend_clear_of(figure, figure.axes[0], np.vstack([mapped, circles[:, :2]]))
    grid_landmarks = np.array([[1.9, 1.9], [-1.9, 1.9], [1.9, -1.9], [0.2, 0.3]])
    figure = plot_grid(tmp_path / "grid.png", _grid(), slam.xy, grid_landmarks)
    _legend_clear_of(figure, figure.axes[0], grid_landmarks)
    errors = slam.poses - truth.poses
    figure = plot_errors(tmp_path / "errors.png", t, errors, np.full((t.size, 3), 0.02))
    for axes in figure.axes:
        figure.draw_without_rendering()
        assert not figure.legends[0].get_window_extent().overlaps(axes.get_window_extent())
    A = np.random.default_rng(0).normal(size=(7, 7))
    plot_covariance(tmp_path / "covariance.png", A @ A.T + np.eye(7))
    for name in ("trajectory.png", "grid.png", "errors.png", "covariance.png"):
        data = (tmp_path / name).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 10_000, name


def test_the_grid_figure_keys_every_shade_and_what_is_drawn_over_it(tmp_path):
    loops = np.array([[[0.0, 0.0], [0.5, 0.5]]])
    figure = plot_grid(
        tmp_path / "grid.png", _grid(), np.array([[0.0, 0.0], [1.0, 0.5]]), [[0.2, 0.3]], loops
    )
    (legend,) = figure.legends
    entries = {
        text.get_text(): handle for text, handle in zip(legend.texts, legend.legend_handles, strict=True)
    }
    assert set(entries) == {
        "occupied (>= 65 %)", "free (<= 20 %)", "unknown",
        "SLAM path", "mapped landmarks", "loop closures (1)",
    }  # fmt: skip
    # each key's shade is the one the grid is drawn in (map_saver's pixel values on a grey scale)
    for label, pixel in (("occupied", OCCUPIED_PIXEL), ("free", FREE_PIXEL), ("unknown", UNKNOWN_PIXEL)):
        (key,) = [handle for text, handle in entries.items() if text.startswith(label)]
        np.testing.assert_allclose(key.get_facecolor()[:3], [pixel / 255.0] * 3, atol=1e-9)


def test_the_errors_are_plotted_against_the_time_since_the_run_s_start(tmp_path):
    # a recording's clock: stamps near 1.7e9 s; the truth starts 0.5 s before SLAM's first pose
    start_s = 1.7e9
    t = start_s + np.linspace(0.0, 6.0, 61)
    truth, slam = _series(t, 0.0), _series(t[5:], 0.01)
    figure = plot_slam_errors(tmp_path / "errors.png", slam, np.array([np.eye(3) * 1e-4] * len(slam)), truth)
    bottom = figure.axes[-1]
    assert bottom.get_xlabel() == "time since the run's start (s)"
    assert bottom.get_xlim()[0] == 0.0
    (error_line,) = [line for line in bottom.get_lines() if line.get_label() == "SLAM error"]
    np.testing.assert_allclose(error_line.get_xdata(), t[5:] - start_s, atol=1e-6)
    assert error_line.get_xdata()[0] == pytest.approx(0.5, abs=1e-6)
