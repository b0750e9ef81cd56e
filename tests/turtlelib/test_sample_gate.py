"""SampleGate: hand cases of each verdict, and properties: lone hostile samples among a real stream never
change what is accepted; a source that goes on after a silence loses no motion, one reset to its origin
restarts."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from turtlelib.motion.sample_gate import SampleGate, SampleGateConfig, Verdict

MS = 1_000_000  # ns
# 6 rad/s at most, 1.5 x with the default margin; slack 0.001 rad
MAX_RATE = 6.0
SLACK = 0.001


def gate(**config) -> SampleGate:
    return SampleGate(SampleGateConfig(**config), [MAX_RATE, MAX_RATE], [SLACK, SLACK])


def stream(count: int, t0_ms: int = 0, speed: float = 2.0, phi0: float = 0.0, period_ms: int = 50):
    """``count`` samples of both wheels turning at ``speed`` rad/s, every ``period_ms``."""
    return [
        (
            (t0_ms + k * period_ms) * MS,
            (phi0 + speed * k * period_ms / 1000, phi0 - speed * k * period_ms / 1000),
        )
        for k in range(count)
    ]


def offer_all(g: SampleGate, samples):
    return [g.offer(t, s) for t, s in samples]


def test_a_continuing_stream_is_accepted_sample_by_sample():
    g = gate()
    results = offer_all(g, stream(10))
    assert [r.verdict for r in results] == [Verdict.ACCEPTED] * 10
    assert [r.samples for r in results] == [(sample,) for sample in stream(10)]
    assert g.accepted == stream(10)[-1]


def test_an_exact_copy_is_a_duplicate_and_a_changed_copy_refused():
    g = gate()
    offer_all(g, stream(2))
    t, s = stream(2)[-1]
    assert g.offer(t, s).verdict is Verdict.DUPLICATE
    refused = g.offer(t, (s[0] + 0.01, s[1]))
    assert refused.verdict is Verdict.REFUSED and "not after" in refused.reason
    assert g.accepted == (t, s)


def test_the_rate_bound_is_max_rate_times_margin_times_dt_plus_slack():
    # 50 ms at 6 rad/s x 1.5 = 0.45 rad, + 0.001 slack
    g = gate()
    g.offer(0, (0.0, 0.0))
    assert g.offer(50 * MS, (0.451 - 1e-9, 0.0)).verdict is Verdict.ACCEPTED
    g = gate()
    g.offer(0, (0.0, 0.0))
    refused = g.offer(50 * MS, (0.0, -0.451 - 1e-6))
    assert refused.verdict is Verdict.REFUSED and "value 1 moved" in refused.reason


@pytest.mark.parametrize(
    "hostile",
    [
        (1_000 * MS, (0.0, 0.0)),  # replayed from 1 s before the stream's end
        (2_950 * MS, (1.9, -1.9)),  # stamped 2 s in the future
        (1_950 * MS, (1e6, -3.9)),  # one wheel +1e6 rad
        (1_950 * MS, (1e200, 1e200)),  # absurd but finite
        (1_850 * MS, (3.7, -3.7)),  # a copy of an earlier sample
    ],
)
def test_a_lone_hostile_sample_is_refused_and_forgotten(hostile):
    g = gate(restart_samples=2)
    real = stream(42)
    offer_all(g, real[:39])
    assert g.offer(*hostile).verdict is Verdict.REFUSED
    # the real stream goes on; the candidate the hostile sample left is dropped by the first real one
    assert [g.offer(*sample).samples for sample in real[39:]] == [(sample,) for sample in real[39:]]


def test_a_restarted_source_restarts_after_restart_samples_and_loses_no_motion_after_it():
    g = gate(restart_samples=3)
    offer_all(g, stream(40, t0_ms=10_000, phi0=5.0))
    again = stream(4)  # the simulator restarted: time and encoders from 0
    results = offer_all(g, again)
    assert [r.verdict for r in results] == [
        Verdict.REFUSED,
        Verdict.REFUSED,
        Verdict.RESTARTED,
        Verdict.ACCEPTED,
    ]
    assert results[2].samples == tuple(again[:3]) and "restarted" in results[2].reason
    assert results[3].samples == (again[3],)


def test_a_long_silence_is_bridged_once_the_samples_after_it_agree():
    # the wheels could have turned that far in the gap: the gap's motion is kept (bridged)
    g = gate(max_sample_gap=0.5, restart_samples=3)
    offer_all(g, stream(5))
    after = stream(3, t0_ms=200 + 1_900, phi0=0.2 + 0.5)
    results = offer_all(g, after)
    assert [r.verdict for r in results] == [Verdict.REFUSED, Verdict.REFUSED, Verdict.BRIDGED]
    assert results[-1].samples == tuple(after) and "silent for 1.900 s" in results[-1].reason


# an odometry pose (x, y, theta) of a robot at most 0.3 m/s and 2 rad/s, heading read modulo 2 pi
ODOM_RATES = (0.3, 0.3, 2.0)
ODOM_SLACK = (1e-3, 1e-3, 1e-3)


def odom_gate(**config) -> SampleGate:
    return SampleGate(SampleGateConfig(**config), ODOM_RATES, ODOM_SLACK, periods=(None, None, 2 * math.pi))


def odom_arc(times_ms, x0=1.0, y0=-0.5, theta0=0.3, v=0.2, omega=0.25):
    """Odometry poses along a circle at ``v`` m/s, ``omega`` rad/s, from (x0, y0, theta0) at t = 0."""
    poses = []
    for t_ms in times_ms:
        theta = theta0 + omega * t_ms / 1000
        x = x0 + v / omega * (math.sin(theta) - math.sin(theta0))
        y = y0 - v / omega * (math.cos(theta) - math.cos(theta0))
        poses.append((t_ms * MS, (x, y, theta)))
    return poses


def test_an_odometry_silent_for_3_4_s_while_the_robot_drives_on_is_bridged_losing_no_motion():
    # ACES: a recorded odom stream at 10 Hz falls silent for 3.4 s while the robot drives on
    g = odom_gate()
    times_ms = [100 * k for k in range(20)] + [1_900 + 3_400 + 100 * k for k in range(10)]
    real = odom_arc(times_ms)
    applied, verdicts = [], []
    for sample in real:
        result = g.offer(*sample)
        verdicts.append(result.verdict)
        applied.extend(result.samples)
    assert verdicts[20:23] == [Verdict.REFUSED, Verdict.REFUSED, Verdict.BRIDGED]
    assert verdicts[:20] + verdicts[23:] == [Verdict.ACCEPTED] * 27
    # every sample applied, in order: the step across the silence is the measured net motion
    assert applied == real
    assert (g.tally.refused, g.tally.bridged, g.tally.restarts) == (2, 1, 0)
    assert g.tally.longest_bridge_s == pytest.approx(3.4, abs=1e-9)


@pytest.mark.parametrize("silence_ms", [3_400, 9_000])
def test_encoders_reset_to_zero_after_a_silence_restart_though_the_rate_bound_allows_the_change(silence_ms):
    # 1.95 rad back to 0 on each wheel fits 9 rad/s over the silence; a reset starts at the origin, a robot
    # that went on would not be within a tick of it on both wheels at once
    g = gate(restart_samples=3)
    offer_all(g, stream(40, phi0=0.0, speed=1.0))
    last_t, last = g.accepted
    assert last != (0.0, 0.0)
    after = stream(3, t0_ms=last_t // MS + silence_ms, speed=1.0)  # from (0, 0) again
    results = offer_all(g, after)
    assert [r.verdict for r in results] == [Verdict.REFUSED, Verdict.REFUSED, Verdict.RESTARTED]
    assert results[-1].samples == tuple(after) and "origin" in results[-1].reason
    assert (g.tally.bridged, g.tally.restarts) == (0, 1)


def test_an_odometry_reset_to_the_identity_restarts_with_its_heading_unwrapped_by_its_source():
    # the source unwraps the heading against the last accepted one (6.4 rad): a reset reads 2 pi
    g = odom_gate()
    before = odom_arc([0, 100], theta0=6.3, omega=1.0)
    offer_all(g, before)
    reset = [(5_000 * MS + k * 100 * MS, (0.02 * k, 0.0, 2 * math.pi)) for k in range(3)]
    results = offer_all(g, reset)
    assert results[-1].verdict is Verdict.RESTARTED and "origin" in results[-1].reason


def test_a_robot_at_the_origin_before_and_after_a_silence_is_bridged():
    # no motion either way, and no sign of a reset
    g = gate(restart_samples=2)
    offer_all(g, [(0, (0.0, 0.0)), (50 * MS, (0.0, 0.0005))])
    results = offer_all(g, [(3_000 * MS, (0.0, 0.0)), (3_050 * MS, (0.0, 0.0))])
    assert [r.verdict for r in results] == [Verdict.REFUSED, Verdict.BRIDGED]


def test_a_silence_longer_than_max_bridged_gap_restarts_instead_of_making_up_an_arc():
    g = gate(max_sample_gap=0.5, max_bridged_gap=2.0, restart_samples=3)
    offer_all(g, stream(5))
    after = stream(3, t0_ms=200 + 2_001, phi0=0.7)  # the wheels could have turned that far, but over 2 s
    results = offer_all(g, after)
    assert [r.verdict for r in results] == [Verdict.REFUSED, Verdict.REFUSED, Verdict.RESTARTED]
    assert results[-1].samples == tuple(after)


def test_every_refusal_bridge_and_restart_is_counted_with_the_last_reason():
    # nothing refused goes unreported: a bridged silence (2 refused, then bridged), a lone hostile
    # sample, a restart (2 refused, then restarted); duplicates are not refusals; reset keeps the totals
    g = gate(max_sample_gap=0.5, restart_samples=3)
    offer_all(g, stream(5))
    assert (g.tally.refused, g.tally.bridged, g.tally.restarts, g.tally.last_reason) == (0, 0, 0, "")
    g.offer(*stream(5)[-1])
    first_after = stream(3, t0_ms=200 + 1_900, phi0=0.2 + 0.5)
    g.offer(*first_after[0])
    assert g.tally.refused == 1 and "max_sample_gap" in g.tally.last_reason
    offer_all(g, first_after[1:])
    assert (g.tally.refused, g.tally.bridged, g.tally.restarts) == (2, 1, 0)
    assert "bridged" in g.tally.last_reason and g.tally.longest_bridge_s == pytest.approx(1.9)
    t, s = g.accepted
    g.offer(t + 50 * MS, (s[0] + 5.0, s[1]))
    assert (g.tally.refused, g.tally.bridged, g.tally.restarts) == (3, 1, 0)
    assert "max rate" in g.tally.last_reason
    offer_all(g, stream(3))
    assert (g.tally.refused, g.tally.bridged, g.tally.restarts) == (5, 1, 1)
    assert "restarted" in g.tally.last_reason
    g.reset()
    assert (g.tally.refused, g.tally.bridged, g.tally.restarts) == (5, 1, 1)


def test_a_corrupt_first_sample_is_left_behind_by_the_real_stream():
    g = gate(restart_samples=3)
    g.offer(0, (1e200, 1e200))
    results = offer_all(g, stream(4, t0_ms=50))
    assert [r.verdict for r in results][:3] == [Verdict.REFUSED, Verdict.REFUSED, Verdict.RESTARTED]
    assert g.accepted == stream(4, t0_ms=50)[-1]


def test_reset_takes_the_next_sample_as_a_new_start():
    g = gate()
    offer_all(g, stream(3))
    g.reset()
    assert g.accepted is None
    assert g.offer(0, (100.0, 100.0)).verdict is Verdict.ACCEPTED


@pytest.mark.parametrize(
    ("t_ns", "sample"),
    [(0.5, (0.0, 0.0)), (0, (math.nan, 0.0)), (0, (math.inf, 0.0)), (0, (0.0,)), (0, (0.0, 0.0, 0.0))],
)
def test_invalid_samples_raise_and_change_nothing(t_ns, sample):
    g = gate()
    g.offer(*stream(1)[0])
    with pytest.raises(ValueError):
        g.offer(t_ns, sample)
    assert g.accepted == stream(1)[0]


@pytest.mark.parametrize(
    "config",
    [
        {"speed_margin": -0.1},
        {"max_sample_gap": 0.0},
        {"max_sample_gap": 3.0, "max_bridged_gap": 2.0},
        {"restart_samples": 0},
        {"restart_samples": 1.5},
    ],
)
def test_invalid_config_raises(config):
    with pytest.raises(ValueError):
        SampleGateConfig(**config)


def test_rates_and_slack_must_pair_up():
    with pytest.raises(ValueError):
        SampleGate(SampleGateConfig(), [1.0, 1.0], [0.0])
    with pytest.raises(ValueError):
        SampleGate(SampleGateConfig(), [0.0], [0.0])
    with pytest.raises(ValueError):
        SampleGate(SampleGateConfig(), [1.0, 1.0], [0.0, 0.0], periods=[None])
    with pytest.raises(ValueError):
        SampleGate(SampleGateConfig(), [1.0], [0.0], periods=[0.0])


hostile_samples = st.tuples(
    st.integers(min_value=-(10**12), max_value=10**12),
    st.tuples(*[st.floats(min_value=-1e200, max_value=1e200, allow_nan=False)] * 2),
)


@settings(max_examples=200, derandomize=True)
@given(
    positions=st.lists(st.integers(min_value=1, max_value=59), unique=True, max_size=15),
    hostile=st.lists(hostile_samples, min_size=15, max_size=15),
)
def test_lone_hostile_samples_never_change_what_is_accepted(positions, hostile):
    """A real stream with single hostile samples inserted (never two in a row): every real sample is
    accepted, in order, and nothing else is, whatever the hostile ones are (one that happens to continue
    the stream is plausible, and taken: only those that do not continue it are checked)."""
    real = stream(60)
    g = gate(restart_samples=2)
    applied = []
    for k, sample in enumerate(real):
        if k in positions:
            h = hostile[positions.index(k)]
            result = g.offer(*h)
            if result.verdict is Verdict.ACCEPTED:
                return  # a plausible "hostile" sample: not what this property is about
            assert result.verdict in (Verdict.REFUSED, Verdict.DUPLICATE)
        result = g.offer(*sample)
        assert result.verdict is Verdict.ACCEPTED
        applied.extend(result.samples)
    assert applied == real


@settings(max_examples=100, derandomize=True)
@given(
    phi0=st.floats(min_value=-100.0, max_value=100.0),
    speed=st.floats(min_value=-MAX_RATE, max_value=MAX_RATE),
    silence_ms=st.integers(min_value=51, max_value=10_000),
)
def test_a_source_that_goes_on_after_a_silence_up_to_max_bridged_gap_loses_no_motion(phi0, speed, silence_ms):
    """Wheels turning at any speed within the bound, silent for up to max_bridged_gap (10 s): every sample
    is applied, in order, the one after the silence as one step from the one before it."""
    times_ns = [k * 50 * MS for k in range(10)] + [(450 + silence_ms + k * 50) * MS for k in range(5)]
    real = [(t, (phi0 + speed * t / 1e9, phi0 - speed * t / 1e9)) for t in times_ns]
    g = gate()
    applied = [sample for t, s in real for sample in g.offer(t, s).samples]
    assert applied == real
    assert g.tally.restarts == 0 and g.tally.bridged == (silence_ms > 500)


@settings(max_examples=100, derandomize=True)
@given(
    phi0=st.floats(min_value=0.01, max_value=100.0),
    speed=st.floats(min_value=-MAX_RATE, max_value=MAX_RATE),
    silence_ms=st.integers(min_value=501, max_value=60_000),
)
def test_a_source_reset_to_its_origin_after_any_silence_restarts_there(phi0, speed, silence_ms):
    """A source away from its origin, reset to zero after any silence longer than max_sample_gap: the
    stream restarts at the first sample after it, whatever the rate bound allows over the silence."""
    g = gate(restart_samples=3)
    offer_all(g, stream(10, phi0=phi0, speed=speed))
    after = stream(3, t0_ms=450 + silence_ms, speed=speed)
    results = offer_all(g, after)
    assert results[-1].verdict is Verdict.RESTARTED and results[-1].samples == tuple(after)
