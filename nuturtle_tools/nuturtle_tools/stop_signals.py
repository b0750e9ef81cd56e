"""The stop requests of the demo's and the replay's run loop: :class:`StopSignals` of
:mod:`nuturtle_ros_common.stop_signals` (the nodes' too), where ``run.py`` and ``replay_run.py`` import it
from."""

from nuturtle_ros_common.stop_signals import STOP_SIGNALS, StopSignals

__all__ = ["STOP_SIGNALS", "StopSignals"]
