"""MAVLink 2 over UDP on the event loop (no threads), and the vehicle-time → local-time mapping.

Connection URLs as MAVSDK spells them: ``udpin://HOST:PORT`` listens there and answers whoever
writes (a vehicle that sends to this port, as PX4 SITL sends to 14540); ``udpout://HOST:PORT``
sends there first (a vehicle that listens, as ArduPilot SITL's ``--out``). ``udp://:PORT`` is
the old spelling of ``udpin``.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from urllib.parse import urlsplit

from pymavlink.dialects.v20 import common as mavlink

log = logging.getLogger(__name__)

#: A companion computer's usual MAVLink identity (MAV_COMP_ID_ONBOARD_COMPUTER).
GCS_SYSTEM_ID = 245
ONBOARD_COMPONENT_ID = 191


@dataclass(frozen=True, slots=True)
class Endpoint:
    listen: bool  # udpin: bind here, answer whoever writes
    host: str
    port: int

    @classmethod
    def parse(cls, url: str) -> Endpoint:
        parts = urlsplit(url)
        if parts.scheme not in ("udpin", "udpout", "udp") or parts.port is None:
            raise ValueError(f"unsupported MAVLink connection {url!r}: expected "
                             "udpin://HOST:PORT, udpout://HOST:PORT or udp://:PORT")
        listen = parts.scheme in ("udpin", "udp")
        host = parts.hostname or ("0.0.0.0" if listen else "127.0.0.1")
        return cls(listen, host, parts.port)


def pack(mav, msg) -> bytes:
    """Encode ``msg`` with ``mav``'s identity and next sequence number (``MAVLink.pack``
    alone leaves the sequence at 0, which receivers count as lost packets)."""
    data = msg.pack(mav)
    mav.seq = (mav.seq + 1) % 256
    return data


class MavlinkUdp(asyncio.DatagramProtocol):
    """One UDP MAVLink link: parses datagrams into messages for ``on_message``."""

    def __init__(self, on_message: Callable[[object], None], *,
                 system_id: int = GCS_SYSTEM_ID, component_id: int = ONBOARD_COMPONENT_ID) -> None:
        self._on_message = on_message
        self.mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._rx = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._rx.robust_parsing = True
        self.transport: asyncio.DatagramTransport | None = None
        self.peer: tuple[str, int] | None = None
        self.bad_data = 0

    @classmethod
    async def open(cls, url: str, on_message: Callable[[object], None], **kwargs) -> MavlinkUdp:
        endpoint = Endpoint.parse(url)
        loop = asyncio.get_running_loop()
        link = cls(on_message, **kwargs)
        if endpoint.listen:
            await loop.create_datagram_endpoint(lambda: link,
                                                local_addr=(endpoint.host, endpoint.port))
        else:
            await loop.create_datagram_endpoint(lambda: link, local_addr=("0.0.0.0", 0))
            link.peer = (endpoint.host, endpoint.port)
        return link

    def connection_made(self, transport) -> None:
        self.transport = transport

    def datagram_received(self, data: bytes, addr) -> None:
        self.peer = addr
        try:
            messages = self._rx.parse_buffer(data) or []
        except Exception:  # pymavlink raises on some corrupt frames even when robust
            self.bad_data += 1
            return
        for msg in messages:
            if msg.get_type() == "BAD_DATA":
                self.bad_data += 1
                continue
            self._on_message(msg)

    def error_received(self, exc: Exception) -> None:
        log.debug("MAVLink link: %s", exc)

    def send(self, msg) -> bool:
        """Send if the peer is known (a listening link learns it from the first packet)."""
        if self.transport is None or self.transport.is_closing() or self.peer is None:
            return False
        self.transport.sendto(pack(self.mav, msg), self.peer)
        return True

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()


class BootTimeMapper:
    """Maps the vehicle's boot-time stamps (``time_boot_ms``) onto the local clock.

    Best from MAVLink TIMESYNC round trips (:meth:`observe_sync`): the offset local − vehicle
    from the exchange with the shortest round trip seen recently, which assumes only that the
    way there and back take equally long. Until a round trip has been measured, telemetry
    stamps give an upper bound (:meth:`observe`: the smallest local − vehicle seen, which still
    contains the vehicle's own telemetry latency). Either estimate may creep by
    ``drift_per_s`` per second to follow clock drift, and is reset when the vehicle's time
    jumps back (a reboot).
    """

    def __init__(self, drift_per_s: float = 1e-4) -> None:
        self._drift = drift_per_s
        self._offset = math.nan
        self._last_local = math.nan
        self._last_vehicle = math.nan
        self._synced = False
        self._rtt = math.inf
        self._sync_at = 0.0

    @property
    def ready(self) -> bool:
        return math.isfinite(self._offset)

    def observe(self, vehicle_s: float, local_s: float) -> None:
        """A telemetry sample stamped ``vehicle_s`` arrived at ``local_s``."""
        if vehicle_s < self._last_vehicle - 1.0:  # the vehicle rebooted
            self._offset, self._synced, self._rtt = math.nan, False, math.inf
        if not self._synced:
            sample = local_s - vehicle_s
            if not self.ready:
                self._offset = sample
            else:
                crept = self._offset + self._drift * max(0.0, local_s - self._last_local)
                self._offset = min(crept, sample)
        self._last_local, self._last_vehicle = local_s, vehicle_s

    def observe_sync(self, sent_local_s: float, vehicle_s: float, received_local_s: float) -> None:
        """A TIMESYNC exchange: sent at ``sent_local_s``, answered with the vehicle's time
        ``vehicle_s``, the answer received at ``received_local_s``."""
        rtt = received_local_s - sent_local_s
        if rtt < 0.0:
            return
        # older round trips count for less as time passes (drift): inflate them slowly
        aged = self._rtt + 2.0 * self._drift * max(0.0, received_local_s - self._sync_at)
        if not self._synced or rtt <= aged:
            self._offset = (sent_local_s + received_local_s) / 2.0 - vehicle_s
            self._rtt, self._sync_at, self._synced = rtt, received_local_s, True

    @property
    def round_trip_s(self) -> float:
        """The round trip of the exchange the offset comes from (inf before any)."""
        return self._rtt

    def to_local(self, vehicle_s: float) -> float:
        return vehicle_s + self._offset
