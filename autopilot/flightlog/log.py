"""The flight log: every record goes to ``flight.mcap`` as it happens (so a run that crashes
still leaves a readable log). Memory stays bounded however long the flight: records stream to
the file and are not kept; only a log without a file (tests), or one whose file failed, keeps
them in memory. The end-of-run metrics read them back from the file as they use them
(:meth:`FlightLog.read_back`, :class:`StoredLog`): a channel's records one at a time, never
the whole flight's records at once.

One channel per stream, JSON-encoded with a JSON Schema per channel (``jsonschema`` encoding),
which Foxglove Studio and PlotJuggler open. Camera frames go to one channel per camera as
``foxglove.CompressedImage`` (protobuf, JPEG data); they are written but not kept in memory.
Records in memory may hold numpy values and NaN; in the file they are plain numbers and null.
Log time is the run's clock (simulated seconds in lockstep), in nanoseconds.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import os
import struct
import threading
from collections import defaultdict, deque
from collections.abc import Container, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np
import orjson
from mcap.writer import Writer

from autopilot.flightlog import records as ch
from autopilot.flightlog.records import SCHEMAS
from drivers.stages import STAGES

log = logging.getLogger(__name__)

CHUNK_SIZE_B = 64 * 1024


def _plain(value):
    if isinstance(value, np.ndarray):  # (a strided view, which orjson does not take as is)
        return np.ascontiguousarray(value)
    raise TypeError(f"{type(value).__name__} is not JSON")


def encode(record: dict) -> bytes:
    """Strict JSON: numpy arrays and scalars as numbers, NaN and infinities as null."""
    return orjson.dumps(record, default=_plain, option=orjson.OPT_SERIALIZE_NUMPY)


#: Bytes waiting for the writer thread above which camera frames are dropped (and counted)
#: rather than queued: a disk slower than the camera must not eat the companion's memory.
MAX_PENDING_B = 64 << 20
#: The writer thread is woken when this much is waiting, and otherwise every WAKE_S seconds
#: (wall): woken per message, it fights the event loop for the GIL thousands of times a second.
WAKE_B = 1 << 20
WAKE_S = 0.25


def _has_arrays(record: dict) -> bool:
    return any(isinstance(v, np.ndarray) or (isinstance(v, dict) and any(
        isinstance(w, np.ndarray) for w in v.values())) for v in record.values())


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
        self._sequence = 0
        self._image_schema: int | None = None
        if path is not None:
            file = open(path, "wb")  # noqa: SIM115 - closed by the writer thread
            self._queue = deque()
            self._thread = threading.Thread(target=self._write_all, args=(file,),
                                            name="flight-log", daemon=True)
            self._thread.start()

    def write(self, topic: str, time_s: float, record: dict) -> None:
        """Log ``record`` (plain values, or numpy arrays: a large record — a planned path —
        is encoded from its arrays at C speed; kept in memory as read back, in plain lists)."""
        with STAGES.stage("logging"):
            data = encode(record)
            if self._queue is not None and self._put(topic, time_s, data, None) and \
                    not self.keep:
                return
            self.records[topic].append(orjson.loads(data) if _has_arrays(record) else record)

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

    def read_back(self) -> Mapping[str, Sequence[Mapping]]:
        """The flight's records after :meth:`close`, for the end-of-run metrics: from the file
        as they are used (:class:`StoredLog`: memory independent of the flight's length);
        a log kept in memory (no file, ``keep``, or a write error) as :meth:`all_records`."""
        if self.path is None or self.keep or self.error is not None or self.records:
            return self.all_records()
        try:
            return StoredLog(self.path)
        except Exception:  # the file went wrong after all: what can be read of it
            return self.all_records()

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

    def _write_batch(self, writer: Writer, batch: deque, channels: dict[str, int]) -> None:
        """Write ``batch``'s records, each taken off it once written (what is left was not)."""
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
        from mcap_protobuf.schema import register_schema

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
                    if self._image_schema is None:
                        self._image_schema = register_schema(writer, CompressedImage)
                    channels[topic] = writer.register_channel(
                        topic=topic, message_encoding="protobuf", schema_id=self._image_schema)
                message = CompressedImage(frame_id=camera, data=data, format="jpeg")
                message.timestamp.FromNanoseconds(ns)
                data = message.SerializeToString()
            self._sequence += 1
            writer.add_message(channels[topic], log_time=ns, publish_time=ns,
                               sequence=self._sequence, data=data)
            batch.popleft()

    def _write_all(self, file: IO[bytes]) -> None:

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
            while True:
                self._wake.wait(WAKE_S)
                self._wake.clear()
                closing = self._closing  # read first: what was written before close() is taken
                batch = self._take_all()
                with STAGES.stage("logging"):
                    self._write_batch(writer, batch, channels)
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
            STAGES.sample_threads()  # (the writer's thread takes its CPU time with it)
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
    from mcap.records import Channel

    records: dict[str, list[dict]] = defaultdict(list)
    topics: dict[int, str] = {}
    complete: list[bool] = []
    for record in _messages(path, topics, complete):
        if isinstance(record, Channel):
            if record.message_encoding == "json":
                topics[record.id] = record.topic
        elif record[0] in topics:
            records[topics[record[0]]].append(json.loads(record[1]))
    return records, bool(complete)


class StoredLog(Mapping):
    """A flight log's records by channel (as :func:`read_log` gives them), read from its file as
    they are used: a channel with few records (the plan, events, camera info, photos, …) is
    read once and kept; a long one (telemetry, ground truth, detections, setpoints) is a
    :class:`StoredChannel`, read from the file again each time it is iterated, one record at a
    time. Memory is that of the short channels, whatever the flight's length; what a user keeps
    of the records is up to it (the metrics keep columns of the numbers they score).

    :attr:`derived` holds what users compute once per log (the ground truth's columns)."""

    #: channels with more records than this are read from the file when used, not kept
    KEEP_MAX = 256

    def __init__(self, path: Path) -> None:
        from mcap.records import Channel

        self.path = path
        self.derived: dict = {}
        self._channels: dict[str, StoredChannel | list[dict]] = {}
        ids: dict[int, str] = {}
        counts: dict[str, int] = defaultdict(int)
        kept: dict[str, list[dict] | None] = {}
        first: dict[str, bytes] = {}
        last: dict[str, bytes] = {}
        for record in _messages(path, ids):
            if isinstance(record, Channel):
                if record.message_encoding == "json":
                    ids[record.id] = record.topic
                    kept.setdefault(record.topic, [])
                continue
            topic = ids.get(record[0])
            if topic is None:
                continue
            data = record[1]
            counts[topic] += 1
            last[topic] = data
            first.setdefault(topic, data)
            items = kept.get(topic)
            if items is not None:
                if len(items) < self.KEEP_MAX:
                    items.append(orjson.loads(data))
                else:
                    kept[topic] = None  # a long channel: read when used
        for topic in dict.fromkeys(ids.values()):
            if not counts[topic]:  # (as read_log: only channels with records)
                continue
            items = kept[topic]
            if items is not None:
                self._channels[topic] = items
            else:
                self._channels[topic] = StoredChannel(
                    path, {i for i, t in ids.items() if t == topic}, counts[topic],
                    orjson.loads(first[topic]), orjson.loads(last[topic]))

    def __getitem__(self, topic: str) -> Sequence[Mapping]:
        return self._channels[topic]

    def __iter__(self) -> Iterator[str]:
        return iter(self._channels)

    def __len__(self) -> int:
        return len(self._channels)


class StoredChannel(Sequence):
    """One channel's records in a flight log file: iterating reads them from the file, one at a
    time (each iteration reads the file again); its length, first and last record are known
    without reading. Other indices and slices read the file up to them."""

    def __init__(self, path: Path, channel_ids: set[int], count: int, first: dict,
                 last: dict) -> None:
        self.path = path
        self._ids = channel_ids
        self._count = count
        self._first = first
        self._last = last

    def __len__(self) -> int:
        return self._count

    def __iter__(self) -> Iterator[dict]:
        ids = self._ids
        for record in _messages(self.path, ids):
            if type(record) is tuple:
                yield orjson.loads(record[1])

    def __reversed__(self) -> Iterator[dict]:
        return reversed(list(self))

    def __getitem__(self, index):
        n = self._count
        if isinstance(index, slice):
            wanted = range(n)[index]
            if not wanted:
                return []
            if len(wanted) == 1:
                return [self[wanted[0]]]
            picked = set(wanted)
            found = {i: r for i, r in enumerate(self) if i in picked}
            return [found[i] for i in wanted]
        i = range(n)[index]  # (an IndexError as a list's)
        if i == 0:
            return self._first
        if i == n - 1:
            return self._last
        return next(r for k, r in enumerate(self) if k == i)


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


_MAGIC = b"\x89MCAP0\r\n"
_RECORD = struct.Struct("<BQ")  # an MCAP record's opcode and length
_CHUNK = struct.Struct("<QQQII")  # start and end time, uncompressed size and CRC, len(compression)
_MESSAGE_CHANNEL = struct.Struct("<H")
_OP_FOOTER, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 0x02, 0x04, 0x05, 0x06
_MESSAGE_HEADER_B = 2 + 4 + 8 + 8  # channel id, sequence, log time, publish time


def _messages(path: Path, channels: Container[int], complete: list | None = None
              ) -> Iterator:
    """The messages of an MCAP file's ``channels`` (ids; the container may grow as the
    channels are met) front to back as (channel id, data) tuples, and all its
    :class:`mcap.records.Channel` records; ``complete`` (a list) gets an item when the file
    has its footer. A file cut short (or damaged) stops quietly where it does.

    The records are read here, by the MCAP specification's layout, rather than by ``mcap``'s
    reader, which makes a Python object of every record (each chunk's message indexes
    too): reading one channel of a flight log with camera frames takes a third of the time."""
    import zstandard
    from mcap.exceptions import McapError

    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        if f.read(len(_MAGIC)) != _MAGIC:
            return  # empty, cut inside its magic, or not an MCAP file: no records
        while True:
            head = f.read(_RECORD.size)
            if len(head) < _RECORD.size:
                return
            opcode, length = _RECORD.unpack(head)
            if length > size - f.tell():
                return  # cut short (or a damaged length)
            if opcode not in (_OP_CHUNK, _OP_MESSAGE, _OP_CHANNEL, _OP_FOOTER):
                f.seek(length, io.SEEK_CUR)
                continue
            body = f.read(length)
            if len(body) < length:
                return  # cut short
            if opcode == _OP_FOOTER:
                if complete is not None:
                    complete.append(True)
                continue
            try:
                if opcode == _OP_CHUNK:
                    yield from _chunk_messages(body, channels)
                else:
                    yield from _record(opcode, body, 0, length, channels)
            except (ValueError, struct.error, EOFError, RuntimeError, McapError,
                    zstandard.ZstdError):
                return  # damaged (lz4 raises RuntimeError): keep what was read


def _chunk_messages(chunk: bytes, channels: Container[int]) -> Iterator:
    _start, _end, size, _crc, name_b = _CHUNK.unpack_from(chunk, 0)
    at = _CHUNK.size
    compression = chunk[at:at + name_b].decode()
    at += name_b
    (records_b,) = struct.unpack_from("<Q", chunk, at)
    at += 8
    data = chunk[at:at + records_b]
    if compression == "zstd":
        import zstandard

        data = zstandard.decompress(data, size)
    elif compression == "lz4":
        import lz4.frame

        data = lz4.frame.decompress(data)
    elif compression:
        raise ValueError(f"chunk compression {compression!r}")
    at, end = 0, len(data)
    while at + _RECORD.size <= end:
        opcode, length = _RECORD.unpack_from(data, at)
        at += _RECORD.size
        if at + length > end:
            raise ValueError("a chunk record runs past its chunk")
        if opcode in (_OP_MESSAGE, _OP_CHANNEL):
            yield from _record(opcode, data, at, length, channels)
        at += length


def _record(opcode: int, data: bytes, at: int, length: int, channels: Container[int]
            ) -> Iterator:
    if opcode == _OP_MESSAGE:
        channel = _MESSAGE_CHANNEL.unpack_from(data, at)[0]
        if channel in channels:  # (others are not copied out: camera frames are large)
            yield channel, data[at + _MESSAGE_HEADER_B:at + length]
    else:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Channel

        yield Channel.read(ReadDataStream(io.BytesIO(data[at:at + length])))


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
