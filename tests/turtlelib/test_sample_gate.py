"""SampleGate: hand cases of each verdict, and a property: lone hostile samples among a real stream never
change what is accepted."""

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


def test_a_long_silence_continues_once_the_samples_after_it_agree():
    # the wheels could have turned that far in the gap: the gap's motion is kept (bridged)
    g = gate(max_sample_gap=0.5, restart_samples=3)
    offer_all(g, stream(5))
    after = stream(3, t0_ms=200 + 1_900, phi0=0.2 + 0.5)
    results = offer_all(g, after)
    assert [r.verdict for r in results] == [Verdict.REFUSED, Verdict.REFUSED, Verdict.ACCEPTED]
    assert results[-1].samples == tuple(after)


def test_a_silence_longer_than_max_bridged_gap_restarts_instead_of_making_up_an_arc():
    g = gate(max_sample_gap=0.5, max_bridged_gap=2.0, restart_samples=3)
    offer_all(g, stream(5))
    after = stream(3, t0_ms=200 + 2_001, phi0=0.7)  # the wheels could have turned that far, but over 2 s
    results = offer_all(g, after)
    assert [r.verdict for r in results] == [Verdict.REFUSED, Verdict.REFUSED, Verdict.RESTARTED]
    assert results[-1].samples == tuple(after)


def test_every_refused_sample_and_every_restart_is_counted_with_the_last_reason():
    # nothing refused goes unreported: a bridged silence (2 refused, then accepted), a lone hostile
    # sample, a restart (2 refused, then restarted); duplicates are not refusals; reset keeps the totals
    g = gate(max_sample_gap=0.5, restart_samples=3)
    offer_all(g, stream(5))
    assert (g.tally.refused, g.tally.restarts, g.tally.last_reason) == (0, 0, "")
    g.offer(*stream(5)[-1])
    offer_all(g, stream(3, t0_ms=200 + 1_900, phi0=0.2 + 0.5))
    assert (g.tally.refused, g.tally.restarts) == (2, 0) and "max_sample_gap" in g.tally.last_reason
    t, s = g.accepted
    g.offer(t + 50 * MS, (s[0] + 5.0, s[1]))
    assert (g.tally.refused, g.tally.restarts) == (3, 0) and "max rate" in g.tally.last_reason
    offer_all(g, stream(3))
    assert (g.tally.refused, g.tally.restarts) == (5, 1) and "restarted" in g.tally.last_reason
    g.reset()
    assert (g.tally.refused, g.tally.restarts) == (5, 1)


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
        {"max_sample_gap": 3.0},  # beyond max_bridged_gap
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
