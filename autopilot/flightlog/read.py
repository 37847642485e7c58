"""Reading a flight log back: ``flight.mcap`` → records per channel (as they were written)."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

from mcap.reader import make_reader


def read_records(path: str | Path) -> dict[str, list[dict]]:
    records: dict[str, list[dict]] = defaultdict(list)
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            records[channel.topic].append(json.loads(message.data))
    return dict(records)
