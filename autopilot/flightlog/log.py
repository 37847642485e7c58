"""The flight log: every record goes to ``flight.mcap`` as it happens (so a run that crashes
still leaves a readable log). Memory stays bounded however long the flight: records stream to
the file and are not kept (the end-of-run metrics read them back from it: :meth:`FlightLog.
all_records`); only a log without a file (tests), or one whose file failed, keeps them in memory.

One channel per stream, JSON-encoded with a JSON Schema per channel (``jsonschema`` encoding),
which Foxglove Studio and PlotJuggler open. Camera frames go to one channel per camera as
``foxglove.CompressedImage`` (protobuf, JPEG data); they are written but not kept in memory.
Records in memory may hold numpy values and NaN; in the file they are plain numbers and null.
Log time is the run's clock (simulated seconds in lockstep), in nanoseconds.
"""

from __future__ import annotations

import contextlib
import json
import logging
import struct
import threading
from collections import defaultdict, deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import orjson
from mcap.writer import Writer

from autopilot.flightlog import records as ch
from autopilot.flightlog.records import SCHEMAS

log = logging.getLogger(__name__)

CHUNK_SIZE_B = 64 * 1024


def encode(record: dict) -> bytes:
    """Strict JSON: numpy arrays and scalars as numbers, NaN and infinities as null."""
    return orjson.dumps(record, option=orjson.OPT_SERIALIZE_NUMPY)


#: Bytes waiting for the writer thread above which camera frames are dropped (and counted)
#: rather than queued: a disk slower than the camera must not eat the companion's memory.
MAX_PENDING_B = 64 << 20
#: The writer thread is woken when this much is waiting, and otherwise every WAKE_S seconds
#: (wall): woken per message, it fights the event loop for the GIL thousands of times a second.
WAKE_B = 1 << 20
WAKE_S = 0.25


class FlightLog:
    """Records to the file through a writer thread (encoding, chunking, compression and disk
    writes stay off the event loop); in memory only without a file. A write error stops the
    file, not the flight: it is kept in :attr:`error`, and the records from then on stay in
    memory (``keep``: keep every record in memory too)."""

    def __init__(self, path: Path | None, *, keep: bool = False) -> None:
        self.records: dict[str, list[dict]] = defaultdict(list)
        self.keep = keep or path is None
        self.path = path
        self.images_written = 0
        self.images_dropped = 0
        self.error: BaseException | None = None
        self._queue: deque | None = None
        self._thread: threading.Thread | None = None
        self._pending_b = 0
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._closing = False
        if path is not None:
            file = open(path, "wb")  # noqa: SIM115 - closed by the writer thread
            self._queue = deque()
            self._thread = threading.Thread(target=self._write_all, args=(file,),
                                            name="flight-log", daemon=True)
            self._thread.start()

    def write(self, topic: str, time_s: float, record: dict) -> None:
        if self._queue is not None and self._put(topic, time_s, encode(record), None):
            if self.keep:
                self.records[topic].append(record)
        else:  # no file, or it failed
            self.records[topic].append(record)

    def all_records(self) -> dict[str, list[dict]]:
        """Every record of the flight, after :meth:`close`: read back from the file (as
        :func:`read_log` gives them: plain numbers, NaN as null), then those kept in memory
        after a write error; without a file, the ones in memory."""
        if self.path is None or self.keep:
            return self.records
        records: dict[str, list[dict]] = defaultdict(list)
        if self.path.exists():
            try:
                for topic, items in read_log(self.path).items():
                    records[topic].extend(items)
            except Exception:  # a file cut short by the error: what is in memory still counts
                pass
        for topic, items in self.records.items():
            records[topic].extend(items)
        return records

    def write_image(self, camera: str, time_s: float, jpeg: bytes) -> None:
        """A camera frame (JPEG bytes) captured at ``time_s``, as ``foxglove.CompressedImage``."""
        if self._queue is None:  # no file (a run without a log folder), or it failed
            if self.error is not None:
                self.images_dropped += 1
            return
        if self._pending_b > MAX_PENDING_B:
            self.images_dropped += 1
            return
        if self._put(ch.camera_image_topic(camera), time_s, jpeg, camera):
            self.images_written += 1
        else:  # the writer failed: frames are not kept in memory (records are)
            self.images_dropped += 1

    def _put(self, topic: str, time_s: float, data: bytes, camera: str | None) -> bool:
        """Queue for the file; False once the writer has failed (the caller keeps it)."""
        with self._lock:  # (the writer's failure swaps the queue out under it: order holds)
            q = self._queue
            if q is None:
                return False
            self._pending_b += len(data)
            pending = self._pending_b
            q.append((topic, max(0, round(time_s * 1e9)), data, camera))
        if pending >= WAKE_B:
            self._wake.set()
        return True

    def _write_all(self, file: IO[bytes]) -> None:
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
        from mcap_protobuf.schema import register_schema

        batch: deque = deque()
        try:
            # small chunks: a run that crashes loses at most the unfinished chunk (about a
            # second of records), not the megabyte a default chunk holds
            writer = Writer(file, chunk_size=CHUNK_SIZE_B)
            writer.start(profile="", library="autopilot")
            channels: dict[str, int] = {}
            for topic, schema in SCHEMAS.items():
                schema_id = writer.register_schema(
                    name=schema["title"], encoding="jsonschema", data=json.dumps(schema).encode())
                channels[topic] = writer.register_channel(
                    topic=topic, message_encoding="json", schema_id=schema_id)
            image_schema: int | None = None
            sequence = 0
            while True:
                self._wake.wait(WAKE_S)
                self._wake.clear()
                closing = self._closing  # read first: what was written before close() is taken
                batch = self._take_all()
                while batch:
                    topic, ns, data, camera = batch[0]
                    if camera is None and topic not in channels:  # a channel met late
                        schema = SCHEMAS.get(topic) or {"title": topic, "type": "object"}
                        schema_id = writer.register_schema(
                            name=schema["title"], encoding="jsonschema",
                            data=json.dumps(schema).encode())
                        channels[topic] = writer.register_channel(
                            topic=topic, message_encoding="json", schema_id=schema_id)
                    if camera is not None:
                        if topic not in channels:
                            if image_schema is None:
                                image_schema = register_schema(writer, CompressedImage)
                            channels[topic] = writer.register_channel(
                                topic=topic, message_encoding="protobuf",
                                schema_id=image_schema)
                        message = CompressedImage(frame_id=camera, data=data, format="jpeg")
                        message.timestamp.FromNanoseconds(ns)
                        data = message.SerializeToString()
                    sequence += 1
                    writer.add_message(channels[topic], log_time=ns, publish_time=ns,
                                       sequence=sequence, data=data)
                    batch.popleft()
                if closing:
                    break
            writer.finish()
        except Exception as exc:  # e.g. the disk is full: the flight goes on without the file
            with self._lock:  # from now on records stay in memory, after the unwritten ones
                # (kept before the queue is swapped out: a write that saw the queue waits on
                # the lock, then finds it gone and appends after them)
                kept = self._keep_unwritten([*batch, *(self._queue or ())])
                self._queue = None
            self.error = exc
            log.warning("flight log %s: writing failed (%s: %s); the flight goes on, its "
                        "records in memory from now on (%d unwritten ones kept)", self.path,
                        type(exc).__name__, exc, kept)
        finally:
            try:
                file.close()  # flushes: may fail the same way
            except OSError as exc:
                self.error = self.error or exc

    def _keep_unwritten(self, items) -> int:
        """Records queued for the file when it failed: into memory (camera frames are not
        kept; the file was their only place)."""
        kept = 0
        for topic, _ns, data, camera in items:
            if camera is None and not self.keep:
                with contextlib.suppress(ValueError):
                    self.records[topic].append(orjson.loads(data))
                    kept += 1
        return kept

    def _take_all(self) -> deque:
        q = self._queue
        items: deque = deque()
        while q:
            items.append(q.popleft())
        with self._lock:
            self._pending_b -= sum(len(item[2]) for item in items)
        return items

    def close(self) -> None:
        """Write what is queued, finish the file (its summary and footer) and close it."""
        if self._thread is not None:
            self._closing = True
            self._wake.set()
            self._thread.join()
            self._thread = None


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
