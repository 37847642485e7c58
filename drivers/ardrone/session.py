"""The client's side of the AR.Drone 2.0's navdata stream (the SDK 2.0 developer guide, 7.1), as
a synchronous state machine the driver feeds with what arrives and asks what to send — no
sockets, no clock of its own, so tests drive it packet by packet.

The handshake: the client sends a few bytes to UDP 5554 (:data:`WAKE_UP`); the drone answers
with navdata in *bootstrap* mode (``State.NAVDATA_BOOTSTRAP``: the header alone); the client
asks for demo navdata (``CONFIG general:navdata_demo TRUE``, after ``CONFIG_IDS``: AR.Drone
2.0 applies a CONFIG under the session, user and application ids of the ``CONFIG_IDS`` before
it); the drone acknowledges (``State.COMMAND``); the client clears the acknowledgement
(``CTRL 5``); demo navdata follows at 15 Hz. In full mode (``mode="full"``) the client asks
instead for the options it reads (``general:navdata_options``: :data:`FULL_OPTIONS`) and
``navdata_demo FALSE``, and navdata follows at 200 Hz.

Upkeep: packets older than the newest (UDP reorders) are dropped, except that a sequence
number of 1 or below the newest by more than :data:`RESTART_GAP` means the drone restarted its
count (after its communication watchdog, or a reboot); ``State.COM_WATCHDOG`` (no command
received for a while) is answered with ``COMWDG``; a CONFIG not acknowledged within
:data:`CONFIG_RETRY_S` is sent again.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from drivers.ardrone.at import AtCommands, config_value
from drivers.ardrone.navdata import RATES_HZ, Navdata, State, Tag, option_mask

#: what the client sends to UDP 5554 to start (and keep) the navdata coming
WAKE_UP = b"\x01\x00\x00\x00"
#: a sequence number this far below the newest: the drone restarted its count
RESTART_GAP = 1000
#: a CONFIG not acknowledged within this long is sent again
CONFIG_RETRY_S = 0.5
#: CTRL mode that clears the command acknowledgement
CTRL_ACK = 5
#: the ids AR.Drone 2.0's default session runs under
DEFAULT_IDS = ("00000000", "00000000", "00000000")
#: the options the driver reads in full mode
FULL_OPTIONS = option_mask(Tag.DEMO, Tag.TIME, Tag.PHYS_MEASURES, Tag.EULER_ANGLES,
                           Tag.ALTITUDE, Tag.MAGNETO)


@dataclass(frozen=True, slots=True)
class Step:
    """What one packet led to: the navdata to use (None: dropped or not yet in demo mode)
    and the AT commands to send, in order."""

    navdata: Navdata | None
    commands: tuple[bytes, ...] = ()


@dataclass
class _Pending:
    key: str
    value: str
    sent_s: float = field(default=-1e9)


class NavdataSession:
    def __init__(self, commands: AtCommands, ids: tuple[str, str, str] = DEFAULT_IDS, *,
                 mode: str = "demo",
                 configs: Mapping[str, str | int | float | bool] | None = None) -> None:
        if mode not in RATES_HZ:
            raise ValueError(f"navdata {mode!r}: expected "
                             + " or ".join(f"'{m}' ({hz:g} Hz)" for m, hz in RATES_HZ.items()))
        self._at = commands
        self.full = mode == "full"
        self._ids = ids
        self._newest: int | None = None
        #: ``configs`` (the user's keys, ``link.ardrone_config``) go after the navdata mode
        self._configs: list[_Pending] = [_Pending(k, config_value(v))
                                         for k, v in (configs or {}).items()]
        self._awaiting_ack = False
        self._bootstrap = True
        #: counts, for the driver's statistics
        self.dropped = 0
        self.watchdog_resets = 0
        self.restarts = 0

    @property
    def demo(self) -> bool:
        """Is the drone sending navdata past the bootstrap (the handshake done)?"""
        return self._newest is not None and not self._bootstrap

    @property
    def configured(self) -> bool:
        """Past the bootstrap, with every queued CONFIG acknowledged?"""
        return self.demo and not self._configs

    @property
    def pending_key(self) -> str | None:
        """The CONFIG key waiting for its acknowledgement, if any."""
        return self._configs[0].key if self._configs else None

    def configure(self, key: str, value: str | int | float | bool) -> None:
        """Queue a CONFIG: sent (with its ids) when the drone can take it, again until it is
        acknowledged; one at a time, in order."""
        self._configs.append(_Pending(key, config_value(value)))

    def on_packet(self, navdata: Navdata, now_s: float) -> Step:
        """A navdata packet received at ``now_s``: what to use of it and what to send."""
        if not self._fresh(navdata.sequence):
            self.dropped += 1
            return Step(None)
        state = navdata.state
        self._bootstrap = State.NAVDATA_BOOTSTRAP in state
        out: list[bytes] = []
        if State.COM_WATCHDOG in state:
            self.watchdog_resets += 1
            out.append(self._at.comwdg())
        if self._bootstrap and not any(p.key == "general:navdata_demo" for p in self._configs):
            self._configs.insert(0, _Pending("general:navdata_demo",
                                             "FALSE" if self.full else "TRUE"))
            if self.full:  # (read while still in bootstrap: the options, then the mode)
                self._configs.insert(0, _Pending("general:navdata_options",
                                                 str(FULL_OPTIONS)))
        if State.COMMAND in state:
            if self._awaiting_ack and self._configs:
                self._configs.pop(0)  # acknowledged
            self._awaiting_ack = False
            out.append(self._at.ctrl(CTRL_ACK))
        elif self._configs and now_s - self._configs[0].sent_s >= CONFIG_RETRY_S:
            pending = self._configs[0]
            out.append(self._at.config_ids(*self._ids))
            out.append(self._at.config(pending.key, pending.value))
            pending.sent_s = now_s
            self._awaiting_ack = True
        usable = navdata if not self._bootstrap and navdata.demo is not None else None
        return Step(usable, tuple(out))

    def _fresh(self, sequence: int) -> bool:
        newest = self._newest
        if newest is None or sequence > newest:
            self._newest = sequence
            return True
        if sequence <= 1 or newest - sequence > RESTART_GAP:
            self.restarts += 1
            self._newest = sequence
            return True
        return False
