"""The flight log: every record goes to ``flight.mcap`` as it happens (so a run that crashes
still leaves a readable log) and stays in memory for the end-of-run metrics.

One channel per stream, JSON-encoded with a JSON Schema per channel (``jsonschema`` encoding),
which Foxglove Studio and PlotJuggler open. Camera frames go to one channel per camera as
``foxglove.CompressedImage`` (protobuf, JPEG data); they are written but not kept in memory.
Records in memory may hold numpy values and NaN; in the file they are plain numbers and null.
Log time is the run's clock (simulated seconds in lockstep), in nanoseconds.
"""

from __future__ import annotations

import json
import struct
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import orjson
from mcap.writer import Writer

from autopilot.flightlog import records as ch
from autopilot.flightlog.records import SCHEMAS

CHUNK_SIZE_B = 64 * 1024


def encode(record: dict) -> bytes:
    """Strict JSON: numpy arrays and scalars as numbers, NaN and infinities as null."""
    return orjson.dumps(record, option=orjson.OPT_SERIALIZE_NUMPY)


class FlightLog:
    def __init__(self, path: Path | None) -> None:
        self.records: dict[str, list[dict]] = defaultdict(list)
        self.path = path
        self._file: IO[bytes] | None = None
        self._writer: Writer | None = None
        self._channels: dict[str, int] = {}
        self._seq = 0
        self._image_schema: int | None = None
        self.images_written = 0
        if path is not None:
            self._file = open(path, "wb")  # noqa: SIM115 - closed in close()
            # small chunks: a run that crashes loses at most the unfinished chunk (about a
            # second of records), not the megabyte a default chunk holds
            self._writer = Writer(self._file, chunk_size=CHUNK_SIZE_B)
            self._writer.start(profile="", library="autopilot")
            for topic, schema in SCHEMAS.items():
                schema_id = self._writer.register_schema(
                    name=schema["title"], encoding="jsonschema",
                    data=json.dumps(schema).encode())
                self._channels[topic] = self._writer.register_channel(
                    topic=topic, message_encoding="json", schema_id=schema_id)

    def write(self, topic: str, time_s: float, record: dict) -> None:
        self.records[topic].append(record)
        if self._writer is not None:
            ns = max(0, round(time_s * 1e9))
            self._seq += 1
            self._writer.add_message(self._channels[topic], log_time=ns, publish_time=ns,
                                     sequence=self._seq, data=encode(record))

    def write_image(self, camera: str, time_s: float, jpeg: bytes) -> None:
        """A camera frame (JPEG bytes) captured at ``time_s``, as ``foxglove.CompressedImage``."""
        if self._writer is None:
            return
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

        topic = ch.camera_image_topic(camera)
        if topic not in self._channels:
            if self._image_schema is None:
                from mcap_protobuf.schema import register_schema

                self._image_schema = register_schema(self._writer, CompressedImage)
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="protobuf", schema_id=self._image_schema)
        ns = max(0, round(time_s * 1e9))
        message = CompressedImage(frame_id=camera, data=jpeg, format="jpeg")
        message.timestamp.FromNanoseconds(ns)
        self._seq += 1
        self._writer.add_message(self._channels[topic], log_time=ns, publish_time=ns,
                                 sequence=self._seq, data=message.SerializeToString())
        self.images_written += 1

    def close(self) -> None:
        if self._writer is not None:
            self._writer.finish()
            self._writer = None
        if self._file is not None:
            self._file.close()
            self._file = None


def read_log(path: Path) -> dict[str, list[dict]]:
    """The records of a ``.mcap`` flight log by channel, in log order (as :class:`FlightLog`
    holds them in memory). A log cut short (a crashed run) yields what was written."""
    return read_log_checked(path)[0]


def read_log_checked(path: Path) -> tuple[dict[str, list[dict]], bool]:
    """:func:`read_log`, and whether the log was complete (closed properly: it has its footer)."""
    from mcap.records import Channel, Footer, Message

    records: dict[str, list[dict]] = defaultdict(list)
    topics: dict[int, str] = {}
    complete = False
    for record in _stream(path):
        if isinstance(record, Channel):
            if record.message_encoding == "json":
                topics[record.id] = record.topic
        elif isinstance(record, Message) and record.channel_id in topics:
            records[topics[record.channel_id]].append(json.loads(record.data))
        elif isinstance(record, Footer):
            complete = True
    return records, complete


@dataclass(frozen=True, slots=True)
class ChannelInfo:
    topic: str
    schema: str
    encoding: str
    messages: int


def channel_counts(path: Path) -> list[ChannelInfo]:
    """Every channel of a flight log with its schema, encoding and message count (read front
    to back, so a log cut short gives what it holds)."""
    from mcap.records import Channel, Message, Schema

    schemas: dict[int, str] = {}
    channels: dict[int, Channel] = {}
    counts: dict[int, int] = defaultdict(int)
    for record in _stream(path):
        if isinstance(record, Message):
            counts[record.channel_id] += 1
        elif isinstance(record, Channel):
            channels.setdefault(record.id, record)
        elif isinstance(record, Schema):
            schemas[record.id] = record.name
    return [ChannelInfo(c.topic, schemas.get(c.schema_id, ""), c.message_encoding,
                        counts[cid]) for cid, c in sorted(channels.items())]


@dataclass(frozen=True, slots=True)
class LoggedImage:
    camera: str
    time_s: float  # capture time
    jpeg: bytes


def read_images(path: Path, camera: str | None = None) -> Iterator[LoggedImage]:
    """The camera frames of a flight log (one camera's, or all), in log order, one at a time
    (a log cut short yields what was written)."""
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
    from mcap.records import Channel, Message

    cameras: dict[int, str] = {}
    for record in _stream(path):
        if isinstance(record, Channel):
            name = ch.image_topic_camera(record.topic)
            if name is not None and (camera is None or name == camera):
                cameras[record.id] = name
        elif isinstance(record, Message) and record.channel_id in cameras:
            image = CompressedImage.FromString(record.data)
            yield LoggedImage(cameras[record.channel_id], image.timestamp.ToNanoseconds() / 1e9,
                              image.data)


def _stream(path: Path) -> Iterator:
    """The records of an MCAP file front to back (a file cut short has no footer or summary
    to seek), stopping quietly where a truncated file ends."""
    from mcap.exceptions import McapError
    from mcap.stream_reader import StreamReader

    with open(path, "rb") as f:
        stream = StreamReader(f, validate_crcs=False)
        try:
            yield from stream.records
        except (McapError, EOFError, ValueError, struct.error):
            return  # truncated: keep what was read
