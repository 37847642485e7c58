"""The flight log: every record goes to ``flight.mcap`` as it happens (so a run that crashes
still leaves a readable log) and stays in memory for the end-of-run metrics.

One channel per stream, JSON-encoded with a JSON Schema per channel (``jsonschema`` encoding),
which Foxglove Studio and PlotJuggler open. Records in memory may hold numpy values and NaN;
in the file they are plain numbers and null. Log time is the run's clock (simulated seconds in
lockstep), in nanoseconds.
"""

from __future__ import annotations

import json
import struct
from collections import defaultdict
from pathlib import Path
from typing import IO

import orjson
from mcap.writer import Writer

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
    from mcap.exceptions import McapError
    from mcap.records import Channel, Footer, Message
    from mcap.stream_reader import StreamReader

    records: dict[str, list[dict]] = defaultdict(list)
    topics: dict[int, str] = {}
    complete = False
    with open(path, "rb") as f:
        # front to back, record by record: a file cut short has no footer or summary to seek
        stream = StreamReader(f, validate_crcs=False)
        try:
            for record in stream.records:
                if isinstance(record, Channel):
                    topics[record.id] = record.topic
                elif isinstance(record, Message) and record.channel_id in topics:
                    records[topics[record.channel_id]].append(json.loads(record.data))
                elif isinstance(record, Footer):
                    complete = True
        except (McapError, EOFError, ValueError, struct.error):
            pass  # truncated: keep what was read
    return records, complete
