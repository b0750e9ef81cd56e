"""Batches of motion steps: ``integrate_twists``, ``BatchMotionModel.steps``, ``EkfSlam.predict_along`` and
the timeline handing its sample intervals over together.

The reference is always the one-step path: ``integrate_twist``, ``step`` after ``step``, ``predict`` after
``predict``. A batch must give the same poses, composite Jacobian and noise to rounding, and refuse what a
single step refuses, without changing the filter.
"""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_motion_models import NOISE, TRUCK

from turtlelib import (
    DiffDrive,
    DiffDriveMotion,
    EkfSlam,
    HeldInputs,
    OdometryMotion,
    SlamConfig,
    SlamTimeline,
    TimelineConfig,
    Transform2D,
    Twist2D,
    UnicycleMotion,
    integrate_twist,
)
from turtlelib.estimation.range_bearing import predict_observations
from turtlelib.geometry.se2 import integrate_twists
from turtlelib.motion.motion_models import BatchMotionModel

UNICYCLE = UnicycleMotion(NOISE)
MS = 1_000_000
LANDMARKS = np.array([[3.0, 1.0], [-2.0, 4.0], [5.0, -3.0]])


def random_inputs(model, rng, n):
    """n inputs of ``model``, 5-60 ms each, turning both ways (some turns beyond 1 rad per step)."""
    dt = rng.integers(5, 60, n) * MS
    if model is TRUCK:
        return [
            (float(v), float(a), int(t))
            for v, a, t in zip(rng.uniform(-1, 6, n), rng.uniform(-0.5, 0.5, n), dt, strict=True)
        ]
    return [
        (float(v), float(w), int(t))
        for v, w, t in zip(rng.uniform(-1, 2, n), rng.uniform(-30, 30, n), dt, strict=True)
    ]


def one_by_one(model, T, inputs):
    """Poses (n, 3) and the composite ``G``, ``Q`` of ``step`` after ``step``."""
    poses, G, Q = [], np.eye(3), np.zeros((3, 3))
    for u in inputs:
        q, G_k, Q_k = model.step(T, u)
        G, Q = G_k @ G, G_k @ Q @ G_k.T + Q_k
        poses.append(q)
        T = Transform2D(*q)
    return np.array(poses), G, Q


@given(st.lists(st.tuples(st.floats(-40, 40), st.floats(-3, 3), st.floats(-3, 3)), min_size=1, max_size=20))
def test_integrate_twists_is_integrate_twist_of_each(twists):
    omega, vx, vy = np.array(twists).T
    p = integrate_twists(omega, vx, vy)
    for k, (w, x, y) in enumerate(twists):
        T = integrate_twist(Twist2D(w, x, y))
        np.testing.assert_allclose(p[k], [T.x, T.y], rtol=0.0, atol=1e-15 * max(1.0, abs(x), abs(y)))


def test_integrate_twists_of_short_turns_only():
    # every |omega| below the series switch: the batch skips the closed forms
    omega = np.array([0.0, 1e-9, -3e-3, 9.9e-3])
    p = integrate_twists(omega, np.full(4, 0.7), np.full(4, -0.2))
    for k, w in enumerate(omega):
        T = integrate_twist(Twist2D(w, 0.7, -0.2))
        np.testing.assert_allclose(p[k], [T.x, T.y], rtol=0.0, atol=1e-16)


def test_the_twist_models_are_batch_models_and_the_others_step_only():
    assert isinstance(TRUCK, BatchMotionModel) and isinstance(UNICYCLE, BatchMotionModel)
    assert not isinstance(OdometryMotion(NOISE), BatchMotionModel)
    assert not isinstance(DiffDriveMotion(DiffDrive(0.033, 0.16), 0.05), BatchMotionModel)


@pytest.mark.parametrize("model", [TRUCK, UNICYCLE], ids=["ackermann", "unicycle"])
@pytest.mark.parametrize("seed", range(5))
def test_steps_are_the_steps_one_by_one(model, seed):
    rng = np.random.default_rng(seed)
    T0 = Transform2D(*rng.uniform(-5, 5, 2), rng.uniform(-math.pi, math.pi))
    inputs = random_inputs(model, rng, int(rng.integers(1, 40)))
    poses, G, Q = model.steps(T0, inputs)
    expected_poses, expected_G, expected_Q = one_by_one(model, T0, inputs)
    assert poses.shape == (len(inputs), 3)
    np.testing.assert_allclose(poses[:, :2], expected_poses[:, :2], rtol=0.0, atol=1e-11)
    heading_error = np.angle(np.exp(1j * (poses[:, 2] - expected_poses[:, 2])))
    np.testing.assert_allclose(heading_error, 0.0, atol=1e-11)
    np.testing.assert_allclose(G, expected_G, rtol=0.0, atol=1e-11)
    np.testing.assert_allclose(Q, expected_Q, rtol=0.0, atol=1e-12 * np.abs(expected_Q).max())
    np.testing.assert_array_equal(Q, Q.T)


def test_short_steps_take_the_series_path_and_agree():
    # 25 ms steps of a car: every turn far below 1 rad (the batch's fast path)
    inputs = [(4.0, 0.3 * math.sin(k / 5.0), 25 * MS) for k in range(30)]
    poses, G, Q = TRUCK.steps(Transform2D(1.0, -2.0, 3.0), inputs)
    expected_poses, expected_G, expected_Q = one_by_one(TRUCK, Transform2D(1.0, -2.0, 3.0), inputs)
    np.testing.assert_allclose(poses, expected_poses, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(Q, expected_Q, rtol=0.0, atol=1e-13 * np.abs(expected_Q).max())


@pytest.mark.parametrize(
    ("model", "bad"),
    [
        (TRUCK, (1.0, 1.6, 10 * MS)),
        (TRUCK, (1.0, math.atan(2.83 / 0.76) + 0.01, 10 * MS)),
        (TRUCK, (math.nan, 0.0, 10 * MS)),
        (UNICYCLE, (1.0, 0.0, -1)),
        (UNICYCLE, (1.0, 0.0, 0.5)),
        (UNICYCLE, (1.0, 0.0, True)),
        (UNICYCLE, (1.0, 0.0)),
    ],
)
def test_a_batch_refuses_what_a_step_refuses(model, bad):
    poses, G, Q = model.steps(Transform2D(1.0, 2.0, 0.5), [])
    assert poses.shape == (0, 3) and np.array_equal(G, np.eye(3)) and not Q.any()
    with pytest.raises(ValueError):
        model.step(Transform2D(), bad)
    with pytest.raises(ValueError):
        model.steps(Transform2D(), [(1.0, 0.1, 10 * MS), bad])


def mapped(model, linearization):
    config = SlamConfig(
        initial_xy_std=0.1, initial_theta_std=0.05, linearization=linearization, max_range=20.0, sensor_x=0.4
    )
    slam = EkfSlam(config, model)
    pose = slam.pose.as_array()
    z, _, _ = predict_observations(pose, LANDMARKS, Transform2D(0.4, 0.0, 0.0))
    slam.update_known([0, 1, 2], z + 0.05)
    return slam


@pytest.mark.parametrize("linearization", ["standard", "fej", "oc", "invariant"])
@pytest.mark.parametrize(
    "model",
    [TRUCK, UNICYCLE, DiffDriveMotion(DiffDrive(0.033, 0.16), 0.05)],
    ids=["ackermann", "unicycle", "wheels"],
)
def test_predict_along_is_predict_after_predict(model, linearization):
    rng = np.random.default_rng(3)
    if isinstance(model, DiffDriveMotion):
        inputs = [tuple(rng.uniform(-0.5, 1.5, 2)) for _ in range(12)]
    else:
        inputs = random_inputs(model, rng, 12)
    batch, reference = mapped(model, linearization), mapped(model, linearization)
    for round_ in range(3):
        poses = batch.predict_along(inputs)
        expected = []
        for u in inputs:
            reference.predict(u)
            expected.append(reference.pose.as_array())
        np.testing.assert_allclose(poses[:, :2], np.array(expected)[:, :2], rtol=0.0, atol=1e-10)
        np.testing.assert_allclose(batch.state, reference.state, rtol=0.0, atol=1e-10)
        np.testing.assert_allclose(batch.covariance, reference.covariance, rtol=0.0, atol=1e-11)
        # an update between the batches: the FEJ / OC correction of the next batch's first step matters
        z, _, _ = predict_observations(batch.pose.as_array(), LANDMARKS, Transform2D(0.4, 0.0, 0.0))
        batch.update_known([0, 1, 2], z + 0.02 * round_)
        reference.update_known([0, 1, 2], z + 0.02 * round_)


def test_one_input_is_exactly_predict():
    model = DiffDriveMotion(DiffDrive(0.033, 0.16), 0.05)
    batch, reference = mapped(model, "oc"), mapped(model, "oc")
    batch.predict_along([(0.7, 1.1)])
    reference.predict((0.7, 1.1))
    np.testing.assert_array_equal(batch.state, reference.state)
    np.testing.assert_array_equal(batch.covariance, reference.covariance)


@pytest.mark.parametrize(
    "model", [TRUCK, DiffDriveMotion(DiffDrive(0.033, 0.16), 0.05)], ids=["batch", "step"]
)
def test_a_refused_input_leaves_the_filter_unchanged(model):
    slam = mapped(model, "oc")
    state, covariance = slam.state, slam.covariance
    good = (2.0, 0.1, 10 * MS) if model is TRUCK else (0.5, 0.6)
    bad = (2.0, 1.6, 10 * MS) if model is TRUCK else (math.nan, 0.6)
    with pytest.raises(ValueError):
        slam.predict_along([good, good, bad, good])
    np.testing.assert_array_equal(slam.state, state)
    np.testing.assert_array_equal(slam.covariance, covariance)
    assert slam.predict_along([]).shape == (0, 3)


def test_the_timeline_batches_its_intervals_and_keeps_the_track():
    # held samples every 25 ms, a scan every 220 ms: with a long hold the filter advances only to the
    # scans, each over the samples since the last one, and must equal the filter advanced at every sample
    rng = np.random.default_rng(8)
    t = np.arange(200) * 25 * MS
    samples = np.column_stack([rng.uniform(0, 2, 200), rng.uniform(-0.3, 0.3, 200)])
    scans = [(int(k * 220 * MS + 3 * MS), 0.05 * rng.standard_normal((3, 2))) for k in range(1, 22)]
    z0, _, _ = predict_observations(np.zeros(3), LANDMARKS, Transform2D(0.4, 0.0, 0.0))
    hold = TimelineConfig(max_observation_delay=100.0)
    held = SlamTimeline(mapped(TRUCK, "oc"), HeldInputs(), hold, keep_track=True)
    eager = SlamTimeline(mapped(TRUCK, "oc"), HeldInputs(), TimelineConfig(max_observation_delay=0.0))
    eager_track = []
    i = 0
    for k in range(len(t)):
        for timeline in (held, eager):
            timeline.add_motion(int(t[k]), samples[k])
        eager_track.append(eager.slam.pose.as_array())
        # the scans stamped before the next sample
        while i < len(scans) and (k + 1 == len(t) or scans[i][0] < t[k + 1]):
            for timeline in (held, eager):
                timeline.add_observations(scans[i][0], z0 + scans[i][1], ids=[0, 1, 2])
            i += 1
    held.add_motion(int(t[-1]) + 25 * MS, samples[-1])
    eager.add_motion(int(t[-1]) + 25 * MS, samples[-1])
    stamps, track = held.take_track()
    assert np.all(np.diff(stamps) > 0) and stamps[-1] == scans[-1][0]
    # the held filter passed every sample up to the last scan, at the eager filter's poses
    at_samples = np.isin(stamps, t)
    # (the first sample only starts the timeline)
    passed = int(np.searchsorted(t, scans[-1][0])) - 1
    assert at_samples.sum() == passed
    np.testing.assert_allclose(track[at_samples][:, :2], np.array(eager_track)[1 : passed + 1, :2], atol=1e-9)
    np.testing.assert_allclose(held.slam.landmarks, eager.slam.landmarks, rtol=0.0, atol=1e-10)
    assert held.take_track()[0].shape == (0,)
    with pytest.raises(ValueError, match="keep_track"):
        eager.take_track()


def test_a_refused_held_sample_is_refused_when_it_arrives_and_forgotten():
    # held inputs: the sample at t[5] (a steering beyond 90 degrees) would be the input of the interval
    # after it, so it is refused on arrival, and the held filter drives on from the sample before it
    t = [k * 25 * MS for k in range(10)]
    samples = [(2.0, 0.1)] * 10
    samples[5] = (2.0, 1.6)
    held = SlamTimeline(
        mapped(TRUCK, "oc"), HeldInputs(), TimelineConfig(max_observation_delay=100.0), keep_track=True
    )
    reference = mapped(TRUCK, "oc")
    for k in range(9):
        if k == 5:
            with pytest.raises(ValueError, match="steering"):
                held.add_motion(t[k], samples[k])
        else:
            held.add_motion(t[k], samples[k])
    for k in [0, 1, 2, 3, 4, 4, 6, 7]:  # from t[4] to t[6]: the steering of t[4], held
        reference.predict((*samples[k], 25 * MS))
    assert held.add_observations(t[8], np.zeros((0, 2)), ids=np.zeros(0, dtype=int))[0][0] == t[8]
    assert held.filter_time_ns == t[8]
    np.testing.assert_allclose(held.slam.state, reference.state, rtol=0.0, atol=1e-12)
    stamps, _ = held.take_track()
    assert stamps.tolist() == [*t[1:5], *t[6:9]]
