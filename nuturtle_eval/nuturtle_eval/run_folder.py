"""An output folder that a run never destroys: the run writes into a staging folder beside it and the
previous result is replaced only when the run completes. No ROS.

For the output folder ``OUT`` (``--out``) of a run with pid ``P``::

    OUT.partial-P/   the staging folder the run writes into, holding INCOMPLETE from its first moment
                     (what a kill -9 or a power cut leaves: the marker says which run, since when)
    OUT/             the last complete result: replaced by the staging folder only when the run completes
                     (INCOMPLETE removed, then ``OUT`` renamed aside, the staging folder renamed to ``OUT``,
                     the old one deleted: two renames in one parent folder, so ``OUT`` is always a whole
                     result, and between the renames ``OUT.previous-P`` holds the old one)
    OUT.incomplete/  a run stopped early (a signal, an error after it started): its outputs, with
                     INCOMPLETE saying why; ``OUT`` is left as it was

A folder is only ever replaced or deleted when every entry in it is one the run writes (``outputs``,
INCOMPLETE, and the files named in ``keep``): anything else in ``OUT`` or ``OUT.incomplete`` makes
:func:`check_replaceable` a ValueError before the run starts, so a mistyped ``--out ~`` is refused. Files
in ``keep`` directly inside ``OUT`` (the demo's ``--map-file``, which slam may write during the run) are
moved into the new result when it replaces the old one.

One output folder, one run at a time: a run holds an exclusive lock (``flock``) on its staging folder while
it writes, which the system releases when the process ends however it ends. A run whose ``OUT`` another
live run is writing (a staging folder beside it whose lock is held) is refused before it starts
(:func:`check_no_other_run`, ValueError). :func:`unfinished_runs` finds the staging folders no run holds,
those of killed runs (the commands name them before a run); :func:`say_previous_result` names the result
a run will replace, as it starts. :func:`error_line` is how the commands (demo, replay, dataset runs) print
an error: one line; :func:`outputs_line` how they name what a run left in its folder.
"""

from __future__ import annotations

import fcntl
import os
import shutil
import sys
import time
from collections.abc import Iterable
from pathlib import Path

# The marker of a folder that does not hold a complete run
INCOMPLETE = "INCOMPLETE"
INCOMPLETE_SUFFIX = ".incomplete"


def incomplete_folder(final: Path) -> Path:
    """Where a run stopped early leaves its outputs: ``OUT.incomplete`` beside ``OUT``."""
    return final.with_name(final.name + INCOMPLETE_SUFFIX)


def check_replaceable(folder: Path, outputs: Iterable[str], keep: Iterable[Path] = ()) -> None:
    """ValueError unless ``folder`` is missing, or a folder whose entries are all in ``outputs``,
    INCOMPLETE or the names of the ``keep`` files inside it: a folder a run may replace."""
    if not folder.exists():
        return
    if not folder.is_dir():
        raise ValueError(f"output folder {folder} is a file")
    allowed = set(outputs) | {INCOMPLETE} | {p.name for p in keep if p.parent.resolve() == folder.resolve()}
    foreign = sorted(entry.name for entry in folder.iterdir() if entry.name not in allowed)
    if foreign:
        shown = ", ".join(foreign[:5]) + (", ..." if len(foreign) > 5 else "")
        raise ValueError(
            f"output folder {folder} holds files a run does not write ({shown}): not replacing it; "
            "choose another --out"
        )


def say_previous_result(final: Path) -> None:
    """A note on stderr, for a run that starts (its inputs good): the previous result in ``final`` it
    replaces when it completes and when that was written (the folder's last change). Nothing when ``final``
    is missing or empty."""
    final = Path(final)
    if not final.is_dir() or not any(final.iterdir()):
        return
    written = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(final.stat().st_mtime))
    print(
        f"note: {final}/ holds a previous result (written {written}): this run replaces it when it "
        "completes (choose another --out to keep it)",
        file=sys.stderr,
    )


def check_no_other_run(final: Path, own: Path | None = None) -> None:
    """ValueError when another live run is writing ``final``: a staging folder beside it (``own``, the
    caller's, excepted) whose lock its run holds."""
    for staging in _staging_folders(final):
        if staging != own and _held(staging):
            pid = staging.name.rpartition("-")[2]
            raise ValueError(
                f"another run (process {pid}) is writing {final}: its staging folder {staging}/ replaces "
                f"{final} when it completes; wait for it to finish or choose another --out"
            )


class RunFolder:
    """The staging folder of one run for the output folder ``final`` (module docstring).

    ``outputs``: the names of the entries a run writes (files and folders). Creating it checks ``final``
    and ``final.incomplete`` (:func:`check_replaceable`, ValueError), creates the staging folder ``path``
    with its INCOMPLETE marker and holds its lock, and then refuses (ValueError, the staging folder deleted)
    when another live run is writing ``final`` (:func:`check_no_other_run`). Then exactly one of
    :meth:`complete`, :meth:`keep_incomplete` or :meth:`discard`; each returns where the outputs are (None
    for discard) and lets go of the lock."""

    def __init__(self, final: Path, outputs: Iterable[str], keep: Iterable[Path] = ()) -> None:
        self.final = Path(final)
        self.outputs = frozenset(outputs)
        self.keep = [Path(p) for p in keep]
        check_replaceable(self.final, self.outputs, self.keep)
        check_replaceable(incomplete_folder(self.final), self.outputs)
        self.final.parent.mkdir(parents=True, exist_ok=True)
        self.path = self.final.with_name(f"{self.final.name}.partial-{os.getpid()}")
        if self.path.exists():
            shutil.rmtree(self.path)
        self.path.mkdir()
        # waiting: another run's check_no_other_run holds it for an instant at most
        self._lock: int | None = os.open(self.path, os.O_RDONLY | os.O_DIRECTORY)
        fcntl.flock(self._lock, fcntl.LOCK_EX)
        started = time.strftime("%Y-%m-%d %H:%M:%S %Z")
        self._mark(f"this run has not finished: started {started}, process {os.getpid()}")
        try:
            check_no_other_run(self.final, own=self.path)
        except ValueError:
            self.discard()
            raise

    def _mark(self, reason: str) -> None:
        (self.path / INCOMPLETE).write_text(
            f"{reason}\nThe outputs here are not a complete run; complete runs go to {self.final} only.\n",
            encoding="utf-8",
        )

    def complete(self) -> Path:
        """Replace ``final`` with the staging folder (the ``keep`` files inside ``final`` move along);
        ``final``."""
        (self.path / INCOMPLETE).unlink()
        if self.final.exists():
            for kept in self.keep:
                if kept.parent.resolve() == self.final.resolve() and kept.is_file():
                    kept.rename(self.path / kept.name)
            previous = self.final.with_name(f"{self.final.name}.previous-{os.getpid()}")
            self.final.rename(previous)
            self.path.rename(self.final)
            shutil.rmtree(previous)
        else:
            self.path.rename(self.final)
        self._release()
        return self.final

    def keep_incomplete(self, reason: str) -> Path:
        """Leave the outputs in ``final.incomplete`` (replacing an earlier incomplete run's) with INCOMPLETE
        saying ``reason``; ``final`` stays as it was. That folder."""
        self._mark(reason)
        target = incomplete_folder(self.final)
        if target.exists():
            shutil.rmtree(target)
        self.path.rename(target)
        self._release()
        return target

    def discard(self) -> None:
        """Delete the staging folder: the run wrote nothing worth keeping."""
        shutil.rmtree(self.path, ignore_errors=True)
        self._release()

    def _release(self) -> None:
        if self._lock is not None:
            os.close(self._lock)
            self._lock = None


def unfinished_runs(final: Path) -> list[Path]:
    """The staging folders beside ``final`` that no run holds: runs that were killed (SIGKILL, a power cut)
    and left their outputs there, marked INCOMPLETE. They are never deleted automatically."""
    return [staging for staging in _staging_folders(final) if not _held(staging)]


def _staging_folders(final: Path) -> list[Path]:
    """The staging folders ``final.partial-<pid>`` beside ``final``."""
    final = Path(final)
    found = final.parent.glob(f"{final.name}.partial-*")
    return sorted(path for path in found if path.is_dir() and path.name.rpartition("-")[2].isdigit())


def _held(staging: Path) -> bool:
    """Whether a run holds the lock of the folder ``staging`` (tried without waiting, let go at once)."""
    try:
        fd = os.open(staging, os.O_RDONLY | os.O_DIRECTORY)
    except FileNotFoundError:  # renamed or deleted by its run meanwhile
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


def error_line(error: BaseException) -> str:
    """What a run's command prints after ``error: ``: the error and its notes (where a failed run left its
    outputs, added by the run) on one line, whatever line breaks they hold (a YAML error spans several)."""
    return "; ".join(" ".join(str(part).split()) for part in [error, *getattr(error, "__notes__", ())])


def outputs_line(folder: Path) -> str:
    """``outputs in FOLDER/: a.json b.png run/ ...``: every entry ``folder`` holds, read from the folder
    itself (so the line cannot drift from what a run writes), sorted by name, a folder with a trailing
    ``/``."""
    folder = Path(folder)
    entries = sorted(entry.name + ("/" if entry.is_dir() else "") for entry in folder.iterdir())
    return f"outputs in {folder}/: {' '.join(entries)}"
