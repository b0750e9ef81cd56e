"""Reading a rosbag2 MCAP bag back without rosbags (which writes the demo's bags): the `mcap` library for the
file, rclpy's ``deserialize_message`` with the installed message classes for the CDR, ``yaml.safe_load`` for
metadata.yaml. Shared by the recorder and end-to-end tests."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from mcap.reader import make_reader
from mcap.records import Channel, Schema
from rclpy.serialization import deserialize_message

from nuturtle_tools.recorder import message_class

SEPARATOR = "\n" + "=" * 80 + "\n"
# a message type inside an rclpy field type: 'std_msgs/Header', 'sequence<geometry_msgs/Point, 3>'
NESTED_TYPE = re.compile(r"[A-Za-z0-9_]+/[A-Za-z0-9_]+")


@dataclass(frozen=True)
class Record:
    topic: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes


@dataclass(frozen=True)
class Bag:
    """A bag as read back: ``metadata`` (metadata.yaml's rosbag2_bagfile_information), the MCAP header's
    ``profile``, ``schemas`` by type name, ``channels`` and their schema names (``channel_types``) by topic,
    ``records`` in file order and the MCAP summary's message counts by topic."""

    metadata: dict[str, Any]
    profile: str
    schemas: dict[str, Schema]
    channels: dict[str, Channel]
    channel_types: dict[str, str]
    records: list[Record]
    summary_counts: dict[str, int]

    def topic_records(self, topic: str) -> list[Record]:
        return [record for record in self.records if record.topic == topic]

    def decoded(self, topic: str) -> list[Any]:
        """The messages of ``topic``, deserialised by rclpy into the installed message class."""
        cls = message_class(self.channel_types[topic])
        return [deserialize_message(record.data, cls) for record in self.topic_records(topic)]

    def topic_metadata(self) -> dict[str, dict[str, Any]]:
        """metadata.yaml's topics_with_message_count by topic: topic_metadata plus message_count."""
        by_topic = {}
        for entry in self.metadata["topics_with_message_count"]:
            topic = entry["topic_metadata"]
            by_topic[topic["name"]] = {**topic, "message_count": entry["message_count"]}
        return by_topic


def read_bag(path: Path) -> Bag:
    """Read the bag directory ``path``: metadata.yaml, then the one storage file it names."""
    document = yaml.safe_load((path / "metadata.yaml").read_text(encoding="utf-8"))
    metadata = document["rosbag2_bagfile_information"]
    (storage_file,) = metadata["relative_file_paths"]
    with open(path / storage_file, "rb") as stream:
        reader = make_reader(stream)
        profile = reader.get_header().profile
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        schemas = {schema.name: schema for schema in summary.schemas.values()}
        channels = {channel.topic: channel for channel in summary.channels.values()}
        channel_types = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        counts = summary.statistics.channel_message_counts
        summary_counts = {c.topic: counts.get(c.id, 0) for c in summary.channels.values()}
        records = [
            Record(channel.topic, message.log_time, message.publish_time, message.data)
            for _, channel, message in reader.iter_messages(log_time_order=False)
        ]
    return Bag(metadata, profile, schemas, channels, channel_types, records, summary_counts)


def definition_sections(text: str) -> dict[str, list[str]]:
    """A ros2msg schema text -> {type name: its field names in order}; the root type is keyed ``''``.
    Comments and constants (``TYPE NAME=VALUE``) are skipped."""
    root, *dependencies = text.split(SEPARATOR)
    sections = {"": root}
    for section in dependencies:
        header, _, body = section.partition("\n")
        assert header.startswith("MSG: "), header
        sections[header.removeprefix("MSG: ")] = body
    fields = {}
    for name, body in sections.items():
        lines = (line.split("#", 1)[0].strip() for line in body.splitlines())
        fields[name] = [line.split()[1] for line in lines if line and "=" not in line]
    return fields


def rclpy_definitions(type_name: str) -> dict[str, list[str]]:
    """What ``definition_sections`` should find for ``type_name`` (``pkg/msg/Name``), from the rclpy
    message classes: the root's field names under ``''`` and every type it depends on (``pkg/Name``)."""
    package, _, name = type_name.split("/")
    root = f"{package}/{name}"
    found: dict[str, list[str]] = {}
    seen, pending = {root}, [root]
    while pending:
        current = pending.pop()
        package, name = current.split("/")
        fields = message_class(f"{package}/msg/{name}").get_fields_and_field_types()
        found["" if current == root else current] = list(fields)
        for dependency in NESTED_TYPE.findall(" ".join(fields.values())):
            if dependency not in seen:
                seen.add(dependency)
                pending.append(dependency)
    return found
