"""The monitor's storage: RowTable keeps its newest block in memory and the older rows in a temporary file,
and reads every row back in order; a stream replaces a sample whose stamp is not later than the last."""

import numpy as np
import pytest
from nav_msgs.msg import Odometry

from nuturtle_tools.monitor import POSE_COLUMNS, RowTable, _Stream


def table_with(n: int, width: int = 3, block_rows: int = 4, directory=None) -> tuple[RowTable, np.ndarray]:
    expected = np.arange(n * width, dtype=np.float64).reshape(n, width)
    table = RowTable(width, block_rows=block_rows, directory=directory)
    for row in expected:
        table.append(row)
    return table, expected


@pytest.mark.parametrize("n", [0, 1, 3, 4, 5, 8, 9, 23])
def test_every_row_reads_back_in_order_across_the_file_and_the_block(n, tmp_path):
    table, expected = table_with(n, directory=str(tmp_path))
    assert len(table) == n
    assert np.array_equal(table.rows(), expected)
    assert table.rows().shape == (n, 3)
    for start in range(-n - 2, n + 2):
        assert np.array_equal(table.rows(start), expected[start:] if start >= -n else expected), start
    table.close()
    assert len(table) == 0


def test_only_the_newest_block_stays_in_memory():
    table, expected = table_with(23, block_rows=4)
    assert table._in_block <= 4 and table._in_file == 20
    assert table._block.shape == (4, 3)
    table.append([1.0, 2.0, 3.0])  # a block boundary does not lose the newest row
    assert np.array_equal(table.last, [1.0, 2.0, 3.0])
    assert np.array_equal(table.rows()[:-1], expected)


def test_last_replaces_the_newest_row_in_place():
    table, expected = table_with(9)
    table.last[:] = [-1.0, -2.0, -3.0]
    expected[-1] = [-1.0, -2.0, -3.0]
    assert np.array_equal(table.rows(), expected)
    with pytest.raises(IndexError):
        _ = RowTable(2).last


def test_rows_are_copies():
    table, expected = table_with(5)
    table.rows()[:] = 0.0
    assert np.array_equal(table.rows(), expected)


@pytest.mark.parametrize("width, block_rows", [(0, 4), (3, 0)])
def test_invalid_sizes_are_refused(width, block_rows):
    with pytest.raises(ValueError):
        RowTable(width, block_rows=block_rows)


def odometry(t_s: float, x: float, y: float = 0.0, theta: float = 0.0, variances=None) -> Odometry:
    msg = Odometry()
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(t_s), round((t_s % 1.0) * 1e9)
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = np.sin(theta / 2), np.cos(theta / 2)
    if variances is not None:
        covariance = np.zeros((6, 6))
        covariance[0, 0], covariance[1, 1], covariance[5, 5] = variances
        msg.pose.covariance = covariance.reshape(36).tolist()
    return msg


def test_a_stream_replaces_a_sample_that_is_not_later_and_keeps_covariances():
    stream = _Stream(covariances=True)
    stream.add(odometry(0.0, 1.0), np.eye(3))
    stream.add(odometry(0.05, 2.0), 2.0 * np.eye(3))
    stream.add(odometry(0.05, 3.0), 3.0 * np.eye(3))  # same stamp: replaces
    stream.add(odometry(0.1, 4.0), 4.0 * np.eye(3))
    series = stream.series(None)
    assert np.allclose(series.t_s, [0.0, 0.05, 0.1])
    assert np.allclose(series.poses[:, 0], [1.0, 3.0, 4.0])
    assert np.allclose(stream.covariances(), np.array([1.0, 3.0, 4.0])[:, None, None] * np.eye(3))
    assert np.allclose(stream.series(2).t_s, [0.05, 0.1])
    assert stream.table.width == POSE_COLUMNS + 9
    with pytest.raises(ValueError):
        stream.series(0)


@pytest.mark.ros
def test_the_live_slam_error_is_against_the_truth_interpolated_at_the_slam_stamp_in_batches(ros):
    from std_msgs.msg import Float64MultiArray

    from nuturtle_tools.monitor import ERROR_LABELS, SLAM_TOPIC, TRUTH_TOPIC, RunMonitor

    monitor = ros.add(RunMonitor(context=ros.context))
    source = ros.node("monitor_source")
    truth = source.create_publisher(Odometry, TRUTH_TOPIC, 10)
    slam = source.create_publisher(Odometry, SLAM_TOPIC, 10)
    errors: list[Float64MultiArray] = []
    source.create_subscription(Float64MultiArray, "demo_monitor/slam_error", errors.append, 10)
    assert ros.spin_until(lambda: truth.get_subscription_count() and slam.get_subscription_count())
    assert ros.spin_until(lambda: monitor.count_subscribers("demo_monitor/slam_error") == 1)
    truth.publish(odometry(1.0, 0.0, 0.0, 0.0))
    # at t = 1.5 s, between truth samples (0, 0, 0) and (1, 2, 0.4): truth (0.5, 1, 0.2)
    slam.publish(odometry(1.5, 0.8, 1.4, 0.1, variances=(0.01, 0.04, 0.01)))
    # a second estimate of the same instant (after the update) replaces the first
    slam.publish(odometry(1.5, 0.8, 0.6, 0.3, variances=(0.01, 0.04, 0.01)))
    ros.spin_for(0.3)
    assert errors == []  # the truth has not passed 1.5 s yet
    truth.publish(odometry(2.0, 1.0, 2.0, 0.4))
    assert ros.spin_until(lambda: len(errors) == 1)
    position_m, heading_rad, nees_value = errors[0].data
    # e = (0.3, -0.4, 0.1): |e_xy| = 0.5, NEES = 0.09/0.01 + 0.16/0.04 + 0.01/0.01 = 14
    assert position_m == pytest.approx(0.5, abs=1e-9)
    assert heading_rad == pytest.approx(0.1, abs=1e-9)
    assert nees_value == pytest.approx(14.0, rel=1e-9)
    assert errors[0].layout.dim[0].label == ",".join(ERROR_LABELS)
    # in batches: a sample the truth has passed waits for the truth to enter the next ERROR_BATCH_S period
    slam.publish(odometry(2.1, 1.0, 2.0, 0.4, variances=(0.01, 0.04, 0.01)))
    ros.spin_for(0.2)
    truth.publish(odometry(2.2, 1.2, 2.0, 0.4))  # passes 2.1 s, still in the period [2.0, 2.5)
    ros.spin_for(0.3)
    assert len(errors) == 1
    truth.publish(odometry(2.5, 1.6, 2.0, 0.4))
    assert ros.spin_until(lambda: len(errors) == 2)
    # truth at 2.1 s: (1.1, 2.0, 0.4), so e = (-0.1, 0, 0)
    assert errors[1].data[0] == pytest.approx(0.1, abs=1e-9)
    assert errors[1].data[1] == pytest.approx(0.0, abs=1e-9)
    ros.spin_for(0.2)
    assert len(errors) == 2
