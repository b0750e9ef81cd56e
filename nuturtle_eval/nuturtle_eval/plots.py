"""The demo's figures (PNG): trajectories and map, SLAM pose error against its 2-sigma bounds, the final
covariance matrix.

matplotlib is imported lazily, inside each function, and only its object-oriented API is used
(``matplotlib.figure.Figure`` renders with the Agg canvas): no pyplot state, no display needed. Each
``plot_*`` returns the figure it saved. Legends go below the axes (:func:`legend_below`), never over the
data.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from turtlelib.mapping.grid_map_file import (
    FREE_PIXEL,
    FREE_THRESH,
    OCCUPIED_PIXEL,
    OCCUPIED_THRESH,
    UNKNOWN_PIXEL,
)
from turtlelib.mapping.occupancy_grid import GridMap

from .metrics import PoseSeries, pose_errors

TRUTH_COLOR = "tab:red"
ODOM_COLOR = "tab:blue"
SLAM_COLOR = "tab:green"
LOOP_COLOR = "tab:purple"
LANDMARK_SIGMAS = 2.0
DPI = 130


def new_figure(width_in: float, height_in: float) -> Any:
    from matplotlib.figure import Figure

    return Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")


def legend_below(figure: Any, axes: Any, max_columns: int = 3, keys: Sequence[Any] = ()) -> None:
    """The legend of the ``keys`` (labelled artists drawn nowhere: :func:`grid_key`) and of ``axes``'
    labelled artists, below all of ``figure``'s axes (the constrained layout makes room for it), so it
    covers no data; nothing when there is no label."""
    handles, labels = axes.get_legend_handles_labels()
    handles, labels = [*keys, *handles], [*(key.get_label() for key in keys), *labels]
    if handles:
        figure.legend(handles, labels, loc="outside lower center", ncols=min(max_columns, len(handles)),
                      fontsize="small")  # fmt: skip


def ellipse_points(
    center: NDArray[np.float64], covariance: NDArray[np.float64], n_sigma: float, samples: int = 64
) -> NDArray[np.float64]:
    """Points (samples, 2) of the ellipse ``(p - c)^T C^-1 (p - c) = n_sigma^2`` of a 2x2 covariance.

    ``C = V diag(lambda) V^T`` gives ``p = c + n_sigma V diag(sqrt(lambda)) [cos t, sin t]``.
    """
    eigenvalues, V = np.linalg.eigh(np.asarray(covariance, dtype=np.float64))
    t = np.linspace(0.0, 2.0 * math.pi, samples)
    unit = np.vstack([np.cos(t), np.sin(t)])
    # p = c + n V sqrt(Lambda) u
    return (
        np.asarray(center)[:, None] + n_sigma * V @ (np.sqrt(np.maximum(eigenvalues, 0.0))[:, None] * unit)
    ).T


def plot_trajectory(
    path: str | Path,
    truth: PoseSeries | None,
    odom: PoseSeries | None,
    slam: PoseSeries,
    true_circles: NDArray[np.float64],
    mapped_xy: NDArray[np.float64],
    mapped_covariances: NDArray[np.float64],
    walls: NDArray[np.float64] | None,
    loops: NDArray[np.float64] | None = None,
) -> Any:
    """trajectory.png: the arena walls, the true cylinders (rows ``[x, y, r]``), the ground truth (red),
    odometry (blue) and SLAM (green) paths in the world frame, the mapped landmarks (n, 2) with their
    2-sigma ellipses from ``mapped_covariances`` (n, 2, 2) and SLAM's loop closures (:func:`draw_loops`).
    Without ``truth`` or ``odom`` (None), true cylinders (no rows) or ``loops`` (None) those are left out.
    ``walls`` (K, 4) rows ``[x0, y0, x1, y1]`` are drawn and frame the axes; without them (None) the axes
    fit the data."""
    from matplotlib.patches import Circle

    figure = new_figure(7.0, 7.0)
    axes = figure.add_subplot()
    true_circles = np.asarray(true_circles, dtype=np.float64).reshape(-1, 3)
    mapped_xy = np.asarray(mapped_xy).reshape(-1, 2)
    if walls is not None:
        for x0, y0, x1, y1 in np.asarray(walls, dtype=np.float64).reshape(-1, 4):
            axes.plot([x0, x1], [y0, y1], color="black", linewidth=2.0)
    for x, y, r in true_circles:
        axes.add_patch(Circle((x, y), r, color="0.35", alpha=0.8))
    if true_circles.shape[0]:
        axes.plot([], [], "o", color="0.35", label="true cylinders")
    if truth is not None:
        axes.plot(*truth.xy.T, color=TRUTH_COLOR, linewidth=1.6, label="ground truth")
    if odom is not None:
        axes.plot(*odom.xy.T, color=ODOM_COLOR, linewidth=1.0, label="odometry")
    axes.plot(*slam.xy.T, color=SLAM_COLOR, linewidth=1.0, linestyle="--", label="SLAM")
    start = truth if truth is not None else slam
    if len(start):
        axes.plot(*start.xy[0], "k^", markersize=8, label="start")
    covariances = np.asarray(mapped_covariances).reshape(-1, 2, 2)
    for center, covariance in zip(mapped_xy, covariances, strict=True):
        axes.plot(*ellipse_points(center, covariance, LANDMARK_SIGMAS).T, color=SLAM_COLOR, linewidth=1.0)
    axes.plot(*mapped_xy.T, "+", color=SLAM_COLOR, markersize=9, label="mapped landmarks (2σ)")
    draw_loops(axes, loops)
    axes.set_aspect("equal")
    margin = 0.15
    if walls is not None:
        corners = np.asarray(walls, dtype=np.float64).reshape(-1, 2)
        low, high = corners.min(axis=0) - margin, corners.max(axis=0) + margin
        axes.set_xlim(low[0], high[0])
        axes.set_ylim(low[1], high[1])
    else:
        series = [s.xy for s in (truth, odom, slam) if s is not None]
        xy = np.vstack([*series, mapped_xy, true_circles[:, :2]])
        if xy.shape[0]:
            low, high = xy.min(axis=0) - margin, xy.max(axis=0) + margin
            axes.set_xlim(low[0], high[0])
            axes.set_ylim(low[1], high[1])
    axes.set_xlabel("x (m), nusim/world = map" if truth is not None else "x (m), map")
    axes.set_ylabel("y (m)")
    axes.set_title("Trajectories and map")
    axes.grid(True, alpha=0.3)
    legend_below(figure, axes)
    figure.savefig(path)
    return figure


def plot_grid(
    path: str | Path,
    grid: GridMap,
    path_xy: NDArray[np.float64],
    landmarks_xy: NDArray[np.float64],
    loops: NDArray[np.float64] | None = None,
) -> Any:
    """grid.png: the occupancy grid as map_saver's trinary image shows it (occupied >= 65 black, free <= 20
    white, the rest grey: :mod:`turtlelib.mapping.grid_map_file`; its key in the legend:
    :func:`grid_key`) with the SLAM path ``path_xy`` (K, 2), the mapped landmarks (n, 2) and the loop
    closures (:func:`draw_loops`) over it, in the map frame (m)."""
    figure = new_figure(7.0, 7.0)
    axes = figure.add_subplot()
    draw_grid(axes, grid)
    x0, y0, res = grid.origin.x, grid.origin.y, grid.resolution_m
    path_xy = np.asarray(path_xy, dtype=np.float64).reshape(-1, 2)
    landmarks_xy = np.asarray(landmarks_xy, dtype=np.float64).reshape(-1, 2)
    axes.plot(*path_xy.T, color=SLAM_COLOR, linewidth=1.0, label="SLAM path")
    axes.plot(*landmarks_xy.T, "+", color="tab:orange", markersize=9, mew=2, label="mapped landmarks")
    draw_loops(axes, loops)
    observed = np.argwhere(grid.occupancy >= 0)
    if observed.size:
        (row_low, col_low), (row_high, col_high) = observed.min(axis=0), observed.max(axis=0) + 1
        margin = 0.2
        axes.set_xlim(x0 + col_low * res - margin, x0 + col_high * res + margin)
        axes.set_ylim(y0 + row_low * res - margin, y0 + row_high * res + margin)
    axes.set_aspect("equal")
    axes.set_xlabel("x (m), map")
    axes.set_ylabel("y (m)")
    axes.set_title(f"Occupancy grid ({res:g} m cells)")
    legend_below(figure, axes, keys=grid_key())
    figure.savefig(path)
    return figure


def draw_loops(axes: Any, loops: NDArray[np.float64] | None) -> None:
    """SLAM's loop closures ``loops`` (L, 2, 2), each the positions of its two keyframes ``[[x_i, y_i],
    [x_j, y_j]]`` (m): a line between them and a circle at the newer, counted in the legend; nothing for
    None."""
    if loops is None:
        return
    loops = np.asarray(loops, dtype=np.float64).reshape(-1, 2, 2)
    for (x_i, y_i), (x_j, y_j) in loops:
        axes.plot([x_i, x_j], [y_i, y_j], color=LOOP_COLOR, linewidth=1.5)
    axes.plot(*loops[:, 1].T, "o", color=LOOP_COLOR, markersize=5, fillstyle="none",
              label=f"loop closures ({len(loops)})")  # fmt: skip


def grid_key() -> list[Any]:
    """The shades of :func:`draw_grid` as labelled patches for a legend (:func:`legend_below`): occupied,
    free and unknown cells with their thresholds (occupancy in per cent)."""
    from matplotlib.patches import Patch

    return [
        Patch(facecolor=str(pixel / 255.0), edgecolor="black", linewidth=0.5, label=label)
        for label, pixel in (
            (f"occupied (>= {round(100.0 * OCCUPIED_THRESH)} %)", OCCUPIED_PIXEL),
            (f"free (<= {round(100.0 * FREE_THRESH)} %)", FREE_PIXEL),
            ("unknown", UNKNOWN_PIXEL),
        )
    ]


def draw_grid(axes: Any, grid: GridMap) -> None:
    """``grid`` on matplotlib ``axes`` in the map frame (m), as map_saver's trinary image shows it
    (occupied >= 65 black, free <= 20 white, the rest grey: :mod:`turtlelib.mapping.grid_map_file`)."""
    occupancy = grid.occupancy
    shade = np.full(occupancy.shape, UNKNOWN_PIXEL, dtype=np.uint8)
    shade[(occupancy >= 0) & (occupancy <= round(100.0 * FREE_THRESH))] = FREE_PIXEL
    shade[occupancy >= round(100.0 * OCCUPIED_THRESH)] = OCCUPIED_PIXEL
    x0, y0, res = grid.origin.x, grid.origin.y, grid.resolution_m
    # one quad per cell (pcolormesh: imshow would resample the grid to the figure's pixels as floats,
    # 36 MB and twice the CPU for the demo's grid)
    x_edges = x0 + res * np.arange(grid.width + 1)
    y_edges = y0 + res * np.arange(grid.height + 1)
    axes.pcolormesh(x_edges, y_edges, shade, cmap="gray", vmin=0, vmax=255)


def plot_slam_errors(
    path: str | Path, slam: PoseSeries, slam_covariances: NDArray[np.float64], truth: PoseSeries
) -> Any:
    """errors.png of the SLAM poses (K,) with their covariances (K, 3, 3) against the ground truth, over the
    time the truth covers (:func:`plot_errors`), against the time since the run's start: the first stamp
    of either series, ``t - min(t_slam[0], t_truth[0])`` (a simulation's clock starts near 0, a
    recording's at its wall clock, ~1.7e9 s)."""
    covered = slam.within(truth.t_s[0], truth.t_s[-1])
    sigmas = np.sqrt(np.clip(np.diagonal(slam_covariances[covered], axis1=1, axis2=2), 0.0, None))
    start_s = min(slam.t_s[0], truth.t_s[0])
    return plot_errors(path, slam.t_s[covered] - start_s, pose_errors(slam, truth), sigmas)


def plot_errors(
    path: str | Path, t_s: NDArray[np.float64], errors: NDArray[np.float64], sigmas: NDArray[np.float64]
) -> Any:
    """errors.png: SLAM pose error ``e = [x, y, theta]`` (K, 3) over the time since the run's start ``t_s``
    (K,) (s) with its +-2 sigma bounds (``sigmas`` (K, 3), square roots of the covariance diagonal); the
    time axis starts at 0."""
    figure = new_figure(8.0, 7.0)
    labels = ("x error (m)", "y error (m)", "heading error (rad)")
    axes_list = figure.subplots(3, 1, sharex=True)
    for k, (axes, label) in enumerate(zip(axes_list, labels, strict=True)):
        axes.fill_between(t_s, -2 * sigmas[:, k], 2 * sigmas[:, k], color=SLAM_COLOR, alpha=0.2, label="±2σ")
        axes.plot(t_s, errors[:, k], color=SLAM_COLOR, linewidth=1.0, label="SLAM error")
        axes.axhline(0.0, color="black", linewidth=0.5)
        axes.set_ylabel(label)
        axes.grid(True, alpha=0.3)
    axes_list[0].set_title("SLAM pose error against its ±2σ bounds")
    axes_list[-1].set_xlabel("time since the run's start (s)")
    axes_list[-1].set_xlim(left=0.0)
    legend_below(figure, axes_list[0])
    figure.savefig(path)
    return figure


def plot_covariance(path: str | Path, P: NDArray[np.float64]) -> Any:
    """covariance.png: the final (N, N) covariance of ``[x, y, theta, m_0x, m_0y, ...]``: log10 |P_ij|
    (left) and the correlation coefficients ``P_ij / sqrt(P_ii P_jj)`` (right), robot and landmark blocks
    outlined."""
    from matplotlib.colors import Normalize

    P = np.asarray(P, dtype=np.float64)
    n = P.shape[0]
    d = np.sqrt(np.clip(np.diag(P), 1e-300, None))
    correlation = P / np.outer(d, d)
    magnitude = np.log10(np.abs(P) + 1e-16)
    figure = new_figure(12.0, 5.6)
    left, right = figure.subplots(1, 2)
    image = left.imshow(magnitude, cmap="viridis", interpolation="nearest", vmin=max(magnitude.min(), -12.0))
    figure.colorbar(image, ax=left, label="log10 |P_ij|")
    image = right.imshow(correlation, cmap="RdBu_r", norm=Normalize(-1.0, 1.0), interpolation="nearest")
    figure.colorbar(image, ax=right, label="correlation")
    edges = [3 + 2 * k for k in range((n - 3) // 2 + 1)]
    ticks = [1.0] + [3.5 + 2 * k for k in range((n - 3) // 2)]
    names = ["robot"] + [f"m{k}" for k in range((n - 3) // 2)]
    for axes, title in ((left, "final covariance, log10 |P|"), (right, "final correlation")):
        for edge in edges:
            axes.axhline(edge - 0.5, color="white", linewidth=0.6)
            axes.axvline(edge - 0.5, color="white", linewidth=0.6)
        axes.set_xticks(ticks, names, rotation=90, fontsize="small")
        axes.set_yticks(ticks, names, fontsize="small")
        axes.set_title(title)
    figure.savefig(path)
    return figure
