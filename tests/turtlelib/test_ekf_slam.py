"""EkfSlam / SlamConfig: configuration, the public views, tentative landmarks, reset, and bad input.

Bad input must raise ValueError and leave the filter exactly as it was.
"""

import copy
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import DiffDrive, Transform2D, TwistNoise, UnicycleMotion
from turtlelib.estimation.ekf_slam import EkfSlam, ObservationStatus, SlamConfig
from turtlelib.estimation.matching import chi2_gate
from turtlelib.estimation.range_bearing import predict_observations
from turtlelib.motion.motion_models import DiffDriveMotion

PI = math.pi
BURGER = DiffDrive(wheel_radius=0.033, track_width=0.16)
MOTION = DiffDriveMotion(BURGER, 0.05)
SCAN_NS = 200_000_000  # scans at 5 Hz: scan k is stamped k * SCAN_NS
MATCHED, NEW, REJECTED = ObservationStatus.MATCHED, ObservationStatus.NEW, ObservationStatus.REJECTED


BURGER_CONFIG = SlamConfig(sensor_x=-0.032)  # the LDS-01 behind the Burger's wheel axle


def observe(slam_or_pose, landmarks, config=BURGER_CONFIG):
    pose = slam_or_pose.pose if isinstance(slam_or_pose, EkfSlam) else slam_or_pose
    z, _, _ = predict_observations(pose.as_array(), np.asarray(landmarks, dtype=float), config.T_body_sensor)
    return z


def drive(slam: EkfSlam, forward_m: float = 0.05) -> None:
    """Drive ``forward_m`` straight ahead: a new viewpoint, as a tentative landmark needs to confirm."""
    slam.predict((forward_m / BURGER.wheel_radius, forward_m / BURGER.wheel_radius))


def snapshot(slam: EkfSlam):
    return (
        slam.state,
        slam.covariance,
        slam.landmark_ids,
        slam.tentative_ids,
        slam.tentative_landmarks,
    )


def assert_same(before, after):
    for a, b in zip(before, after, strict=True):
        np.testing.assert_array_equal(a, b)


# --- configuration -----------------------------------------------------------------------------------------


def test_default_config_knows_no_robot():
    """The filter's defaults describe no robot: the sensor sits at the body origin unless told."""
    assert SlamConfig().T_body_sensor == Transform2D()
    config = SlamConfig(sensor_x=-0.032)
    assert config.T_body_sensor == Transform2D(-0.032, 0.0, 0.0)
    np.testing.assert_array_equal(
        config.measurement_covariance(2),
        np.tile(np.diag([config.range_std**2, config.bearing_std**2]), (2, 1, 1)),
    )
    assert config.matcher == "nn"
    np.testing.assert_array_equal(config.initial_pose_covariance(), np.zeros((3, 3)))


def test_the_default_range_noise_grows_with_the_range():
    """``sigma_r = range_std + range_std_per_m r``: a hand case, and the update's default R uses it."""
    config = SlamConfig(range_std=0.02, range_std_per_m=0.03, bearing_std=0.01, max_range=10.0)
    np.testing.assert_allclose(
        config.observation_covariances(np.array([0.0, 2.0])),
        [np.diag([0.02**2, 0.01**2]), np.diag([0.08**2, 0.01**2])],
        rtol=1e-15,
    )
    # without the range part, every range gets R of range_std (bit for bit what it was)
    flat = SlamConfig(range_std=0.02, bearing_std=0.01)
    np.testing.assert_array_equal(
        flat.observation_covariances(np.array([0.5, 3.0])), flat.measurement_covariance(2)
    )
    # an update without R fuses the far observation with its larger range noise: the same as given explicitly
    z = np.array([[1.0, 0.2], [4.0, -0.3]])
    implicit, explicit = (
        EkfSlam(config, UnicycleMotion(TwistNoise())),
        EkfSlam(config, UnicycleMotion(TwistNoise())),
    )
    for z_k in (z, z + 0.01):
        implicit.update_known([0, 1], z_k)
        explicit.update_known([0, 1], z_k, config.observation_covariances(z_k[:, 0]))
    np.testing.assert_array_equal(implicit.covariance, explicit.covariance)
    np.testing.assert_array_equal(implicit.state, explicit.state)


@pytest.mark.parametrize(
    "field, value",
    [
        ("range_std", 0.0),
        ("bearing_std", -1.0),
        ("bearing_std", math.inf),
        ("sensor_x", math.nan),
        ("sensor_theta", "0"),
        ("matcher", "icp"),
        ("gate_associate", 0.0),
        ("gate_associate", 0.99999),  # not below gate_new
        ("gate_new", 1.0),
        ("gate_known", 0.0),
        ("gate_known", 1.5),
        ("gate_known", math.nan),
        ("linearization", "exact"),
        ("range_std_per_m", -0.01),
        ("range_std_per_m", math.nan),
        ("confirm_count", 0),
        ("confirm_count", 2.0),
        ("confirm_count", True),
        ("tentative_timeout", 0),
        ("tentative_timeout", 0.0),
        ("tentative_timeout", -1.0),
        ("tentative_timeout", math.nan),
        ("tentative_timeout", math.inf),
        ("max_range", 0.0),
        ("initial_xy_std", -0.01),
        ("initial_theta_std", math.nan),
        ("jcbb_max_nodes", 0),
    ],
)
def test_config_rejects_invalid_values(field, value):
    with pytest.raises(ValueError):
        SlamConfig(**{field: value})


def test_config_takes_a_short_timeout_and_no_gate():
    # the timeout is a time now: any positive one is valid, whatever confirm_count needs
    assert SlamConfig(confirm_count=5, tentative_timeout=0.1).tentative_timeout == 0.1
    assert SlamConfig(gate_known=1.0).gate_known == 1.0


@pytest.mark.parametrize("wheel_noise", [-0.1, math.nan, math.inf])
def test_motion_model_rejects_invalid_wheel_noise(wheel_noise):
    with pytest.raises(ValueError):
        DiffDriveMotion(BURGER, wheel_noise)


# --- views -------------------------------------------------------------------------------------------------


def test_initial_filter():
    config = SlamConfig(sensor_x=-0.032, initial_xy_std=0.1, initial_theta_std=0.2)
    slam = EkfSlam(config, MOTION, Transform2D(1.0, 2.0, 3.0))
    assert slam.pose == Transform2D(1.0, 2.0, 3.0)
    np.testing.assert_allclose(slam.pose_covariance, np.diag([0.01, 0.01, 0.04]))
    np.testing.assert_array_equal(slam.state, [1.0, 2.0, 3.0])
    assert slam.covariance.shape == (3, 3)
    assert slam.landmark_ids.shape == (0,)
    assert slam.landmarks.shape == (0, 2)
    assert slam.landmark_covariances.shape == (0, 2, 2)
    assert EkfSlam(config, MOTION).pose == Transform2D()


def test_new_landmark_from_the_inverse_model():
    # robot at the origin facing +x with the LDS-01 at x = -0.032: 1 m at +90 deg is (-0.032, 1)
    slam = EkfSlam(SlamConfig(sensor_x=-0.032), MOTION)
    result = slam.update_known([3], [[1.0, 0.5 * PI]])
    np.testing.assert_array_equal(result.status, [NEW])
    np.testing.assert_array_equal(result.landmark_ids, [3])
    np.testing.assert_allclose(slam.landmarks, [[-0.032, 1.0]], atol=1e-15)
    # with a certain pose the landmark covariance is G_z R G_z^T: range along y, bearing (1 m) along -x
    config = SlamConfig(sensor_x=-0.032)
    np.testing.assert_allclose(
        slam.landmark_covariances[0], np.diag([config.bearing_std**2, config.range_std**2]), atol=1e-18
    )


def test_views_are_ordered_by_id_and_consistent():
    slam = EkfSlam(SlamConfig(sensor_x=-0.032, initial_xy_std=0.05, initial_theta_std=0.05), MOTION)
    world = np.array([[1.0, 0.5], [2.0, -1.0], [-1.0, 1.5], [0.5, -2.0]])
    ids = np.array([7, 2, 11, 5])
    slam.update_known(ids, observe(slam, world))
    slam.predict((5.0, 7.0))
    slam.update_known(ids[:3], observe(slam, world[:3]))
    np.testing.assert_array_equal(slam.landmark_ids, [2, 5, 7, 11])
    order = np.argsort(ids)
    np.testing.assert_allclose(slam.landmarks, world[order], atol=0.05)
    state, P = slam.state, slam.covariance
    np.testing.assert_array_equal(state[3:].reshape(-1, 2), slam.landmarks)
    for i, landmark_id in enumerate(slam.landmark_ids):
        block = P[3 + 2 * i : 5 + 2 * i, 3 + 2 * i : 5 + 2 * i]
        np.testing.assert_array_equal(slam.landmark_covariances[i], block)
        position, covariance = slam.landmark_estimate(int(landmark_id))
        np.testing.assert_array_equal(position, slam.landmarks[i])
        np.testing.assert_array_equal(covariance, block)
    np.testing.assert_array_equal(P[:3, :3], slam.pose_covariance)
    # views are copies
    slam.covariance[0, 0] = 1e9
    slam.landmarks[0, 0] = 1e9
    assert slam.covariance[0, 0] < 1.0 and slam.landmarks[0, 0] < 1e9


def test_landmark_estimate_of_an_unknown_id_raises():
    slam = EkfSlam(SlamConfig(sensor_x=-0.032), MOTION)
    slam.update_known([1], [[1.0, 0.0]])
    for bad in (0, 2, -1, 1.0, "1"):
        with pytest.raises(ValueError):
            slam.landmark_estimate(bad)


def test_observations_beyond_max_range_are_rejected():
    slam = EkfSlam(SlamConfig(sensor_x=-0.032, max_range=2.0), MOTION)
    result = slam.update_known([0, 1], [[1.0, 0.0], [2.5, 1.0]])
    np.testing.assert_array_equal(result.status, [NEW, REJECTED])
    np.testing.assert_array_equal(result.landmark_ids, [0, -1])
    np.testing.assert_array_equal(slam.landmark_ids, [0])
    result = EkfSlam(SlamConfig(sensor_x=-0.032, max_range=2.0), MOTION).update_unknown(
        [[1.0, 0.0], [2.5, 1.0]], stamp_ns=0
    )
    np.testing.assert_array_equal(result.status, [NEW, REJECTED])


# --- unknown association: tentative landmarks ---------------------------------------------------------------


def test_tentative_landmark_is_confirmed_after_confirm_count_sightings():
    # a timeout of 5 scans at 5 Hz; the robot drives 5 cm between scans (several viewpoints)
    config = SlamConfig(sensor_x=-0.032, confirm_count=3, tentative_timeout=1.0)
    slam = EkfSlam(config, MOTION)
    landmark = [[1.0, 0.5]]
    first = slam.update_unknown(observe(slam, landmark), stamp_ns=0)
    np.testing.assert_array_equal(first.status, [NEW])
    new_id = int(first.landmark_ids[0])
    np.testing.assert_array_equal(slam.tentative_ids, [new_id])
    assert slam.landmark_ids.shape == (0,)
    assert slam.covariance.shape == (3, 3)  # tentative landmarks are not in the public state

    slam.update_unknown(np.zeros((0, 2)), stamp_ns=SCAN_NS)  # a scan without detections
    drive(slam)
    second = slam.update_unknown(observe(slam, landmark), stamp_ns=2 * SCAN_NS)
    np.testing.assert_array_equal(second.status, [MATCHED])
    np.testing.assert_array_equal(second.landmark_ids, [new_id])
    assert second.confirmed_ids.shape == (0,)
    drive(slam)
    third = slam.update_unknown(observe(slam, landmark), stamp_ns=3 * SCAN_NS)
    np.testing.assert_array_equal(third.confirmed_ids, [new_id])
    np.testing.assert_array_equal(slam.landmark_ids, [new_id])
    assert slam.tentative_ids.shape == (0,)


def test_sightings_at_one_stamp_count_once_so_a_flood_confirms_nothing():
    """A tentative landmark is confirmed by sightings in confirm_count scans (distinct stamps): the same
    observation sent again and again at one stamp (a flood of copies of a scan) counts once, and the
    landmark expires as any unconfirmed one does."""
    config = SlamConfig(sensor_x=-0.032, confirm_count=2, tentative_timeout=1.0)
    slam = EkfSlam(config, MOTION)
    landmark = [[1.0, 0.5]]
    new_id = int(slam.update_unknown(observe(slam, landmark), stamp_ns=0).landmark_ids[0])
    for _ in range(50):
        again = slam.update_unknown(observe(slam, landmark), stamp_ns=0)
        np.testing.assert_array_equal(again.landmark_ids, [new_id])
        assert again.confirmed_ids.shape == (0,)
    np.testing.assert_array_equal(slam.tentative_ids, [new_id])
    # the next scan, from 10 cm further on, confirms it
    drive(slam, 0.1)
    np.testing.assert_array_equal(
        slam.update_unknown(observe(slam, landmark), stamp_ns=SCAN_NS).confirmed_ids, [new_id]
    )
    # another landmark flooded at one stamp expires unconfirmed
    other = [[2.0, -1.0]]
    other_id = int(slam.update_unknown(observe(slam, other), stamp_ns=2 * SCAN_NS).landmark_ids[-1])
    for _ in range(50):
        slam.update_unknown(observe(slam, other), stamp_ns=2 * SCAN_NS)
    dropped = slam.update_unknown(np.zeros((0, 2)), stamp_ns=7 * SCAN_NS)  # 1 s later: the timeout
    np.testing.assert_array_equal(dropped.dropped_ids, [other_id])
    np.testing.assert_array_equal(slam.landmark_ids, [new_id])


def test_unconfirmed_landmark_is_dropped_after_the_timeout():
    # a timeout of 3 scans at 5 Hz
    config = SlamConfig(sensor_x=-0.032, confirm_count=2, tentative_timeout=0.6)
    slam = EkfSlam(config, MOTION)
    landmarks = [[1.0, 0.5], [-1.0, 2.0]]
    first = slam.update_unknown(observe(slam, landmarks), stamp_ns=0)
    keep, lonely = (int(i) for i in first.landmark_ids)
    # the first landmark is seen again from 10 cm further on and confirmed; the second never again
    drive(slam, 0.1)
    confirming = slam.update_unknown(observe(slam, landmarks[:1]), stamp_ns=SCAN_NS)
    assert confirming.confirmed_ids.tolist() == [keep]
    assert slam.update_unknown([], stamp_ns=2 * SCAN_NS).dropped_ids.tolist() == []
    dropped = slam.update_unknown([], stamp_ns=3 * SCAN_NS)  # three scans after the one that created it
    np.testing.assert_array_equal(dropped.dropped_ids, [lonely])
    np.testing.assert_array_equal(slam.landmark_ids, [keep])
    assert slam.tentative_ids.shape == (0,)
    # the rest of the filter still works on the compacted state
    slam.predict((1.0, 1.2))
    result = slam.update_unknown(observe(slam, landmarks[:1]), stamp_ns=4 * SCAN_NS)
    np.testing.assert_array_equal(result.landmark_ids, [keep])
    assert np.linalg.eigvalsh(slam.covariance).min() > 0.0


def test_the_timeout_is_time_not_calls():
    # scans 1 ms apart: many more calls than a timeout of 0.6 s at 5 Hz would count (3 scans), but the
    # tentative landmark lasts until 0.6 s have passed since its first sighting, and goes at once then
    config = SlamConfig(sensor_x=-0.032, confirm_count=2, tentative_timeout=0.6)
    slam = EkfSlam(config, MOTION)
    lonely = int(slam.update_unknown(observe(slam, [[-1.0, 2.0]]), stamp_ns=0).landmark_ids[0])
    ms = 1_000_000
    for k in range(1, 600):
        assert slam.update_unknown([], stamp_ns=k * ms).dropped_ids.tolist() == []
    np.testing.assert_array_equal(slam.tentative_ids, [lonely])
    dropped = slam.update_unknown([], stamp_ns=600 * ms)
    np.testing.assert_array_equal(dropped.dropped_ids, [lonely])
    assert slam.tentative_ids.shape == (0,)
    # and without calls in between, the first call after the timeout drops it too
    slam = EkfSlam(config, MOTION)
    lonely = int(slam.update_unknown(observe(slam, [[-1.0, 2.0]]), stamp_ns=0).landmark_ids[0])
    np.testing.assert_array_equal(slam.update_unknown([], stamp_ns=700 * ms).dropped_ids, [lonely])


def test_confirm_count_one_maps_at_once():
    slam = EkfSlam(SlamConfig(sensor_x=-0.032, confirm_count=1), MOTION)
    result = slam.update_unknown(observe(slam, [[1.0, 0.5], [2.0, -1.0]]), stamp_ns=0)
    np.testing.assert_array_equal(result.confirmed_ids, result.landmark_ids)
    np.testing.assert_array_equal(slam.landmark_ids, result.landmark_ids)


def test_observation_between_the_gates_is_discarded():
    config = SlamConfig(sensor_x=-0.032, confirm_count=1, range_std=0.01, bearing_std=0.01)
    slam = EkfSlam(config, MOTION)
    slam.update_unknown([[1.0, 0.0]], stamp_ns=0)
    # S = 2 R here (certain pose): a range off by 4 sigma_S gives D2 = 16, between 9.2 and 18.4
    sigma = math.sqrt(2.0) * config.range_std
    result = slam.update_unknown([[1.0 + f * sigma, 0.0] for f in (4.0, 1.0, 6.0)], stamp_ns=SCAN_NS)
    # one compatible (matched), one ambiguous (discarded), one far (new) -- the first two compete for
    # the landmark and the closer wins
    np.testing.assert_array_equal(result.status, [REJECTED, MATCHED, NEW])


@pytest.mark.parametrize("linearization", ["standard", "fej", "oc", "invariant"])
def test_gating_leaves_out_only_landmarks_beyond_gate_new_of_every_observation(linearization):
    # unknown association forms S only for the landmarks a bound of D2 cannot rule out: every landmark
    # some observation lies within gate_new of must be kept, with the D2 the full gating gives
    rng = np.random.default_rng(7)
    config = SlamConfig(sensor_x=0.3, sensor_y=-0.1, confirm_count=1, linearization=linearization)
    slam = EkfSlam(config, UnicycleMotion(TwistNoise(forward_m2_per_m=0.01, heading_rad2_per_m=0.01)))
    truth = rng.uniform(-6.0, 6.0, size=(40, 2))
    for k in range(6):
        slam.update_unknown(observe(slam, truth, config) + rng.normal(0.0, 0.01, (40, 2)), stamp_ns=k)
        slam.predict((0.5, 0.3, 1_000_000_000))
    kept = 0
    for _ in range(20):
        # three observations near mapped landmarks (some inside the gates, some between them), three anywhere
        mapped = slam.state[3:].reshape(-1, 2)[rng.choice(len(slam.landmark_ids), 3, replace=False)]
        near_mapped = observe(slam, mapped, config) + rng.normal(0.0, [0.3, 0.1], (3, 2))
        z = np.vstack([near_mapped, np.column_stack([rng.uniform(0.2, 9.0, 3), rng.uniform(-PI, PI, 3)])])
        R = config.observation_covariances(z[:, 0])
        gate_new = chi2_gate(config.gate_new, 2)
        gating_near = slam.view().gate_near(z, R, gate_new)
        near, d2_near = gating_near.slots, gating_near.d2
        d2_all = slam.view().gate(z, R, np.arange(len(slam.landmark_ids))).d2
        within = (d2_all <= gate_new).any(axis=0).nonzero()[0]
        assert set(within) <= set(near)
        np.testing.assert_array_equal(d2_near, d2_all[:, near])
        kept += len(near)
    # and it does leave landmarks out (6 observations against 40 landmarks spread around)
    assert kept < 0.8 * 20 * len(slam.landmark_ids)


def test_two_detections_in_one_scan_never_start_two_landmarks_on_one_spot():
    slam = EkfSlam(SlamConfig(sensor_x=-0.032, confirm_count=1), MOTION)
    result = slam.update_unknown([[1.0, 0.0], [1.005, 0.001], [2.0, 1.0]], stamp_ns=0)
    np.testing.assert_array_equal(result.status, [NEW, REJECTED, NEW])
    assert len(slam.landmark_ids) == 2


def test_tentative_landmarks_do_not_steal_from_confirmed_ones():
    # a tentative landmark right next to a confirmed one gets no sightings and expires
    # a timeout of 3 scans at 5 Hz
    config = SlamConfig(
        sensor_x=-0.032, confirm_count=2, tentative_timeout=0.6, range_std=0.01, bearing_std=0.01
    )
    slam = EkfSlam(config, MOTION)
    # a landmark 1 m ahead of the sensor, confirmed from 5 cm further on
    slam.update_unknown([[1.0, 0.0]], stamp_ns=0)
    drive(slam)
    confirmed = int(slam.update_unknown(observe(slam, [[0.968, 0.0]]), stamp_ns=SCAN_NS).confirmed_ids[0])
    # 10 cm behind it: far enough (in sigmas) to start a tentative landmark
    ghost = slam.update_unknown(observe(slam, [[1.068, 0.0]]), stamp_ns=2 * SCAN_NS)
    np.testing.assert_array_equal(ghost.status, [NEW])
    # observations between the two are compatible with both; they go to the confirmed landmark
    for k in range(3, 6):
        result = slam.update_unknown(observe(slam, [[0.988, 0.0]]), stamp_ns=k * SCAN_NS)
        np.testing.assert_array_equal(result.landmark_ids, [confirmed])
    np.testing.assert_array_equal(slam.landmark_ids, [confirmed])
    assert slam.tentative_ids.shape == (0,)


def test_update_keeps_the_heading_wrapped():
    # a landmark mapped from a certain pose; then the robot, believed at heading pi - 0.001 (+- 0.05),
    # sees it as if its heading were pi + 0.01: the corrected heading crosses pi and must wrap
    slam = EkfSlam(SlamConfig(sensor_x=-0.032, range_std=0.001, bearing_std=0.001), MOTION)
    slam.update_known([0], [[2.0, 0.0]])
    believed = Transform2D(0.0, 0.0, PI - 0.001)
    slam.reset(believed, np.diag([1e-8, 1e-8, 0.05**2]), keep_map=True)
    truth = Transform2D(0.0, 0.0, PI + 0.01)
    slam.update_known([0], observe(truth, slam.landmarks))
    assert -PI < slam.state[2] <= PI
    assert slam.state[2] == pytest.approx(-PI + 0.01, abs=1e-3)


# --- reset and modes ---------------------------------------------------------------------------------------


def test_reset_empties_the_map_or_keeps_it():
    slam = EkfSlam(SlamConfig(sensor_x=-0.032, initial_xy_std=0.1), MOTION)
    slam.update_known([0, 1], [[1.0, 0.0], [2.0, 1.0]])
    landmarks, blocks = slam.landmarks, slam.landmark_covariances
    pose_cov = np.diag([0.04, 0.09, 0.01])
    slam.reset(Transform2D(1.0, 1.0, 0.5), pose_cov, keep_map=True)
    assert slam.pose == Transform2D(1.0, 1.0, 0.5)
    np.testing.assert_array_equal(slam.pose_covariance, pose_cov)
    np.testing.assert_array_equal(slam.landmarks, landmarks)
    np.testing.assert_array_equal(slam.landmark_covariances, blocks)
    np.testing.assert_array_equal(slam.covariance[:3, 3:], 0.0)
    slam.reset()
    assert slam.pose == Transform2D()
    np.testing.assert_allclose(slam.pose_covariance, np.diag([0.01, 0.01, 0.0]))
    assert slam.landmark_ids.shape == (0,)


def test_one_association_mode_per_filter():
    slam = EkfSlam(SlamConfig(sensor_x=-0.032), MOTION)
    slam.update_known([0], [[1.0, 0.0]])
    before = snapshot(slam)
    with pytest.raises(ValueError):
        slam.update_unknown([[1.0, 0.0]], stamp_ns=0)
    assert_same(before, snapshot(slam))
    slam.reset()
    slam.update_unknown([[1.0, 0.0]], stamp_ns=0)
    with pytest.raises(ValueError):
        slam.update_known([0], [[1.0, 0.0]])


@pytest.mark.parametrize(
    "pose, covariance",
    [
        (Transform2D(), np.diag([0.1, 0.1, -0.1])),
        (Transform2D(), np.array([[0.1, 0.05, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]])),
        (Transform2D(), np.full((3, 3), math.nan)),
        (Transform2D(), np.eye(2)),
        ((0.0, 0.0, 0.0), np.eye(3)),
    ],
)
def test_reset_rejects_bad_input(pose, covariance):
    slam = EkfSlam(SlamConfig(sensor_x=-0.032), MOTION)
    slam.update_known([0], [[1.0, 0.0]])
    before = snapshot(slam)
    with pytest.raises(ValueError):
        slam.reset(pose, covariance, keep_map=True)
    assert_same(before, snapshot(slam))


# --- bad input ---------------------------------------------------------------------------------------------

GOOD_Z = [[1.0, 0.2], [2.0, -0.3]]
GOOD_R = [np.diag([1e-4, 1e-4])] * 2
BAD_OBSERVATIONS = [
    pytest.param([[math.nan, 0.2], [2.0, -0.3]], GOOD_R, id="nan-range"),
    pytest.param([[1.0, math.inf], [2.0, -0.3]], GOOD_R, id="inf-bearing"),
    pytest.param([[-1.0, 0.2], [2.0, -0.3]], GOOD_R, id="negative-range"),
    pytest.param([[0.0, 0.2], [2.0, -0.3]], GOOD_R, id="zero-range"),
    pytest.param([1.0, 0.2], GOOD_R[:1], id="not-2d"),
    pytest.param([[1.0, 0.2, 0.0], [2.0, -0.3, 0.0]], GOOD_R, id="three-columns"),
    pytest.param(GOOD_Z, [np.diag([-1e-4, 1e-4])] * 2, id="negative-variance"),
    pytest.param(GOOD_Z, [np.diag([1e-4, 0.0])] * 2, id="zero-variance"),
    pytest.param(GOOD_Z, [[[1e-4, 2e-4], [2e-4, 1e-4]]] * 2, id="indefinite"),
    pytest.param(GOOD_Z, [[[1e-4, 1e-5], [0.0, 1e-4]]] * 2, id="asymmetric"),
    pytest.param(GOOD_Z, [np.diag([math.nan, 1e-4])] * 2, id="nan-noise"),
    pytest.param(GOOD_Z, GOOD_R[:1], id="too-few-R"),
]


def filter_with_map(mode):
    slam = EkfSlam(SlamConfig(sensor_x=-0.032, initial_xy_std=0.01, confirm_count=2), MOTION)
    z = observe(slam, [[1.0, 0.2], [1.5, -0.8]])
    if mode == "known":
        slam.update_known([0, 1], z)
    else:
        slam.update_unknown(z, stamp_ns=0)
    slam.predict((1.0, 1.1))
    return slam


@pytest.mark.parametrize("z, R", BAD_OBSERVATIONS)
def test_bad_observations_raise_and_leave_the_filter_unchanged(z, R):
    for mode in ("known", "unknown"):
        slam = filter_with_map(mode)
        reference = copy.deepcopy(slam)
        before = snapshot(slam)
        with pytest.raises(ValueError):
            if mode == "known":
                slam.update_known(list(range(len(z))) if np.ndim(z) == 2 else [0], z, R)
            else:
                slam.update_unknown(z, R, stamp_ns=SCAN_NS)
        assert_same(before, snapshot(slam))
        # and the next good update does exactly what it does on an untouched filter
        good = observe(slam, [[1.0, 0.2], [1.5, -0.8]])
        if mode == "known":
            a, b = slam.update_known([0, 1], good), reference.update_known([0, 1], good)
        else:
            a = slam.update_unknown(good, stamp_ns=SCAN_NS)
            b = reference.update_unknown(good, stamp_ns=SCAN_NS)
        assert_same(dataclasses.astuple(a), dataclasses.astuple(b))
        assert_same(snapshot(slam), snapshot(reference))


@pytest.mark.parametrize(
    "ids",
    [
        pytest.param([0, -1], id="negative"),
        pytest.param([0.0, 1.0], id="float"),
        pytest.param([0, 0], id="duplicate"),
        pytest.param([0], id="too-few"),
        pytest.param([[0, 1]], id="2d"),
        pytest.param(["a", "b"], id="strings"),
    ],
)
def test_bad_landmark_ids_raise_and_leave_the_filter_unchanged(ids):
    slam = filter_with_map("known")
    before = snapshot(slam)
    with pytest.raises(ValueError):
        slam.update_known(ids, GOOD_Z)
    assert_same(before, snapshot(slam))


# --- properties --------------------------------------------------------------------------------------------

observation_batches = st.lists(
    st.tuples(st.integers(0, 7), st.floats(0.2, 3.0), st.floats(-PI, PI)), min_size=0, max_size=6
)
motions = st.tuples(st.floats(-5.0, 10.0), st.floats(-5.0, 10.0))


@settings(deadline=None, max_examples=40)
@given(st.lists(st.tuples(motions, observation_batches), min_size=1, max_size=8), st.booleans())
def test_any_valid_sequence_keeps_the_covariance_symmetric_positive_definite(steps, known):
    # arbitrary (even mutually inconsistent) observations never break the filter's numerics; no known
    # gate, so that known association fuses them all
    config = SlamConfig(
        sensor_x=-0.032, initial_xy_std=0.01, initial_theta_std=0.01, confirm_count=1, gate_known=1.0
    )
    slam = EkfSlam(config, MOTION)
    for k, ((left, right), batch) in enumerate(steps):
        slam.predict((left, right))
        unique = {landmark_id: (r, b) for landmark_id, r, b in batch}
        z = np.array(list(unique.values())).reshape(-1, 2)
        if known:
            slam.update_known(list(unique), z)
        else:
            slam.update_unknown(z, stamp_ns=k * SCAN_NS)
        P = slam.covariance
        assert np.all(np.isfinite(slam.state))
        np.testing.assert_array_equal(P, P.T)
        assert np.linalg.eigvalsh(P).min() > 0.0
        assert -PI < slam.state[2] <= PI
