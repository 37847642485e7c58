"""MAVLink 2 links on the event loop (no threads), and the vehicle-time → local-time mapping.

Connection URLs as MAVSDK spells them:

* ``udpin://HOST:PORT`` listens there and answers the vehicle that writes (PX4 SITL sends to
  14540); ``udp://:PORT`` is the old spelling. ``udpout://HOST:PORT`` sends there first (a
  vehicle that listens, as ArduPilot SITL's ``--out``).
* ``tcpout://HOST:PORT`` (or ``tcp://``) connects to a vehicle's TCP server (ArduPilot SITL 5760,
  a WiFi telemetry bridge); ``tcpin://HOST:PORT`` waits for one to connect.
* ``serial:///dev/ttyAMA0:921600`` opens a serial port (a companion computer wired to the
  flight controller's TELEM port); the baud rate defaults to 57600.

A link *locks on* to its vehicle: once the driver has recognised the autopilot (its first
HEARTBEAT), :meth:`MavlinkLink.lock` fixes the address it came from, and datagrams from any other
address are dropped before they are parsed, with one log line naming the sender — a second
ground station or a stray script can neither inject messages nor redirect the setpoints.
With a :class:`~drivers.mavlink.signing.Signing` key, everything sent is signed and what arrives
unsigned or badly signed is dropped (counted in :attr:`MavlinkLink.stats`).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import math
import os
import re
import socket
import termios
from collections.abc import Callable
from dataclasses import dataclass
from urllib.parse import urlsplit

# ArduPilot's dialect (common and its own messages: EKF_STATUS_REPORT…): the link reads either
# firmware's vehicle
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from drivers.mavlink.signing import Signing, refresh

log = logging.getLogger(__name__)

#: A companion computer's usual MAVLink identity (MAV_COMP_ID_ONBOARD_COMPUTER).
GCS_SYSTEM_ID = 245
ONBOARD_COMPONENT_ID = 191
DEFAULT_BAUD = 57600
_SERIAL = re.compile(r"^serial://(?P<device>/.+?)(?::(?P<baud>\d+))?$")
#: what may wait for a slow port before newer frames are dropped (a 57600-baud radio moves
#: ~5.7 kB/s: older setpoints queued behind more would arrive seconds late)
MAX_PENDING_B = 8 << 10
TCP_CONNECT_TIMEOUT_S = 10.0
_URL_FORMS = ("udpin://HOST:PORT, udpout://HOST:PORT, tcpout://HOST:PORT, tcpin://HOST:PORT "
              "or serial:///dev/DEVICE[:BAUD]")


class LinkError(ConnectionError):
    """A link that cannot be opened; the message says what was tried and what to do."""


class UrlError(ValueError):
    """A connection URL that is malformed or names a transport we do not have."""


@dataclass(frozen=True, slots=True)
class Endpoint:
    kind: str  # udpin | udpout | tcpout | tcpin | serial
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = DEFAULT_BAUD

    @property
    def listen(self) -> bool:
        return self.kind in ("udpin", "tcpin")

    @classmethod
    def parse(cls, url: str) -> Endpoint:
        match = _SERIAL.match(url)
        if match:
            baud = int(match["baud"] or DEFAULT_BAUD)
            if _baud_constant(baud) is None:
                raise UrlError(f"{url!r}: {baud} is not a baud rate this system's serial ports "
                               "support (e.g. 57600, 115200, 921600)")
            return cls("serial", device=match["device"], baud=baud)
        try:
            parts = urlsplit(url)
            port = parts.port
        except ValueError as exc:
            raise UrlError(f"malformed MAVLink connection {url!r} ({exc}): expected "
                           f"{_URL_FORMS}") from None
        scheme = {"udp": "udpin", "tcp": "tcpout"}.get(parts.scheme, parts.scheme)
        if scheme == "serial":
            raise UrlError(f"malformed serial connection {url!r}: expected "
                           "serial:///dev/DEVICE[:BAUD], e.g. serial:///dev/ttyAMA0:921600")
        if scheme not in ("udpin", "udpout", "tcpout", "tcpin") or port is None:
            raise UrlError(f"unsupported MAVLink connection {url!r}: expected {_URL_FORMS}")
        # no host: this machine (a listening link binds loopback unless told otherwise)
        return cls(scheme, parts.hostname or "127.0.0.1", port)

    def __str__(self) -> str:
        if self.kind == "serial":
            return f"serial://{self.device}:{self.baud}"
        return f"{self.kind}://{self.host}:{self.port}"


def pack(mav, msg) -> bytes:
    """Encode ``msg`` with ``mav``'s identity and next sequence number (``MAVLink.pack``
    alone leaves the sequence at 0, which receivers count as lost packets)."""
    data = msg.pack(mav)
    mav.seq = (mav.seq + 1) % 256
    return data


@dataclass
class LinkStats:
    received: int = 0
    bad_data: int = 0
    bad_signature: int = 0
    #: datagrams from senders other than the locked-on vehicle
    ignored: int = 0
    #: frames not sent because a slow serial or TCP link had too much waiting
    dropped_out: int = 0


class MavlinkLink:
    """One MAVLink link: parses what arrives into messages for ``on_message(msg, address)``
    and sends messages (or raw frames) to the vehicle."""

    def __init__(self, endpoint: Endpoint, on_message: Callable[[object, object], None], *,
                 system_id: int = GCS_SYSTEM_ID, component_id: int = ONBOARD_COMPONENT_ID,
                 signing: Signing | None = None) -> None:
        self.endpoint = endpoint
        self._on_message = on_message
        self.mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._rx = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._rx.robust_parsing = True
        self.signing = signing
        if signing is not None:
            signing.apply(self.mav, self._rx)
        self.stats = LinkStats()
        #: where sends go: the locked-on vehicle, the first sender, or the udpout target
        self.peer: tuple[str, int] | None = None
        self.locked: object | None = None
        self._transport = None  # DatagramTransport | StreamWriter | serial fd
        self._closed = False
        self._warned: set[str] = set()
        self._reader_task: asyncio.Task | None = None
        self._server: asyncio.base_events.Server | None = None
        self._serial_fd: int | None = None
        self._serial_out = bytearray()

    # ------------------------------------------------------------------------------------
    # Opening and closing
    # ------------------------------------------------------------------------------------

    @classmethod
    async def open(cls, url: str, on_message: Callable[[object, object], None],
                   **kwargs) -> MavlinkLink:
        """Open ``url``; :class:`UrlError` for a bad URL, :class:`LinkError` when the
        transport cannot be opened (port in use, device missing, connection refused)."""
        endpoint = Endpoint.parse(url)
        link = cls(endpoint, on_message, **kwargs)
        try:
            await link._open()
        except OSError as exc:
            link.close()
            raise LinkError(link._open_error(exc)) from None
        return link

    def _open_error(self, exc: OSError) -> str:
        e = self.endpoint
        why = exc.strerror or str(exc)
        if exc.errno == errno.EADDRINUSE:
            return (f"cannot listen on {e}: address already in use (another autopilot, "
                    "MAVProxy or QGroundControl has the port; stop it or choose another port)")
        if exc.errno in (errno.EADDRNOTAVAIL, errno.EINVAL) and e.kind in ("udpin", "tcpin"):
            return f"cannot listen on {e}: {why} (is {e.host} an address of this machine?)"
        if e.kind == "serial":
            hint = {errno.ENOENT: "no such device (is the cable in, the UART enabled?)",
                    errno.EACCES: "permission denied (add the user to the 'dialout' group)",
                    errno.EBUSY: "busy (another program has it open)"}.get(exc.errno, why)
            return f"cannot open {e}: {hint}"
        if e.kind == "tcpout":
            return f"cannot connect to {e}: {why} (is the vehicle's TCP server up?)"
        return f"cannot open {e}: {why}"

    async def _open(self) -> None:
        loop = asyncio.get_running_loop()
        e = self.endpoint
        if e.kind in ("udpin", "udpout"):
            local = (e.host, e.port) if e.kind == "udpin" else ("0.0.0.0", 0)
            self._transport, _ = await loop.create_datagram_endpoint(
                lambda: _Datagrams(self), local_addr=local)
            if e.kind == "udpout":
                # replies come from a numeric address: lock onto that, not onto a host name
                infos = await loop.getaddrinfo(e.host, e.port, family=socket.AF_INET,
                                               type=socket.SOCK_DGRAM)
                self.peer = infos[0][4][:2]
                self.lock(self.peer)  # only the vehicle we were told to talk to
        elif e.kind == "tcpout":
            try:
                reader, writer = await asyncio.wait_for(
                    asyncio.open_connection(e.host, e.port), TCP_CONNECT_TIMEOUT_S)
            except TimeoutError:
                raise OSError(errno.ETIMEDOUT, f"no answer within {TCP_CONNECT_TIMEOUT_S:g} s") \
                    from None
            self._stream(reader, writer)
        elif e.kind == "tcpin":
            connected = loop.create_future()

            def client(reader, writer) -> None:
                if self._transport is not None:  # one vehicle per link
                    log.warning("%s: refusing a second TCP connection from %s", e,
                                writer.get_extra_info("peername"))
                    writer.close()
                    return
                self._stream(reader, writer)
                if not connected.done():
                    connected.set_result(None)

            self._server = await asyncio.start_server(client, e.host, e.port)
        else:
            self._open_serial()

    def _stream(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._transport = writer
        self.peer = writer.get_extra_info("peername")

        async def read() -> None:
            try:
                while data := await reader.read(4096):
                    self._feed(data, self.peer)
                log.warning("%s: the vehicle closed the connection", self.endpoint)
            except OSError as exc:
                log.warning("%s: the connection failed: %s", self.endpoint, exc)
            finally:  # a listening link takes the vehicle's next connection
                writer.close()
                if self._transport is writer:
                    self._transport = None

        self._reader_task = asyncio.get_running_loop().create_task(read(), name="mavlink-tcp")

    def _open_serial(self) -> None:
        e = self.endpoint
        fd = os.open(e.device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            attrs = termios.tcgetattr(fd)
            iflag, oflag, cflag, lflag, _, _, cc = attrs
            speed = _baud_constant(e.baud)
            # raw 8N1, no flow control, no echo: MAVLink is binary
            iflag = 0
            oflag = 0
            cflag = (cflag & ~(termios.CSIZE | termios.PARENB | termios.CSTOPB
                               | getattr(termios, "CRTSCTS", 0))) | termios.CS8 \
                | termios.CREAD | termios.CLOCAL
            lflag = 0
            cc[termios.VMIN], cc[termios.VTIME] = 0, 0
            termios.tcsetattr(fd, termios.TCSANOW, [iflag, oflag, cflag, lflag, speed, speed,
                                                    cc])
        except termios.error as exc:
            os.close(fd)
            raise OSError(errno.EINVAL, f"not a serial port ({exc})") from None
        self._serial_fd = fd
        self._transport = fd
        self.peer = (e.device, e.baud)
        asyncio.get_running_loop().add_reader(fd, self._serial_readable)

    def _serial_readable(self) -> None:
        try:
            data = os.read(self._serial_fd, 4096)
        except BlockingIOError:
            return
        except OSError as exc:
            data, error = b"", exc
        else:
            error = "hung up"
        if data:
            self._feed(data, self.peer)
            return
        # unplugged, or the other end closed: stop listening (a readable fd that never gives
        # data would spin the loop); the driver's heartbeat watchdog declares the link lost
        log.warning("%s: the serial port is gone (%s)", self.endpoint, error)
        with contextlib.suppress(Exception):
            asyncio.get_event_loop().remove_reader(self._serial_fd)

    def close(self) -> None:
        self._closed = True
        if self._reader_task is not None:
            self._reader_task.cancel()
        if self._server is not None:
            self._server.close()
        t = self._transport
        self._transport = None
        if t is not None and self._serial_fd is None:
            t.close()
        if self._serial_fd is not None:
            loop = asyncio.get_event_loop()
            with contextlib.suppress(Exception):
                loop.remove_reader(self._serial_fd)
                loop.remove_writer(self._serial_fd)
            with contextlib.suppress(OSError):
                os.close(self._serial_fd)
            self._serial_fd = None

    # ------------------------------------------------------------------------------------
    # Receiving
    # ------------------------------------------------------------------------------------

    def lock(self, address) -> None:
        """From now on, talk to ``address`` only (the vehicle's)."""
        if self.locked is None:
            self.locked = address
            self.peer = address
            log.info("%s: locked onto the vehicle at %s", self.endpoint, _where(address))

    def _datagram(self, data: bytes, address) -> None:
        if self.locked is not None and address != self.locked:
            self.stats.ignored += 1
            self._once(f"sender {address}", logging.WARNING,
                       "%s: ignoring MAVLink from %s: this link is locked onto the vehicle at %s",
                       self.endpoint, _where(address), _where(self.locked))
            return
        self._feed(data, address)

    def _feed(self, data: bytes, address) -> None:
        try:
            messages = self._rx.parse_buffer(data) or []
        except Exception:  # pymavlink raises on some corrupt frames even when robust
            self.stats.bad_data += 1
            return
        for msg in messages:
            if msg.get_type() == "BAD_DATA":
                reason = str(getattr(msg, "reason", ""))
                if "signature" in reason.lower():
                    self.stats.bad_signature += 1
                    self._once("signature", logging.WARNING,
                               "%s: dropping unsigned or badly signed MAVLink from %s "
                               "(this link requires signing)", self.endpoint, _where(address))
                else:
                    self.stats.bad_data += 1
                continue
            self.stats.received += 1
            self._on_message(msg, address)

    # ------------------------------------------------------------------------------------
    # Sending
    # ------------------------------------------------------------------------------------

    def send(self, msg) -> bool:
        """Send ``msg`` (False if there is nobody to send it to yet, or the link is closed)."""
        if not self._can_send():
            return False
        refresh(self.mav)
        return self._write(pack(self.mav, msg))

    def send_frame(self, frame: bytes) -> bool:
        """Send an already encoded frame (another MAVLink stack's, e.g. MAVSDK's)."""
        if not self._can_send():
            return False
        return self._write(frame)

    def _can_send(self) -> bool:
        if self._closed or self._transport is None:
            return False
        return self.peer is not None

    def _write(self, data: bytes) -> bool:
        t = self._transport
        if self._serial_fd is not None:
            if len(self._serial_out) > MAX_PENDING_B:
                self.stats.dropped_out += 1  # the port is not keeping up: newer frames lose
                return False
            self._serial_out += data
            self._serial_flush()
            return True
        if t.is_closing():
            return False
        if isinstance(t, asyncio.StreamWriter):
            if t.transport.get_write_buffer_size() > MAX_PENDING_B:
                self.stats.dropped_out += 1
                return False
            t.write(data)
        else:  # a datagram transport (asyncio's own class does not derive DatagramTransport)
            t.sendto(data, self.peer)
        return True

    def _serial_flush(self) -> None:
        fd = self._serial_fd
        if fd is None:
            return
        loop = asyncio.get_event_loop()
        try:
            while self._serial_out:
                written = os.write(fd, self._serial_out)
                del self._serial_out[:written]
        except BlockingIOError:
            loop.add_writer(fd, self._serial_flush)
            return
        except OSError as exc:
            self._once("serial-write", logging.WARNING, "%s: %s", self.endpoint, exc)
            self._serial_out.clear()
        with contextlib.suppress(Exception):
            loop.remove_writer(fd)

    def _once(self, key: str, level: int, message: str, *args) -> None:
        if key not in self._warned:
            self._warned.add(key)
            log.log(level, message, *args)


class _Datagrams(asyncio.DatagramProtocol):
    def __init__(self, link: MavlinkLink) -> None:
        self.link = link

    def datagram_received(self, data: bytes, addr) -> None:
        self.link._datagram(data, addr)

    def error_received(self, exc: Exception) -> None:  # e.g. ICMP port unreachable
        log.debug("MAVLink link: %s", exc)


def unheard(message: str, link: MavlinkLink | None) -> str:
    """``message`` (nothing heard from a vehicle), with what the link did hear instead."""
    stats = link.stats if link is not None else None
    if stats is None:
        return message
    if stats.bad_signature:
        return (f"{message} ({stats.bad_signature} messages dropped for a missing or wrong "
                "signature: is the signing key the vehicle's?)")
    if stats.ignored:
        return f"{message} ({stats.ignored} datagrams from other senders ignored)"
    if stats.bad_data:
        return (f"{message} ({stats.bad_data} unreadable frames: wrong baud rate, or not "
                "MAVLink 2?)")
    return message


def _where(address) -> str:
    if isinstance(address, tuple) and len(address) == 2:
        return f"{address[0]}:{address[1]}"
    return str(address)


def _baud_constant(baud: int) -> int | None:
    return getattr(termios, f"B{baud}", None)


#: how long after a proven-wrong mapping :attr:`BootTimeMapper.settling` stays true
SETTLING_S = 5.0


class BootTimeMapper:
    """Maps the vehicle's boot-time stamps (``time_boot_ms``) onto the local clock.

    Best from MAVLink TIMESYNC round trips (:meth:`observe_sync`): the offset local − vehicle
    from the exchange with the shortest round trip seen recently, which assumes only that the
    way there and back take equally long. Until a round trip has been measured, telemetry
    stamps give an upper bound (:meth:`observe`: the smallest local − vehicle seen, which still
    contains the vehicle's own telemetry latency). Either estimate may creep by
    ``drift_per_s`` per second to follow clock drift, and is reset when the vehicle's time
    jumps back (a reboot). A mapping that a newer exchange proves wrong (the vehicle's answer
    falls outside the interval it was sent and received in, as when a simulated vehicle's
    clock lags a starved CPU, or a telemetry sample arrives before its mapped capture) moves
    at once to the nearest offset the newer evidence allows, however short its round trip was.
    """

    def __init__(self, drift_per_s: float = 1e-4) -> None:
        self._drift = drift_per_s
        self._offset = math.nan
        self._last_local = math.nan
        self._last_vehicle = math.nan
        self._synced = False
        self._rtt = math.inf
        self._sync_at = 0.0
        self._corrected_at = -math.inf
        self._last_sync = -math.inf

    @property
    def ready(self) -> bool:
        return math.isfinite(self._offset)

    def observe(self, vehicle_s: float, local_s: float) -> None:
        """A telemetry sample stamped ``vehicle_s`` arrived at ``local_s``."""
        if vehicle_s < self._last_vehicle - 1.0:  # the vehicle rebooted
            self._offset, self._synced, self._rtt = math.nan, False, math.inf
        sample = local_s - vehicle_s
        if self._synced:
            # a sample cannot arrive before it was taken: the offset is at most this
            self._offset = min(self._offset, sample)
        else:
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
        self._last_sync = received_local_s
        if not self._synced or rtt <= aged:
            self._offset = (sent_local_s + received_local_s) / 2.0 - vehicle_s
            self._rtt, self._sync_at, self._synced = rtt, received_local_s, True
            return
        # the answer bounds the offset to [sent, received] − vehicle time: outside it, the
        # mapping is wrong, whatever round trip it came from; it moves to the nearest offset
        # the answer allows (not to this longer round trip's midpoint)
        low, high = sent_local_s - vehicle_s, received_local_s - vehicle_s
        if not low <= self._offset <= high:
            self._offset = min(max(self._offset, low), high)
            self._corrected_at = received_local_s

    @property
    def settling(self) -> bool:
        """True for a few seconds after an exchange proved the mapping wrong: the vehicle's
        clock is moving against ours, and more frequent exchanges follow it closer."""
        return self._last_sync - self._corrected_at < SETTLING_S

    @property
    def round_trip_s(self) -> float:
        """The round trip of the exchange the offset comes from (inf before any)."""
        return self._rtt

    def to_local(self, vehicle_s: float) -> float:
        return vehicle_s + self._offset


class TimesyncRequests:
    """Our outstanding TIMESYNC requests: an answer counts only if it echoes one of them
    (``ts1``), so another client's exchange on the same link cannot skew our clock mapping."""

    def __init__(self, keep: int = 32) -> None:
        self._sent: dict[int, float] = {}
        self._keep = keep

    def sent(self, ts1_ns: int, local_s: float) -> None:
        self._sent[ts1_ns] = local_s
        while len(self._sent) > self._keep:
            del self._sent[next(iter(self._sent))]

    def answer(self, ts1_ns: int) -> float | None:
        """When the request this answer echoes was sent (None: not ours)."""
        return self._sent.pop(ts1_ns, None)
