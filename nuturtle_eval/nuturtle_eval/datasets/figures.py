"""The dataset run's figures (PNG): trajectory and map, error against +-2 sigma, NEES over time.

matplotlib is imported lazily through :mod:`nuturtle_eval.plots` (object-oriented API, Agg canvas); the
legends go below the axes (:func:`nuturtle_eval.plots.legend_below`), never over the data.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from turtlelib import Transform2D

from ..plots import LANDMARK_SIGMAS, SLAM_COLOR, TRUTH_COLOR, ellipse_points, legend_below, new_figure
from .evaluation import Evaluation


def plot_trajectory(path: str | Path, evaluation: Evaluation, title: str) -> None:
    """trajectory.png: the reference (Vicon or GPS), the estimate, the map with 2-sigma ellipses and the true
    landmarks (if known); left in the map frame, right after the rigid motion that best fits the estimate to
    the reference (the global frame is unobservable)."""
    figure = new_figure(14.0, 7.0)
    panels = figure.subplots(1, 2)
    for axes, T, label in zip(
        panels, (Transform2D(), evaluation.T_align), ("map frame", "after rigid alignment"), strict=True
    ):
        _draw_run(axes, evaluation, T)
        axes.set_title(f"{title}: {label}")
    legend_below(figure, panels[0], max_columns=4)
    figure.savefig(path)


def plot_side_by_side(path: str | Path, filtered: Evaluation, smoothed: Evaluation, title: str) -> None:
    """smoothed.png: the filter's run (left) and the smoothed run (right), each after its own rigid
    alignment to the reference, with their maps and 2-sigma ellipses."""
    figure = new_figure(14.0, 7.0)
    panels = figure.subplots(1, 2)
    for axes, evaluation, label in zip(panels, (filtered, smoothed), ("filter", "smoother"), strict=True):
        _draw_run(axes, evaluation, evaluation.T_align)
        ate = evaluation.metrics["ate_rmse_aligned_m"]
        axes.set_title(f"{title}: {label}, aligned (ATE {ate:.3f} m)")
    legend_below(figure, panels[0], max_columns=4)
    figure.savefig(path)


def plot_error_comparison(path: str | Path, filtered: Evaluation, smoothed: Evaluation) -> None:
    """smoothed_errors.png: the position error against the reference over time, filter and smoother, in
    the map frame (top) and after each one's rigid alignment (bottom)."""
    figure = new_figure(9.0, 5.5)
    top, bottom = figure.subplots(2, 1, sharex=True)
    for evaluation, label, color in ((filtered, "filter", SLAM_COLOR), (smoothed, "smoother", "black")):
        top.plot(evaluation.t_s, np.linalg.norm(evaluation.errors[:, :2], axis=1), color=color,
                 linewidth=0.7, label=label)  # fmt: skip
        bottom.plot(evaluation.t_s, evaluation.aligned_errors_m, color=color, linewidth=0.7, label=label)
    top.set_ylabel("position error (m)")
    bottom.set_ylabel("aligned error (m)")
    bottom.set_xlabel("time since start (s)")
    top.set_title(f"Position error against {filtered.reference_label}")
    for axes in (top, bottom):
        axes.grid(True, alpha=0.3)
    legend_below(figure, top)
    figure.savefig(path)


def _draw_run(axes, evaluation: Evaluation, T: Transform2D) -> None:
    """The reference, the estimate and the map moved by ``T`` on ``axes``, labelled for the legend."""
    style = "-" if evaluation.true_landmarks is not None else "."
    axes.plot(
        *evaluation.reference_track.T, style, color=TRUTH_COLOR, linewidth=1.0, markersize=1.5,
        label=evaluation.reference_label,
    )  # fmt: skip
    axes.plot(*(T @ evaluation.estimate_track).T, color=SLAM_COLOR, linewidth=0.8, label="SLAM estimate")
    R = T.rotation_matrix()
    landmarks = T @ evaluation.landmarks if len(evaluation.landmarks) else evaluation.landmarks
    for center, covariance in zip(landmarks, evaluation.landmark_covariances, strict=True):
        # C' = R C R^T
        ellipse = ellipse_points(center, R @ covariance @ R.T, LANDMARK_SIGMAS)
        axes.plot(*ellipse.T, color="tab:blue", linewidth=0.6)
    axes.plot(*landmarks.reshape(-1, 2).T, "+", color="tab:blue", markersize=6, label="map (2σ ellipses)")
    if evaluation.true_landmarks is not None:
        axes.plot(*evaluation.true_landmarks.T, "kx", markersize=7, label="true landmarks")
    axes.set_aspect("equal")
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    axes.grid(True, alpha=0.3)


def plot_errors(path: str | Path, evaluation: Evaluation) -> None:
    """errors.png: each error component over time with the filter's +-2 sigma."""
    labels = evaluation.error_labels
    figure = new_figure(9.0, 2.4 * len(labels))
    axes_list = np.atleast_1d(figure.subplots(len(labels), 1, sharex=True))
    t = evaluation.t_s
    for k, (axes, label) in enumerate(zip(axes_list, labels, strict=True)):
        sigma = evaluation.sigmas[:, k]
        axes.fill_between(t, -2 * sigma, 2 * sigma, color=SLAM_COLOR, alpha=0.25, label="±2σ (filter)")
        axes.plot(t, evaluation.errors[:, k], color="black", linewidth=0.6, label="error")
        axes.set_ylabel(label)
        axes.grid(True, alpha=0.3)
    axes_list[0].set_title(f"Error against {evaluation.reference_label} and the filter's ±2σ")
    axes_list[-1].set_xlabel("time since start (s)")
    legend_below(figure, axes_list[0])
    figure.savefig(path)


def plot_nees(path: str | Path, evaluation: Evaluation) -> None:
    """nees.png: the NEES of every sample (log scale), its running mean over 50 samples and the 95 %
    interval of one sample."""
    figure = new_figure(9.0, 4.0)
    axes = figure.add_subplot()
    nees = evaluation.nees
    t = evaluation.t_s
    low, high = evaluation.metrics["nees_band_95"]
    axes.semilogy(t, nees, ".", color="0.5", markersize=2, label="NEES")
    finite = np.isfinite(nees)
    if finite.sum() >= 50:
        running = np.convolve(nees[finite], np.ones(50) / 50, mode="same")
        axes.semilogy(t[finite], running, color=SLAM_COLOR, linewidth=1.2, label="running mean (50)")
    axes.axhline(
        evaluation.nees_dof, color="black", linewidth=1.0, label=f"ideal mean ({evaluation.nees_dof})"
    )
    axes.axhspan(low, high, color="tab:blue", alpha=0.12, label="95 % interval of one sample")
    axes.set_xlabel("time since start (s)")
    axes.set_ylabel(f"NEES ({evaluation.nees_dof} dof)")
    mean, inside = evaluation.metrics["nees_pose_mean"], evaluation.metrics["nees_pose_within_95_fraction"]
    axes.set_title(f"NEES: mean {mean:.2f}, {100 * inside:.0f} % inside the 95 % interval")
    axes.grid(True, alpha=0.3, which="both")
    legend_below(figure, axes, max_columns=2)
    figure.savefig(path)
