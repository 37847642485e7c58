"""AR.Drone 2.0 AT commands (the SDK 2.0 developer guide, chapter 6): the text commands a client
sends to the drone over UDP 5556, and their parsing on the drone's side (the simulated
AR.Drone's firmware).

A command is ``AT*NAME=<seq>[,<arg>...]`` and a line end (the guide writes a line feed;
ARDroneLib and most clients send a carriage return, which is what this module sends; the drone
takes either); one datagram may carry several (at most 1,024 characters in all, never split
across datagrams). The sequence number starts at 1
and increases with every command; the drone ignores a command whose number is not above the
last one it took, except that 1 restarts the count (a new client, or after ``COMWDG``).
Arguments are decimal integers, quoted strings, or floats sent as the signed 32-bit integer
with the same bits (IEEE-754 single precision): −0.8 is sent as −1085485875.

``REF`` carries the basic commands in a bit field: bits 18, 20, 22, 24 and 28 always set, bit 9
takes off (clear: land), bit 8 toggles the emergency state. ``PCMD``'s flag bit 0 enables the
progressive command (clear: hover, the arguments ignored), bit 1 the combined yaw; its roll,
pitch, gaz and yaw are fractions in [−1, 1] of ``control:euler_angle_max``,
``control:control_vz_max`` and ``control:control_yaw`` — tilts and rates, not velocities.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass

#: the bits REF always carries
REF_BASE = (1 << 18) | (1 << 20) | (1 << 22) | (1 << 24) | (1 << 28)
REF_TAKEOFF = 1 << 9
REF_EMERGENCY = 1 << 8
#: PCMD flag bits
PCMD_PROGRESSIVE = 1 << 0
PCMD_COMBINED_YAW = 1 << 1
#: a datagram's limit (the drone rejects the whole datagram beyond it)
MAX_DATAGRAM = 1024
#: the commands the drone knows (the SDK 2.0's)
COMMANDS = frozenset({"REF", "PCMD", "PCMD_MAG", "FTRIM", "CALIB", "CONFIG", "CONFIG_IDS",
                      "COMWDG", "CTRL", "LED", "ANIM"})

#: (an empty last argument, ``AT*COMWDG=5,``, is taken as none: a client that joins its
#: arguments after a comma sends it for commands without any, and the drone takes them)
_COMMAND = re.compile(r'AT\*([A-Z_]+)=(\d+)((?:,(?:-?\d+|"[^"\n]*"))*),?$')
_ARGUMENT = re.compile(r',(-?\d+|"[^"\n]*")')


class AtError(ValueError):
    """A malformed AT command."""


def float_arg(value: float) -> int:
    """A float as AT commands carry it: the signed 32-bit integer with its bits."""
    return struct.unpack("<i", struct.pack("<f", float(value)))[0]


def arg_float(value: int) -> float:
    """The float an AT command's integer argument carries (the inverse of :func:`float_arg`)."""
    return struct.unpack("<f", struct.pack("<i", int(value)))[0]


def config_value(value: str | int | float | bool) -> str:
    """A configuration value as CONFIG carries it (booleans as ``TRUE`` / ``FALSE``)."""
    if isinstance(value, bool):
        return "TRUE" if value else "FALSE"
    return str(value)


def _clamp(value: float) -> float:
    return max(-1.0, min(1.0, float(value)))


class AtCommands:
    """A client's AT commands, numbered in order (sequence numbers from 1)."""

    def __init__(self) -> None:
        self._seq = 0

    @property
    def seq(self) -> int:
        """The last sequence number used (0: none yet)."""
        return self._seq

    def restart(self) -> None:
        """Number from 1 again (as after ``COMWDG``, or a new session)."""
        self._seq = 0

    def _line(self, name: str, *args: int | str) -> bytes:
        parts = []
        for arg in args:
            if isinstance(arg, str):
                if '"' in arg or "\n" in arg or "\r" in arg or not arg.isascii():
                    raise AtError(f"AT*{name}: a string argument must be ASCII without quotes "
                                  f"or line breaks: {arg!r}")
                parts.append(f'"{arg}"')
            else:
                parts.append(str(int(arg)))
        self._seq += 1  # (a refused command uses no number)
        return ",".join([f"AT*{name}={self._seq}", *parts]).encode("ascii") + b"\r"

    def ref(self, takeoff: bool = False, emergency: bool = False) -> bytes:
        """Take off (``takeoff``) or land; ``emergency`` toggles the emergency state."""
        return self._line("REF", REF_BASE | (REF_TAKEOFF if takeoff else 0)
                          | (REF_EMERGENCY if emergency else 0))

    def pcmd(self, roll: float, pitch: float, gaz: float, yaw: float, *,
             hover: bool = False, combined_yaw: bool = False) -> bytes:
        """A progressive command, each value a fraction of its limit clamped to [−1, 1]:
        ``roll`` (positive: tilt right, flying right), ``pitch`` (negative: nose down, flying
        forward), ``gaz`` (positive: climb) and ``yaw`` (positive: turn clockwise seen from
        above); ``hover``: the drone's own hover (the values ignored)."""
        flag = 0 if hover else PCMD_PROGRESSIVE | (PCMD_COMBINED_YAW if combined_yaw else 0)
        values = (0.0, 0.0, 0.0, 0.0) if hover else (roll, pitch, gaz, yaw)
        return self._line("PCMD", flag, *(float_arg(_clamp(v)) for v in values))

    def pcmd_mag(self, roll: float, pitch: float, gaz: float, yaw: float, psi: float,
                 psi_accuracy: float) -> bytes:
        """PCMD with the controller's magnetic heading (absolute control; ``psi`` in [−1, 1]
        of ±180°)."""
        return self._line("PCMD_MAG", PCMD_PROGRESSIVE,
                          *(float_arg(_clamp(v)) for v in (roll, pitch, gaz, yaw, psi)),
                          float_arg(psi_accuracy))

    def ftrim(self) -> bytes:
        """Flat trim: the drone takes its attitude now as level (on the ground only)."""
        return self._line("FTRIM")

    def calib(self, device: int = 0) -> bytes:
        """Magnetometer calibration (in flight)."""
        return self._line("CALIB", device)

    def config(self, key: str, value: str | int | float | bool) -> bytes:
        """Set a configuration key (``section:name``), e.g. ``control:altitude_max``."""
        return self._line("CONFIG", key, config_value(value))

    def config_ids(self, session: str, user: str, application: str) -> bytes:
        """The ids a CONFIG applies under (AR.Drone 2.0 needs them before each CONFIG)."""
        return self._line("CONFIG_IDS", session, user, application)

    def comwdg(self) -> bytes:
        """Reset the communication watchdog."""
        return self._line("COMWDG")

    def ctrl(self, mode: int, arg: int = 0) -> bytes:
        """Control mode: 4 asks for the configuration file over TCP 5559, 5 acknowledges a
        CONFIG (clears the navdata's command-ack bit)."""
        return self._line("CTRL", mode, arg)


def datagrams(commands: list[bytes]) -> list[bytes]:
    """Commands packed into as few datagrams as the drone takes (each ≤ 1,024 bytes)."""
    out: list[bytes] = []
    current = b""
    for command in commands:
        if len(command) > MAX_DATAGRAM:
            raise AtError(f"an AT command of {len(command)} bytes (at most {MAX_DATAGRAM})")
        if len(current) + len(command) > MAX_DATAGRAM:
            out.append(current)
            current = b""
        current += command
    if current:
        out.append(current)
    return out


@dataclass(frozen=True, slots=True)
class AtCommand:
    """A command as the drone reads it."""

    name: str
    seq: int
    args: tuple[int | str, ...]

    def floats(self, start: int = 0) -> tuple[float, ...]:
        """The integer arguments from ``start`` on, read as the floats they carry."""
        return tuple(arg_float(a) for a in self.args[start:] if isinstance(a, int))


def parse(datagram: bytes) -> list[AtCommand]:
    """The commands of one datagram, in order; a malformed one raises :class:`AtError` (the
    drone ignores it: the simulated firmware counts it and goes on). Commands end with a
    carriage return or a line feed (clients send either)."""
    if len(datagram) > MAX_DATAGRAM:
        raise AtError(f"a datagram of {len(datagram)} bytes (at most {MAX_DATAGRAM})")
    try:
        text = datagram.decode("ascii")
    except UnicodeDecodeError as exc:
        raise AtError(f"not ASCII: {exc}") from None
    commands = []
    for line in re.split(r"[\r\n]+", text):
        if not line:
            continue
        match = _COMMAND.match(line)
        if match is None:
            raise AtError(f"not an AT command: {line[:60]!r}")
        name = match.group(1)
        if name not in COMMANDS:
            raise AtError(f"unknown AT command {name!r}")
        args = tuple(a[1:-1] if a.startswith('"') else int(a)
                     for a in _ARGUMENT.findall(match.group(3)))
        if any(isinstance(a, int) and not -2**31 <= a < 2**31 for a in args):
            raise AtError(f"AT*{name}: an integer argument outside 32 bits")
        commands.append(AtCommand(name, int(match.group(2)), args))
    return commands
