"""One run of a command (the demo, the replay) into a :class:`nuturtle_eval.run_folder.RunFolder`, under
:class:`nuturtle_ros_common.stop_signals.StopSignals`: where its outputs end up, whatever ends it.

- it completes: the staging folder replaces the output folder;
- a stop signal ends it early: its outputs go to ``OUT.incomplete`` with the reason;
- it raises once it has started (a full disk): what it wrote goes to ``OUT.incomplete`` and the error
  carries a note saying where; before it started (a bad input, a port in use): nothing is kept.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from nuturtle_eval.run_folder import RunFolder
from nuturtle_ros_common.stop_signals import StopSignals

Result = TypeVar("Result")


def run_staged(
    folder: RunFolder,
    body: Callable[[Path, StopSignals], Result],
    started: Callable[[], bool],
    stopped_reason: Callable[[Result], str | None],
    what: str,
) -> tuple[Result, Path]:
    """``body(staging folder, stop)``'s result and where its outputs are (module docstring).
    ``started()``: whether the run has begun writing outputs worth keeping; ``stopped_reason(result)``:
    None for a complete run, else why it ended early; ``what`` names the run in the failure's reason."""
    try:
        with StopSignals() as stop:
            result = body(folder.path, stop)
    except BaseException as error:
        if started():
            where = folder.keep_incomplete(f"{what} failed: {error}")
            error.add_note(f"the outputs written so far are in {where}/")
        else:
            folder.discard()
        raise
    reason = stopped_reason(result)
    return result, folder.complete() if reason is None else folder.keep_incomplete(reason)
