"""A detection that never becomes a landmark never moves the pose.

Under unknown association a detection starts a tentative landmark; until it is confirmed, observations of it
refine that landmark alone (the pose and the other landmarks are considered, as the Schmidt update of
localization considers the map). So a recording without landmarks (only clutter the detector finds and
that never confirms) gives exactly the motion input: the chair legs of an office must not turn the robot.
"""

import dataclasses
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import (
    DiffDrive,
    OdometryMotion,
    OdometryPoses,
    SlamTimeline,
    Transform2D,
    TwistNoise,
    integrate_twist,
)
from turtlelib.estimation.ekf_slam import EkfSlam, ObservationStatus, SlamConfig
from turtlelib.estimation.range_bearing import predict_observations
from turtlelib.estimation.slip_recovery import SlipRecovery
from turtlelib.geometry.se2 import Twist2D

POSE_ATOL = 1e-9
NOISE = TwistNoise.from_wheel_slip(DiffDrive(0.033, 0.16), 0.05)
# tentative landmarks that never confirm (a sighting per scan, but far fewer scans than confirm_count)
CONFIG = SlamConfig(sensor_x=0.0, confirm_count=1000, tentative_timeout=5.0, max_range=8.0)
MS = 1_000_000
# clutter: chair legs in an office, none of them a mapped landmark
CLUTTER = np.array([[2.0, 0.5], [2.3, -0.8], [3.1, 0.2], [1.2, 1.4], [4.0, -1.5], [3.4, 1.9], [5.0, 0.0]])


def odometry_run(seed: int, steps: int = 120) -> list[tuple[int, Transform2D]]:
    """An odometry trail at 10 Hz along a wavy path (the robot's own dead reckoning)."""
    rng = np.random.default_rng(seed)
    T, trail = Transform2D(), []
    for k in range(steps):
        trail.append((k * 100 * MS, T))
        T = T @ integrate_twist(Twist2D(rng.uniform(-0.3, 0.3) * 0.1, 0.5 * 0.1, 0.0))
    return trail


def sample(T_odom_body: Transform2D) -> tuple[float, float, float]:
    return T_odom_body.x, T_odom_body.y, T_odom_body.theta


def noisy_detections(rng, T_map_body: Transform2D) -> np.ndarray:
    """The clutter in range, seen with range-bearing noise far larger than the filter's (wrong noise: the
    clutter's centres wander as the viewpoint changes)."""
    z, _, _ = predict_observations(T_map_body.as_array(), CLUTTER, CONFIG.T_body_sensor)
    z = z[(z[:, 0] > CONFIG.min_range) & (z[:, 0] < CONFIG.max_range)]
    return z + rng.normal(0.0, [0.08, 0.05], size=z.shape)


def test_a_recording_whose_detections_never_confirm_gives_the_odometry_exactly():
    for step in (None, SlipRecovery()):
        rng = np.random.default_rng(7)
        slam = EkfSlam(CONFIG, OdometryMotion(NOISE))
        timeline = SlamTimeline(slam, OdometryPoses(), step=step)
        trail = odometry_run(seed=3)
        matched = 0
        for k, (t_ns, T_odom_body) in enumerate(trail):
            timeline.add_motion(t_ns, sample(T_odom_body))
            if k % 3 == 1:  # a scan half-way from the sample before, at the odometry's pose there
                before = trail[k - 1][1]
                T_scan = Transform2D(*OdometryPoses().at(sample(before), sample(T_odom_body), 0.5))
                t_scan = t_ns - 50 * MS
                for result in timeline.add_observations(t_scan, noisy_detections(rng, T_scan)):
                    matched += result.association.counts["matched"]
        assert matched > 50  # the clutter was associated (tracks kept), scan after scan
        assert len(slam.landmark_ids) == 0
        T_slam, _ = timeline.latest_pose()
        T_odom = trail[-1][1]
        np.testing.assert_allclose(
            [T_slam.x, T_slam.y, T_slam.theta], [T_odom.x, T_odom.y, T_odom.theta], atol=POSE_ATOL, rtol=0
        )


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    linearization=st.sampled_from(["standard", "fej", "oc", "invariant"]),
)
def test_observations_of_tentative_landmarks_refine_them_and_leave_the_pose_and_the_map(seed, linearization):
    """A filter with two confirmed landmarks and two tentative ones: a scan of the tentative ones only
    changes nothing of the pose (mean and covariance, bit for bit) nor of the confirmed landmarks' means and
    covariance, and shrinks the tentative ones' covariance; a scan of both kinds moves the pose as the scan
    of the confirmed landmarks alone would (to rounding)."""
    rng = np.random.default_rng(seed)
    config = dataclasses.replace(CONFIG, confirm_count=2, linearization=linearization)
    confirmed_xy = np.array([[2.0, 1.0], [1.5, -1.2]])
    tentative_xy = np.array([[3.0, 0.2], [0.8, 1.9]])
    model = OdometryMotion(NOISE)

    def start() -> EkfSlam:
        slam = EkfSlam(dataclasses.replace(config, initial_xy_std=0.05, initial_theta_std=0.05), model)
        for scan in range(2):  # the first two seen twice, from two viewpoints 0.2 m apart: confirmed
            if scan:
                slam.predict((0.2, 0.0, 0.0, 100 * MS))
            z, _, _ = predict_observations(slam.pose.as_array(), confirmed_xy, config.T_body_sensor)
            slam.update_unknown(z, stamp_ns=scan * 100 * MS)
        z, _, _ = predict_observations(slam.pose.as_array(), tentative_xy, config.T_body_sensor)
        slam.update_unknown(z + offset, stamp_ns=200 * MS)
        slam.predict((0.3, 0.05, 0.1, 100 * MS))
        assert len(slam.landmark_ids) == 2 and len(slam.tentative_ids) == 2
        return slam

    offset = rng.normal(0.0, 0.01, (2, 2))
    slam = start()
    pose, P_pose = slam.pose.as_array(), slam.pose_covariance
    landmarks, P_map = slam.landmarks.copy(), slam.covariance[3:, 3:].copy()
    tentative_cov = np.linalg.det(slam._state.landmark_blocks(slam._state.tracks.slots_by_id(False)))
    z, _, _ = predict_observations(pose, tentative_xy, config.T_body_sensor)
    association = slam.update_unknown(z + offset, stamp_ns=300 * MS)
    assert (association.status == ObservationStatus.MATCHED).all()
    np.testing.assert_array_equal(slam.pose.as_array(), pose)
    np.testing.assert_array_equal(slam.pose_covariance, P_pose)
    np.testing.assert_array_equal(slam.landmarks[:2], landmarks)
    np.testing.assert_array_equal(slam.covariance[3:7, 3:7], P_map)
    # now confirmed by this second sighting: the scan refined them
    refined = np.linalg.det(slam.landmark_covariances[2:])
    assert (refined < tentative_cov).all()

    # both kinds in one scan: the pose moves as with the confirmed landmarks' observations alone
    both, alone = start(), start()
    pose = both.pose.as_array()
    z_confirmed, _, _ = predict_observations(pose, confirmed_xy, config.T_body_sensor)
    z_tentative, _, _ = predict_observations(pose, tentative_xy, config.T_body_sensor)
    both.update_unknown(np.vstack([z_confirmed + offset, z_tentative - offset]), stamp_ns=300 * MS)
    alone.update_unknown(z_confirmed + offset, stamp_ns=300 * MS)
    np.testing.assert_allclose(both.pose.as_array(), alone.pose.as_array(), atol=1e-12, rtol=0)
    assert math.isclose(float(np.trace(both.pose_covariance)), float(np.trace(alone.pose_covariance)))
