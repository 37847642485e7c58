"""AR.Drone 2.0 navdata (the SDK 2.0 developer guide, chapter 7; ``navdata_common.h``): the
packets the drone sends to UDP 5554 once a client has sent it a datagram there — read by the
driver, written by the simulated AR.Drone's firmware.

A packet, little-endian: the header ``0x55667788``, the drone's state (a bit field:
:class:`State`), a sequence number, the vision flag, then options, each a 16-bit tag, a 16-bit
size (its 4-byte head included) and its data; the last option is the checksum (tag ``0xFFFF``,
size 8: the 32-bit sum of every byte before it). In bootstrap mode (``State.NAVDATA_BOOTSTRAP``)
the drone sends the header alone until the client sets ``general:navdata_demo``; in demo mode
(15 Hz) the options are the demo option (tag 0) and the checksum; in full mode (200 Hz) more.

The demo option's values in their units on the wire: pitch (``theta``), roll (``phi``) and yaw
(``psi``) in millidegrees; the altitude an integer in millimetres (the header's comment says
centimetres; what AR.Drone 2.0 sends, and what clients read, is millimetres); velocities in
mm/s along the drone's axes (ardrone_autonomy turns them into ROS's x forward, y left, z up
by negating y and z, and negates ``theta`` and ``psi``); the battery in percent; the control
state's major value in the upper 16 bits (:class:`ControlState`).
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Iterator
from dataclasses import dataclass

HEADER = 0x55667788
TAG_DEMO = 0
TAG_CHECKSUM = 0xFFFF
_HEAD = struct.Struct("<IIII")  # header, state, sequence, vision flag
_OPTION = struct.Struct("<HH")
#: the demo option after its tag and size: control state, battery %, theta, phi, psi (mdeg),
#: altitude (mm), vx, vy, vz (mm/s), frame index, then deprecated camera fields (to 148 bytes)
_DEMO = struct.Struct("<IIfffifffI")
DEMO_SIZE = 148
_CHECKSUM = struct.Struct("<HHI")


class NavdataError(ValueError):
    """A packet that is not navdata, cut short, or whose checksum does not match."""


class State(enum.IntFlag):
    """The drone's state bits (``def_ardrone_state_mask_t``)."""

    FLY = 1 << 0
    VIDEO = 1 << 1
    VISION = 1 << 2
    CONTROL = 1 << 3  # (1) angular speed control, (0) euler angles control
    ALTITUDE = 1 << 4  # altitude control active
    USER_FEEDBACK_START = 1 << 5
    COMMAND = 1 << 6  # a CONFIG acknowledged (cleared by CTRL 5)
    CAMERA = 1 << 7
    TRAVELLING = 1 << 8
    USB = 1 << 9
    NAVDATA_DEMO = 1 << 10
    NAVDATA_BOOTSTRAP = 1 << 11
    MOTORS = 1 << 12  # a motor problem
    COM_LOST = 1 << 13
    SOFTWARE_FAULT = 1 << 14
    VBAT_LOW = 1 << 15
    USER_EMERGENCY_LANDING = 1 << 16
    TIMER_ELAPSED = 1 << 17
    MAGNETO_NEEDS_CALIB = 1 << 18
    ANGLES_OUT_OF_RANGE = 1 << 19
    WIND = 1 << 20
    ULTRASOUND = 1 << 21  # the sonar is deaf
    CUTOUT = 1 << 22
    PIC_VERSION = 1 << 23
    ATCODEC_THREAD_ON = 1 << 24
    NAVDATA_THREAD_ON = 1 << 25
    VIDEO_THREAD_ON = 1 << 26
    ACQ_THREAD_ON = 1 << 27
    CTRL_WATCHDOG = 1 << 28
    ADC_WATCHDOG = 1 << 29
    COM_WATCHDOG = 1 << 30  # no command for 50 ms: send COMWDG
    EMERGENCY = 1 << 31


class ControlState(enum.IntEnum):
    """The demo option's control state (its upper 16 bits; ardrone_autonomy's ``state``)."""

    DEFAULT = 0
    INIT = 1
    LANDED = 2
    FLYING = 3
    HOVERING = 4
    TEST = 5
    TAKING_OFF = 6
    GOTO_FIX = 7
    LANDING = 8
    LOOPING = 9


@dataclass(frozen=True, slots=True)
class Demo:
    """The demo option, in the units it carries (see the module's notes): ``theta`` (pitch),
    ``phi`` (roll) and ``psi`` (yaw) in millidegrees, the altitude in millimetres, velocities
    in mm/s along the drone's axes."""

    control_state: int  # the whole word: major state << 16 | minor
    battery_percent: int
    theta_mdeg: float
    phi_mdeg: float
    psi_mdeg: float
    altitude_mm: int
    vx_mm_s: float
    vy_mm_s: float
    vz_mm_s: float
    frame_index: int = 0

    @property
    def major_state(self) -> ControlState | int:
        major = self.control_state >> 16
        try:
            return ControlState(major)
        except ValueError:
            return major


@dataclass(frozen=True, slots=True)
class Navdata:
    """One navdata packet: its state bits, sequence number, the demo option if it carried one,
    and every option's raw bytes by tag (for the options this module does not decode)."""

    state: State
    sequence: int
    vision_flag: int
    demo: Demo | None
    options: dict[int, bytes]


def checksum(data: bytes) -> int:
    """The navdata checksum: the sum of the bytes, modulo 2³²."""
    return sum(data) & 0xFFFFFFFF


def _options(packet: bytes) -> Iterator[tuple[int, int, bytes]]:
    """(offset, tag, data) of each option after the header."""
    offset = _HEAD.size
    while offset < len(packet):
        if offset + _OPTION.size > len(packet):
            raise NavdataError(f"an option's head cut short at byte {offset}")
        tag, size = _OPTION.unpack_from(packet, offset)
        if size < _OPTION.size or offset + size > len(packet):
            raise NavdataError(f"option {tag} of {size} bytes at byte {offset} does not fit "
                               f"the packet's {len(packet)}")
        yield offset, tag, packet[offset + _OPTION.size:offset + size]
        offset += size


def parse(packet: bytes) -> Navdata:
    """A navdata packet, checked (header, option sizes, checksum when it carries one)."""
    if len(packet) < _HEAD.size:
        raise NavdataError(f"{len(packet)} bytes: shorter than navdata's 16-byte header")
    header, state, sequence, vision = _HEAD.unpack_from(packet)
    if header != HEADER:
        raise NavdataError(f"header 0x{header:08x}, not navdata's 0x{HEADER:08x}")
    demo, options = None, {}
    for offset, tag, data in _options(packet):
        if tag == TAG_CHECKSUM:
            if len(data) != 4:
                raise NavdataError(f"a checksum option of {len(data) + 4} bytes (8 expected)")
            (expected,) = struct.unpack("<I", data)
            actual = checksum(packet[:offset])
            if actual != expected:
                raise NavdataError(f"checksum 0x{actual:08x}, the packet says 0x{expected:08x}")
            break
        options[tag] = data
        if tag == TAG_DEMO:
            if len(data) + _OPTION.size < DEMO_SIZE:
                raise NavdataError(f"a demo option of {len(data) + _OPTION.size} bytes "
                                   f"({DEMO_SIZE} expected)")
            demo = Demo(*_DEMO.unpack_from(data))
    return Navdata(State(state), sequence, vision, demo, options)


def build(state: int, sequence: int, demo: Demo | None = None, *, vision_flag: int = 1,
          options: dict[int, bytes] | None = None) -> bytes:
    """A navdata packet as the drone sends it (the simulated firmware's side): the header,
    the demo option if given, other options' data by tag, and the checksum."""
    body = bytearray(_HEAD.pack(HEADER, state & 0xFFFFFFFF, sequence & 0xFFFFFFFF,
                                vision_flag))
    if demo is not None:
        data = _DEMO.pack(demo.control_state, demo.battery_percent, demo.theta_mdeg,
                          demo.phi_mdeg, demo.psi_mdeg, demo.altitude_mm, demo.vx_mm_s,
                          demo.vy_mm_s, demo.vz_mm_s, demo.frame_index)
        data += bytes(DEMO_SIZE - _OPTION.size - len(data))  # the deprecated camera fields
        body += _OPTION.pack(TAG_DEMO, DEMO_SIZE) + data
    for tag, data in (options or {}).items():
        if tag in (TAG_DEMO, TAG_CHECKSUM):
            raise ValueError(f"option {tag}: the demo and checksum options are built here")
        body += _OPTION.pack(tag, _OPTION.size + len(data)) + data
    return bytes(body) + _CHECKSUM.pack(TAG_CHECKSUM, _CHECKSUM.size, checksum(body))
