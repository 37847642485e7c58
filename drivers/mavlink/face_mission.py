"""The mission protocol of the simulator's MAVLink face, as PX4's ``mavlink_mission`` speaks it.

Upload (MISSION_COUNT → the vehicle requests each item → MISSION_ITEM_INT or MISSION_ITEM →
MISSION_ACK), download (MISSION_REQUEST_LIST → MISSION_COUNT → requests → items → the client's
ACK), MISSION_CLEAR_ALL and MISSION_SET_CURRENT, for the mission, geofence and rally lists.

Items are requested with MISSION_REQUEST until the client shows it wants the INT form, as PX4
does: MAVSDK answers a MISSION_REQUEST with MISSION_ACK(UNSUPPORTED), and from then on the link
uses MISSION_REQUEST_INT. Unlike PX4, receiving a MISSION_ITEM_INT does not switch the link to
MISSION_REQUEST_INT: MAVProxy answers MISSION_REQUEST with MISSION_ITEM_INT but does not answer
MISSION_REQUEST_INT at all, so that switch would stall its uploads after the first item.
A request unanswered for 250 ms is sent again; a transfer idle for 5 s is abandoned.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from drivers.mission import (
    GLOBAL_FRAMES,
    MAX_ITEMS,
    MISSION_ACCEPTED,
    MISSION_ERROR,
    MISSION_INVALID,
    MISSION_NO_SPACE,
    MISSION_OPERATION_CANCELLED,
    MISSION_UNSUPPORTED,
    Frame,
    MissionItem,
    MissionRejected,
    MissionType,
    check_items,
)

log = logging.getLogger(__name__)

RETRY_S = 0.25
TIMEOUT_S = 5.0
_ALL_TYPES = 255
#: MISSION_ITEM_INT carries local positions in units of 0.1 mm (metres × 1e4)
_LOCAL_SCALE = 1e4
_FLOAT_TO_INT_FRAME = {Frame.GLOBAL: Frame.GLOBAL_INT,
                       Frame.GLOBAL_RELATIVE_ALT: Frame.GLOBAL_RELATIVE_ALT_INT,
                       Frame.GLOBAL_TERRAIN_ALT: Frame.GLOBAL_TERRAIN_ALT_INT}
_INT_TO_FLOAT_FRAME = {v: k for k, v in _FLOAT_TO_INT_FRAME.items()}


class MissionStore(Protocol):
    """What the face needs of a vehicle that stores and flies missions."""

    async def upload_mission(self, items: list[MissionItem], mission_type: int = 0) -> None: ...

    def mission_items(self, mission_type: int = 0) -> list[MissionItem]: ...

    async def set_mission_current(self, seq: int) -> None: ...

    @property
    def mission_status(self): ...


@dataclass
class _Transfer:
    """An upload in progress on one link."""

    mission_type: int
    count: int
    peer: tuple[int, int]  # the uploader's (system, component)
    items: list[MissionItem] = field(default_factory=list)
    last_request_s: float = 0.0
    last_progress_s: float = 0.0

    @property
    def next_seq(self) -> int:
        return len(self.items)


def item_from_message(msg) -> MissionItem:
    """A MISSION_ITEM or MISSION_ITEM_INT as a :class:`MissionItem` (positions decoded)."""
    is_int = msg.get_type() == "MISSION_ITEM_INT"
    frame = msg.frame
    x, y = float(msg.x), float(msg.y)
    if is_int:
        if frame in GLOBAL_FRAMES or frame in _INT_TO_FLOAT_FRAME:
            x, y = x / 1e7, y / 1e7
        elif frame in (Frame.LOCAL_NED, Frame.LOCAL_ENU, Frame.LOCAL_OFFSET_NED):
            x, y = x / _LOCAL_SCALE, y / _LOCAL_SCALE
    return MissionItem(seq=msg.seq, frame=frame, command=msg.command, param1=msg.param1,
                       param2=msg.param2, param3=msg.param3, param4=msg.param4, x=x, y=y,
                       z=float(msg.z), autocontinue=bool(msg.autocontinue),
                       mission_type=getattr(msg, "mission_type", 0))


def item_message(mav, item: MissionItem, target: tuple[int, int], current: bool,
                 as_int: bool):
    """The MISSION_ITEM_INT (or MISSION_ITEM) that carries ``item``."""
    frame = item.frame
    x, y = item.x, item.y
    if as_int:
        frame = _FLOAT_TO_INT_FRAME.get(frame, frame)
        if frame in GLOBAL_FRAMES:
            xi, yi = _int(x * 1e7), _int(y * 1e7)
        elif frame in (Frame.LOCAL_NED, Frame.LOCAL_ENU, Frame.LOCAL_OFFSET_NED):
            xi, yi = _int(x * _LOCAL_SCALE), _int(y * _LOCAL_SCALE)
        else:
            xi, yi = _int(x), _int(y)
        return mav.mission_item_int_encode(*target, item.seq, frame, item.command, int(current),
                                           int(item.autocontinue), item.param1, item.param2,
                                           item.param3, item.param4, xi, yi, item.z,
                                           item.mission_type)
    frame = _INT_TO_FLOAT_FRAME.get(frame, frame)
    return mav.mission_item_encode(*target, item.seq, frame, item.command, int(current),
                                   int(item.autocontinue), item.param1, item.param2,
                                   item.param3, item.param4, _finite(x), _finite(y), item.z,
                                   item.mission_type)


def _int(value: float) -> int:
    return round(value) if math.isfinite(value) else 0


def _finite(value: float) -> float:
    return value if math.isfinite(value) else 0.0


class MissionServer:
    """Serves the mission protocol for one vehicle on any number of links.

    ``send(link, msg)`` sends, ``spawn(coro)`` runs a coroutine owned by the face,
    ``say(link, text, severity)`` sends a STATUSTEXT.
    """

    def __init__(self, store: MissionStore, send: Callable, spawn: Callable, say: Callable,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.store = store
        self._send = send
        self._spawn = spawn
        self._say = say
        self._clock = clock
        self._uploads: dict[object, _Transfer] = {}
        #: links whose client answered MISSION_REQUEST with ACK(UNSUPPORTED): INT from then on
        self._int_links: set[object] = set()

    # ------------------------------------------------------------------------------------
    # Upload
    # ------------------------------------------------------------------------------------

    def on_count(self, link, msg) -> None:
        mission_type = getattr(msg, "mission_type", 0)
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        if mission_type not in tuple(MissionType):
            self._ack(link, peer, MISSION_INVALID, mission_type)
            return
        if msg.count > MAX_ITEMS:
            self._ack(link, peer, MISSION_NO_SPACE, mission_type)
            return
        busy = self._uploads.get(link)
        if busy is not None and busy.peer != peer and \
                self._clock() - busy.last_progress_s < TIMEOUT_S:
            self._ack(link, peer, MISSION_ERROR, mission_type)
            return
        if msg.count == 0:
            self._uploads.pop(link, None)
            self._spawn(self._store(link, peer, [], mission_type))
            return
        now = self._clock()
        transfer = _Transfer(mission_type, msg.count, peer, last_progress_s=now)
        self._uploads[link] = transfer
        self._request(link, transfer)

    def on_item(self, link, msg) -> None:
        transfer = self._uploads.get(link)
        if transfer is None:
            return
        mission_type = getattr(msg, "mission_type", 0)
        if mission_type != transfer.mission_type:
            self._abort(link, transfer, MISSION_ERROR)
            return
        if msg.seq != transfer.next_seq:
            return  # a repeat, or one ahead of what we asked for: ask again on the timer
        try:
            item = item_from_message(msg)
            check_items([item], transfer.mission_type)
        except MissionRejected as exc:
            log.info("mission upload refused: %s", exc)
            self._say(link, f"mission item {msg.seq} refused: {exc}", 4)
            self._abort(link, transfer, exc.result)
            return
        transfer.items.append(item)
        transfer.last_progress_s = self._clock()
        if transfer.next_seq < transfer.count:
            self._request(link, transfer)
            return
        del self._uploads[link]
        self._spawn(self._store(link, transfer.peer, transfer.items, transfer.mission_type))

    async def _store(self, link, peer: tuple[int, int], items: list[MissionItem],
                     mission_type: int) -> None:
        try:
            check_items(items, mission_type)
            await self.store.upload_mission(items, mission_type)
        except MissionRejected as exc:
            self._say(link, f"mission refused: {exc}", 4)
            self._ack(link, peer, exc.result, mission_type)
            return
        except Exception as exc:  # the vehicle could not take it: say so, never hang
            log.warning("mission upload failed: %s", exc)
            self._ack(link, peer, MISSION_ERROR, mission_type)
            return
        self._ack(link, peer, MISSION_ACCEPTED, mission_type)

    def on_ack(self, link, msg) -> None:
        transfer = self._uploads.get(link)
        if transfer is not None and msg.type == MISSION_UNSUPPORTED and link not in \
                self._int_links:
            # MAVSDK's answer to MISSION_REQUEST: it speaks MISSION_REQUEST_INT only
            self._int_links.add(link)
            self._request(link, transfer)
        elif transfer is not None and msg.type != MISSION_ACCEPTED:
            log.info("mission upload cancelled by the client (MISSION_ACK %d)", msg.type)
            del self._uploads[link]

    def _request(self, link, transfer: _Transfer) -> None:
        transfer.last_request_s = self._clock()
        if link in self._int_links:
            msg = link.mav.mission_request_int_encode(*transfer.peer, transfer.next_seq,
                                                      transfer.mission_type)
        else:
            msg = link.mav.mission_request_encode(*transfer.peer, transfer.next_seq,
                                                  transfer.mission_type)
        self._send(link, msg)

    def _abort(self, link, transfer: _Transfer, result: int) -> None:
        self._uploads.pop(link, None)
        self._ack(link, transfer.peer, result, transfer.mission_type)

    def _ack(self, link, peer: tuple[int, int], result: int, mission_type: int) -> None:
        self._send(link, link.mav.mission_ack_encode(*peer, result, mission_type))

    def tick(self) -> None:
        """Re-request lost items, and give up on transfers that went quiet."""
        now = self._clock()
        for link, transfer in list(self._uploads.items()):
            if now - transfer.last_progress_s > TIMEOUT_S:
                log.info("mission upload timed out at item %d of %d", transfer.next_seq,
                         transfer.count)
                self._abort(link, transfer, MISSION_OPERATION_CANCELLED)
            elif now - transfer.last_request_s > RETRY_S:
                self._request(link, transfer)

    # ------------------------------------------------------------------------------------
    # Download, clear, set current
    # ------------------------------------------------------------------------------------

    def on_request_list(self, link, msg) -> None:
        mission_type = getattr(msg, "mission_type", 0)
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        if mission_type not in tuple(MissionType):
            self._ack(link, peer, MISSION_INVALID, mission_type)
            return
        count = len(self.store.mission_items(mission_type))
        self._send(link, link.mav.mission_count_encode(*peer, count, mission_type))

    def on_request(self, link, msg) -> None:
        mission_type = getattr(msg, "mission_type", 0)
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        items = self.store.mission_items(mission_type)
        if not 0 <= msg.seq < len(items):
            self._ack(link, peer, MISSION_ERROR, mission_type)
            return
        current = mission_type == MissionType.MISSION and \
            msg.seq == self.store.mission_status.current
        self._send(link, item_message(link.mav, items[msg.seq], peer, current,
                                      as_int=msg.get_type() == "MISSION_REQUEST_INT"))

    def on_clear_all(self, link, msg) -> None:
        mission_type = getattr(msg, "mission_type", 0)
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        types = list(MissionType) if mission_type == _ALL_TYPES else [mission_type]
        if any(t not in tuple(MissionType) for t in types):
            self._ack(link, peer, MISSION_INVALID, mission_type)
            return

        async def clear() -> None:
            for kind in types:
                await self.store.upload_mission([], kind)
            self._ack(link, peer, MISSION_ACCEPTED, mission_type)

        self._spawn(clear())

    def on_set_current(self, link, msg) -> None:
        total = len(self.store.mission_items(MissionType.MISSION))
        if not 0 <= msg.seq < total:
            self._say(link, "WPM: WP CURR CMD: Not in list", 4)
            return
        self._spawn(self.store.set_mission_current(msg.seq))

