"""Progress lines for the person watching a run: one line every few seconds (or a live line on
a terminal), in wall time."""

from __future__ import annotations

import asyncio
import sys
from collections.abc import Callable


async def report_progress(line: Callable[[], str], sink: Callable[[str], None],
                          interval_s: float) -> None:
    """Until cancelled: on a terminal, rewrite one status line 4 times a second; otherwise
    hand ``line()`` to ``sink`` every ``interval_s``."""
    interactive = sys.stderr.isatty()
    interval = 0.25 if interactive else interval_s
    while True:
        await asyncio.sleep(interval)  # wall time: progress is for the person watching
        text = line()
        if interactive:
            sys.stderr.write("\r" + text.ljust(100))
            sys.stderr.flush()
        else:
            sink(text)
