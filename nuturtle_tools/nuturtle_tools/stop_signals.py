"""Stop requests for a run's own loop (the demo's, the replay's): SIGINT (Ctrl-C), SIGTERM (``timeout``,
systemd, docker, CI) and SIGHUP (the terminal closed) all end a run the same way.

:class:`StopSignals` is a context manager: inside it the first of these signals only records its name in
``received``; the run's loop checks it, leaves, and closes its bag and writes the metrics of what ran, as
after Ctrl-C. A second signal raises KeyboardInterrupt (stop now, outputs unfinished). Leaving the context
restores the previous handlers. Outside the main thread (where Python cannot take signals) it installs
nothing and ``received`` stays None.
"""

from __future__ import annotations

import signal
import threading
from types import FrameType, TracebackType
from typing import Any

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class StopSignals:
    """``received``: the name of the first stop signal (``SIGTERM``), None until one came."""

    def __init__(self) -> None:
        self.received: str | None = None
        self._previous: dict[int, Any] = {}

    def _handle(self, number: int, frame: FrameType | None) -> None:
        if self.received is not None:
            raise KeyboardInterrupt(f"{signal.Signals(number).name} after {self.received}")
        self.received = signal.Signals(number).name

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():
            for number in STOP_SIGNALS:
                self._previous[number] = signal.signal(number, self._handle)
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, traceback: TracebackType | None
    ) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)
        self._previous.clear()
