"""The Victoria Park reader on the 30 s excerpt (data/README.md), the GPS outlier check on hand-made
tracks, and both on the full shared copy when it is present."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from nuturtle_eval.datasets.victoria import VictoriaRecording, gps_outliers, load_victoria

EXCERPT = Path(__file__).parent / "data" / "victoria_30s"
FULL = Path("/work/shared/datasets/victoria_park")
DETECTIONS = Path("detections_rfsslam") / "measurements.dat"


@pytest.fixture(scope="module")
def recording() -> VictoriaRecording:
    return load_victoria(EXCERPT)


@pytest.fixture
def copy(tmp_path: Path) -> Path:
    """A writable copy of the excerpt."""
    return Path(shutil.copytree(EXCERPT, tmp_path / "excerpt"))


def full_directory() -> Path:
    if not FULL.is_dir():
        pytest.skip(f"{FULL} is absent (a clean clone has only the excerpt)")
    return FULL


def test_the_excerpt_keeps_the_original_variables():
    for name, variables in [
        ("aa3_dr.mat", ("time", "speed", "steering")),
        ("aa3_gpsx.mat", ("timeGps", "Lo_m", "La_m")),
    ]:
        contents = scipy.io.loadmat(EXCERPT / name)
        for variable in variables:
            assert contents[variable].ndim == 2 and contents[variable].shape[1] == 1, (name, variable)
            assert contents[variable].dtype == (np.int32 if variable.startswith("time") else np.float64)


def test_shapes_and_dtypes(recording):
    # 1,162 odometry samples, 1,538 detections in 137 scans and 133 GPS fixes in the first 30 s
    for names, size in [
        (("odometry_t_ns", "speed_mps", "steering_rad"), 1162),
        (("detection_t_ns", "detection_range_m", "detection_bearing_rad", "detection_diameter_m"), 1538),
        (("gps_t_ns",), 133),
    ]:
        for name in names:
            value = getattr(recording, name)
            assert value.shape == (size,), name
            assert value.dtype == (np.int64 if name.endswith("_ns") else np.float64), name
    assert recording.gps_xy.shape == (133, 2) and recording.gps_xy.dtype == np.float64
    assert np.unique(recording.detection_t_ns).size == 137


def test_times_are_on_the_common_base(recording):
    # aa3_dr.mat time[0] = 21940 ms and timeGps[0] = 20967 ms: the first odometry sample at 0.973 s;
    # measurements.dat starts "0.852 20.46202 0.88575 0.35404"; the excerpt ends before 30 s
    assert recording.gps_t_ns[0] == 0
    assert recording.odometry_t_ns[0] == 973_000_000
    assert recording.detection_t_ns[0] == 852_000_000
    assert np.all(np.diff(recording.odometry_t_ns) == 25_000_000)
    assert np.all(np.diff(recording.gps_t_ns) > 0)
    assert np.all(np.diff(recording.detection_t_ns) >= 0)
    for t_ns in (recording.odometry_t_ns, recording.detection_t_ns, recording.gps_t_ns):
        assert np.all(t_ns % 1_000_000 == 0) and t_ns[-1] <= 30_000_000_000


def test_first_rows_match_the_files(recording):
    # inputs.dat (the same odometry on the same base, rounded): "0.973 0.000 -0.0035"
    assert recording.speed_mps[0] == 0.0
    assert recording.steering_rad[0] == pytest.approx(-0.0035, abs=5e-5)
    # acfr_ascii/GPS.txt "1.001 0.05 -0.08": the second fix 0.05 m north and 0.08 m west of the first
    assert recording.gps_t_ns[1] == 1_001_000_000
    np.testing.assert_allclose(recording.gps_xy[1] - recording.gps_xy[0], [-0.08, 0.05], atol=0.005)
    assert recording.gps_xy[0].tolist() == pytest.approx([-67.649, -41.714], abs=5e-4)
    assert recording.detection_range_m[0] == 20.46202 and recording.detection_diameter_m[0] == 0.35404
    assert recording.detection_bearing_rad[0] == pytest.approx(0.88575 - np.pi / 2, abs=1e-12)


def test_bearings_are_in_the_vehicle_frame(copy, recording):
    assert np.all(np.abs(recording.detection_bearing_rad) <= np.pi / 2)
    # laser frame: pi/2 straight ahead, 0 to the right, pi to the left
    (copy / DETECTIONS).write_text(
        "     1.000   10.00000    1.57080    0.30000\n"
        "     1.000   10.00000    0.00000    0.30000\n"
        "     1.000   10.00000    3.14159    0.30000\n"
    )
    bearings = load_victoria(copy).detection_bearing_rad
    np.testing.assert_allclose(bearings, [0.0, -np.pi / 2, np.pi / 2], atol=1e-5)


def test_the_full_recording_when_present():
    full = load_victoria(full_directory())
    assert full.odometry_t_ns.size == 61_945
    assert full.odometry_t_ns[0] == 973_000_000 and full.odometry_t_ns[-1] == 1_549_573_000_000
    assert full.detection_t_ns.size == 52_974 and np.unique(full.detection_t_ns).size == 7_230
    assert full.gps_t_ns.size == 4_466 and full.gps_t_ns[0] == 0
    excerpt = load_victoria(EXCERPT)
    np.testing.assert_array_equal(full.odometry_t_ns[: excerpt.odometry_t_ns.size], excerpt.odometry_t_ns)
    np.testing.assert_array_equal(full.gps_xy[: excerpt.gps_t_ns.size], excerpt.gps_xy)


def test_the_full_gps_has_one_outlier_region_near_1221_s():
    full = load_victoria(full_directory())
    flagged_t_s = full.gps_t_ns[gps_outliers(full.gps_t_ns, full.gps_xy)] * 1e-9
    # one fix, at 1223.284 s, about 140 m off the track (the README's isolated outlier)
    assert 1 <= flagged_t_s.size <= 3
    assert np.all((flagged_t_s > 1219.0) & (flagged_t_s < 1226.0)), flagged_t_s


@pytest.mark.parametrize(
    ("name", "match"),
    [("aa3_dr.mat", r"aa3_dr\.mat: no such file"), ("aa3_gpsx.mat", r"aa3_gpsx\.mat: no such file")],
)
def test_a_missing_mat_file_is_named(copy, name, match):
    (copy / name).unlink()
    with pytest.raises(ValueError, match=match):
        load_victoria(copy)


def test_a_missing_detection_file_is_named(copy):
    (copy / DETECTIONS).unlink()
    with pytest.raises(ValueError, match=r"measurements\.dat: no such file"):
        load_victoria(copy)


def test_a_wrong_column_count_is_named(copy):
    (copy / DETECTIONS).write_text("     0.852   20.46202    0.88575\n")
    with pytest.raises(ValueError, match=r"measurements\.dat: 3 columns, expected 4"):
        load_victoria(copy)


def test_a_file_that_is_not_a_mat_file_is_named(copy):
    (copy / "aa3_dr.mat").write_bytes(b"not a MAT-file\n")
    with pytest.raises(ValueError, match=r"aa3_dr\.mat: not a readable MAT-file"):
        load_victoria(copy)


def rewrite_dr(copy: Path, **changes: np.ndarray | None) -> None:
    """Re-save the excerpt's aa3_dr.mat with variables replaced (or removed, for None)."""
    contents = scipy.io.loadmat(copy / "aa3_dr.mat")
    variables = {name: contents[name] for name in ("time", "speed", "steering")} | changes
    scipy.io.savemat(copy / "aa3_dr.mat", {k: v for k, v in variables.items() if v is not None})


def test_a_missing_variable_is_named(copy):
    rewrite_dr(copy, steering=None)
    with pytest.raises(ValueError, match=r"aa3_dr\.mat: variable\(s\) \['steering'\] missing"):
        load_victoria(copy)


def test_unequal_lengths_are_named(copy):
    rewrite_dr(copy, speed=np.zeros((5, 1)))
    with pytest.raises(ValueError, match=r"aa3_dr\.mat: time, speed, steering have unequal lengths"):
        load_victoria(copy)


def test_a_wrong_shape_is_named(copy):
    rewrite_dr(copy, speed=np.zeros((1162, 2)))
    with pytest.raises(ValueError, match=r"aa3_dr\.mat: speed must have shape \(N, 1\)"):
        load_victoria(copy)


def test_a_non_integer_time_is_named(copy):
    rewrite_dr(copy, time=scipy.io.loadmat(copy / "aa3_dr.mat")["time"].astype(np.float64))
    with pytest.raises(ValueError, match=r"aa3_dr\.mat: time must hold integer milliseconds"):
        load_victoria(copy)


def test_times_out_of_order_are_named(copy):
    rewrite_dr(copy, time=scipy.io.loadmat(copy / "aa3_dr.mat")["time"][::-1])
    with pytest.raises(ValueError, match=r"aa3_dr\.mat: times must be increasing"):
        load_victoria(copy)
    lines = (EXCERPT / DETECTIONS).read_text().splitlines(keepends=True)
    (copy / DETECTIONS).write_text("".join(lines[::-1]))
    shutil.copy(EXCERPT / "aa3_dr.mat", copy / "aa3_dr.mat")
    with pytest.raises(ValueError, match=r"measurements\.dat: times must be non-decreasing"):
        load_victoria(copy)


def track(n: int = 50, step_s: float = 0.2, speed_mps: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """A straight GPS track heading north-east at a car's speed, fixes every ``step_s``."""
    t_ns = np.arange(n, dtype=np.int64) * round(step_s * 1e9)
    xy = np.outer(np.arange(n) * speed_mps * step_s, [np.cos(0.6), np.sin(0.6)])
    return t_ns, xy


def test_gps_outliers_flags_an_isolated_jump():
    t_ns, xy = track()
    xy[20] += [140.0, 0.0]
    assert np.flatnonzero(gps_outliers(t_ns, xy)).tolist() == [20]


def test_gps_outliers_keeps_a_consistent_track():
    t_ns, xy = track()
    assert not gps_outliers(t_ns, xy).any()
    # a car at 19 m/s, just under the limit
    t_ns, xy = track(speed_mps=19.0)
    assert not gps_outliers(t_ns, xy).any()


def test_gps_outliers_keeps_a_jump_after_a_gap_followed_by_a_consistent_track():
    t_ns, xy = track()
    # no fix for 10 s after fix 24, then the track resumes 300 m away (30 m/s across the gap)
    t_ns[25:] += 10_000_000_000
    xy[25:] += [0.0, 300.0]
    assert not gps_outliers(t_ns, xy).any()
    # the same jump without the gap is also one-sided: a step in the track, not an isolated fix
    t_ns, xy = track()
    xy[25:] += [0.0, 300.0]
    assert not gps_outliers(t_ns, xy).any()


def test_gps_outliers_leaves_two_adjacent_bad_fixes():
    t_ns, xy = track()
    xy[20:22] += [140.0, 0.0]
    assert not gps_outliers(t_ns, xy).any()


@pytest.mark.parametrize("end", [0, -1])
def test_gps_outliers_flags_an_end_fix_whose_neighbour_agrees_with_the_track(end):
    t_ns, xy = track()
    xy[end] += [140.0, 0.0]
    assert np.flatnonzero(gps_outliers(t_ns, xy)).tolist() == [end % t_ns.size]
    # an end fix next to an outlier is not blamed for the outlier's jump
    t_ns, xy = track()
    xy[1 if end == 0 else -2] += [140.0, 0.0]
    assert np.flatnonzero(gps_outliers(t_ns, xy)).tolist() == [1 if end == 0 else t_ns.size - 2]


@pytest.mark.parametrize("n", [0, 1, 2])
def test_gps_outliers_flags_nothing_with_fewer_than_three_fixes(n):
    t_ns, xy = track(n)
    if n == 2:
        xy[1] += [140.0, 0.0]
    flags = gps_outliers(t_ns, xy)
    assert flags.shape == (n,) and flags.dtype == np.bool_ and not flags.any()


def test_gps_outliers_uses_the_speed_limit():
    t_ns, xy = track(speed_mps=5.0)
    # 3 m sideways of a track with 1 m steps: sqrt(1 + 9) m in 0.2 s, 15.8 m/s to and from its neighbours
    xy[20] += 3.0 * np.array([-np.sin(0.6), np.cos(0.6)])
    assert not gps_outliers(t_ns, xy).any()
    assert np.flatnonzero(gps_outliers(t_ns, xy, max_speed_mps=10.0)).tolist() == [20]


@pytest.mark.parametrize(
    ("t_ns", "xy", "max_speed_mps", "match"),
    [
        (np.array([0, 2, 1]), np.zeros((3, 2)), 20.0, "gps_t_ns must be increasing"),
        (np.array([0, 1, 1]), np.zeros((3, 2)), 20.0, "gps_t_ns must be increasing"),
        (np.array([0.0, 1.0, 2.0]), np.zeros((3, 2)), 20.0, "gps_t_ns must be a 1-D integer array"),
        (np.array([0, 1, 2]), np.zeros((3, 3)), 20.0, r"gps_xy must have shape \(3, 2\)"),
        (np.array([0, 1, 2]), np.zeros((3, 2)), 0.0, "max_speed_mps must be positive"),
        (np.array([0, 1, 2]), np.zeros((3, 2)), float("nan"), "max_speed_mps must be positive"),
    ],
)
def test_gps_outliers_refuses_bad_input(t_ns, xy, max_speed_mps, match):
    with pytest.raises(ValueError, match=match):
        gps_outliers(t_ns, xy, max_speed_mps)
