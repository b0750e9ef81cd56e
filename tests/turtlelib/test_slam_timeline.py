"""SlamTimeline / TimelineConfig: time alignment of wheel samples and stamped observations (times in ns).

The reference throughout is an EkfSlam driven by hand: the wheel angles are interpolated linearly between
samples (np.interp), the filter is predicted to each observation's stamp, updated there, and predicted
onward. The timeline must give the same mean and covariance wherever it splits the motion (its filter lags
the newest sample by max_observation_delay), whether an observation arrives on time, late or early (then
queued), and bad input must raise ValueError and leave everything as it was.
"""

import copy
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib import DiffDrive, DiffDriveMotion, SlamTimeline, TimelineConfig, Transform2D, WheelAngles
from turtlelib.estimation.ekf_slam import EkfSlam, ObservationStatus, SlamConfig
from turtlelib.estimation.range_bearing import predict_observations

PI = math.pi
BURGER = DiffDrive(wheel_radius=0.033, track_width=0.16)
MOTION = DiffDriveMotion(BURGER, 0.08)
CONFIG = SlamConfig(sensor_x=-0.032, initial_xy_std=0.02, initial_theta_std=0.03)
LANDMARKS = np.array([[1.5, 0.5], [0.6, -1.2], [-0.8, 1.1]])
MEAN_ATOL = 1e-9
MS = 1_000_000  # ns


def mapped_filter() -> EkfSlam:
    """A filter with landmarks 0, 1, 2 (known association) correlated with an uncertain pose."""
    slam = EkfSlam(CONFIG, MOTION, Transform2D(0.1, -0.2, 0.3))
    slam.update_known([0, 1, 2], observe(slam.pose, LANDMARKS))
    return slam


def timeline_of(slam: EkfSlam, config: TimelineConfig | None = None) -> SlamTimeline:
    return SlamTimeline(slam, WheelAngles(), config)


def delay_config(delay_ns: int) -> TimelineConfig:
    """A max_observation_delay (s) of exactly ``delay_ns`` ns in the timeline's arithmetic."""
    return TimelineConfig(max_observation_delay=delay_ns / 1e9)


def add(timeline: SlamTimeline, sample):
    """Feed one wheel sample ``(t_ns, phi_left, phi_right)``."""
    t_ns, left, right = sample
    return timeline.add_motion(t_ns, (left, right))


def observe(pose: Transform2D, landmarks, offset=(0.0, 0.0)) -> np.ndarray:
    z, _, _ = predict_observations(pose.as_array(), np.asarray(landmarks, float), CONFIG.T_body_sensor)
    return z + np.asarray(offset)


def angles_at(samples, t):
    """The linearly interpolated wheel angles at ``t`` (ns, within the samples' time span)."""
    times, left, right = np.asarray(samples, dtype=float).T
    return float(np.interp(t, times, left)), float(np.interp(t, times, right))


def drive_by_hand(slam: EkfSlam, samples, observations, t_stop):
    """The reference: predict along every sample interval (split at the observation stamps), update each
    observation ``(t_o, ids, z)`` at its stamp, stop at ``t_stop`` (times in ns). Changes ``slam``."""
    cuts = sorted({s[0] for s in samples if s[0] <= t_stop} | {t for t, _, _ in observations} | {t_stop})
    by_stamp = sorted(observations, key=lambda o: o[0])
    phi = angles_at(samples, cuts[0])
    for t in cuts:
        nxt = angles_at(samples, t)
        if nxt != phi:
            slam.predict((nxt[0] - phi[0], nxt[1] - phi[1]))
        phi = nxt
        while by_stamp and by_stamp[0][0] == t:
            _, ids, z = by_stamp.pop(0)
            slam.update_known(ids, z)
    assert not by_stamp
    return slam


def assert_same_filter(a: EkfSlam, b: EkfSlam, atol=MEAN_ATOL):
    np.testing.assert_array_equal(a.landmark_ids, b.landmark_ids)
    np.testing.assert_allclose(a.state, b.state, rtol=0.0, atol=atol)
    P = b.covariance
    np.testing.assert_allclose(a.covariance, P, rtol=0.0, atol=1e-9 * np.abs(P).max())


def snapshot(timeline: SlamTimeline):
    slam = timeline.slam
    pose, P = timeline.latest_pose() if timeline.filter_time_ns is not None else (None, None)
    return (
        slam.state.copy(),
        slam.covariance.copy(),
        slam.landmark_ids.copy(),
        timeline.filter_time_ns,
        timeline.latest_time_ns,
        timeline.pending_count,
        pose,
        P,
    )


def assert_unchanged(before, after):
    for a, b in zip(before, after, strict=True):
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)
        else:
            assert a == b


def straight_samples(n, dt_ns=50 * MS, speed=8.0):
    """Both wheels at ``speed`` rad/s from t = 0: a straight line at constant speed."""
    return [(k * dt_ns, speed * k * dt_ns / 1e9, speed * k * dt_ns / 1e9) for k in range(n)]


# --- configuration -----------------------------------------------------------------------------------------


def test_default_config():
    config = TimelineConfig()
    assert config.max_observation_delay == 0.25
    assert config.max_pending_observations == 20
    # zero delay, integral delay and numpy scalars are valid
    TimelineConfig(max_observation_delay=0)
    TimelineConfig(max_observation_delay=np.float64(0.1), max_pending_observations=np.int64(1))


@pytest.mark.parametrize(
    "field, value",
    [
        ("max_observation_delay", -0.01),
        ("max_observation_delay", -math.inf),
        ("max_observation_delay", math.nan),
        ("max_observation_delay", math.inf),
        ("max_observation_delay", True),
        ("max_observation_delay", False),
        ("max_observation_delay", "0.1"),
        ("max_observation_delay", None),
        ("max_pending_observations", 0),
        ("max_pending_observations", -3),
        ("max_pending_observations", 2.0),
        ("max_pending_observations", True),
        ("max_pending_observations", "5"),
        ("max_pending_observations", None),
    ],
)
def test_config_rejects_invalid_values(field, value):
    with pytest.raises(ValueError):
        TimelineConfig(**{field: value})


# --- splitting the motion does not matter ------------------------------------------------------------------

intervals = st.lists(st.integers(10 * MS, 100 * MS), min_size=3, max_size=10)  # ns
wheel_speeds = st.tuples(st.floats(-10.0, 10.0), st.floats(-10.0, 10.0))
delays = st.one_of(st.just(0), st.integers(0, 300 * MS))  # ns


def samples_from(dts_ns, speeds):
    """Wheel samples ``(t_ns, phi_left, phi_right)`` from t = 0 after intervals ``dts_ns`` at ``speeds``
    (rad/s)."""
    t, left, right = 0, 0.0, 0.0
    samples = [(t, left, right)]
    for dt, (w_left, w_right) in zip(dts_ns, speeds, strict=False):
        t, left, right = t + dt, left + w_left * dt / 1e9, right + w_right * dt / 1e9
        samples.append((t, left, right))
    return samples


def run_timeline(samples, observation, arrive_after, delay_ns):
    """Feed ``samples``, delivering ``observation`` (t_o, ids, z) right after sample ``arrive_after``."""
    timeline = timeline_of(mapped_filter(), delay_config(delay_ns))
    applied = []
    for k, sample in enumerate(samples):
        applied += add(timeline, sample)
        if k == arrive_after:
            t_o, ids, z = observation
            applied += timeline.add_observations(t_o, z, ids=ids)
    return timeline, applied


def latest_arrival(samples, t_o, delay_ns):
    """The last sample after which an observation stamped t_o is not stale (the filter is at
    max(t_0, t_k - delay) after sample k, the timeline's own arithmetic)."""
    return max(k for k, (t, _, _) in enumerate(samples) if k == 0 or t - delay_ns <= t_o)


def observation_at(samples, t_o, ids=(0, 1), offset=(0.01, -0.005)):
    """z of landmarks ``ids`` from the reference pose at t_o, off by a few cm / mrad (a real correction)."""
    slam = drive_by_hand(mapped_filter(), samples, [], t_o)
    return t_o, list(ids), observe(slam.pose, LANDMARKS[list(ids)], offset)


@settings(deadline=None, max_examples=60)
@given(intervals, st.floats(-10.0, 10.0), st.floats(-10.0, 10.0), st.floats(0.05, 0.95), delays, st.data())
def test_constant_wheel_speeds_one_prediction_to_the_stamp_and_one_onward(
    dts, w_left, w_right, fraction, delay, data
):
    # the wheels turn at constant speed (one arc): the reference predicts in ONE step to the stamp, updates
    # and predicts in ONE step onward, whereas the timeline splits at every sample and t_k - delay
    samples = samples_from(dts, [(w_left, w_right)] * len(dts))
    t_end = samples[-1][0]
    t_o = round(fraction * t_end)
    observation = observation_at(samples, t_o)
    arrive_after = data.draw(st.integers(0, latest_arrival(samples, t_o, delay)), label="arrive_after")
    timeline, applied = run_timeline(samples, observation, arrive_after, delay)

    assert [r.t_ns for r in applied] == [t_o]
    assert timeline.pending_count == 0
    assert timeline.latest_time_ns == t_end
    t_f = timeline.filter_time_ns
    assert t_f == max(t_o, t_end - delay)

    reference = mapped_filter()
    phi_o = angles_at(samples, t_o)
    reference.predict(phi_o)
    reference.update_known(observation[1], observation[2])
    phi_f = angles_at(samples, t_f)
    reference.predict((phi_f[0] - phi_o[0], phi_f[1] - phi_o[1]))
    assert_same_filter(timeline.slam, reference)

    # and the published pose at t_w is the reference moved on to t_end
    pose, P = timeline.latest_pose()
    reference.predict((samples[-1][1] - phi_f[0], samples[-1][2] - phi_f[1]))
    np.testing.assert_allclose(pose.as_array(), reference.pose.as_array(), rtol=0.0, atol=MEAN_ATOL)
    np.testing.assert_allclose(P, reference.pose_covariance, rtol=0.0, atol=1e-9 * np.abs(P).max())


@settings(deadline=None, max_examples=60)
@given(intervals, st.lists(wheel_speeds, min_size=10, max_size=10), st.floats(0.05, 0.95), delays, st.data())
def test_changing_wheel_speeds_same_filter_as_predicting_sample_by_sample(dts, speeds, fraction, delay, data):
    # the wheel speeds change at every sample: the timeline must follow each interval's own arc however
    # the delay cuts the motion, i.e. match the reference predicting interval by interval
    samples = samples_from(dts, speeds)
    t_o = round(fraction * samples[-1][0])
    observation = observation_at(samples, t_o, ids=(0, 1, 2))
    arrive_after = data.draw(st.integers(0, latest_arrival(samples, t_o, delay)), label="arrive_after")
    timeline, applied = run_timeline(samples, observation, arrive_after, delay)

    assert [r.t_ns for r in applied] == [t_o]
    np.testing.assert_array_equal(applied[0].association.status, [ObservationStatus.MATCHED] * 3)
    reference = drive_by_hand(mapped_filter(), samples, [observation], timeline.filter_time_ns)
    assert_same_filter(timeline.slam, reference)


def test_the_result_does_not_depend_on_the_delay():
    # a hand sequence with turns: delays 0, one sample period and more give the same filter once the
    # robot has stopped for longer than the delay
    rng = np.random.default_rng(7)
    speeds = [tuple(rng.uniform(-6.0, 12.0, 2)) for _ in range(20)] + [(0.0, 0.0)] * 10
    samples = samples_from([50 * MS] * 30, speeds)
    observation = observation_at(samples, 470 * MS, ids=(0, 2))
    filters = []
    for delay_ns in (0, 50 * MS, 120 * MS, 300 * MS):
        # delivered after the sample at 0.45 s: queued (on time) for every delay
        timeline, applied = run_timeline(samples, observation, 9, delay_ns)
        assert [r.t_ns for r in applied] == [470 * MS]
        assert timeline.filter_time_ns == 1500 * MS - delay_ns
        filters.append(timeline.slam)
    reference = drive_by_hand(mapped_filter(), samples, [observation], samples[-1][0])
    for slam in filters:
        assert_same_filter(slam, reference)


# --- an observation applies at its own time ----------------------------------------------------------------


def test_a_late_observation_is_applied_at_its_stamp_not_at_the_current_pose():
    samples = straight_samples(12, dt_ns=50 * MS, speed=8.0)  # 0.264 m/s
    t_o = samples[3][0]
    observation = observation_at(samples, t_o, ids=(0, 1))
    delay_ns = 200 * MS
    on_time, applied_on_time = run_timeline(samples, observation, 3, delay_ns)
    late, applied_late = run_timeline(samples, observation, 6, delay_ns)  # three samples (0.15 s) later
    assert [r.t_ns for r in applied_on_time] == [r.t_ns for r in applied_late] == [t_o]
    assert_same_filter(late.slam, on_time.slam, atol=1e-12)
    np.testing.assert_array_equal(applied_late[0].association.landmark_ids, [0, 1])
    np.testing.assert_allclose(applied_late[0].association.nis, applied_on_time[0].association.nis, rtol=1e-9)

    # applying it at the pose of its arrival instead (4 cm further on) gives a visibly different map
    wrong = timeline_of(mapped_filter(), TimelineConfig(max_observation_delay=0.0))
    for k, sample in enumerate(samples):
        add(wrong, sample)
        if k == 6:
            wrong.slam.update_known(observation[1], observation[2])
    for slam in (late.slam, on_time.slam):
        assert np.abs(slam.state - wrong.slam.state).max() > 1e-3


def test_an_observation_at_the_newest_sample_applies_at_once():
    samples = straight_samples(5)
    timeline = timeline_of(mapped_filter(), TimelineConfig(max_observation_delay=0.1))
    for sample in samples:
        add(timeline, sample)
    t_w = samples[-1][0]
    _, ids, z = observation_at(samples, t_w)
    applied = timeline.add_observations(t_w, z, ids=ids)
    assert [r.t_ns for r in applied] == [t_w]
    assert timeline.filter_time_ns == t_w
    assert timeline.pending_count == 0
    reference = drive_by_hand(mapped_filter(), samples, [(t_w, ids, z)], t_w)
    assert_same_filter(timeline.slam, reference)


# --- queued observations -----------------------------------------------------------------------------------


def test_observations_newer_than_every_sample_wait_and_apply_in_stamp_order():
    samples = [
        (0, 0.0, 0.0),
        (50 * MS, 0.4, 0.5),
        (100 * MS, 0.8, 1.1),
        (150 * MS, 1.3, 1.6),
        (250 * MS, 2.1, 2.8),
    ]
    timeline = timeline_of(mapped_filter(), TimelineConfig(max_observation_delay=0.1))
    for sample in samples[:3]:
        assert add(timeline, sample) == []
    # three observations from the future, given out of order, each of different landmarks
    stamps_ids = [(220 * MS, (1, 2)), (130 * MS, (0,)), (170 * MS, (1,))]
    observations = [observation_at(samples, t, ids) for t, ids in stamps_ids]
    before = snapshot(timeline)
    for count, (t_o, ids, z) in enumerate(observations, start=1):
        assert timeline.add_observations(t_o, z, ids=ids) == []
        assert timeline.pending_count == count
    assert_unchanged(before[:5], snapshot(timeline)[:5])  # the filter does not move for queued ones

    # the sample at 0.15 s reaches only the one stamped 0.13 s
    applied = add(timeline, samples[3])
    assert [r.t_ns for r in applied] == [130 * MS]
    np.testing.assert_array_equal(applied[0].association.landmark_ids, [0])
    assert timeline.pending_count == 2
    assert timeline.filter_time_ns == 130 * MS  # max(0.13, 0.15 - 0.1) s
    # the sample at 0.25 s reaches the other two, oldest first
    applied = add(timeline, samples[4])
    assert [r.t_ns for r in applied] == [170 * MS, 220 * MS]
    # times are integer ns, exactly
    assert all(type(r.t_ns) is int for r in applied)
    assert type(timeline.filter_time_ns) is int and type(timeline.latest_time_ns) is int
    np.testing.assert_array_equal(applied[0].association.landmark_ids, [1])
    np.testing.assert_array_equal(applied[1].association.landmark_ids, [1, 2])
    for association in [r.association for r in applied]:
        assert np.all(association.status == ObservationStatus.MATCHED)
        assert association.nis > 0.0
    assert timeline.pending_count == 0
    assert timeline.filter_time_ns == 220 * MS

    reference = drive_by_hand(mapped_filter(), samples, observations, 220 * MS)
    assert_same_filter(timeline.slam, reference)
    # the order matters: the updates in arrival order give another filter
    wrong_order = mapped_filter()
    phi = (0.0, 0.0)
    for t_o, ids, z in observations:
        phi_o = angles_at(samples, t_o)
        wrong_order.predict((phi_o[0] - phi[0], phi_o[1] - phi[1]))
        wrong_order.update_known(ids, z)
        phi = phi_o
    assert np.abs(wrong_order.state - reference.state).max() > 1e-4


def test_equal_stamps_wait_in_arrival_order():
    samples = straight_samples(4)
    timeline = timeline_of(mapped_filter(), TimelineConfig(max_observation_delay=0.0))
    add(timeline, samples[0])
    first = observation_at(samples, 70 * MS, (0,))
    second = observation_at(samples, 70 * MS, (2,), offset=(-0.01, 0.003))
    timeline.add_observations(first[0], first[2], ids=first[1])
    timeline.add_observations(second[0], second[2], ids=second[1])
    add(timeline, samples[1])
    applied = add(timeline, samples[2])
    assert [list(r.association.landmark_ids) for r in applied] == [[0], [2]]
    reference = mapped_filter()
    reference.predict(angles_at(samples, 70 * MS))
    reference.update_known(first[1], first[2])
    reference.update_known(second[1], second[2])
    phi = angles_at(samples, 70 * MS)
    reference.predict((samples[2][1] - phi[0], samples[2][2] - phi[1]))
    assert_same_filter(timeline.slam, reference)


def test_unknown_association_observations_are_timed_too():
    # without ids the timeline calls update_unknown: one scan, one call, at the stamp
    samples = straight_samples(6)
    config = dataclasses.replace(CONFIG, confirm_count=1)
    slam = EkfSlam(config, MOTION, Transform2D(0.1, -0.2, 0.3))
    slam.update_unknown(observe(slam.pose, LANDMARKS), stamp_ns=0)
    reference = copy.deepcopy(slam)
    timeline = timeline_of(slam, TimelineConfig(max_observation_delay=0.1))
    t_o, _, z = observation_at(samples, 120 * MS, ids=(0, 1, 2))
    for k, sample in enumerate(samples):
        applied = add(timeline, sample)
        if k == 2:
            assert timeline.add_observations(t_o, z) == []
        if k == 3:
            assert [r.t_ns for r in applied] == [t_o]
            np.testing.assert_array_equal(applied[0].association.status, [ObservationStatus.MATCHED] * 3)
    phi_o = angles_at(samples, t_o)
    reference.predict(phi_o)
    reference.update_unknown(z, stamp_ns=t_o)
    phi_f = angles_at(samples, timeline.filter_time_ns)
    reference.predict((phi_f[0] - phi_o[0], phi_f[1] - phi_o[1]))
    assert_same_filter(timeline.slam, reference)


# --- bad input and its refusal -----------------------------------------------------------------------------


def started_timeline(delay=0.05, pending=20, n=5):
    config = TimelineConfig(max_observation_delay=delay, max_pending_observations=pending)
    timeline = timeline_of(mapped_filter(), config)
    for sample in straight_samples(n):
        add(timeline, sample)
    return timeline


GOOD_Z = [[1.0, 0.2], [1.4, -0.6]]


def test_a_stale_observation_is_refused_and_changes_nothing():
    timeline = started_timeline(delay=0.05)  # samples 0 .. 0.2 s, filter at 0.15 s
    assert timeline.filter_time_ns == 150 * MS
    before = snapshot(timeline)
    with pytest.raises(ValueError, match="stale"):
        timeline.add_observations(149 * MS, GOOD_Z, ids=[0, 1])
    with pytest.raises(ValueError, match="stale"):
        timeline.add_observations(150 * MS - 1, GOOD_Z, ids=[0, 1])  # one ns too late
    assert_unchanged(before, snapshot(timeline))
    # exactly at the filter time is still in time
    assert [r.t_ns for r in timeline.add_observations(timeline.filter_time_ns, GOOD_Z, ids=[0, 1])] == [
        before[3]
    ]


def test_observations_before_the_first_wheel_sample_are_refused():
    timeline = timeline_of(mapped_filter())
    state = timeline.slam.state.copy()
    with pytest.raises(ValueError):
        timeline.add_observations(1_000_000_000, GOOD_Z, ids=[0, 1])
    with pytest.raises(ValueError):
        timeline.latest_pose()
    assert timeline.pending_count == 0
    assert timeline.filter_time_ns is None and timeline.latest_time_ns is None
    np.testing.assert_array_equal(timeline.slam.state, state)
    # the first wheel sample only starts the timeline
    assert timeline.add_motion(2_000_000_000, (5.0, 6.0)) == []
    assert timeline.filter_time_ns == timeline.latest_time_ns == 2_000_000_000
    np.testing.assert_array_equal(timeline.slam.state, state)


def test_too_many_waiting_observations_are_refused():
    timeline = started_timeline(pending=2)
    t_w = timeline.latest_time_ns
    timeline.add_observations(t_w + 10 * MS, GOOD_Z, ids=[0, 1])
    timeline.add_observations(t_w + 20 * MS, GOOD_Z, ids=[0, 1])
    before = snapshot(timeline)
    with pytest.raises(ValueError):
        timeline.add_observations(t_w + 30 * MS, GOOD_Z, ids=[0, 1])
    assert_unchanged(before, snapshot(timeline))
    # an observation that applies at once does not wait, so it is not limited
    assert len(timeline.add_observations(t_w, GOOD_Z, ids=[0, 1])) == 1
    assert timeline.pending_count == 2


@pytest.mark.parametrize(
    "stamp",
    [math.nan, math.inf, -math.inf, True, "1.0", None, 0.25, 250_000_000.0, np.float64(250_000_000.0)],
)
def test_non_integer_observation_stamps_are_refused(stamp):
    # stamps are integer ns: a float (even an integral one, e.g. a time in seconds) is refused
    timeline = started_timeline()
    before = snapshot(timeline)
    with pytest.raises(ValueError):
        timeline.add_observations(stamp, GOOD_Z, ids=[0, 1])
    assert_unchanged(before, snapshot(timeline))


T_LATER = 1_000_000_000  # ns, after every sample of started_timeline


@pytest.mark.parametrize(
    "t_ns, angles",
    [
        pytest.param(math.nan, (1.0, 1.0), id="nan-time"),
        pytest.param(math.inf, (1.0, 1.0), id="inf-time"),
        pytest.param(1.0, (1.0, 1.0), id="float-time"),  # a float time (seconds?) is not integer ns
        pytest.param(float(T_LATER), (1.0, 1.0), id="integral-float-time"),
        pytest.param(True, (1.0, 1.0), id="bool-time"),
        pytest.param(T_LATER, (math.nan, 1.0), id="nan-angle"),
        pytest.param(T_LATER, (1.0, -math.inf), id="inf-angle"),
        pytest.param(T_LATER, (1.0, True), id="bool-angle"),
        pytest.param(T_LATER, (1.0, "2"), id="string-angle"),
        pytest.param(T_LATER, (1.0, 1.0, 1.0), id="three-angles"),  # not the two of the earlier samples
        pytest.param(T_LATER, (1.0,), id="one-angle"),
    ],
)
def test_invalid_wheel_samples_are_refused(t_ns, angles):
    timeline = started_timeline()
    timeline.add_observations(timeline.latest_time_ns + 500 * MS, GOOD_Z, ids=[0, 1])
    before = snapshot(timeline)
    with pytest.raises(ValueError):
        timeline.add_motion(t_ns, angles)
    with pytest.raises(ValueError):
        timeline.restart(t_ns, angles)
    assert_unchanged(before, snapshot(timeline))


def test_time_going_backwards_is_refused_and_changes_nothing():
    timeline = started_timeline()
    t_w = timeline.latest_time_ns
    timeline.add_observations(t_w + 30 * MS, GOOD_Z, ids=[0, 1])
    before = snapshot(timeline)
    with pytest.raises(ValueError, match="backwards"):
        timeline.add_motion(t_w - 1, (100.0, 100.0))  # one ns before
    assert_unchanged(before, snapshot(timeline))
    # the same time again is not backwards: a repeated sample is accepted
    assert add(timeline, straight_samples(5)[-1]) == []
    assert_unchanged(before, snapshot(timeline))


@pytest.mark.parametrize(
    "delay, waiting",
    [(0.0, 0), (0.05, 0), (0.05, 2), (0.3, 2)],
    ids=["filter-reaches-it", "filter-lags", "releases-observations", "filter-far-behind"],
)
def test_a_motion_sample_the_model_refuses_changes_nothing(delay, waiting):
    # finite wheel angles whose increment the kinematics refuses (dphi_right - dphi_left overflows to -inf),
    # whether the filter would reach the new interval in this call or only later, and with observations
    # waiting that the sample would release
    timeline, twin = started_timeline(delay=delay), started_timeline(delay=delay)
    t_w = timeline.latest_time_ns
    for k in range(1, waiting + 1):
        for t in (timeline, twin):
            t.add_observations(t_w + 10 * k * MS, GOOD_Z, ids=[0, 1])
    before = snapshot(timeline)
    with pytest.raises(ValueError):
        timeline.add_motion(t_w + 50 * MS, (1e308, -1e308))
    assert_unchanged(before, snapshot(timeline))
    # and it is forgotten: the next samples drive on from the last good one, as in a twin that never saw it
    for sample in [(t_w + 60 * MS, 2.0, 2.1), (t_w + 400 * MS, 4.0, 4.5)]:
        assert [r.t_ns for r in add(timeline, sample)] == [r.t_ns for r in add(twin, sample)]
        assert_same_filter(timeline.slam, twin.slam)
        times = (timeline.filter_time_ns, timeline.latest_time_ns, timeline.pending_count)
        assert times == (twin.filter_time_ns, twin.latest_time_ns, twin.pending_count)
        (pose, P), (twin_pose, twin_P) = timeline.latest_pose(), twin.latest_pose()
        np.testing.assert_allclose(pose.as_array(), twin_pose.as_array(), rtol=0.0, atol=MEAN_ATOL)
        np.testing.assert_allclose(P, twin_P, rtol=0.0, atol=1e-9 * np.abs(twin_P).max())


def test_without_the_motion_check_a_refused_sample_is_taken_until_a_prediction_refuses_it():
    # check_motion=False (offline runs that end on the first error): the timeline takes the sample while the
    # filter lags behind it, and the prediction that reaches it raises
    timeline = SlamTimeline(mapped_filter(), WheelAngles(), TimelineConfig(max_observation_delay=0.3))
    unchecked = SlamTimeline(
        mapped_filter(), WheelAngles(), TimelineConfig(max_observation_delay=0.3), check_motion=False
    )
    for sample in straight_samples(5):
        add(timeline, sample)
        add(unchecked, sample)
    t_w = timeline.latest_time_ns
    with pytest.raises(ValueError):
        timeline.add_motion(t_w + 50 * MS, (1e308, -1e308))
    assert unchecked.add_motion(t_w + 50 * MS, (1e308, -1e308)) == []
    assert unchecked.latest_time_ns == t_w + 50 * MS
    with pytest.raises(ValueError):
        unchecked.add_motion(t_w + 400 * MS, (1e308, -1e308))


def test_restart_first_brings_the_filter_to_the_newest_sample():
    # the filter runs max_observation_delay behind; a clock jump must not lose that last stretch of motion
    samples = straight_samples(8)
    timeline = timeline_of(mapped_filter(), TimelineConfig(max_observation_delay=0.2))
    for sample in samples:
        add(timeline, sample)
    assert timeline.filter_time_ns < timeline.latest_time_ns
    expected_pose, expected_P = timeline.latest_pose()
    timeline.restart(0, (0.0, 0.0))
    np.testing.assert_allclose(timeline.slam.pose.as_array(), expected_pose.as_array(), rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(timeline.slam.pose_covariance, expected_P, rtol=1e-12, atol=0.0)


def test_restart_re_anchors_time_keeps_the_estimate_and_drops_waiting_observations():
    timeline = started_timeline(delay=0.0, n=8)
    timeline.add_observations(timeline.latest_time_ns + 20 * MS, GOOD_Z, ids=[0, 1])
    assert timeline.pending_count == 1
    kept = copy.deepcopy(timeline.slam)
    timeline.restart(0, (100.0, 200.0))  # the clock and the wheel angles jumped
    assert timeline.filter_time_ns == timeline.latest_time_ns == 0
    assert timeline.pending_count == 0
    assert_same_filter(timeline.slam, kept, atol=0.0)
    pose, P = timeline.latest_pose()
    assert pose == kept.pose
    np.testing.assert_array_equal(P, kept.pose_covariance)
    # the motion from the new anchor only: increments (0.4, 0.7)
    assert timeline.add_motion(50 * MS, (100.4, 200.7)) == []
    kept.predict((0.4, 0.7))
    assert_same_filter(timeline.slam, kept)
    # observations are placed in the new time
    with pytest.raises(ValueError, match="stale"):
        timeline.add_observations(40 * MS, GOOD_Z, ids=[0, 1])
    assert len(timeline.add_observations(50 * MS, GOOD_Z, ids=[0, 1])) == 1


# --- the published pose ------------------------------------------------------------------------------------


def test_latest_pose_is_the_filter_moved_on_to_the_newest_sample():
    samples = samples_from([50 * MS] * 8, [(4.0, 9.0)] * 8)
    timeline = timeline_of(mapped_filter(), TimelineConfig(max_observation_delay=0.12))
    for sample in samples:
        add(timeline, sample)
    t_f = timeline.filter_time_ns
    assert t_f == samples[-1][0] - 120 * MS
    phi_f = angles_at(samples, t_f)
    increments = samples[-1][1] - phi_f[0], samples[-1][2] - phi_f[1]
    expected_pose, expected_P = timeline.slam.propagated_pose_along([increments])
    predicted = copy.deepcopy(timeline.slam)
    predicted.predict(increments)

    before = snapshot(timeline)
    pose, P = timeline.latest_pose()
    np.testing.assert_allclose(pose.as_array(), expected_pose.as_array(), rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(P, expected_P, rtol=0.0, atol=1e-12 * np.abs(P).max())
    np.testing.assert_allclose(pose.as_array(), predicted.pose.as_array(), rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(P, predicted.pose_covariance, rtol=0.0, atol=1e-12 * np.abs(P).max())
    # it is ahead of the filter (the robot moves), and asking does not move the filter
    assert np.abs(pose.as_array() - timeline.slam.pose.as_array()).max() > 0.01
    assert_unchanged(before, snapshot(timeline))


def test_latest_pose_follows_each_sample_interval_when_the_wheel_speeds_change():
    # over the delay the robot turns left, then right: one arc per interval, as the filter will predict
    speeds = [(4.0, 9.0), (4.0, 9.0), (9.0, 2.0), (-3.0, 6.0), (8.0, 8.0), (1.0, 7.0)]
    samples = samples_from([50 * MS] * len(speeds), speeds)
    timeline = timeline_of(mapped_filter(), TimelineConfig(max_observation_delay=0.17))
    for sample in samples:
        add(timeline, sample)
    t_f = timeline.filter_time_ns
    expected = copy.deepcopy(timeline.slam)
    phi = angles_at(samples, t_f)
    later = [sample for sample in samples if sample[0] > t_f]
    assert len(later) >= 3
    for _, left, right in later:
        expected.predict((left - phi[0], right - phi[1]))
        phi = (left, right)
    pose, P = timeline.latest_pose()
    np.testing.assert_allclose(pose.as_array(), expected.pose.as_array(), rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(P, expected.pose_covariance, rtol=0.0, atol=1e-12 * np.abs(P).max())
    # one arc from t_f straight to the newest sample would not be the same pose
    one_arc, _ = timeline.slam.propagated_pose_along(
        [(later[-1][1] - angles_at(samples, t_f)[0], later[-1][2] - angles_at(samples, t_f)[1])]
    )
    assert np.abs(one_arc.as_array() - pose.as_array()).max() > 1e-4


def test_without_delay_the_filter_is_at_the_newest_sample():
    samples = samples_from(
        [50 * MS, 30 * MS, 70 * MS, 50 * MS], [(3.0, 5.0), (-2.0, 4.0), (6.0, 6.0), (1.0, -1.0)]
    )
    timeline = timeline_of(mapped_filter(), TimelineConfig(max_observation_delay=0.0))
    for t, left, right in samples:
        timeline.add_motion(t, (left, right))
        assert timeline.filter_time_ns == timeline.latest_time_ns == t
        pose, P = timeline.latest_pose()
        assert pose == timeline.slam.pose
        np.testing.assert_array_equal(P, timeline.slam.pose_covariance)
    assert_same_filter(timeline.slam, drive_by_hand(mapped_filter(), samples, [], samples[-1][0]))


# --- invalid observations are refused when they arrive -----------------------------------------------------

R2 = [np.diag([1e-4, 1e-4])] * 2


@pytest.mark.parametrize(
    "z, R, ids",
    [
        pytest.param([[math.nan, 0.2], [1.4, -0.6]], None, [0, 1], id="nan-range"),
        pytest.param([[1.0, math.inf], [1.4, -0.6]], None, [0, 1], id="inf-bearing"),
        pytest.param([[-1.0, 0.2], [1.4, -0.6]], None, [0, 1], id="negative-range"),
        pytest.param([1.0, 0.2], None, [0], id="not-2d"),
        pytest.param([[1.0, 0.2, 0.0], [1.4, -0.6, 0.0]], None, [0, 1], id="three-columns"),
        pytest.param(GOOD_Z, None, [0], id="too-few-ids"),
        pytest.param(GOOD_Z, None, [0, 1, 2], id="too-many-ids"),
        pytest.param(GOOD_Z, None, [1, 1], id="duplicate-ids"),
        pytest.param(GOOD_Z, None, [0, -1], id="negative-id"),
        pytest.param(GOOD_Z, None, [0.0, 1.0], id="float-ids"),
        pytest.param(GOOD_Z, R2[:1], [0, 1], id="too-few-R"),
        pytest.param(GOOD_Z, [np.diag([math.nan, 1e-4])] * 2, [0, 1], id="nan-R"),
        pytest.param(GOOD_Z, [[[1e-4, 2e-4], [2e-4, 1e-4]]] * 2, [0, 1], id="indefinite-R"),
        pytest.param(GOOD_Z, None, None, id="no-ids-for-a-known-association-filter"),
    ],
)
@pytest.mark.parametrize("when", ["queued", "at-once"])
def test_invalid_observations_are_refused_on_arrival(z, R, ids, when):
    timeline = started_timeline()
    t_o = timeline.latest_time_ns + 20 * MS if when == "queued" else timeline.latest_time_ns
    before = snapshot(timeline)
    with pytest.raises(ValueError):
        timeline.add_observations(t_o, z, R, ids)
    assert_unchanged(before, snapshot(timeline))
    # nothing waits that would fail later: the next samples apply nothing
    assert timeline.add_motion(t_o + 50 * MS, (3.0, 3.0)) == []


def test_observations_with_and_without_ids_cannot_wait_together():
    # a fresh filter has no association mode yet; the first update fixes it, so mixing the two kinds in
    # the queue would make add_motion fail later: the second kind is refused on arrival
    slam = EkfSlam(CONFIG, MOTION)
    timeline = timeline_of(slam, TimelineConfig(max_observation_delay=0.0))
    timeline.add_motion(0, (0.0, 0.0))
    timeline.add_observations(10 * MS, GOOD_Z, ids=[0, 1])
    before = snapshot(timeline)
    with pytest.raises(ValueError):
        timeline.add_observations(20 * MS, GOOD_Z)
    with pytest.raises(ValueError):
        timeline.add_observations(0, GOOD_Z)  # nor applied at once ahead of the waiting ones
    assert_unchanged(before, snapshot(timeline))
    applied = timeline.add_motion(50 * MS, (1.0, 1.0))
    assert [r.t_ns for r in applied] == [10 * MS]
    np.testing.assert_array_equal(timeline.slam.landmark_ids, [0, 1])
