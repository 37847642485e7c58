"""The face's MAVLink endpoints (PX4 SITL's two UDP ports: one for the offboard API, one for
ground stations): parsing, signing, the peer each replies to, the message streams each gets and
the requests it made; and the face's counters."""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import common as mavlink

from drivers.mavlink.face_telemetry import DEFAULT_RATES_HZ
from drivers.mavlink.link import pack
from drivers.mavlink.signing import authenticated, refresh

if TYPE_CHECKING:
    from drivers.mavlink.face import MavlinkFace

log = logging.getLogger(__name__)

COMPONENT_ID = 1  # MAV_COMP_ID_AUTOPILOT1: MAVSDK finds an autopilot only there


@dataclass
class FaceStats:
    received: int = 0
    bad_data: int = 0
    bad_signature: int = 0
    ignored: int = 0
    commands: int = 0
    setpoints: int = 0
    rejected_setpoints: int = 0
    landing_targets: int = 0
    link_dropped: int = 0  # lost to a link_loss fault


class FaceLink(asyncio.DatagramProtocol):
    """One UDP port of the vehicle: sends to ``peer`` (the last sender, or the default)."""

    def __init__(self, name: str, face: MavlinkFace, default_peer: tuple[str, int]) -> None:
        self.name = name
        self.face = face
        self.peer = default_peer
        self.heard_from: tuple[str, int] | None = None
        self.transport: asyncio.DatagramTransport | None = None
        dialect = face.dialect  # PX4: common; ArduPilot: ardupilotmega
        self.mav = dialect.MAVLink(None, srcSystem=face.system_id, srcComponent=COMPONENT_ID)
        self._rx = dialect.MAVLink(None, srcSystem=face.system_id, srcComponent=COMPONENT_ID)
        self._rx.robust_parsing = True
        #: the scenario's rover, a second system on the same port (as a router relays it)
        self.rover_mav = dialect.MAVLink(None, srcSystem=face.rover_system_id,
                                         srcComponent=COMPONENT_ID)
        if face.signing is not None:
            face.signing.apply(self.mav, self._rx, face.signed_streams)
            face.signing.apply(self.rover_mav, mavlink.MAVLink(None))

    def connection_made(self, transport) -> None:
        self.transport = transport

    def datagram_received(self, data: bytes, addr) -> None:
        fault = self.face.impairment.fault()
        if fault is not None:  # the simulator's link_loss fault, on the way in
            self.face.impairment.carry(fault, lambda: self._parse(data, addr))
            return
        self._parse(data, addr)

    def _parse(self, data: bytes, addr) -> None:
        try:
            messages = self._rx.parse_buffer(data) or []
        except Exception as exc:  # pymavlink raises on some corrupt (or badly signed) frames
            if "signature" in str(exc).lower():
                self.face.stats.bad_signature += 1
            else:
                self.face.stats.bad_data += 1
            log.debug("%s: unparsable datagram from %s: %s", self.name, addr, exc)
            return
        good = [m for m in messages
                if m.get_type() != "BAD_DATA" and authenticated(m, self.face.signing)]
        if good:  # only a sender that spoke valid (and, with signing, signed) MAVLink is answered
            self.peer = self.heard_from = addr
        for msg in messages:
            self.face.incoming.receive(self, msg)

    def error_received(self, exc: Exception) -> None:  # e.g. ICMP port unreachable
        log.debug("%s: %s", self.name, exc)

    def send(self, msg, mav=None) -> None:
        """``msg`` from the vehicle (or from the system ``mav`` speaks for: the rover)."""
        if self.transport is None or self.transport.is_closing():
            return
        mav = mav or self.mav
        refresh(mav)
        data, peer = pack(mav, msg), self.peer
        fault = self.face.impairment.fault()
        if fault is not None:  # the simulator's link_loss fault, on the way out
            self.face.impairment.carry(fault, lambda: self._sendto(data, peer))
            return
        self._sendto(data, peer)

    def _sendto(self, data: bytes, peer) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.sendto(data, peer)


class FaceStreamLink(FaceLink, asyncio.Protocol):
    """One TCP connection to a serial port of the vehicle (ArduCopter SITL's SERIALn on TCP
    5760, 5762, 5763): the same parsing and sending as a UDP port, on a byte stream.
    ``on_close(link)`` is told when the client goes."""

    def __init__(self, name: str, face: MavlinkFace, on_close=None) -> None:
        super().__init__(name, face, ("", 0))
        self._on_close = on_close

    def connection_made(self, transport) -> None:
        self.transport = transport
        peer = transport.get_extra_info("peername")
        self.peer = self.heard_from = tuple(peer[:2]) if peer else ("", 0)

    def data_received(self, data: bytes) -> None:
        self.datagram_received(data, self.peer)

    def connection_lost(self, exc: Exception | None) -> None:
        if self._on_close is not None:
            self._on_close(self)

    def _sendto(self, data: bytes, peer) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.write(data)


@dataclass
class FaceStreams:
    rates_hz: dict[int, float] = field(default_factory=lambda: dict(DEFAULT_RATES_HZ))
    #: messages whose rate SET_MESSAGE_INTERVAL set: ArduPilot's stream groups
    #: (REQUEST_DATA_STREAM) leave them be
    overridden: set[int] = field(default_factory=set)
    next_s: dict[int, float] = field(default_factory=dict)

    def due(self, msg_id: int, now_s: float) -> bool:
        rate = self.rates_hz.get(msg_id, 0.0)
        if rate <= 0.0:
            return False
        due_s = self.next_s.get(msg_id, 0.0)
        if now_s + 1e-6 < due_s:
            return False
        period = 1.0 / rate
        # stay on the grid, but never try to catch up on missed sends
        self.next_s[msg_id] = max(due_s + period, now_s + 0.5 * period)
        return True


class FaceRequests:
    """What a command may ask of the link it came on (message intervals, a message now)."""

    def __init__(self, face: MavlinkFace, link: FaceLink) -> None:
        self.face, self.link = face, link

    def set_interval(self, msg_id: int, interval_us: float) -> int:
        return self.face.set_interval(self.link, msg_id, interval_us)

    def send_now(self, msg_id: int) -> bool:
        msg = self.face.message(msg_id, self.link.mav)
        if msg is None:
            return False
        self.link.send(msg)
        return True
