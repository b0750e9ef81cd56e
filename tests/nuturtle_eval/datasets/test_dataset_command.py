"""The dataset command end to end on the excerpts (60 s of MRCLAM Dataset 7 robot 1, 30 s of Victoria
Park), its building blocks (scan grouping, parameter files, SE(2) alignment) and the calibration (commands
and noise) on synthetic data with known commands and noise."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from nuturtle_eval.datasets.__main__ import main
from nuturtle_eval.datasets.calibration import (
    Residuals,
    fit_commands,
    fit_motion_noise,
    fit_noise_correlation,
    fit_range_noise,
    measurement_residuals,
    motion_windows,
)
from nuturtle_eval.datasets.experiment import Scans
from nuturtle_eval.datasets.mrclam import MrclamRecording
from nuturtle_eval.datasets.setups import (
    MRCLAM_PARAMS,
    VICTORIA_PARAMS,
    CommandCalibration,
    load_params,
    mrclam_params,
)
from nuturtle_eval.metrics import align_se2
from turtlelib import Transform2D, TwistNoise, UnicycleMotion

DATA = Path(__file__).parent / "data"
REQUIRED_KEYS = {
    "ate_rmse_m",
    "ate_rmse_aligned_m",
    "landmark_rmse_m",
    "landmark_rmse_aligned_m",
    "landmarks_true",
    "landmarks_mapped",
    "landmarks_spurious",
    "landmarks_merged",
    "nees_pose_mean",
    "nees_pose_within_95_fraction",
    "cpu_seconds",
    "update_ms_median",
    "update_ms_p99",
}
FIGURES = ("trajectory.png", "errors.png", "nees.png")
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _outputs(out: Path) -> dict:
    for name in FIGURES:
        assert (out / name).read_bytes()[:8] == PNG_MAGIC, name
    metrics = json.loads((out / "metrics.json").read_text())
    assert REQUIRED_KEYS <= set(metrics)
    return metrics


@pytest.mark.parametrize("association", ["known", "unknown"])
def test_mrclam_excerpt_end_to_end(tmp_path, association, capsys):
    out = tmp_path / "run"
    argv = ["mrclam", "--data", str(DATA / "mrclam7_robot1_60s"), "--robot", "1"]
    assert main([*argv, "--association", association, "--out", str(out), "--no-progress"]) == 0
    metrics = _outputs(out)
    assert "ate_rmse_m" in capsys.readouterr().out
    # 60 s from the Vicon start: within a metre of the truth; known ids map only real landmarks
    assert metrics["landmarks_true"] == 15
    assert 1 <= metrics["landmarks_mapped"] <= 15
    if association == "known":
        assert (
            metrics["landmarks_spurious"] == 0
            and metrics["landmarks_mapped_once"] == metrics["landmarks_mapped"]
        )
    assert 0.0 < metrics["ate_rmse_aligned_m"] <= metrics["ate_rmse_m"] + 1e-12 < 1.0
    assert metrics["cpu_seconds"] > 0.0 and metrics["update_ms_p99"] >= metrics["update_ms_median"] > 0.0
    assert 0.0 <= metrics["nees_pose_within_95_fraction"] <= 1.0
    assert metrics["scans_applied"] > 0


@pytest.mark.parametrize("association", ["known", "unknown"])
def test_smooth_reports_the_smoother_beside_the_unchanged_filter(tmp_path, association, capsys):
    argv = [
        "mrclam",
        "--data",
        str(DATA / "mrclam7_robot1_60s"),
        "--robot",
        "1",
        "--association",
        association,
    ]
    assert main([*argv, "--out", str(tmp_path / "filter"), "--no-progress"]) == 0
    capsys.readouterr()
    assert main([*argv, "--out", str(tmp_path / "both"), "--no-progress", "--smooth"]) == 0
    assert "smoother" in capsys.readouterr().out
    alone, both = _outputs(tmp_path / "filter"), _outputs(tmp_path / "both")
    for name in ("smoothed.png", "smoothed_errors.png"):
        assert (tmp_path / "both" / name).read_bytes()[:8] == PNG_MAGIC
    smoothed = both.pop("smoothed")
    # the filter's figures are those of the run without --smooth (its CPU time aside)
    for metrics in (alone, both):
        metrics.pop("cpu_seconds"), metrics.pop("update_ms_median"), metrics.pop("update_ms_p99")
    assert both == alone
    assert REQUIRED_KEYS <= set(smoothed)
    # the smoother re-estimates the past: no pose covariance, an aligned track at least as good
    assert smoothed["nees_pose_mean"] is None and smoothed["cpu_seconds"] > 0.0
    assert smoothed["ate_rmse_aligned_m"] <= alone["ate_rmse_aligned_m"]
    assert smoothed["landmarks_true"] == 15 and smoothed["landmarks_mapped"] >= 1
    assert ("landmarks_merged_by_smoother" in smoothed) == (association == "unknown")


def test_victoria_excerpt_end_to_end(tmp_path):
    out = tmp_path / "run"
    assert main(["victoria", "--data", str(DATA / "victoria_30s"), "--out", str(out), "--no-progress"]) == 0
    metrics = _outputs(out)
    assert metrics["landmarks_true"] is None and metrics["landmark_rmse_m"] is None
    assert metrics["landmarks_mapped"] > 0
    # started from the GPS: within a few metres of it over the first 30 s
    assert metrics["ate_rmse_m"] < 5.0
    assert metrics["nees_dof"] == 2
    # the default (aligned) protocol adds no published figures
    assert "ate_rmse_published_m" not in metrics and "published_fixes" not in metrics


def test_victoria_published_protocol_end_to_end(tmp_path):
    out = tmp_path / "run"
    argv = ["victoria", "--data", str(DATA / "victoria_30s"), "--out", str(out), "--no-progress"]
    assert main([*argv, "--protocol", "published"]) == 0
    metrics = _outputs(out)
    # the published figures beside the usual ones: a subset of the estimates, within metres of the GPS
    assert 0 < metrics["published_fixes"] < metrics["scans_applied"]
    assert 0.0 < metrics["ate_rmse_published_m"] < 5.0
    assert metrics["published_pairing_s"] == 0.025
    assert "published" in metrics["run"]


def test_victoria_protocol_is_one_of_the_two(tmp_path, capsys):
    argv = ["victoria", "--data", str(DATA / "victoria_30s"), "--out", str(tmp_path / "run")]
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--protocol", "gps"])
    assert exit_info.value.code == 2
    assert "invalid choice: 'gps'" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_calibrate_writes_params_that_a_run_takes(tmp_path, capsys):
    """``calibrate`` on the excerpt (2 s windows: 60 s hold too few of the default 10 s) writes the
    commands, noise and measurement sections; ``mrclam --params`` runs with them and records them."""
    data = ["--data", str(DATA / "mrclam7_robot1_60s"), "--robot", "1", "--no-progress"]
    params = tmp_path / "params.yaml"
    assert main(["calibrate", *data, "--window", "2", "--out", str(params)]) == 0
    fitted = yaml.safe_load(params.read_text())
    assert set(fitted) == {"commands", "noise", "slam"}
    assert set(fitted["slam"]) == {
        "range_std",
        "range_std_per_m",
        "bearing_std",
        "noise_correlation",
        "noise_correlation_length",
    }
    # the camera's errors repeat from one viewpoint (docs/real_data.md): strongly correlated
    assert fitted["slam"]["noise_correlation"] > 0.5
    # the excerpt's robot, like every MRCLAM robot, acts on its commands about 0.2 s late
    assert 0.1 <= fitted["commands"]["delay_s"] <= 0.3
    out = tmp_path / "run"
    assert main(["mrclam", *data, "--params", str(params), "--out", str(out)]) == 0
    used = yaml.safe_load((out / "params.yaml").read_text())
    assert used["commands"] == fitted["commands"] and used["noise"] == fitted["noise"]
    assert used["slam"]["range_std_per_m"] == fitted["slam"]["range_std_per_m"]
    assert used["slam"]["noise_correlation_length"] == fitted["slam"]["noise_correlation_length"]
    # the default window needs more than 60 s of ground truth: a clear error
    assert main(["calibrate", *data]) == 2
    assert "too few" in capsys.readouterr().err


def test_a_missing_directory_or_a_bad_params_file_is_one_error_line_and_the_output_untouched(
    tmp_path, capsys
):
    out = tmp_path / "out"
    out.mkdir()
    (out / "metrics.json").write_text("previous")
    nowhere = tmp_path / "nowhere"
    common = ["--robot", "1", "--no-progress", "--out", str(out)]
    assert main(["mrclam", "--data", str(nowhere), *common]) == 2
    assert capsys.readouterr().err == f"error: {nowhere}: no such folder\n"
    (tmp_path / "bad.yaml").write_text("noise: [")
    assert (
        main(
            [
                "mrclam",
                "--data",
                str(DATA / "mrclam7_robot1_60s"),
                "--params",
                str(tmp_path / "bad.yaml"),
                *common,
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert (
        err.startswith(f"error: {tmp_path / 'bad.yaml'}: not a readable params file") and err.count("\n") == 1
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.yaml", "out"]
    assert (out / "metrics.json").read_text() == "previous"


def test_params_file_replaces_defaults(tmp_path):
    path = tmp_path / "params.yaml"
    path.write_text("noise:\n  forward_m2_per_m: 0.5\nslam:\n  range_std: 0.3\ncommands:\n  delay_s: 0.1\n")
    params = load_params(MRCLAM_PARAMS, path)
    assert params.noise.forward_m2_per_m == 0.5 and params.slam.range_std == 0.3
    assert params.commands.delay_s == 0.1
    assert params.commands.speed_scale == MRCLAM_PARAMS.commands.speed_scale
    assert params.noise.heading_rad2_per_rad == MRCLAM_PARAMS.noise.heading_rad2_per_rad
    path.write_text("slam:\n  range_sd: 0.3\n")
    with pytest.raises(ValueError, match="range_sd"):
        load_params(MRCLAM_PARAMS, path)
    path.write_text("slam:\n  range_std: -1\n")
    with pytest.raises(ValueError, match="range_std"):
        load_params(MRCLAM_PARAMS, path)
    # Victoria Park's inputs are measured, not commanded: no commands section to ignore
    path.write_text("commands:\n  delay_s: 0.1\n")
    with pytest.raises(ValueError, match="commands"):
        load_params(VICTORIA_PARAMS, path)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("delay_s", -0.1),
        ("delay_s", 2.5),
        ("speed_scale", 0.0),
        ("yaw_rate_scale", -1.0),
        ("yaw_rate_bias", math.nan),
    ],
)
def test_command_calibration_refuses_invalid_values(field, value):
    with pytest.raises(ValueError, match=field):
        CommandCalibration(**{field: value})


def test_mrclam_defaults_by_association():
    assert mrclam_params("known").slam.linearization == "invariant"
    assert mrclam_params("unknown").slam.linearization == "invariant"
    assert (mrclam_params("known").slam.matcher, mrclam_params("unknown").slam.matcher) == ("nn", "jcbb")
    # one robot calibration whatever the association
    assert mrclam_params("unknown").commands == mrclam_params("known").commands
    assert mrclam_params("unknown").noise == mrclam_params("known").noise
    with pytest.raises(ValueError, match="association"):
        mrclam_params("both")


def test_scans_group_rows_of_one_stamp():
    scans = Scans.from_rows(np.array([5, 5, 7, 9, 9, 9]), np.arange(12.0).reshape(6, 2), np.arange(6))
    np.testing.assert_array_equal(scans.t_ns, [5, 7, 9])
    z, ids = scans.scan(2)
    np.testing.assert_array_equal(ids, [3, 4, 5])
    np.testing.assert_array_equal(z[:, 0], [6.0, 8.0, 10.0])
    with pytest.raises(ValueError, match="non-decreasing"):
        Scans.from_rows(np.array([2, 1]), np.zeros((2, 2)))


def test_align_se2_hand_case():
    # the square rotated by 90 deg about the origin and shifted by (1, 2)
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    moved = np.column_stack([1.0 - square[:, 1], 2.0 + square[:, 0]])
    T = align_se2(square, moved)
    np.testing.assert_allclose(T.as_array(), [1.0, 2.0, math.pi / 2], atol=1e-12)
    with pytest.raises(ValueError):
        align_se2(square[:1], moved[:1])


@settings(max_examples=30, deadline=None)
@given(x=st.floats(-50, 50), y=st.floats(-50, 50), theta=st.floats(-3.1, 3.1), seed=st.integers(0, 2**16))
def test_align_se2_recovers_any_rigid_motion(x, y, theta, seed):
    points = np.random.default_rng(seed).uniform(-10.0, 10.0, (12, 2))
    T_true = Transform2D(x, y, theta)
    np.testing.assert_allclose(align_se2(points, T_true @ points).as_array(), T_true.as_array(), atol=1e-8)


def _synthetic_recording(noise: TwistNoise, seed: int, duration_s: float = 600.0) -> MrclamRecording:
    """A unicycle on varying commands at 50 Hz whose true motion has exactly ``noise``, and one landmark
    observed with known noise every second. Each 20 ms sample draws its increment from the model's own
    ``Q``: the noise integrated along the sample's arc, which splitting the sample into shorter steps
    leaves unchanged (tests/turtlelib/test_motion_models.py), so one draw per sample has the noise of a
    finely simulated one at a tenth of the cost."""
    rng = np.random.default_rng(seed)
    dt_ns = 20_000_000
    n = int(duration_s * 50)
    t = np.arange(n, dtype=np.int64) * dt_ns + 1_000_000_000_000
    v = 0.2 + 0.15 * np.sin(np.arange(n) / 300.0)
    omega = 0.5 * np.sin(np.arange(n) / 170.0)
    truth = np.zeros((n, 3))
    model = UnicycleMotion(noise)
    T = Transform2D()
    for k in range(n - 1):
        q, _, Q = model.step(T, (v[k], omega[k], dt_ns))
        T = Transform2D(*(q + np.linalg.cholesky(Q + 1e-18 * np.eye(3)) @ rng.normal(size=3)))
        truth[k + 1] = T.as_array()
    landmark = np.array([[1.0, 2.0]])
    rows = np.arange(0, n, 50)
    d = landmark - truth[rows, :2]
    z_range = np.hypot(d[:, 0], d[:, 1]) + rng.normal(0.0, 0.05, len(rows))
    z_bearing = np.arctan2(d[:, 1], d[:, 0]) - truth[rows, 2] + rng.normal(0.0, 0.02, len(rows))
    return MrclamRecording(
        robot=1,
        odometry_t_ns=t,
        odometry_v_mps=v,
        odometry_omega_rad_s=omega,
        measurement_t_ns=t[rows],
        measurement_subject=np.full(len(rows), 6, dtype=np.int64),
        measurement_range_m=z_range,
        measurement_bearing_rad=np.remainder(z_bearing + np.pi, 2 * np.pi) - np.pi,
        truth_t_ns=t,
        truth_poses=truth,
        landmark_subjects=np.array([6], dtype=np.int64),
        landmark_xy=landmark,
        dropped_measurements=0,
    )


def test_calibration_recovers_the_noise_of_synthetic_data():
    true_noise = TwistNoise(forward_m2_per_m=4e-3, lateral_m2_per_m=5e-4, heading_rad2_per_rad=2e-2)
    recording = _synthetic_recording(true_noise, seed=3)
    errors, bases = motion_windows(recording, window_s=2.0)
    fitted, _ = fit_motion_noise(errors, bases)
    # 300 windows: the dominant terms within 25 %, the absent ones small against them
    assert fitted.forward_m2_per_m == pytest.approx(4e-3, rel=0.25)
    assert fitted.heading_rad2_per_rad == pytest.approx(2e-2, rel=0.25)
    assert fitted.lateral_m2_per_m == pytest.approx(5e-4, rel=0.4)
    assert fitted.heading_rad2_per_s < 2e-3 and fitted.forward_m2_per_s < 4e-4
    _, _, range_m, nu = measurement_residuals(recording)
    # constant range noise: the range-proportional part is small against it
    range_std, range_std_per_m = fit_range_noise(range_m, nu[:, 0])
    assert range_std + range_std_per_m * np.mean(range_m) == pytest.approx(0.05, rel=0.15)
    assert range_std_per_m * np.mean(range_m) < 0.3 * range_std
    assert np.sqrt(np.mean(nu[:, 1] ** 2)) == pytest.approx(0.02, rel=0.15)
    # independent errors: no correlation to speak of
    correlation, _ = fit_noise_correlation(measurement_residuals(recording), range_std, range_std_per_m, 0.02)
    assert correlation < 0.1


@pytest.mark.parametrize(("c", "length"), [(0.9, 0.3), (0.6, 1.0), (0.95, 0.1)])
def test_fit_noise_correlation_recovers_viewpoint_correlated_errors(c, length):
    """Three landmarks, each seen 2000 times along a line with steps of 0 to 0.2 m (a third of them
    standing still), errors ``sqrt(c) AR(1) + sqrt(1 - c) white`` with ``rho = exp(-step / length)``: the
    fit recovers ``c`` and ``length``."""
    rng = np.random.default_rng(5)
    subjects, positions, errors = [], [], []
    for subject in (6, 7, 8):
        step = np.where(rng.random(2000) < 1 / 3, 0.0, rng.uniform(0.0, 0.2, 2000))
        rho = np.exp(-step / length)
        ar1 = np.empty((2000, 2))
        ar1[0] = rng.normal(size=2)
        for k in range(1, 2000):
            ar1[k] = rho[k] * ar1[k - 1] + math.sqrt(1.0 - rho[k] ** 2) * rng.normal(size=2)
        subjects.append(np.full(2000, subject))
        positions.append(np.column_stack([np.cumsum(step), np.zeros(2000)]))
        errors.append(math.sqrt(c) * ar1 + math.sqrt(1.0 - c) * rng.normal(size=(2000, 2)))
    range_m = np.full(6000, 2.0)
    # sigma_r = 0.02 + 0.01 r = 0.04 m, bearing 0.03 rad
    nu = np.concatenate(errors) * [0.04, 0.03]
    residuals = Residuals(np.concatenate(subjects), np.concatenate(positions), range_m, nu)
    fitted_c, fitted_length = fit_noise_correlation(residuals, 0.02, 0.01, 0.03)
    assert fitted_c == pytest.approx(c, abs=0.05)
    assert fitted_length == pytest.approx(length, rel=0.2)
    with pytest.raises(ValueError, match="seen twice"):
        fit_noise_correlation(
            Residuals(np.array([6, 7]), np.zeros((2, 2)), np.ones(2), np.zeros((2, 2))), 0.1, 0, 0.1
        )
    with pytest.raises(ValueError, match="seen twice"):
        fit_noise_correlation(
            Residuals(np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2))),
            0.1,
            0,
            0.1,
        )


@pytest.mark.parametrize(("range_std", "range_std_per_m"), [(0.02, 0.03), (0.1, 0.0), (0.005, 0.05)])
def test_fit_range_noise_recovers_noise_that_grows_with_the_range(range_std, range_std_per_m):
    rng = np.random.default_rng(11)
    range_m = rng.uniform(0.5, 8.0, 4000)
    nu = rng.normal(size=4000) * (range_std + range_std_per_m * range_m)
    fitted_std, fitted_per_m = fit_range_noise(range_m, nu)
    # 4000 samples: sigma at 1 m and at 6 m within 5 %
    for r in (1.0, 6.0):
        assert fitted_std + fitted_per_m * r == pytest.approx(range_std + range_std_per_m * r, rel=0.05)
    with pytest.raises(ValueError, match="too few"):
        fit_range_noise(range_m[:1], nu[:1])


def _commanded_recording(
    commands: CommandCalibration, seed: int, duration_s: float = 300.0
) -> MrclamRecording:
    """Commands at 50 Hz and the noise-free motion they make through ``commands``: the command stamped ``t``
    acts from ``t + delay_s`` (a whole number of samples here) at the scaled speed and yaw rate."""
    rng = np.random.default_rng(seed)
    dt_ns = 20_000_000
    n = int(duration_s * 50)
    t = np.arange(n, dtype=np.int64) * dt_ns + 1_000_000_000_000
    # piecewise-constant commands held 0.2-2 s, as a waypoint follower gives them
    v, omega = np.empty(n), np.empty(n)
    k = 0
    while k < n:
        hold = int(rng.integers(10, 100))
        v[k : k + hold], omega[k : k + hold] = rng.uniform(0.0, 0.3), rng.uniform(-0.6, 0.6)
        k += hold
    lag = round(commands.delay_s * 1e9 / dt_ns)
    model = UnicycleMotion(TwistNoise())
    truth = np.zeros((n, 3))
    T = Transform2D(0.5, -0.3, 0.2)
    truth[0] = T.as_array()
    for k in range(n - 1):
        # the motion over [t_k, t_k+1] is that of the command stamped lag samples earlier (none before)
        j = k - lag
        u = (0.0, 0.0) if j < 0 else (v[j], omega[j])
        actual = (commands.speed_scale * u[0], commands.yaw_rate_scale * u[1] + commands.yaw_rate_bias)
        T = Transform2D(*model.step(T, (*actual, dt_ns))[0])
        truth[k + 1] = T.as_array()
    return MrclamRecording(
        robot=1,
        odometry_t_ns=t,
        odometry_v_mps=v,
        odometry_omega_rad_s=omega,
        measurement_t_ns=t[:0],
        measurement_subject=np.zeros(0, dtype=np.int64),
        measurement_range_m=np.zeros(0),
        measurement_bearing_rad=np.zeros(0),
        truth_t_ns=t,
        truth_poses=truth,
        landmark_subjects=np.array([6], dtype=np.int64),
        landmark_xy=np.array([[1.0, 2.0]]),
        dropped_measurements=0,
    )


@pytest.mark.parametrize(
    "commands",
    [
        CommandCalibration(delay_s=0.2, speed_scale=0.9, yaw_rate_scale=0.94, yaw_rate_bias=-0.004),
        CommandCalibration(delay_s=0.0, speed_scale=1.1, yaw_rate_scale=1.05, yaw_rate_bias=0.002),
        CommandCalibration(),
    ],
)
def test_fit_commands_recovers_how_the_commands_move_the_robot(commands):
    fitted = fit_commands(_commanded_recording(commands, seed=5), window_s=2.0)
    assert fitted.delay_s == pytest.approx(commands.delay_s, abs=1e-9)
    assert fitted.speed_scale == pytest.approx(commands.speed_scale, rel=1e-3)
    assert fitted.yaw_rate_scale == pytest.approx(commands.yaw_rate_scale, rel=1e-3)
    assert fitted.yaw_rate_bias == pytest.approx(commands.yaw_rate_bias, abs=1e-4)


def test_applied_commands_dead_reckon_the_truth():
    commands = CommandCalibration(delay_s=0.2, speed_scale=0.9, yaw_rate_scale=0.94, yaw_rate_bias=-0.004)
    recording = _commanded_recording(commands, seed=7, duration_s=60.0)
    identity = CommandCalibration().apply(recording)
    for name in ("odometry_t_ns", "odometry_v_mps", "odometry_omega_rad_s"):
        np.testing.assert_array_equal(getattr(identity, name), getattr(recording, name))
    calibrated = commands.apply(recording)
    np.testing.assert_array_equal(calibrated.odometry_t_ns, recording.odometry_t_ns + 200_000_000)
    errors, _ = motion_windows(calibrated, window_s=2.0)
    raw_errors, _ = motion_windows(recording, window_s=2.0)
    # the calibrated commands explain the motion to rounding; the raw ones do not
    assert np.abs(errors).max() < 1e-9
    assert np.abs(raw_errors).max() > 1e-2
