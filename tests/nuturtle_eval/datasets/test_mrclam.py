"""The MRCLAM reader on the 60 s excerpt of Dataset 7, robot 1 (data/README.md), and on the full shared
copy when it is present. Expected numbers are read off the excerpt's text files by hand."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest

from nuturtle_eval.datasets.mrclam import MrclamRecording, load_mrclam

EXCERPT = Path(__file__).parent / "data" / "mrclam7_robot1_60s"
FULL = Path("/work/shared/datasets/utias_mrclam/MRCLAM_Dataset7")
HEADER_LINES = 4


@pytest.fixture(scope="module")
def recording() -> MrclamRecording:
    return load_mrclam(EXCERPT, 1)


@pytest.fixture
def copy(tmp_path: Path) -> Path:
    """A writable copy of the excerpt."""
    return Path(shutil.copytree(EXCERPT, tmp_path / "excerpt"))


def data_lines(path: Path) -> list[bytes]:
    return path.read_bytes().splitlines(keepends=True)[HEADER_LINES:]


def test_shapes_and_dtypes(recording):
    # data rows: 3,653 odometry, 88 measurements (40 landmark, 48 robot), 5,036 truth; 15 landmarks
    assert recording.robot == 1
    for name, size in [
        ("odometry_t_ns", 3653),
        ("odometry_v_mps", 3653),
        ("odometry_omega_rad_s", 3653),
        ("measurement_t_ns", 40),
        ("measurement_subject", 40),
        ("measurement_range_m", 40),
        ("measurement_bearing_rad", 40),
        ("truth_t_ns", 5036),
        ("landmark_subjects", 15),
    ]:
        value = getattr(recording, name)
        assert value.shape == (size,), name
        assert value.dtype == (np.int64 if name.endswith(("_ns", "subject", "subjects")) else np.float64), (
            name
        )
    assert recording.truth_poses.shape == (5036, 3) and recording.truth_poses.dtype == np.float64
    assert recording.landmark_xy.shape == (15, 2) and recording.landmark_xy.dtype == np.float64
    assert recording.dropped_measurements == 48


def test_times_are_sorted_whole_milliseconds_in_ns(recording):
    for t_ns in (recording.odometry_t_ns, recording.measurement_t_ns, recording.truth_t_ns):
        assert np.all(np.diff(t_ns) >= 0)
        assert np.all(t_ns % 1_000_000 == 0)
    assert np.all(np.diff(recording.truth_t_ns) > 0)
    # the excerpt spans 60 s of odometry; truth starts 6.207 s earlier and ends 61 s after
    assert recording.odometry_t_ns[-1] - recording.odometry_t_ns[0] == 59_992_000_000
    assert recording.odometry_t_ns[0] - recording.truth_t_ns[0] == 6_207_000_000


def test_first_rows_match_the_files(recording):
    # Robot1_Odometry.dat:    1248446188.323   0.086  -0.398
    assert recording.odometry_t_ns[0] == 1_248_446_188_323_000_000
    assert recording.odometry_v_mps[0] == 0.086 and recording.odometry_omega_rad_s[0] == -0.398
    # Robot1_Measurement.dat: 1248446189.249  61  1.682  0.032 ... 1248446189.708  90  1.613  0.045, then
    # 61 at the same time; Barcodes.dat maps barcode 61 to subject 14 and 90 to 15 (Dataset 7)
    assert recording.measurement_t_ns[0] == 1_248_446_189_249_000_000
    assert recording.measurement_range_m[0] == 1.682 and recording.measurement_bearing_rad[0] == 0.032
    assert recording.measurement_subject[:4].tolist() == [14, 14, 15, 14]
    assert recording.measurement_t_ns[2] == recording.measurement_t_ns[3] == 1_248_446_189_708_000_000
    # Robot1_Groundtruth.dat: 1248446182.116  2.21390910  4.22886590  -1.76340000
    assert recording.truth_t_ns[0] == 1_248_446_182_116_000_000
    assert recording.truth_poses[0].tolist() == [2.21390910, 4.22886590, -1.76340000]
    # Landmark_Groundtruth.dat: 6  0.58842660  -4.28209684 ... 20 in the last row
    assert recording.landmark_subjects.tolist() == list(range(6, 21))
    assert recording.landmark_xy[0].tolist() == [0.58842660, -4.28209684]


def test_the_excerpt_has_crlf_line_endings_and_reads(recording):
    for path in EXCERPT.glob("*.dat"):
        raw = path.read_bytes()
        assert raw.count(b"\r\n") == raw.count(b"\n") > HEADER_LINES, path.name
        assert b"\t" in raw and raw.startswith(b"# UTIAS"), path.name
    # every CRLF data line became one row
    assert recording.odometry_t_ns.size == len(data_lines(EXCERPT / "Robot1_Odometry.dat"))
    assert recording.truth_t_ns.size == len(data_lines(EXCERPT / "Robot1_Groundtruth.dat"))
    assert not np.isnan(recording.odometry_omega_rad_s).any() and not np.isnan(recording.truth_poses).any()


def test_the_recording_is_frozen(recording):
    with pytest.raises(dataclasses.FrozenInstanceError):
        recording.dropped_measurements = 0


def test_robot_barcodes_are_dropped(recording):
    # Barcodes 14, 23, 32, 41 are robots 2, 5, 4, 3: 2 + 26 + 6 + 14 of the 88 rows; the landmark
    # barcodes 81, 7, 70, 61, 90 are subjects 7, 8, 9, 14, 15
    assert set(recording.measurement_subject.tolist()) == {7, 8, 9, 14, 15}
    assert set(recording.measurement_subject.tolist()) <= set(recording.landmark_subjects.tolist())
    assert recording.dropped_measurements + recording.measurement_t_ns.size == 88


def test_a_barcode_missing_from_barcodes_dat_is_dropped_and_counted(copy, recording):
    path = copy / "Robot1_Measurement.dat"
    lines = path.read_bytes().splitlines(keepends=True)
    assert b"  99 " not in b"".join(lines)
    lines.insert(HEADER_LINES + 1, b"1248446189.300 \t  99 \t  2.000 \t  0.100 \r\n")
    path.write_bytes(b"".join(lines))
    loaded = load_mrclam(copy, 1)
    assert loaded.dropped_measurements == recording.dropped_measurements + 1
    np.testing.assert_array_equal(loaded.measurement_t_ns, recording.measurement_t_ns)
    np.testing.assert_array_equal(loaded.measurement_subject, recording.measurement_subject)


def test_a_file_out_of_order_is_sorted_stably(copy, recording):
    path = copy / "Robot1_Measurement.dat"
    lines = path.read_bytes().splitlines(keepends=True)
    # the first data row moves to the end; rows 3 and 4 (barcodes 90, 61) share a time and stay in order
    path.write_bytes(b"".join(lines[:HEADER_LINES] + lines[HEADER_LINES + 1 :] + [lines[HEADER_LINES]]))
    loaded = load_mrclam(copy, 1)
    np.testing.assert_array_equal(loaded.measurement_t_ns, recording.measurement_t_ns)
    np.testing.assert_array_equal(loaded.measurement_subject, recording.measurement_subject)
    np.testing.assert_array_equal(loaded.measurement_range_m, recording.measurement_range_m)


@pytest.mark.parametrize("robot", [0, 6, -1, 1.0, True, "1"])
def test_a_robot_outside_1_to_5_is_refused(robot):
    with pytest.raises(ValueError, match="robot must be one of 1..5"):
        load_mrclam(EXCERPT, robot)


def test_a_robot_without_files_is_refused():
    with pytest.raises(ValueError, match=r"Robot2_Odometry\.dat: no such file"):
        load_mrclam(EXCERPT, 2)


@pytest.mark.parametrize(
    "name", ["Barcodes.dat", "Landmark_Groundtruth.dat", "Robot1_Measurement.dat", "Robot1_Groundtruth.dat"]
)
def test_a_missing_file_is_named(copy, name):
    (copy / name).unlink()
    with pytest.raises(ValueError, match=rf"{name}: no such file"):
        load_mrclam(copy, 1)


def test_a_wrong_column_count_is_named(copy):
    path = copy / "Robot1_Odometry.dat"
    lines = path.read_bytes().splitlines(keepends=True)
    path.write_bytes(
        b"".join(line if line.startswith(b"#") else line.rstrip() + b" \t 0.0 \r\n" for line in lines)
    )
    with pytest.raises(ValueError, match=r"Robot1_Odometry\.dat: 4 columns, expected 3"):
        load_mrclam(copy, 1)


def test_a_ragged_row_is_named(copy):
    path = copy / "Robot1_Groundtruth.dat"
    lines = path.read_bytes().splitlines(keepends=True)
    lines[HEADER_LINES + 2] = b"1248446182.136 \t 2.21384980 \t 4.22894820 \r\n"
    path.write_bytes(b"".join(lines))
    with pytest.raises(ValueError, match=r"Robot1_Groundtruth\.dat: not a table of 4 numeric columns"):
        load_mrclam(copy, 1)


def test_a_file_without_data_rows_is_named(copy):
    path = copy / "Barcodes.dat"
    path.write_bytes(b"".join(path.read_bytes().splitlines(keepends=True)[:HEADER_LINES]))
    with pytest.raises(ValueError, match=r"Barcodes\.dat: no data rows"):
        load_mrclam(copy, 1)


def test_a_non_integer_barcode_is_named(copy):
    path = copy / "Robot1_Measurement.dat"
    lines = path.read_bytes().splitlines(keepends=True)
    lines[HEADER_LINES] = b"1248446189.249 \t  61.5 \t  1.682 \t  0.032 \r\n"
    path.write_bytes(b"".join(lines))
    with pytest.raises(ValueError, match=r"Robot1_Measurement\.dat: the barcode column holds a non-integer"):
        load_mrclam(copy, 1)


def test_a_barcode_listed_twice_is_named(copy):
    path = copy / "Barcodes.dat"
    path.write_bytes(path.read_bytes() + b"  21 \t  61 \r\n")
    with pytest.raises(ValueError, match=r"Barcodes\.dat: a barcode is listed twice"):
        load_mrclam(copy, 1)


def test_a_landmark_listed_twice_is_named(copy):
    path = copy / "Landmark_Groundtruth.dat"
    path.write_bytes(path.read_bytes() + data_lines(path)[0])
    with pytest.raises(ValueError, match=r"Landmark_Groundtruth\.dat: a landmark subject is listed twice"):
        load_mrclam(copy, 1)


def test_a_repeated_truth_time_is_named(copy):
    path = copy / "Robot1_Groundtruth.dat"
    path.write_bytes(path.read_bytes() + data_lines(path)[-1])
    with pytest.raises(ValueError, match=r"Robot1_Groundtruth\.dat: a time stamp is repeated"):
        load_mrclam(copy, 1)


def test_the_full_recording_when_present():
    if not FULL.is_dir():
        pytest.skip(f"{FULL} is absent (a clean clone has only the excerpt)")
    full = load_mrclam(FULL, 1)
    # the counts of the shared README: 58,598 odometry rows, 3,228 measurements = 2,578 landmark rows
    # (all 15 landmarks seen) + 650 robot rows, 58,389 truth rows
    assert full.odometry_t_ns.size == 58_598
    assert (full.measurement_t_ns.size, full.dropped_measurements) == (2_578, 650)
    assert np.unique(full.measurement_subject).tolist() == list(range(6, 21))
    assert full.truth_t_ns.size == 58_389
    assert full.odometry_t_ns[-1] == 1_248_447_082_113_000_000
    excerpt = load_mrclam(EXCERPT, 1)
    np.testing.assert_array_equal(full.odometry_t_ns[: excerpt.odometry_t_ns.size], excerpt.odometry_t_ns)
