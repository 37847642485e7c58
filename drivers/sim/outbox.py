"""The simulator's outputs on their way to the vehicle interface: each captured with its
delivery time (capture time + latency), handed over in delivery order (ties: in capture order).
A frame's pixels are collected from the renderer when it is due, a photo's likewise; while
frames are shed in real time, one still being drawn when due is handed over when it is drawn."""

from __future__ import annotations

import dataclasses
import heapq
import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Literal

from drivers.base import Frame
from drivers.sim.captures import CameraCaptures

OutputKind = Literal["telemetry", "frame", "truth", "event", "mission", "photo", "uwb",
                     "rover"]
#: the kinds a stepping driver must stop for (the others are delivered to buffered subscribers)
PROMPT_KINDS = ("telemetry", "frame")


@dataclass(frozen=True, slots=True)
class SimOutput:
    delivery_s: float
    kind: OutputKind
    payload: Any


class Outbox:
    def __init__(self, captures: CameraCaptures, finish: Callable[[Frame], Frame]) -> None:
        self._captures = captures
        #: a frame as it leaves (what injected faults make of it)
        self._finish = finish
        self._heap: list[tuple[float, int, SimOutput]] = []
        self._seq = itertools.count()

    def put(self, delivery_s: float, kind: OutputKind, payload: Any) -> None:
        heapq.heappush(self._heap, (delivery_s, next(self._seq),
                                    SimOutput(delivery_s, kind, payload)))

    def due(self, now_s: float, retry_s: float) -> list[SimOutput]:
        """The outputs due by ``now_s``; a frame still being drawn is put back for
        ``retry_s``."""
        out, rendering = [], []
        rig = self._captures.rig
        while self._heap and self._heap[0][0] <= now_s:
            item = heapq.heappop(self._heap)[2]
            if item.kind == "frame":
                if not self._captures.ready(item.payload):
                    rendering.append(item.payload)  # delivered when drawn, later than due
                    continue
                item = SimOutput(item.delivery_s, "frame",
                                 self._finish(rig.finish(item.payload)))
            elif item.kind == "photo" and isinstance(item.payload, tuple):
                meta, pending = item.payload
                item = SimOutput(item.delivery_s, "photo", dataclasses.replace(
                    meta, frame=rig.finish(pending)))
            out.append(item)
        for pending in rendering:
            self.put(retry_s, "frame", pending)
        return out

    def deliveries(self, every_kind: bool = False) -> Iterator[float]:
        """The delivery times waiting (of :data:`PROMPT_KINDS`, or of every kind)."""
        return (d for d, _, out in self._heap if every_kind or out.kind in PROMPT_KINDS)
