"""nuturtle_eval.run_evaluation: the one evaluation a demo run and a replay share (figures, metrics.json,
the sensor range of a cylinder, the progress bar)."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from nuturtle_eval.metrics import PoseSeries, RunMetrics
from nuturtle_eval.run_evaluation import (
    NotApplicable,
    ProgressBar,
    RunRecord,
    RunScope,
    SlamSnapshot,
    evaluate_and_plot,
    failed_targets,
    results_table,
    sensor_range_m,
    target_rows,
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


def _verdicts(metrics, scope):
    return {label: verdict for label, _, _, verdict in target_rows(metrics, scope)}


DRIFT = "final position error, odometry (m)"
LANDMARKS = "landmarks: true / came in range / mapped"


def test_a_turtlebot3_world_run_is_not_failed_on_the_demo_world_s_odometry_drift():
    # ROBOTIS' world as nusim models it: 1 % slip, nine cylinders, every one mapped; odometry barely drifts
    metrics = RunMetrics(**{
        **FIGURES, "final_position_error_odom_m": 0.0016, "landmarks_true": 9, "landmarks_in_range": 9,
        "landmarks_mapped": 9, "landmarks_paired": 9, "nees_pose_within_95_fraction": 0.928,
    })  # fmt: skip
    scope = RunScope(slip_fraction=0.01)
    verdicts = _verdicts(metrics, scope)
    assert verdicts[DRIFT] == NotApplicable("set for 30 % wheel slip, this world's is 1 %")
    assert verdicts[LANDMARKS] is True
    assert failed_targets(metrics, scope=scope) == []
    table = results_table(metrics, scope=scope)
    assert "✗" not in table
    assert f"| {DRIFT} | 0.0016 | >= 0.2 | n/a: set for 30 % wheel slip, this world's is 1 % |" in table
    # the targets that apply still fail honestly
    worse = replace(metrics, final_position_error_slam_m=0.05, nees_pose_within_95_fraction=0.5)
    assert failed_targets(worse, scope=scope) == [
        "final position error, SLAM (m)",
        "pose NEES inside the 95% band",
    ]


def test_a_localization_run_is_not_failed_on_mapping_targets():
    # the demo's world, localizing in the map of 8 a mapping run saved: 6 came in range, the map holds 8
    metrics = RunMetrics(**{
        **FIGURES, "final_position_error_odom_m": 0.26, "landmarks_in_range": 6,
        "landmarks_in_range_unmapped": 1, "landmarks_duplicate": 1,
    })  # fmt: skip
    scope = RunScope(mode="localization", grid_loaded=True, slip_fraction=0.3)
    verdicts = _verdicts(metrics, scope)
    assert verdicts[LANDMARKS] == NotApplicable("localization: the landmark map was loaded, not made")
    assert verdicts[DRIFT] is True
    assert failed_targets(metrics, scope=scope) == []
    # the same counts in a mapping run are a failure
    assert failed_targets(metrics, scope=RunScope(slip_fraction=0.3)) == [LANDMARKS]
    # localization's own targets apply
    lost = replace(metrics, final_position_error_slam_m=0.3, final_heading_error_slam_rad=0.1)
    assert failed_targets(lost, scope=scope) == [
        "final position error, SLAM (m)",
        "final heading error, SLAM (rad)",
    ]


@pytest.mark.parametrize(
    ("slip_fraction", "sim_seconds", "odometry_m", "verdict"),
    [
        # the demo's world over its two minutes: the target applies, met or failed
        (0.3, 120.0, 0.42, True),
        (0.3, 120.0, 0.1, False),
        (0.5, 120.0, 0.1, False),
        # a recording of it spans its run less a fraction of the last period; slip not known
        (None, 119.96, 0.1, False),
        # a shorter run
        (0.3, 40.0, 0.1, NotApplicable("set for a run of 120 s")),
        (None, 60.0, 0.1, NotApplicable("set for a run of 120 s")),
        (0.1, 120.0, 0.1, NotApplicable("set for 30 % wheel slip, this world's is 10 %")),
    ],
)
def test_the_odometry_drift_target_applies_to_the_demo_world_s_slip_over_its_run(
    slip_fraction, sim_seconds, odometry_m, verdict
):
    metrics = RunMetrics(**{**FIGURES, "sim_seconds": sim_seconds, "final_position_error_odom_m": odometry_m})
    assert _verdicts(metrics, RunScope(slip_fraction=slip_fraction))[DRIFT] == verdict


def test_a_world_without_cylinders_in_range_has_no_landmark_target_and_still_counts_spurious_ones():
    metrics = RunMetrics(**{
        **FIGURES, "landmarks_true": 0, "landmarks_in_range": 0, "landmarks_mapped": 1, "landmarks_paired": 0,
        "landmarks_spurious": 1,
    })  # fmt: skip
    assert _verdicts(metrics, RunScope())[LANDMARKS] == NotApplicable("no cylinder came in range")
    assert "| landmarks: in range but unmapped / duplicates / spurious | 0 / 0 / 1 |" in results_table(
        metrics
    )


@pytest.mark.parametrize(
    ("fields", "message"),
    [({"mode": "mapless"}, "mode must be one of"), ({"slip_fraction": 1.5}, "slip_fraction must be in")],
)
def test_a_bad_scope_is_refused(fields, message):
    with pytest.raises(ValueError, match=message):
        RunScope(**fields)


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
