"""The Victoria Park starts, from the GPS (``setups.gps_start``) and the published one
(``setups.published_start``), and the scan cut the first runs on (``Scans.until``), on hand-made scans and the
30 s excerpt (data/README.md)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from nuturtle_eval.datasets.experiment import Experiment, Scans, run_experiment
from nuturtle_eval.datasets.setups import (
    GPS_MIN_STD_M,
    PUBLISHED_THETA_STD_RAD,
    START_WINDOW_S,
    VICTORIA_PARAMS,
    gps_start,
    laser_points,
    published_start,
    victoria_experiment,
)
from nuturtle_eval.datasets.victoria import load_victoria
from turtlelib import Transform2D

EXCERPT = Path(__file__).parent / "data" / "victoria_30s"


@pytest.fixture(scope="module")
def recording():
    return load_victoria(EXCERPT)


def at_the_identity(run: Experiment) -> Experiment:
    """``run`` started exactly at the identity, as ``victoria_experiment`` gives it to ``gps_start``."""
    config = dataclasses.replace(run.config, initial_xy_std=0.0, initial_theta_std=0.0)
    return dataclasses.replace(run, T_map_body0=Transform2D(), config=config)


def test_until_keeps_the_scans_at_or_before_a_time():
    t_ns = np.array([10, 10, 20, 30, 30, 30], dtype=np.int64)
    z = np.arange(12.0).reshape(6, 2)
    scans = Scans.from_rows(t_ns, z, np.arange(6))
    for t, count, rows in [(9, 0, 0), (10, 1, 2), (25, 2, 3), (30, 3, 6), (99, 3, 6)]:
        cut = scans.until(t)
        assert len(cut) == count and len(cut.z) == rows and len(cut.ids) == rows
        for i in range(count):
            np.testing.assert_array_equal(cut.scan(i)[0], scans.scan(i)[0])
    assert scans.until(25).ids.tolist() == [0, 1, 2]
    assert Scans.from_rows(t_ns, z).until(25).ids is None


def test_the_start_is_the_rigid_motion_from_the_filter_track_to_the_gps(recording):
    """GPS fixes that are exactly a rigid motion of the filter's laser track (filtered from the identity
    over the start window) give that motion back, with the residual at its floor."""
    run = victoria_experiment(recording, VICTORIA_PARAMS)
    from_identity = at_the_identity(run)
    end_ns = run.motion_t_ns[0] + round(START_WINDOW_S * 1e9)
    k_end = int(np.searchsorted(run.motion_t_ns, end_ns, side="right"))
    window = dataclasses.replace(
        from_identity,
        motion_t_ns=run.motion_t_ns[:k_end],
        motion_samples=run.motion_samples[:k_end],
        scans=run.scans.until(end_ns),
    )
    result = run_experiment(window)
    track, _ = laser_points(result.track)
    T_true = Transform2D(-70.0, 40.0, 2.5)
    # fixes only where the track is defined (from the start to the last scan of the window)
    fixes = (recording.gps_t_ns >= result.track_t_ns[0]) & (recording.gps_t_ns <= result.track_t_ns[-1])
    at_fixes = np.column_stack(
        [np.interp(recording.gps_t_ns[fixes], result.track_t_ns, track[:, i]) for i in range(2)]
    )
    synthetic = dataclasses.replace(recording, gps_t_ns=recording.gps_t_ns[fixes], gps_xy=T_true @ at_fixes)
    T_start, xy_std, theta_std = gps_start(from_identity, synthetic)
    np.testing.assert_allclose(T_start.as_array(), T_true.as_array(), atol=1e-9)
    assert xy_std == GPS_MIN_STD_M and theta_std < 1e-9
    # the experiment's own start is its GPS start, with the config's start sigmas from the residual
    T_real, xy_real, theta_real = gps_start(from_identity, recording)
    np.testing.assert_allclose(run.T_map_body0.as_array(), T_real.as_array())
    assert (run.config.initial_xy_std, run.config.initial_theta_std) == (xy_real, theta_real)


def test_too_few_fixes_in_the_start_window_is_a_clear_error(recording):
    run = at_the_identity(victoria_experiment(recording, VICTORIA_PARAMS))
    late = dataclasses.replace(recording, gps_t_ns=recording.gps_t_ns[:2], gps_xy=recording.gps_xy[:2])
    with pytest.raises(ValueError, match="fewer than 3 GPS fixes"):
        gps_start(run, late)


def test_the_published_start_moves_the_laser_pose_to_the_rear_axle_centre():
    """The published pose (-67.6493 m, -41.7142 m, 35.5 deg) is the laser's; by hand, with
    cos 35.5 deg = 0.814116 and sin 35.5 deg = 0.580703, the laser offset R(theta) [3.78, 0.50] is
    (3.78 cos - 0.50 sin, 3.78 sin + 0.50 cos) = (2.787005, 2.602115) m, so the rear-axle centre is at
    (-67.6493 - 2.787005, -41.7142 - 2.602115) = (-70.436305, -44.316315) m, with the same heading."""
    T_map_body0 = published_start()
    np.testing.assert_allclose(
        T_map_body0.as_array(), [-70.436305, -44.316315, math.radians(35.5)], rtol=0, atol=1e-6
    )
    # and the laser of that body pose is the published point again
    laser, _ = laser_points(T_map_body0.as_array()[None, :])
    np.testing.assert_allclose(laser[0], [-67.6493, -41.7142], rtol=0, atol=1e-12)


def test_the_published_protocol_starts_there_without_the_gps_window(recording):
    run = victoria_experiment(recording, VICTORIA_PARAMS, "published")
    np.testing.assert_array_equal(run.T_map_body0.as_array(), published_start().as_array())
    assert (run.config.initial_xy_std, run.config.initial_theta_std) == (
        GPS_MIN_STD_M,
        PUBLISHED_THETA_STD_RAD,
    )
    # the rest of the run is the aligned protocol's
    aligned = victoria_experiment(recording, VICTORIA_PARAMS, "aligned")
    np.testing.assert_array_equal(run.scans.t_ns, aligned.scans.t_ns)
    np.testing.assert_array_equal(run.motion_samples, aligned.motion_samples)
    with pytest.raises(ValueError, match="protocol"):
        victoria_experiment(recording, VICTORIA_PARAMS, "gps")
