"""Recover an unfinished MCAP recording: what a recorder killed with SIGKILL (or stopped by a power cut)
leaves. No ROS.

What such a recording is
------------------------
rosbags' MCAP writer (the demo's and the replay's :class:`nuturtle_tools.recorder.BagWriter`) writes the
header, then the messages in zstd chunks, each chunk holding the schemas and channels first used in it;
only ``close()`` writes the summary (the chunk index, the statistics), the footer and then metadata.yaml.
A killed recorder leaves the header and every chunk it had finished, possibly a cut-off last chunk, no
summary, no footer and no metadata.yaml: rosbags, ``ros2 bag`` and mcap's indexed reader refuse it. The
recorder closes a chunk at least every ``FLUSH_PERIOD_S`` of wall time (recorder.py), so at most that
much is lost.

Recovery
--------
mcap's stream reader (:class:`mcap.stream_reader.StreamReader`, which needs no summary) reads the records
in file order, each chunk only once it is whole; its schemas, channels (with their
``offered_qos_profiles``) and messages are written unchanged into a new MCAP file by mcap's writer,
which then has a summary and a footer, so rosbags opens it as a single .mcap file. Reading stops at the
first record that is cut off or damaged; the bytes from there on are dropped and counted.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

MAGIC = b"\x89MCAP0\r\n"
METADATA_FILE = "metadata.yaml"


@dataclass(frozen=True)
class Recovery:
    """What :func:`recover_mcap` got out of ``source``: ``messages`` on ``channels`` channels, and
    ``dropped_bytes`` at its end that held no whole record (a cut-off chunk)."""

    source: Path
    messages: int
    channels: int
    dropped_bytes: int

    def note(self) -> str:
        return (
            f"{self.source} is an unfinished recording (no MCAP footer or metadata.yaml: its recorder "
            f"was killed): recovered {self.messages} messages on {self.channels} topics from its complete "
            f"chunks, dropped the last {self.dropped_bytes} bytes"
        )


def unfinished_mcap(path: Path) -> Path | None:
    """The MCAP file of an unfinished recording at ``path`` (a folder without metadata.yaml holding one
    .mcap file, or a .mcap file whose end is no MCAP footer), else None."""
    if path.is_dir():
        files = sorted(path.glob("*.mcap"))
        if (path / METADATA_FILE).exists() or len(files) != 1:
            return None
        path = files[0]
    if path.suffix != ".mcap" or not path.is_file():
        return None
    with path.open("rb") as stream:
        if stream.read(len(MAGIC)) != MAGIC:
            return None
        stream.seek(0, 2)
        size = stream.tell()
        stream.seek(max(size - len(MAGIC), 0))
        finished = size > 2 * len(MAGIC) and stream.read() == MAGIC
    return None if finished else path


def recover_mcap(source: Path, target: Path) -> Recovery:
    """Write the whole records of the unfinished MCAP file ``source`` (module docstring) into the new
    MCAP file ``target``. ValueError when not even the header can be read."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Header, Message, Schema
    from mcap.stream_reader import StreamReader
    from mcap.writer import CompressionType, Writer

    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    messages = 0
    with source.open("rb") as stream, target.open("wb") as out:
        writer: Writer | None = None
        read_up_to = 0
        try:
            for record in StreamReader(stream).records:
                if isinstance(record, Header):
                    writer = Writer(out, compression=CompressionType.ZSTD)
                    writer.start(profile=record.profile, library=record.library)
                elif writer is None:
                    break
                elif isinstance(record, Schema) and record.id not in schemas:
                    schemas[record.id] = writer.register_schema(record.name, record.encoding, record.data)
                elif isinstance(record, Channel) and record.id not in channels:
                    channels[record.id] = writer.register_channel(
                        record.topic,
                        record.message_encoding,
                        schemas.get(record.schema_id, 0),
                        record.metadata,
                    )
                elif isinstance(record, Message) and record.channel_id in channels:
                    writer.add_message(
                        channels[record.channel_id], record.log_time, record.data, record.publish_time,
                        record.sequence,
                    )  # fmt: skip
                    messages += 1
                read_up_to = stream.tell()
        except (McapError, EOFError, ValueError, OSError, KeyError, IndexError):
            pass  # the cut-off end
        if writer is None:
            raise ValueError(f"{source}: no MCAP header to recover a recording from")
        writer.finish()
        size = stream.seek(0, 2)
    return Recovery(source, messages, len(channels), max(size - read_up_to, 0))
