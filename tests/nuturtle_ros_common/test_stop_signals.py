"""nuturtle_ros_common.stop_signals with real signals sent to this process: SIGHUP, SIGTERM and SIGINT only
record a stop request; a second one raises KeyboardInterrupt (a run) or is ignored (a node); a signal
ignored on entry stays ignored; the previous handlers come back."""

import os
import signal

import pytest

from nuturtle_ros_common.stop_signals import StopSignals


@pytest.mark.parametrize("number", [signal.SIGHUP, signal.SIGTERM, signal.SIGINT])
def test_the_first_stop_signal_is_recorded_and_a_second_one_interrupts(number):
    before = signal.getsignal(number)
    with StopSignals() as stop:
        assert stop.received is None
        os.kill(os.getpid(), number)
        assert stop.received == signal.Signals(number).name
        with pytest.raises(KeyboardInterrupt, match=f"SIGINT after {signal.Signals(number).name}"):
            os.kill(os.getpid(), signal.SIGINT)
    assert signal.getsignal(number) is before


def test_a_node_ignores_a_second_signal_and_one_ignored_before_stays_ignored():
    before = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        with StopSignals(second="ignore") as stop:
            assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
            os.kill(os.getpid(), signal.SIGHUP)
            assert stop.received is None
            os.kill(os.getpid(), signal.SIGTERM)
            os.kill(os.getpid(), signal.SIGINT)
            assert stop.received == "SIGTERM"
    finally:
        signal.signal(signal.SIGHUP, before)


def test_what_a_second_signal_does_is_one_of_two():
    with pytest.raises(ValueError, match="second must be 'interrupt' or 'ignore'"):
        StopSignals(second="exit")
