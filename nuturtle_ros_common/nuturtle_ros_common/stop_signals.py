"""Stop requests for a loop of our own (a node's spin loop, the demo's and the replay's run loop): SIGINT
(Ctrl-C), SIGTERM (launch after its ``sigterm_timeout``, ``timeout``, systemd, docker, CI) and SIGHUP (the
terminal closed) all end it the same way.

:class:`StopSignals` is a context manager: inside it the first of these signals only records its name in
``received``; the loop checks it, leaves, and stops in order (a node: its safe command, then the node and
its context; a run: its bag closed and the metrics of what ran, as after Ctrl-C). A second signal either
raises KeyboardInterrupt (``second="interrupt"``, a run: stop now, outputs unfinished) or is ignored
(``second="ignore"``, a node, whose stop is bounded: launch signals a node a second time when a script
signals its process group). A signal ignored on entry stays ignored (``nohup``, a background job of a
script). Leaving the context restores the previous handlers. Outside the main thread (where Python cannot
take signals) it installs nothing and ``received`` stays None.
"""

from __future__ import annotations

import signal
import threading
from types import FrameType, TracebackType
from typing import Any, Literal

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class StopSignals:
    """``received``: the name of the first stop signal (``SIGTERM``), None until one came; ``second``:
    what a later one does (module docstring)."""

    def __init__(self, second: Literal["interrupt", "ignore"] = "interrupt") -> None:
        if second not in ("interrupt", "ignore"):
            raise ValueError(f"second must be 'interrupt' or 'ignore', got {second!r}")
        self.second = second
        self.received: str | None = None
        self._previous: dict[int, Any] = {}

    def _handle(self, number: int, frame: FrameType | None) -> None:
        if self.received is None:
            self.received = signal.Signals(number).name
        elif self.second == "interrupt":
            raise KeyboardInterrupt(f"{signal.Signals(number).name} after {self.received}")

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():
            for number in STOP_SIGNALS:
                if signal.getsignal(number) is not signal.SIG_IGN:
                    self._previous[number] = signal.signal(number, self._handle)
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, traceback: TracebackType | None
    ) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)
        self._previous.clear()


def ignore_stop_signals() -> None:
    """Ignore every stop signal from now on, for a process whose work is done and that is exiting. (Python's
    exit restores the default action of every signal it handles before C++ tears DDS down, ~0.3 s in which a
    second SIGINT would otherwise end the process with -2; SIG_IGN survives it.)"""
    for number in STOP_SIGNALS:
        signal.signal(number, signal.SIG_IGN)
