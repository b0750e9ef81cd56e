"""EkfSlam.propagated_pose_along (the pose predict would give, filter unchanged) and
EkfSlam.checked_observations (the validation that the updates and SlamTimeline use to refuse bad observations
before queuing them).
"""

import copy
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import DiffDrive, Transform2D
from turtlelib.estimation.ekf_slam import EkfSlam, SlamConfig
from turtlelib.estimation.range_bearing import predict_observations
from turtlelib.motion.motion_models import DiffDriveMotion

PI = math.pi
BURGER = DiffDrive(wheel_radius=0.033, track_width=0.16)
LANDMARKS = np.array([[1.0, 0.5], [-0.5, 1.5], [0.3, -1.2]])

wheel_rad = st.floats(-20.0, 20.0, allow_nan=False)
poses = st.builds(Transform2D, st.floats(-5.0, 5.0), st.floats(-5.0, 5.0), st.floats(-PI, PI))


def filter_with_map(pose: Transform2D, mode="known", wheel_noise=0.05) -> EkfSlam:
    """Landmarks mapped from an uncertain pose, then moved on: a full, correlated covariance."""
    config = SlamConfig(sensor_x=-0.032, initial_xy_std=0.03, initial_theta_std=0.05, confirm_count=1)
    slam = EkfSlam(config, DiffDriveMotion(BURGER, wheel_noise), pose)
    z, _, _ = predict_observations(pose.as_array(), pose @ LANDMARKS, config.T_body_sensor)
    if mode == "known":
        slam.update_known([0, 1, 2], z)
    else:
        slam.update_unknown(z, stamp_ns=0)
    slam.predict((3.0, 4.0))
    return slam


def snapshot(slam: EkfSlam):
    return slam.state.copy(), slam.covariance.copy(), slam.landmark_ids.copy(), slam.tentative_ids.copy()


def assert_same(before, after):
    for a, b in zip(before, after, strict=True):
        np.testing.assert_array_equal(a, b)


# --- propagated_pose_along ---------------------------------------------------------------------------------


@settings(deadline=None, max_examples=150)
@given(poses, wheel_rad, wheel_rad, st.sampled_from([0.0, 0.05, 0.3]))
def test_propagated_pose_is_what_predict_gives(pose, left, right, wheel_noise):
    slam = filter_with_map(pose, wheel_noise=wheel_noise)
    before = snapshot(slam)
    predicted = copy.deepcopy(slam)
    predicted.predict((left, right))

    T, P = slam.propagated_pose_along([(left, right)])
    assert isinstance(T, Transform2D)
    np.testing.assert_allclose(T.as_array(), predicted.pose.as_array(), rtol=0.0, atol=1e-12)
    expected = predicted.pose_covariance
    np.testing.assert_allclose(P, expected, rtol=0.0, atol=1e-13 * np.abs(expected).max())
    np.testing.assert_array_equal(P, P.T)
    # the filter itself did not move
    assert_same(before, snapshot(slam))
    # and the result does not alias the filter's storage
    P[:] = 1e9
    assert_same(before, snapshot(slam))


def test_propagated_pose_hand_case():
    # from the origin with a certain pose, both wheels 10 rad: 0.33 m straight ahead, covariance = Q only
    slam = EkfSlam(SlamConfig(sensor_x=-0.032), DiffDriveMotion(BURGER, 0.1))
    T, P = slam.propagated_pose_along([(10.0, 10.0)])
    assert T.x == pytest.approx(0.33, abs=1e-15)
    assert T.y == 0.0 and T.theta == 0.0
    # Q of a straight line: var_v = q r^2 / 2, var_w = 2 q r^2 / d^2, u = r dphi, q = k^2 dphi
    q, r, d, u = 0.01 * 10.0, 0.033, 0.16, 0.33
    var_v, var_w = q * r * r / 2.0, 2.0 * q * r * r / (d * d)
    expected = np.array(
        [[var_v, 0.0, 0.0], [0.0, var_w * u * u / 3.0, var_w * u / 2.0], [0.0, var_w * u / 2.0, var_w]]
    )
    np.testing.assert_allclose(P, expected, rtol=1e-12, atol=1e-20)
    assert slam.pose == Transform2D()
    np.testing.assert_array_equal(slam.pose_covariance, np.zeros((3, 3)))


def test_propagated_pose_without_motion_is_the_current_pose():
    slam = filter_with_map(Transform2D(1.0, -2.0, 2.5))
    T, P = slam.propagated_pose_along([(0.0, 0.0)])
    assert T == slam.pose
    np.testing.assert_array_equal(P, slam.pose_covariance)
    # no inputs at all: the current pose too
    T, P = slam.propagated_pose_along([])
    assert T == slam.pose
    np.testing.assert_array_equal(P, slam.pose_covariance)


def test_propagated_pose_does_not_chain():
    # it always starts from the filter's pose: twice the same call, the same answer
    slam = filter_with_map(Transform2D(0.2, 0.1, -0.4))
    first = slam.propagated_pose_along([(2.0, 1.0)])
    second = slam.propagated_pose_along([(2.0, 1.0)])
    assert first[0] == second[0]
    np.testing.assert_array_equal(first[1], second[1])
    assert first[0] != slam.pose


@pytest.mark.parametrize("left, right", [(math.nan, 0.0), (0.0, math.inf), (-math.inf, 1.0)])
def test_propagated_pose_rejects_non_finite_increments(left, right):
    slam = filter_with_map(Transform2D())
    before = snapshot(slam)
    with pytest.raises(ValueError):
        slam.propagated_pose_along([(left, right)])
    assert_same(before, snapshot(slam))


# --- checked_observations ----------------------------------------------------------------------------------

GOOD_Z = [[1.0, 0.2], [2.0, -0.3]]
GOOD_R = [np.diag([1e-4, 2e-4])] * 2


def test_checked_observations_returns_validated_arrays():
    slam = filter_with_map(Transform2D())
    before = snapshot(slam)
    z, R, ids = slam.checked_observations(GOOD_Z, GOOD_R, [4, 1])
    assert z.dtype == np.float64 and z.shape == (2, 2)
    np.testing.assert_array_equal(z, GOOD_Z)
    np.testing.assert_array_equal(R, GOOD_R)
    assert ids.dtype == np.int64
    np.testing.assert_array_equal(ids, [4, 1])
    # default R from the config, one per observation
    _, R, _ = slam.checked_observations(GOOD_Z, ids=[0, 1])
    config = SlamConfig(sensor_x=-0.032)
    default_R = np.diag([config.range_std**2, config.bearing_std**2])
    np.testing.assert_array_equal(R, np.tile(default_R, (2, 1, 1)))
    # no observations is valid
    z, R, ids = slam.checked_observations([], ids=[])
    assert z.shape == (0, 2) and R.shape == (0, 2, 2) and ids.shape == (0,)
    assert_same(before, snapshot(slam))
    # a filter without an association mode yet takes either kind
    fresh = EkfSlam(SlamConfig(sensor_x=-0.032), DiffDriveMotion(BURGER, 0.05))
    assert fresh.checked_observations(GOOD_Z)[2] is None
    assert fresh.checked_observations(GOOD_Z, ids=[0, 1])[2] is not None


@pytest.mark.parametrize(
    "z, R, ids",
    [
        pytest.param([[math.nan, 0.2], [2.0, -0.3]], None, [0, 1], id="nan-range"),
        pytest.param([[1.0, -math.inf], [2.0, -0.3]], None, [0, 1], id="inf-bearing"),
        pytest.param([[0.0, 0.2], [2.0, -0.3]], None, [0, 1], id="zero-range"),
        pytest.param([[-1.0, 0.2], [2.0, -0.3]], None, [0, 1], id="negative-range"),
        pytest.param([1.0, 0.2], None, [0], id="1-d"),
        pytest.param([[[1.0, 0.2]]], None, [0], id="3-d"),
        pytest.param([[1.0, 0.2, 0.0]], None, [0], id="three-columns"),
        pytest.param(GOOD_Z, GOOD_R[:1], [0, 1], id="too-few-R"),
        pytest.param(GOOD_Z, np.diag([1e-4, 1e-4]), [0, 1], id="R-not-stacked"),
        pytest.param(GOOD_Z, [np.diag([math.nan, 1e-4])] * 2, [0, 1], id="nan-R"),
        pytest.param(GOOD_Z, [np.diag([-1e-4, 1e-4])] * 2, [0, 1], id="negative-variance"),
        pytest.param(GOOD_Z, [np.diag([1e-4, 0.0])] * 2, [0, 1], id="zero-variance"),
        pytest.param(GOOD_Z, [[[1e-4, 2e-4], [2e-4, 1e-4]]] * 2, [0, 1], id="indefinite-R"),
        pytest.param(GOOD_Z, [[[1e-4, 1e-5], [0.0, 1e-4]]] * 2, [0, 1], id="asymmetric-R"),
        pytest.param(GOOD_Z, None, [0], id="too-few-ids"),
        pytest.param(GOOD_Z, None, [0, 1, 2], id="too-many-ids"),
        pytest.param(GOOD_Z, None, [3, 3], id="duplicate-ids"),
        pytest.param(GOOD_Z, None, [0, -2], id="negative-id"),
        pytest.param(GOOD_Z, None, [0.0, 1.0], id="float-ids"),
        pytest.param(GOOD_Z, None, [True, False], id="bool-ids"),
        pytest.param(GOOD_Z, None, [[0, 1]], id="2-d-ids"),
        pytest.param(GOOD_Z, None, ["a", "b"], id="string-ids"),
    ],
)
def test_checked_observations_rejects_bad_input(z, R, ids):
    slam = filter_with_map(Transform2D())
    before = snapshot(slam)
    with pytest.raises(ValueError):
        slam.checked_observations(z, R, ids)
    assert_same(before, snapshot(slam))
    # what checked_observations refuses, the update refuses too
    with pytest.raises(ValueError):
        slam.update_known([0] if ids is None else ids, z, R)
    assert_same(before, snapshot(slam))


@pytest.mark.parametrize("mode", ["known", "unknown"])
def test_checked_observations_rejects_the_other_association_mode(mode):
    # the first update fixes the mode: observations for the other one would fail in the update
    slam = filter_with_map(Transform2D(), mode=mode)
    before = snapshot(slam)
    with pytest.raises(ValueError, match="association"):
        if mode == "known":
            slam.checked_observations(GOOD_Z)
        else:
            slam.checked_observations(GOOD_Z, ids=[0, 1])
    assert_same(before, snapshot(slam))
    # the own mode is fine, and a reset (without the map) forgets the mode
    slam.checked_observations(GOOD_Z, ids=[0, 1] if mode == "known" else None)
    slam.reset()
    slam.checked_observations(GOOD_Z, ids=None if mode == "known" else [0, 1])


@pytest.mark.parametrize("mode", ["known", "unknown"])
def test_update_takes_checked_observations_only_and_is_the_update_they_were_checked_for(mode):
    ids = [0, 1] if mode == "known" else None
    via_update, direct = filter_with_map(Transform2D(), mode=mode), filter_with_map(Transform2D(), mode=mode)
    checked = via_update.checked_observations(GOOD_Z, GOOD_R, ids)
    before = snapshot(via_update)
    # the arrays themselves, unchecked, are refused
    with pytest.raises(ValueError, match="checked_observations"):
        via_update.update(tuple(checked), stamp_ns=1)
    assert_same(before, snapshot(via_update))
    result = via_update.update(checked, stamp_ns=1)
    if mode == "known":
        expected = direct.update_known(ids, GOOD_Z, GOOD_R)
    else:
        expected = direct.update_unknown(GOOD_Z, GOOD_R, stamp_ns=1)
    np.testing.assert_array_equal(result.status, expected.status)
    assert_same(snapshot(direct), snapshot(via_update))
