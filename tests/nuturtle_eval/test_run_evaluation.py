"""nuturtle_eval.run_evaluation: the one evaluation a demo run and a replay share (figures, metrics.json,
the sensor range of a cylinder, the progress bar)."""

import json
import math

import numpy as np
import pytest

from nuturtle_eval.metrics import PoseSeries
from nuturtle_eval.run_evaluation import (
    ProgressBar,
    RunRecord,
    SlamSnapshot,
    evaluate_and_plot,
    sensor_range_m,
    write_metrics,
)
from turtlelib import arena_walls

CIRCLES = np.array([[1.2, 0.3, 0.038], [-1.0, 0.8, 0.05]])


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
    assert {path.name for path in tmp_path.iterdir()} == {"trajectory.png", "covariance.png", "errors.png"}
    write_metrics(tmp_path, metrics.as_dict())
    assert json.loads((tmp_path / "metrics.json").read_text()) == metrics.as_dict()


@pytest.mark.parametrize(
    ("record", "figures"),
    [
        (_record(truth=False), {"trajectory.png", "covariance.png"}),
        (_record(odom=False), {"trajectory.png", "covariance.png"}),
        (_record(slam_samples=0), {"covariance.png"}),
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
