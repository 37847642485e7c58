"""Event hooks: what the autopilot does, for programs that embed it (seed 000's controller
events ``on_status_hovering``, ``before_cmd_land``, …) and for the console's event log.

The runtime *emits* :class:`Event` values (never waiting); subscribers take them at their own
pace::

    async for event in runtime.events.subscribe({"status", "command"}):
        print(event.hook, event.text)

    runtime.events.on("before_cmd_land", lambda event: print("landing", event.time_s))
    runtime.events.on("status", notify)           # a kind: every status change

Kinds: ``status`` (the mission status code changed; hook ``on_status_<label>``), ``mode`` (the
vehicle's flight mode; ``on_mode_<mode>``), ``armed`` (``on_armed`` / ``on_disarmed``),
``step_started``, ``step_ended`` (``on_step_started`` / ``on_step_ended``, with ``outcome``),
``command`` (a command to the vehicle: ``before_cmd_<name>`` as it is sent, ``after_cmd_<name>``
with its ``result``), ``mission`` (other mission events: fallback, abort, goals), ``status_text``
(the vehicle's status messages) and ``console`` (the console's keys: autopilot on/off, follow
mode, emergency stop).

Hooks cannot hold up the control loop: :meth:`EventHub.emit` only appends to each subscriber's
bounded queue. A subscriber whose queue is full — it stopped keeping up — is dropped and a
warning logged; so is a callback that raises or runs longer than its time limit. Synchronous
callbacks run on a thread of their own (use ``loop.call_soon_threadsafe`` to touch the event
loop from one); coroutine callbacks run as tasks of the hub, one event at a time each.
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import logging
import math
from collections import deque
from collections.abc import AsyncIterator, Callable, Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from types import MappingProxyType

log = logging.getLogger(__name__)

KINDS = frozenset({"status", "mode", "armed", "step_started", "step_ended", "command",
                   "mission", "status_text", "console"})
RECENT = 200  # events kept for late subscribers to look back on
QUEUE_LENGTH = 256  # events a subscriber may be behind before it is dropped
CALLBACK_TIMEOUT_S = 1.0  # wall clock: a callback running longer is dropped


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in text.strip().lower()).strip("_")


@dataclass(frozen=True, slots=True)
class Event:
    """Something that happened, at ``time_s`` on the run's clock. ``name`` is what changed to
    (a status label, a mode, a command's name, a step's name); ``data`` carries the details
    (read-only)."""

    kind: str
    name: str
    time_s: float
    text: str = ""
    phase: str = ""  # command: before | after
    data: Mapping[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"unknown event kind {self.kind!r}; kinds: {sorted(KINDS)}")
        object.__setattr__(self, "data", MappingProxyType(dict(self.data)))

    @property
    def hook(self) -> str:
        """Seed 000's name for it: ``on_status_hover``, ``before_cmd_land``, ``on_mode_hold``."""
        if self.kind == "command":
            return f"{self.phase or 'before'}_cmd_{_slug(self.name)}"
        if self.kind in ("status", "mode"):
            return f"on_{self.kind}_{_slug(self.name)}"
        if self.kind == "armed":
            return "on_armed" if self.name == "armed" else "on_disarmed"
        return f"on_{self.kind}"

    def as_dict(self) -> dict:
        return {"kind": self.kind, "name": self.name, "hook": self.hook,
                "time_s": self.time_s if math.isfinite(self.time_s) else None,
                "text": self.text, "phase": self.phase, "data": dict(self.data)}


class Subscription:
    """One subscriber's queue of events. Async-iterable; the iteration ends when the hub
    closes, or when the subscriber fell too far behind (``dropped`` then says why)."""

    def __init__(self, hub: EventHub, select: Callable[[Event], bool], name: str,
                 length: int) -> None:
        self._hub = hub
        self._select = select
        self.name = name
        self._queue: asyncio.Queue[Event | None] = asyncio.Queue(maxsize=length)
        self.dropped: str | None = None
        self.closed = False

    def offer(self, event: Event) -> None:
        if self.closed or not self._select(event):
            return
        try:
            self._queue.put_nowait(event)
        except asyncio.QueueFull:
            self.drop(f"{self._queue.maxsize} events behind")

    def drop(self, why: str) -> None:
        if self.closed:
            return
        self.dropped = why
        log.warning("event hook %s dropped: %s", self.name, why)
        self._hub.dropped.append((self.name, why))
        self.close()

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self._hub._subs.discard(self)
        with contextlib.suppress(asyncio.QueueFull):
            self._queue.put_nowait(None)  # wakes the reader; a full queue wakes it anyway

    def __aiter__(self) -> AsyncIterator[Event]:
        return self

    async def __anext__(self) -> Event:
        if self.closed and self._queue.empty():
            raise StopAsyncIteration
        event = await self._queue.get()
        if event is None or (self.closed and self.dropped is not None):
            raise StopAsyncIteration
        return event

    def get_nowait(self) -> Event | None:
        """The next waiting event, or None (for tests and polling loops)."""
        try:
            event = self._queue.get_nowait()
        except asyncio.QueueEmpty:
            return None
        return event


def _selector(what: str | Iterable[str] | None) -> Callable[[Event], bool]:
    """Events by kind (``status``) or hook name (``before_cmd_land``); None: all."""
    if what is None:
        return lambda event: True
    names = {what} if isinstance(what, str) else set(what)
    unknown = {n for n in names if n not in KINDS and not n.startswith(("on_", "before_cmd_",
                                                                           "after_cmd_"))}
    if unknown:
        raise ValueError(f"not an event kind or hook name: {sorted(unknown)} (kinds: "
                         f"{sorted(KINDS)}; hooks: on_status_<label>, before_cmd_<name>, …)")
    return lambda event: event.kind in names or event.hook in names


class EventHub:
    """Fans the runtime's events out to subscribers without ever waiting on them."""

    def __init__(self, callback_timeout_s: float = CALLBACK_TIMEOUT_S) -> None:
        self._subs: set[Subscription] = set()
        self._callbacks: list[tuple[Subscription, Callable]] = []
        self._runners: list[asyncio.Task] = []
        self._group: asyncio.TaskGroup | None = None
        self.callback_timeout_s = callback_timeout_s
        self.emitted = 0
        #: the newest events (a console that opens mid-flight shows what happened)
        self.recent: deque[Event] = deque(maxlen=RECENT)
        #: (subscriber, why) of every subscriber dropped
        self.dropped: list[tuple[str, str]] = []

    def subscribe(self, what: str | Iterable[str] | None = None, *,
                  length: int = QUEUE_LENGTH, name: str = "subscriber") -> Subscription:
        """Events of some kinds or hooks (None: all), to ``async for`` over."""
        sub = Subscription(self, _selector(what), name, length)
        self._subs.add(sub)
        return sub

    def on(self, what: str | Iterable[str] | None, callback: Callable[[Event], object]
           ) -> Subscription:
        """Call ``callback(event)`` for matching events (a function: on the hooks' thread; a
        coroutine function: as a task). Returns the subscription (``close()`` to stop)."""
        name = getattr(callback, "__qualname__", repr(callback))
        sub = self.subscribe(what, name=name)
        self._callbacks.append((sub, callback))
        if self._group is not None:
            self._start_runner(sub, callback)
        return sub

    def emit(self, event: Event) -> None:
        """Hand ``event`` to every subscriber (never blocks, never raises)."""
        self.emitted += 1
        self.recent.append(event)
        for sub in list(self._subs):
            try:
                sub.offer(event)
            except Exception as exc:  # (a selector's bug): that subscriber goes, not the loop
                sub.drop(f"{type(exc).__name__}: {exc}")

    @property
    def runners(self) -> list[asyncio.Task]:
        """The callbacks' tasks (the owner cancels them when the run ends)."""
        return list(self._runners)

    # -- the callbacks' runners (owned by the runtime's task group) --------------------------

    def tasks(self, group: asyncio.TaskGroup) -> list[asyncio.Task]:
        self._group = group
        for sub, callback in self._callbacks:
            if not sub.closed:
                self._start_runner(sub, callback)
        return self._runners

    def _start_runner(self, sub: Subscription, callback: Callable) -> None:
        task = self._group.create_task(self._run_callback(sub, callback),
                                       name=f"hook-{sub.name}")
        self._runners.append(task)

    async def _run_callback(self, sub: Subscription, callback: Callable) -> None:
        loop = asyncio.get_running_loop()
        is_coroutine = inspect.iscoroutinefunction(callback)
        # a function gets a thread of its own: one that blocks holds up only itself
        pool = None if is_coroutine else ThreadPoolExecutor(
            1, thread_name_prefix=f"hooks-{sub.name}"[:40])
        try:
            async for event in sub:
                try:
                    if is_coroutine:
                        await asyncio.wait_for(callback(event), self.callback_timeout_s)
                    else:
                        await asyncio.wait_for(loop.run_in_executor(pool, callback, event),
                                               self.callback_timeout_s)
                except TimeoutError:
                    sub.drop(f"took longer than {self.callback_timeout_s:g} s")
                    return
                except Exception as exc:  # a hook's bug is the hook's: logged, then dropped
                    sub.drop(f"raised {type(exc).__name__}: {exc}")
                    return
        finally:
            if pool is not None:
                pool.shutdown(wait=False, cancel_futures=True)

    def close(self) -> None:
        """End every subscription (iterators finish; runners stop)."""
        for sub in list(self._subs):
            sub.close()
        self._group = None
