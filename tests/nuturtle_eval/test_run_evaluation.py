"""nuturtle_eval.run_evaluation: the one evaluation a demo run and a replay share (figures, metrics.json,
the sensor range of a cylinder, the progress bar)."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from nuturtle_eval.metrics import PoseSeries, RunMetrics
from nuturtle_eval.run_evaluation import (
    ProgressBar,
    RunRecord,
    SlamSnapshot,
    evaluate_and_plot,
    failed_targets,
    results_table,
    sensor_range_m,
    write_metrics,
)
from turtlelib import arena_walls

CIRCLES = np.array([[1.2, 0.3, 0.038], [-1.0, 0.8, 0.05]])
# a run meeting every target of the results table
FIGURES = dict(
    final_position_error_odom_m=0.3, final_position_error_slam_m=0.01, final_heading_error_odom_rad=0.1,
    final_heading_error_slam_rad=0.01, ate_rmse_odom_m=0.2, ate_rmse_slam_m=0.01, ate_rmse_aligned_odom_m=0.1,
    ate_rmse_aligned_slam_m=0.01, rpe_translation_odom_m=0.05, rpe_rotation_odom_deg=2.0,
    rpe_translation_slam_m=0.02, rpe_rotation_slam_deg=0.5, rpe_pairs=400, landmarks_true=8,
    landmarks_in_range=8, landmarks_mapped=8, landmarks_paired=8, landmarks_in_range_unmapped=0,
    landmarks_duplicate=0, landmarks_spurious=0, landmark_rmse_m=0.01, nees_pose_mean=3.0,
    nees_pose_median=2.4, nees_pose_within_95_fraction=0.95, nees_pose_band_95=(1.0, 8.0), sim_seconds=120.0,
    wall_seconds=20.0,
)  # fmt: skip


def _series(t, phase):
    return PoseSeries(t, np.column_stack([np.cos(t + phase), np.sin(t + phase), t + phase]))


def _record(truth=True, odom=True, slam_samples=50):
    t = np.linspace(0.0, 6.0, 50)
    slam = _series(t[:slam_samples], 0.01)
    snapshot = SlamSnapshot(
        covariance=np.eye(7) * 1e-3,
        landmarks_xy=CIRCLES[:, :2] + 0.01,
        landmark_covariances=np.array([np.eye(2) * 1e-4] * 2),
    )
    return RunRecord(
        truth=_series(t, 0.0) if truth else None,
        odom=_series(t, 0.05) if odom else None,
        slam=slam,
        slam_covariances=np.array([np.eye(3) * 1e-3] * len(slam)),
        snapshot=snapshot,
        circles=CIRCLES,
        sensor_range_m=1.0,
        walls=arena_walls(5.0, 5.0),
    )


def test_with_truth_odometry_and_slam_every_figure_and_the_metrics(tmp_path):
    metrics = evaluate_and_plot(tmp_path, _record(), sim_seconds=6.0, wall_seconds=0.5)
    assert metrics is not None and metrics.landmarks_paired == 2 and metrics.sim_seconds == 6.0
    assert {path.name for path in tmp_path.iterdir()} == {
        "trajectory.png",
        "covariance.png",
        "errors.png",
        "estimate.tum",
        "odometry.tum",
        "reference.tum",
    }
    write_metrics(tmp_path, metrics.as_dict())
    assert json.loads((tmp_path / "metrics.json").read_text()) == metrics.as_dict()


def test_a_figure_that_could_not_be_measured_is_null_in_the_json_and_n_a_in_the_table(tmp_path):
    metrics = evaluate_and_plot(tmp_path, _record(), sim_seconds=6.0, wall_seconds=0.5)
    unmeasured = replace(metrics, nees_pose_mean=math.nan, nees_pose_within_95_fraction=math.nan)
    write_metrics(tmp_path, {**unmeasured.as_dict(), "nested": [math.inf, {"x": np.float64("nan")}]})
    # strict JSON: a bare NaN or Infinity would be refused
    written = json.loads(
        (tmp_path / "metrics.json").read_text(), parse_constant=lambda name: pytest.fail(f"bare {name}")
    )
    assert written["nees_pose_mean"] is None and written["nested"] == [None, {"x": None}]
    table = results_table(unmeasured)
    assert "| pose NEES inside the 95% band | n/a | >= 0.9 |  |" in table
    assert "pose NEES inside the 95% band" not in failed_targets(unmeasured)


def test_without_the_true_landmarks_the_map_is_counted_and_none_is_called_spurious(tmp_path):
    # a recording of another world: a truth of the poses, none of the landmarks
    metrics = evaluate_and_plot(tmp_path, replace(_record(), circles=None), sim_seconds=6.0, wall_seconds=0.5)
    assert metrics is not None and metrics.landmarks_mapped == 2 and metrics.landmarks_spurious is None
    assert (tmp_path / "trajectory.png").read_bytes().startswith(b"\x89PNG")
    for targets in (True, False):
        table = results_table(metrics, targets=targets)
        assert "| landmarks mapped (no true landmarks to judge them by) | 2 |" in table
        assert "| landmark RMSE (m) | n/a |" in table
        assert "spurious" not in table and "duplicates" not in table and "None" not in table
    assert "landmarks" not in " ".join(failed_targets(metrics))


def test_failed_targets_are_the_rows_the_table_marks_failed():
    metrics = RunMetrics(
        **{**FIGURES, "final_position_error_slam_m": 2.7, "final_position_error_odom_m": 0.3}
    )
    table = results_table(metrics)
    assert failed_targets(metrics) == ["final position error, SLAM (m)"]
    assert table.count("✗") == 1 and "| final position error, SLAM (m) | 2.7000 | <= 0.02 | ✗ |" in table
    assert failed_targets(replace(metrics, final_position_error_slam_m=0.01)) == []


@pytest.mark.parametrize(
    ("record", "figures"),
    [
        (_record(truth=False), {"trajectory.png", "covariance.png", "estimate.tum", "odometry.tum"}),
        (_record(odom=False), {"trajectory.png", "covariance.png", "estimate.tum", "reference.tum"}),
        (_record(slam_samples=0), {"covariance.png", "odometry.tum", "reference.tum"}),
    ],
)
def test_without_truth_odometry_or_slam_poses_no_metrics_and_fewer_figures(tmp_path, record, figures):
    assert evaluate_and_plot(tmp_path, record, sim_seconds=6.0, wall_seconds=0.5) is None
    assert {path.name for path in tmp_path.iterdir()} == figures


def test_sensor_range_known_is_the_fake_sensor_s_and_unknown_the_detection_range():
    radii = CIRCLES[:, 2]
    assert sensor_range_m("known", 1.5, 3.5, radii, 3, math.radians(1.0), 3.5) == 1.5
    unknown = sensor_range_m("unknown", 1.5, 3.5, radii, 3, math.radians(1.0), 3.5)
    np.testing.assert_allclose(unknown, 2.0 * radii / (3 * math.radians(1.0)))
    capped = sensor_range_m("unknown", 1.5, 1.0, radii, 3, math.radians(1.0), 3.5)
    np.testing.assert_allclose(capped, [1.0, 1.0])
    assert sensor_range_m("unknown", 1.5, 3.5, radii, 3, None, None) == 3.5
    assert sensor_range_m("unknown", 1.5, 3.5, np.zeros(0), 3, math.radians(1.0), 3.5) == 3.5


def test_the_progress_bar_shows_the_clock_up_to_its_total(capsys):
    with ProgressBar(2.0, "bag", enabled=True) as progress:
        for now_s in np.arange(0.0, 3.0, 0.1):
            progress.advance(float(now_s))
    shown = capsys.readouterr().err
    assert "2.0/2.0 bag s" in shown and "x real time" in shown and "2.5/2.0" not in shown
