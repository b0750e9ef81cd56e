"""Files replaced atomically: a reader sees the old file or the new one, never half a file.

Each file is written to a temporary file ``.<name>.*.tmp`` in its own folder (so the rename cannot cross
file systems), flushed and fsynced, then renamed onto its path (``os.replace``, atomic on POSIX), and the
folder fsynced so the rename survives a power cut. An existing file keeps its permission bits; a new one
gets ``0o644``.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

_NEW_FILE_MODE = 0o644


def replace_files(contents: dict[Path, bytes]) -> None:
    """Write every ``path: content`` of ``contents`` atomically, in the dict's order.

    Missing folders are created. All the temporary files are complete before the first rename, so an
    error while writing them (a full disk, a folder that cannot be written) leaves every old file as it
    was; the renames follow one by one (a crash between two leaves the first files new and the rest
    old). On any error the temporary files left are removed and the error raised.
    """
    temporaries: list[tuple[str, Path]] = []
    try:
        for path, content in contents.items():
            path.parent.mkdir(parents=True, exist_ok=True)
            temporaries.append((_complete_temporary(path, content), path))
        for temporary, path in temporaries:
            os.replace(temporary, path)
    except BaseException:
        for temporary, _ in temporaries:
            try:
                os.unlink(temporary)
            except FileNotFoundError:
                pass
        raise
    for folder in {path.parent for path in contents}:
        _fsync_directory(folder)


def _complete_temporary(path: Path, content: bytes) -> str:
    """A flushed, fsynced temporary file with ``content`` beside ``path``, with ``path``'s mode; its name."""
    try:
        mode = path.stat().st_mode & 0o7777
    except FileNotFoundError:
        mode = _NEW_FILE_MODE
    fd, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as stream:
            stream.write(content)
            stream.flush()
            os.fchmod(stream.fileno(), mode)
            os.fsync(stream.fileno())
    except BaseException:
        os.unlink(temporary)
        raise
    return temporary


def _fsync_directory(directory: Path) -> None:
    """Make the renames durable (POSIX); a no-op where directories cannot be opened."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
