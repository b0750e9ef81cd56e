"""Read a ROS recording for replay: its topics and its messages as ROS 2 CDR, in log-time order. No ROS.

What opens
----------
One code path, ``rosbags.highlevel.AnyReader``, for

* a rosbag2 bag directory with ``metadata.yaml``, MCAP or sqlite3 storage (``rosbags`` reads both, and
  zstd-compressed files or messages), e.g. the demo's ``out/latest/run/``, whatever its name: one named
  ``*.bag/``, which rosbags' AnyReader would take for a ROS 1 file by its suffix, is given to it under
  another name (a symbolic link in a temporary folder, deleted on close);
* a single ``.mcap`` file without ``metadata.yaml`` (the demo's ``run/run.mcap``, a Foxglove export):
  rosbags reads the topics, types and the channels' ``offered_qos_profiles`` from the MCAP summary;
* a single ``.db3`` file (sqlite3 storage without its metadata.yaml);
* a ROS 1 ``.bag`` file (storage ``rosbag1``): rosbags' rosbag1 reader, the message definitions the bag
  stores, and rosbags' ROS 1 -> ROS 2 message conversion (``rosbags.convert``'s, as ``rosbags-convert``
  does it: the ROS 1 serialisation turned into the ROS 2 Jazzy type's CDR, the header's ``seq`` dropped, a
  type whose fields differ migrated field by field), type by type as its messages are read. A ROS 1 bag
  records no QoS: every topic is as if its publishers offered none (best effort for the scan).

An unfinished MCAP recording (a recorder killed with SIGKILL: a bag folder with one .mcap file and no
metadata.yaml, or a .mcap file without its footer) is first recovered into a temporary single .mcap file
(:mod:`nuturtle_tools.bag_recovery`: its complete chunks), deleted on close; ``recovery`` then says what
was recovered. Anything else (a missing path, a folder without metadata.yaml, a file of another kind, a
corrupt bag) is a :class:`BagError` with a message that names the path.

Pieces: :class:`BagTopic` (one topic: name, type, message count, the QoS its publishers offered, as recorded),
:class:`BagSource` (open, ``topics``, ``messages(topics)`` yielding :class:`BagMessage` tuples ``(topic,
type_name, data, log_time_ns)``).
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, NamedTuple

from .bag_recovery import Recovery, recover_mcap, unfinished_mcap

METADATA_FILE = "metadata.yaml"
ROS1_SUFFIX = ".bag"
SINGLE_FILE_SUFFIXES = (".mcap", ".db3", ROS1_SUFFIX)


class BagError(Exception):
    """The path is no readable rosbag2 recording (the message says why)."""


@dataclass(frozen=True)
class BagTopic:
    """One recorded topic: ``name`` (``/scan``), ``type_name`` (``sensor_msgs/msg/LaserScan``),
    ``message_count``, and ``offered_qos`` the QoS profiles its publishers offered as rosbags gives them
    (``rosbags.interfaces.Qos``; empty when the recording did not say)."""

    name: str
    type_name: str
    message_count: int
    offered_qos: tuple[Any, ...] = field(default=())


class BagMessage(NamedTuple):
    """One message: its ``topic``, ``type_name``, CDR bytes ``data`` and ``log_time_ns`` (the recorder's
    clock at reception: simulation time for a ``--use-sim-time`` recording such as the demo's)."""

    topic: str
    type_name: str
    data: bytes
    log_time_ns: int


def storage_of(path: Path) -> str:
    """``mcap``, ``sqlite3`` or ``rosbag1``: the storage of a bag directory (its metadata.yaml) or a single
    file."""
    if unfinished_mcap(path) is not None:
        return "mcap"
    if path.is_dir():
        import yaml

        try:
            metadata = yaml.safe_load((path / METADATA_FILE).read_text(encoding="utf-8"))
            return str(metadata["rosbag2_bagfile_information"]["storage_identifier"])
        except (OSError, KeyError, TypeError, yaml.YAMLError) as error:
            raise BagError(f"{path}: unreadable {METADATA_FILE}: {error}") from error
    return {".mcap": "mcap", ROS1_SUFFIX: "rosbag1"}.get(path.suffix, "sqlite3")


def _check_path(path: Path) -> None:
    if not path.exists():
        raise BagError(f"{path} does not exist")
    if unfinished_mcap(path) is not None:
        return
    if path.is_dir() and not (path / METADATA_FILE).is_file():
        raise BagError(f"{path} is a folder without {METADATA_FILE}: not a rosbag2 bag directory")
    if path.is_file() and path.suffix not in SINGLE_FILE_SUFFIXES:
        raise BagError(
            f"{path} is neither a rosbag2 bag directory nor a single {', '.join(SINGLE_FILE_SUFFIXES)} file"
        )


class BagSource:
    """A ROS recording at ``path`` (module docstring), read through rosbags; a context manager.

    ``topics`` by name once open; ``messages(names)`` the messages of those topics (all topics if None)
    merged in log-time order, as ROS 2 CDR; ``start_ns`` / ``end_ns`` the first and last log time.
    BagError when the path cannot be read as a bag, or (while reading) a ROS 1 message type has no ROS 2
    counterpart.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        _check_path(self.path)
        self.storage = storage_of(self.path)
        self._reader: Any = None
        self._typestore: Any = None
        # ROS 1 serialisation -> ROS 2 CDR, by message type (ROS 1 bags only)
        self._to_cdr: dict[str, Callable[[bytes | memoryview], Any]] = {}
        self.topics: dict[str, BagTopic] = {}
        # an unfinished recording: what was recovered, and the temporary folder of the recovered file
        self.recovery: Recovery | None = None
        # the temporary folder of a recovered file or of a renamed bag directory
        self._temporary: tempfile.TemporaryDirectory | None = None

    def open(self) -> BagSource:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.rosbag1 import ReaderError as Ros1ReaderError
        from rosbags.rosbag2 import ReaderError
        from rosbags.typesys import Stores, get_typestore

        self._typestore = get_typestore(Stores.ROS2_JAZZY)
        readable = self._recover() or self._renamed() or self.path
        reader = AnyReader([readable], default_typestore=self._typestore)
        try:
            reader.open()
        except (AnyReaderError, ReaderError, Ros1ReaderError, OSError, ValueError, KeyError) as error:
            raise BagError(f"{self.path}: not a readable ROS recording: {error}") from error
        except Exception as error:  # rosbags' storage readers raise what their file format gives them
            raise BagError(f"{self.path}: not a readable ROS recording: {error!r}") from error
        self._reader = reader
        topics: dict[str, BagTopic] = {}
        for connection in reader.connections:
            qos = tuple(getattr(connection.ext, "offered_qos_profiles", ()) or ())
            known = topics.get(connection.topic)
            if known is not None and known.type_name != connection.msgtype:
                raise BagError(f"{self.path}: topic {connection.topic} has several types")
            count = connection.msgcount + (known.message_count if known else 0)
            topics[connection.topic] = BagTopic(
                connection.topic, connection.msgtype, count, qos or (known.offered_qos if known else ())
            )
        self.topics = topics
        return self

    def _recover(self) -> Path | None:
        """The recovered single .mcap file of an unfinished recording (module docstring), else None."""
        unfinished = unfinished_mcap(self.path)
        if unfinished is None:
            return None
        self._temporary = tempfile.TemporaryDirectory(prefix="nuturtle_recovered_")
        target = Path(self._temporary.name) / unfinished.name
        try:
            self.recovery = recover_mcap(unfinished, target)
        except (ValueError, OSError) as error:
            raise BagError(
                f"{self.path}: an unfinished recording that cannot be recovered: {error}"
            ) from error
        return target

    def _renamed(self) -> Path | None:
        """A bag directory named ``*.bag`` under another name (module docstring), else None."""
        if not (self.path.is_dir() and self.path.suffix == ROS1_SUFFIX):
            return None
        self._temporary = tempfile.TemporaryDirectory(prefix="nuturtle_bag_")
        link = Path(self._temporary.name) / "rosbag2"
        link.symlink_to(self.path.resolve(), target_is_directory=True)
        return link

    @property
    def start_ns(self) -> int:
        return int(self._open().start_time)

    @property
    def end_ns(self) -> int:
        """The last message's log time (rosbags' end_time is one past it)."""
        return int(self._open().end_time) - 1

    def _open(self) -> Any:
        if self._reader is None:
            raise BagError(f"{self.path} is not open")
        return self._reader

    def messages(self, names: Iterable[str] | None = None) -> Iterator[BagMessage]:
        """The messages of the topics ``names`` (every topic if None; unknown names are ignored) in
        log-time order."""
        reader = self._open()
        wanted = None if names is None else set(names)
        connections = [c for c in reader.connections if wanted is None or c.topic in wanted]
        if not connections:
            return
        for connection, log_time_ns, data in reader.messages(connections=connections):
            if not reader.is2:
                data = self._converter(connection.msgtype)(data)
            yield BagMessage(connection.topic, connection.msgtype, bytes(data), int(log_time_ns))

    def _converter(self, msgtype: str) -> Callable[[bytes | memoryview], Any]:
        """rosbags' ROS 1 -> ROS 2 (Jazzy) CDR conversion of ``msgtype`` (BagError without a ROS 2 type)."""
        converter = self._to_cdr.get(msgtype)
        if converter is None:
            from rosbags.convert.converter import generate_message_converter

            if msgtype not in self._typestore.fielddefs:
                raise BagError(f"{self.path}: the ROS 1 type {msgtype} has no ROS 2 (Jazzy) counterpart")
            converter = generate_message_converter(
                self._reader.typestore, self._typestore, msgtype, msgtype, {}, src_is2=False, dst_is2=True
            )
            self._to_cdr[msgtype] = converter
        return converter

    def close(self) -> None:
        if self._reader is not None:
            reader, self._reader = self._reader, None
            reader.close()
        if self._temporary is not None:
            temporary, self._temporary = self._temporary, None
            temporary.cleanup()

    def __enter__(self) -> BagSource:
        return self.open()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
