"""Latest-value hand-over between pipeline stages.

A :class:`LatestSlot` holds the newest value (or the newest ``capacity`` values): a producer
overwrites what the consumer has not taken yet (counting the drop), so a slow consumer always
gets fresh samples and latency never piles up in a queue. Control stages use capacity 1; a
logger that must miss nothing asks for a small buffer. :class:`Broadcast` fans one producer out
to any number of subscribers, each with its own slot. Both live on the event loop thread (not
thread-safe).
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import AsyncIterator, Callable
from typing import Generic, TypeVar

T = TypeVar("T")

class SlotClosed(Exception):
    """The producer has finished; no more values will come."""


class LatestSlot(Generic[T]):
    def __init__(self, capacity: int = 1) -> None:
        if capacity < 1:
            raise ValueError("capacity must be at least 1")
        self._values: deque[T] = deque(maxlen=capacity)
        self._event = asyncio.Event()
        self._closed = False
        self._error: BaseException | None = None
        #: Values overwritten before anyone took them.
        self.dropped = 0
        #: Values put in total.
        self.received = 0

    def put(self, value: T) -> None:
        if self._closed:
            return
        if len(self._values) == self._values.maxlen:
            self.dropped += 1
        self._values.append(value)
        self.received += 1
        self._event.set()

    def peek(self) -> T | None:
        """The newest waiting value without taking it (None when empty)."""
        return self._values[-1] if self._values else None

    async def get(self) -> T:
        """Take the oldest waiting value (the newest, with capacity 1), waiting for one.

        Raises the close error, or :class:`SlotClosed`, once closed and empty."""
        while not self._values:
            if self._closed:
                if self._error is not None:
                    raise self._error
                raise SlotClosed
            self._event.clear()
            await self._event.wait()
        return self._values.popleft()

    def close(self, error: BaseException | None = None) -> None:
        """No more values; waiting and future ``get`` calls raise ``error`` or SlotClosed
        (values already waiting are still delivered first)."""
        self._closed = True
        self._error = error
        self._event.set()


class Broadcast(Generic[T]):
    """One producer, many latest-value subscribers.

    ``on_first`` / ``on_last`` run when the first subscriber arrives and the last one leaves
    (the simulator uses them to render a camera only while someone watches).
    """

    def __init__(self, on_first: Callable[[], None] | None = None,
                 on_last: Callable[[], None] | None = None) -> None:
        self._slots: set[LatestSlot[T]] = set()
        self._on_first = on_first
        self._on_last = on_last
        self._closed = False
        self._error: BaseException | None = None

    @property
    def subscriber_count(self) -> int:
        return len(self._slots)

    def publish(self, value: T) -> None:
        for slot in self._slots:
            slot.put(value)

    def close(self, error: BaseException | None = None) -> None:
        self._closed = True
        self._error = error
        for slot in self._slots:
            slot.close(error)

    async def subscribe(self, buffer: int = 1) -> AsyncIterator[T]:
        """Iterate over published values, keeping at most the newest ``buffer`` unread ones;
        ends when the broadcast closes (or raises its error).

        Close the iterator (``contextlib.aclosing``) to unsubscribe promptly.
        """
        slot: LatestSlot[T] = LatestSlot(buffer)
        if self._closed:
            slot.close(self._error)
        self._slots.add(slot)
        if len(self._slots) == 1 and self._on_first is not None:
            self._on_first()
        try:
            while True:
                try:
                    value = await slot.get()
                except SlotClosed:
                    return
                yield value
        finally:
            self._slots.discard(slot)
            if not self._slots and self._on_last is not None:
                self._on_last()
