"""AR.Drone 2.0 navdata (the SDK 2.0 developer guide, chapter 7; ``navdata_common.h``): the
packets the drone sends to UDP 5554 once a client has sent it a datagram there — read by the
driver, written by the simulated AR.Drone's firmware.

A packet, little-endian: the header ``0x55667788``, the drone's state (a bit field:
:class:`State`), a sequence number, the vision flag, then options, each a 16-bit tag, a 16-bit
size (its 4-byte head included) and its data; the last option is the checksum (tag ``0xFFFF``,
size 8: the 32-bit sum of every byte before it). In bootstrap mode (``State.NAVDATA_BOOTSTRAP``)
the drone sends the header alone until the client sets ``general:navdata_demo``; in demo mode
(15 Hz) the options are the demo option (tag 0), those ``general:navdata_options`` adds, and the
checksum; in full mode (``navdata_demo`` FALSE, 200 Hz) the options ``general:navdata_options``
selects (a bit per tag, :func:`option_mask`; ardrone_autonomy asks for :data:`FULL_MASK`), in tag
order, each at its size in ``navdata_common.h`` (:data:`OPTION_SIZES`: its structures are
packed).

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
#: navdata's rate in each mode (the SDK 2.0 developer guide, 7.1.2; bootstrap as demo)
RATES_HZ = {"demo": 15.0, "full": 200.0}
TAG_DEMO = 0
TAG_CHECKSUM = 0xFFFF


class Tag(enum.IntEnum):
    """The options' tags (``navdata_keys.h``, in the order the drone sends them)."""

    DEMO = 0
    TIME = 1
    RAW_MEASURES = 2
    PHYS_MEASURES = 3
    GYROS_OFFSETS = 4
    EULER_ANGLES = 5
    REFERENCES = 6
    TRIMS = 7
    RC_REFERENCES = 8
    PWM = 9
    ALTITUDE = 10
    VISION_RAW = 11
    VISION_OF = 12
    VISION = 13
    VISION_PERF = 14
    TRACKERS_SEND = 15
    VISION_DETECT = 16
    WATCHDOG = 17
    ADC_DATA_FRAME = 18
    VIDEO_STREAM = 19
    GAMES = 20
    PRESSURE_RAW = 21
    MAGNETO = 22
    WIND_SPEED = 23
    KALMAN_PRESSURE = 24
    HDVIDEO_STREAM = 25
    WIFI = 26
    ZIMMU_3000 = 27


#: each option's size on the wire, its 4-byte head included (the packed structures of
#: AR.Drone 2.0's ``navdata_common.h``); a client that checks sizes refuses any other
OPTION_SIZES: dict[int, int] = {
    Tag.DEMO: 148, Tag.TIME: 8, Tag.RAW_MEASURES: 52, Tag.PHYS_MEASURES: 46,
    Tag.GYROS_OFFSETS: 16, Tag.EULER_ANGLES: 12, Tag.REFERENCES: 88, Tag.TRIMS: 16,
    Tag.RC_REFERENCES: 24, Tag.PWM: 76, Tag.ALTITUDE: 56, Tag.VISION_RAW: 16,
    Tag.VISION_OF: 44, Tag.VISION: 92, Tag.VISION_PERF: 108, Tag.TRACKERS_SEND: 364,
    Tag.VISION_DETECT: 328, Tag.WATCHDOG: 8, Tag.ADC_DATA_FRAME: 40, Tag.VIDEO_STREAM: 65,
    Tag.GAMES: 12, Tag.PRESSURE_RAW: 18, Tag.MAGNETO: 75, Tag.WIND_SPEED: 56,
    Tag.KALMAN_PRESSURE: 72, Tag.HDVIDEO_STREAM: 32, Tag.WIFI: 8, Tag.ZIMMU_3000: 12,
}
#: every option (NAVDATA_OPTION_FULL_MASK)
FULL_MASK = (1 << len(Tag)) - 1
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


def option_mask(*tags: int) -> int:
    """The ``general:navdata_options`` value that selects ``tags`` (NAVDATA_OPTION_MASK)."""
    mask = 0
    for tag in tags:
        mask |= 1 << int(tag)
    return mask


def masked_tags(mask: int) -> tuple[Tag, ...]:
    """The options a ``general:navdata_options`` value selects, in the order they are sent."""
    return tuple(tag for tag in Tag if mask >> tag & 1)


def time_word(seconds: float) -> int:
    """The time option's word: whole seconds in the upper 11 bits (wrapping at 2048 s),
    microseconds in the lower 21."""
    whole = int(seconds // 1)
    micro = min(999_999, round((seconds - whole) * 1e6))
    return ((whole & 0x7FF) << 21) | micro


def time_seconds(word: int) -> float:
    """The time option's word in seconds (modulo 2048 s)."""
    return (word >> 21) + (word & 0x1FFFFF) * 1e-6


# -- the full mode's options the simulated drone fills (the rest go zero at their size) ------

_PHYS = struct.Struct("<fHffffff")  # accs_temp, gyro_temp, phys_accs (mg), phys_gyros (deg/s)
_EULER = struct.Struct("<ff")  # theta_a, phi_a: the accelerometers' angles (mdeg)
_ALTITUDE = struct.Struct("<ifii")  # altitude_vision (mm), altitude_vz (mm/s), _ref, _raw (mm)
#: mx, my, mz, magneto_raw, _rectified, _offset (3 floats each), then the headings (deg)
_MAGNETO_HEADINGS = struct.Struct("<hhh9ffff")


def time_data(seconds: float) -> bytes:
    return struct.pack("<I", time_word(seconds))


def phys_measures_data(accs_mg: tuple[float, float, float],
                       gyros_deg_s: tuple[float, float, float]) -> bytes:
    """The accelerometers' specific force (mg) and the gyros (deg/s), on the drone's axes
    (x forward, y right, z down: at rest z reads -1000 mg; ardrone_autonomy negates y and z)."""
    return _PHYS.pack(0.0, 0, *accs_mg, *gyros_deg_s)


def euler_angles_data(theta_mdeg: float, phi_mdeg: float) -> bytes:
    return _EULER.pack(theta_mdeg, phi_mdeg)


def altitude_data(vision_mm: int, vz_mm_s: float, ref_mm: int, raw_mm: int) -> bytes:
    return _ALTITUDE.pack(vision_mm, vz_mm_s, ref_mm, raw_mm)


def magneto_heading_data(heading_deg: float) -> bytes:
    """The magnetometer option's headings (unwrapped, gyro, fused), its raw fields zero."""
    return _MAGNETO_HEADINGS.pack(0, 0, 0, *([0.0] * 9), heading_deg, heading_deg,
                                  heading_deg)


def option_time_s(navdata: Navdata) -> float | None:
    """The time option's seconds (the drone's clock, modulo 2048 s), None without one."""
    data = navdata.options.get(Tag.TIME)
    return None if data is None or len(data) < 4 else time_seconds(
        struct.unpack_from("<I", data)[0])


def option_altitude(navdata: Navdata) -> tuple[int, float, int, int] | None:
    """The altitude option's (vision mm, vz mm/s, reference mm, raw sonar mm), None without."""
    data = navdata.options.get(Tag.ALTITUDE)
    return None if data is None or len(data) < _ALTITUDE.size else _ALTITUDE.unpack_from(data)


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


def demo_data(demo: Demo) -> bytes:
    """The demo option's data (after its head), the deprecated camera fields zero."""
    data = _DEMO.pack(demo.control_state, demo.battery_percent, demo.theta_mdeg,
                      demo.phi_mdeg, demo.psi_mdeg, demo.altitude_mm, demo.vx_mm_s,
                      demo.vy_mm_s, demo.vz_mm_s, demo.frame_index)
    return data + bytes(DEMO_SIZE - _OPTION.size - len(data))


def build(state: int, sequence: int, demo: Demo | None = None, *, vision_flag: int = 1,
          options: dict[int, bytes] | None = None) -> bytes:
    """A navdata packet as the drone sends it (the simulated firmware's side): the header,
    the demo option if given and the other options by tag, in tag order — a known option's
    data padded with zeros to its size (:data:`OPTION_SIZES`) —, and the checksum."""
    body = bytearray(_HEAD.pack(HEADER, state & 0xFFFFFFFF, sequence & 0xFFFFFFFF,
                                vision_flag))
    chosen = dict(options or {})
    if TAG_CHECKSUM in chosen:
        raise ValueError("the checksum option is built here")
    if demo is not None:
        if TAG_DEMO in chosen:
            raise ValueError("the demo option given twice")
        chosen[TAG_DEMO] = demo_data(demo)
    for tag in sorted(chosen):
        data = chosen[tag]
        size = OPTION_SIZES.get(tag, _OPTION.size + len(data))
        if _OPTION.size + len(data) > size:
            raise ValueError(f"option {tag}: {len(data)} bytes of data, its size is {size}")
        body += _OPTION.pack(tag, size) + data + bytes(size - _OPTION.size - len(data))
    return bytes(body) + _CHECKSUM.pack(TAG_CHECKSUM, _CHECKSUM.size, checksum(body))
