"""nuturtle_tools.stop_signals with real signals sent to this process: SIGHUP, SIGTERM and SIGINT only
record a stop request, a second one raises KeyboardInterrupt, the previous handlers come back."""

import os
import signal

import pytest

from nuturtle_tools.stop_signals import StopSignals


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
