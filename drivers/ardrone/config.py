"""AR.Drone 2.0 configuration (the SDK 2.0 developer guide, chapter 8; ARDroneLib's
``config_keys.h``): the keys the drone keeps, their defaults and types, what ``AT*CONFIG`` may
set, and the text the drone sends over TCP 5559 when asked with ``AT*CTRL=<seq>,4,0`` — held
by the simulated AR.Drone's firmware (:class:`DroneConfig`), read by the driver
(:func:`parse_config_text`).

The text is one ``section:name = value`` line per key, each ended by a line feed: integers in
decimal, floats as C's ``%.7e`` of their single-precision value (``2.0943999e-01``), booleans
``TRUE`` / ``FALSE``, strings bare (an empty one leaves ``key = ``), calibration vectors as
``{ a b c }``. The drone lists the keys by category — common, application, user, session —
each in ``config_keys.h``'s order.

``AT*CONFIG`` as the simulated firmware takes it (:meth:`DroneConfig.set`): keys are matched
without regard to case (the guide writes ``CONTROL:euler_angle_max``, the dump
``control:euler_angle_max``); a key the drone does not know is ignored, as the guide says of
incorrect AT commands; a read-only key is ignored, and so are the session keys (``video:
video_codec``, ``video:max_bitrate``, ``video:codec_fps`` …) unless the ``CONFIG`` came under a
custom configuration's ids — the guide's "Default: Read only | Multiconfig: Read/Write". The
value must read as the key's type. Where the guide gives a key's range (tilt 0–0.52 rad,
vertical speed 200–2000 mm/s, yaw rate 40–350 °/s, frame rate up to 30), a value outside it is
refused and the old one kept. The real firmware is laxer: it reads numbers as C's ``atof``
does (a client that sent ``0,25`` got a tilt of 0) and flew a tilt of 1.0 rad at some 50°
(ARDrone2Windows/SDK issue 15), so the simulated one refuses what would otherwise reach its
flight model unchecked, and a driver bug shows as a refused ``CONFIG``. ``control:outdoor``
loads the indoor or outdoor tilt, vertical speed and yaw rate, and writing one of those saves
it to the profile in use, as the guide describes.
"""

from __future__ import annotations

import enum
import math
import re
import struct
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

Value = int | float | bool | str


class Kind(enum.Enum):
    INT = "int"  # int32_t
    FLOAT = "float"  # float32_t
    BOOL = "bool"  # bool_t: TRUE / FALSE
    STRING = "string"  # string_t: at most 127 characters


class Category(enum.IntEnum):
    """Where a key is saved (``config_keys.h``'s ``CAT_*``); the dump lists them in this order."""

    COMMON = 0
    APPLI = 1
    USER = 2
    SESSION = 3


#: who may write a key: ``ANY``, ``CUSTOM`` (under a custom configuration's ids), ``NONE``
ANY, CUSTOM, NONE = "any", "custom", "none"
STRING_MAX = 127  # string_t is char[128]
_INT = re.compile(r"[+-]?\d+")
_FLOAT = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_FLOAT_RANGE = (-3.4e38, 3.4e38)


@dataclass(frozen=True, slots=True)
class Key:
    """One configuration key: its name (``section:name``), type, AR.Drone 2.0 default, who may
    write it, where it is saved, and the guide's range or values, if it gives them."""

    name: str
    kind: Kind
    default: Value
    write: str = ANY
    category: Category = Category.COMMON
    limits: tuple[float, float] | None = None
    choices: frozenset[int] | None = None


def _f32(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


_C, _A, _U, _S = Category.COMMON, Category.APPLI, Category.USER, Category.SESSION
_I, _F, _B, _T = Kind.INT, Kind.FLOAT, Kind.BOOL, Kind.STRING
_TILT, _VZ = (0.0, 0.52), (200.0, 2000.0)
_YAW = (math.radians(40.0), 6.11)  # the guide: 40–350 °/s, "approx 0.7 to 6.11 rad/s"

# Sources: [K] config_keys.h (ARDroneLib, SDK 2.0.1: defaults, rights, categories); [G] the
# developer guide, ch. 8 (ranges, values); [D] values a real drone reported.
KEYS: tuple[Key, ...] = (
    Key("general:num_version_config", _I, 1, NONE),  # [K]
    Key("general:num_version_soft", _T, "2.4.8", NONE),  # the last 2.0 firmware; [K]: read-only
    Key("general:ardrone_name", _T, "My ARDrone"),  # [K]
    Key("general:flying_time", _I, 0, NONE),  # s, lifetime; [K]
    Key("general:navdata_demo", _B, False),  # [K]; saved, so a drone may boot with TRUE [D]
    Key("general:navdata_options", _I, 65537, category=_A),  # demo | vision_detect [K][D]
    Key("general:com_watchdog", _I, 2),  # s: COM_INPUT_LANDING_TIME [K]
    Key("general:video_enable", _B, True),  # [K]
    Key("general:vision_enable", _B, True),  # [K]
    Key("general:vbat_min", _I, 9000, NONE),  # mV: VBAT_POWERING_OFF [K] (read-only)
    Key("control:altitude_max", _I, 3000, limits=(500, 100_000)),  # mm [K]; see below
    Key("control:altitude_min", _I, 50),  # mm [K]; [G]: leave it at 50
    Key("control:outdoor", _B, False),  # [K]
    Key("control:flight_without_shell", _B, False),  # [K]
    Key("control:autonomous_flight", _B, False),  # [K]
    Key("control:flight_anim", _T, "0,0"),  # "anim,duration" [K]
    Key("network:ssid_single_player", _T, "ardrone2_000000"),  # ardrone2_<digits>: uncertain
    Key("network:ssid_multi_player", _T, "ardrone2_000000"),  # [K]: the same WIFI_NETWORK_NAME
    Key("network:wifi_mode", _I, 0, choices=frozenset({0, 1, 2})),  # AP, ad-hoc, station [G]
    Key("network:owner_mac", _T, "00:00:00:00:00:00"),  # [K]
    Key("pic:ultrasound_freq", _I, 8, choices=frozenset({7, 8})),  # 22.22 / 25 Hz [K][G][D]
    Key("pic:ultrasound_watchdog", _I, 3),  # [K]
    Key("pic:pic_version", _I, 0x00040030, NONE),  # [K]'s placeholder; a drone reports its own
    Key("video:camif_fps", _I, 30, NONE),  # [K] (2.0 board)
    Key("video:camif_buffers", _I, 2, NONE),  # [K]
    Key("video:num_trackers", _I, 12, NONE),  # [K]
    Key("video:video_storage_space", _I, 0, NONE),  # [K]
    Key("video:video_on_usb", _B, True),  # [K]
    Key("video:video_file_index", _I, 1),  # [K]
    Key("leds:leds_anim", _T, "0,0,0"),  # "anim,frequency bits,duration" [K]
    Key("detect:enemy_colors", _I, 1, choices=frozenset({1, 2, 3})),  # green, yellow, blue [G]
    Key("detect:enemy_without_shell", _I, 0, choices=frozenset({0, 1})),  # [K]
    Key("syslog:output", _I, 7),  # UART | WIFI | FLASH [K]
    Key("syslog:max_size", _I, 102_400),  # [K]
    Key("syslog:nb_files", _I, 5),  # [K]
    Key("control:control_level", _I, 0, category=_A),  # bit 0: combined yaw [K]
    Key("video:bitrate", _I, 1000, CUSTOM, _A),  # kbit/s [K]
    Key("video:bitrate_ctrl_mode", _I, 0, CUSTOM, _A,  # disabled, dynamic, manual [G]
        choices=frozenset({0, 1, 2})),
    Key("video:bitrate_storage", _I, 4000, CUSTOM, _A),  # kbit/s [K]
    Key("custom:application_desc", _T, "Default application configuration", category=_A),  # [K]
    # rad; [D] and the brief: 2.0943999e-01 (0.20944); [K]: 12000 mdeg (2.0943952e-01)
    Key("control:euler_angle_max", _F, 0.20944, category=_U, limits=_TILT),
    Key("control:control_iphone_tilt", _F, 0.34906584, category=_U),  # rad, 20°: [K][D]
    Key("control:control_vz_max", _F, 700.0, category=_U, limits=_VZ),  # mm/s [K][D]
    Key("control:control_yaw", _F, 1.7453293, category=_U, limits=_YAW),  # rad/s, 100°/s [K]
    Key("control:manual_trim", _B, False, category=_U),  # [K]
    Key("control:indoor_euler_angle_max", _F, 0.20944, category=_U, limits=_TILT),  # [K]
    Key("control:indoor_control_vz_max", _F, 700.0, category=_U, limits=_VZ),  # [K]
    Key("control:indoor_control_yaw", _F, 1.7453293, category=_U, limits=_YAW),  # [K]
    Key("control:outdoor_euler_angle_max", _F, 0.34906584, category=_U, limits=_TILT),  # 20°
    Key("control:outdoor_control_vz_max", _F, 1000.0, category=_U, limits=_VZ),  # [K]
    Key("control:outdoor_control_yaw", _F, 3.4906585, category=_U, limits=_YAW),  # 200°/s [K]
    Key("custom:profile_desc", _T, "Default profile configuration", category=_U),  # [K]
    Key("control:flying_mode", _I, 0, category=_S, choices=frozenset({0, 1, 2})),  # [K][G]
    Key("control:hovering_range", _I, 1000, category=_S),  # mm [K]
    Key("video:codec_fps", _I, 30, CUSTOM, _S, limits=(1, 30)),  # [K]; [G]: at most 30
    # 0x81 H264_360P; [G]'s values: MP4_360P 0x80, MP4_360P_H264_720P 0x82, H264_720P 0x83,
    # MP4_360P_H264_360P 0x88 (VLIB/video_codec.h)
    Key("video:video_codec", _I, 0x81, CUSTOM, _S, choices=frozenset({0x80, 0x81, 0x82, 0x83,
                                                                      0x88})),
    Key("video:video_slices", _I, 0, CUSTOM, _S),  # [K]
    Key("video:video_live_socket", _I, 0, CUSTOM, _S),  # [K]
    Key("video:max_bitrate", _I, 1000, CUSTOM, _S),  # kbit/s [K][G]
    # ZAP_CHANNEL_HORI 0 (front), _VERT 1 (bottom); 2 and 3 are AR.Drone 1.0's [G]
    Key("video:video_channel", _I, 0, category=_S, choices=frozenset({0, 1})),
    Key("detect:groundstripe_colors", _I, 16, category=_S),  # [K][D]
    Key("detect:detect_type", _I, 3, category=_S),  # CAD_TYPE_NONE [K][D]
    Key("detect:detections_select_h", _I, 0, category=_S),  # tag bit fields [K]
    Key("detect:detections_select_v_hsync", _I, 0, category=_S),  # [K]
    Key("detect:detections_select_v", _I, 0, category=_S),  # [K]
    Key("userbox:userbox_cmd", _T, "0", category=_S),  # [K]
    Key("custom:application_id", _T, "00000000", category=_S),  # [K]
    Key("custom:profile_id", _T, "00000000", category=_S),  # [K]
    Key("custom:session_id", _T, "00000000", category=_S),  # [K]
    Key("custom:session_desc", _T, "Default session configuration", category=_S),  # [K]
)
# control:altitude_max: the guide gives AR.Drone 1.0 500–5000 mm (or 10000: no limit) and lets
# AR.Drone 2.0 take any value, 100000 (config_keys.h's no_altitude_limit) meaning "unlimited";
# the range here is those two ends.
KEYS_BY_NAME: dict[str, Key] = {k.name: k for k in KEYS}
#: the keys the driver writes itself, and what decides them (not for ``link.ardrone_config``)
DRIVER_KEYS: dict[str, str] = {
    "general:navdata_demo": "link.navdata",
    "general:navdata_options": "link.navdata",
    "video:video_channel": "the camera the active step needs",
}
#: what control:outdoor loads: the live key, its indoor and its outdoor profile
_PROFILES = {live: (f"control:indoor_{live[8:]}", f"control:outdoor_{live[8:]}")
             for live in ("control:euler_angle_max", "control:control_vz_max",
                          "control:control_yaw")}


class ConfigError(ValueError):
    """A ``CONFIG`` the drone does not apply (the simulated firmware ignores it)."""


class UnknownKeyError(ConfigError, KeyError):
    """A key the drone does not have."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class ReadOnlyKeyError(ConfigError):
    """A key a client may not write (or only under a custom configuration's ids)."""


def _parse(key: Key, text: str) -> Value:
    """``text`` as ``key``'s type, checked; raises :class:`ConfigError`."""
    text = text.strip()
    if key.kind is Kind.BOOL:
        if text.upper() not in ("TRUE", "FALSE"):
            raise ConfigError(f"{key.name}: {text!r} is not TRUE or FALSE")
        return text.upper() == "TRUE"
    if key.kind is Kind.STRING:
        if len(text) > STRING_MAX or not text.isascii() or any(c in text for c in "\r\n\0"):
            raise ConfigError(f"{key.name}: at most {STRING_MAX} ASCII characters on one line")
        return text
    if key.kind is Kind.INT:
        if _INT.fullmatch(text):
            value: float = int(text)
        elif _FLOAT.fullmatch(text) and float(text).is_integer():  # "3000.0", as str(3000.0)
            value = int(float(text))
        else:
            raise ConfigError(f"{key.name}: {text!r} is not an integer")
        if not -2**31 <= value < 2**31:
            raise ConfigError(f"{key.name}: {value} does not fit 32 bits")
    else:
        if not _FLOAT.fullmatch(text) or not _FLOAT_RANGE[0] <= float(text) <= _FLOAT_RANGE[1]:
            raise ConfigError(f"{key.name}: {text!r} is not a number")
        value = _f32(float(text))
    if key.limits is not None:
        lo, hi = key.limits
        if key.kind is Kind.FLOAT:  # (the ends as the drone's floats: 6.11 is 6.1100001)
            lo, hi = _f32(lo), _f32(hi)
        if not lo <= value <= hi:
            raise ConfigError(f"{key.name}: {value:g} outside {key.limits[0]:g}..{key.limits[1]:g}")
    if key.choices is not None and value not in key.choices:
        raise ConfigError(f"{key.name}: {value} is not one of {sorted(key.choices)}")
    return value


def format_value(kind: Kind, value: Value) -> str:
    """A value as the drone writes it in its configuration text."""
    if kind is Kind.BOOL:
        return "TRUE" if value else "FALSE"
    if kind is Kind.FLOAT:
        return f"{_f32(float(value)):.7e}"
    return str(value)


class DroneConfig:
    """The drone's configuration: every key of :data:`KEYS` at its default, then ``values``
    (the drone's own, e.g. its flying time or SSID: set as stored, without a client's rights)."""

    def __init__(self, values: Mapping[str, Value] | None = None) -> None:
        self._values: dict[str, Value] = {
            k.name: _f32(float(k.default)) if k.kind is Kind.FLOAT else k.default for k in KEYS}
        for name, value in (values or {}).items():
            key = self._key(name)
            self._values[key.name] = _parse(key, format_value(key.kind, value))

    @staticmethod
    def _key(name: str) -> Key:
        key = KEYS_BY_NAME.get(name.strip().lower())
        if key is None:
            raise UnknownKeyError(f"no configuration key {name!r}")
        return key

    def set(self, name: str, text: str, *, custom: bool = False) -> dict[str, Value]:
        """Apply ``AT*CONFIG`` ``name`` = ``text`` (``custom``: sent under a custom
        configuration's ids): the keys this changed and their values, the key first; raises
        :class:`UnknownKeyError`, :class:`ReadOnlyKeyError` or :class:`ConfigError` (nothing
        changed)."""
        key = self._key(name)
        if key.write == NONE or (key.write == CUSTOM and not custom):
            raise ReadOnlyKeyError(f"{key.name} is read-only" + (
                " outside a custom configuration (multiconfig)" if key.write == CUSTOM else ""))
        value = _parse(key, text)
        changed = {key.name: value}
        outdoor = bool(value) if key.name == "control:outdoor" else self.get_bool(
            "control:outdoor")
        for live, profiles in _PROFILES.items():
            if key.name == "control:outdoor":
                changed[live] = self._values[profiles[outdoor]]
            elif key.name == live:
                changed[profiles[outdoor]] = value
            elif key.name == profiles[outdoor]:
                changed[live] = value
        self._values.update(changed)
        return changed

    def get(self, name: str) -> Value:
        return self._values[self._key(name).name]

    def _typed(self, name: str, kind: Kind) -> Value:
        key = self._key(name)
        if key.kind is not kind:
            raise TypeError(f"{key.name} is {key.kind.value}, not {kind.value}")
        return self._values[key.name]

    def get_int(self, name: str) -> int:
        return int(self._typed(name, Kind.INT))

    def get_float(self, name: str) -> float:
        return float(self._typed(name, Kind.FLOAT))

    def get_bool(self, name: str) -> bool:
        return bool(self._typed(name, Kind.BOOL))

    def get_str(self, name: str) -> str:
        return str(self._typed(name, Kind.STRING))

    def items(self) -> Iterator[tuple[str, Value]]:
        """(key, value) in the order the drone lists them."""
        for key in sorted(KEYS, key=lambda k: k.category):  # (sorted is stable)
            yield key.name, self._values[key.name]

    def to_text(self) -> str:
        """The configuration as the drone sends it over TCP 5559."""
        return "".join(f"{name} = {format_value(KEYS_BY_NAME[name].kind, value)}\n"
                       for name, value in self.items())

    # the values the flight model and the driver use, in their units
    @property
    def euler_angle_max_rad(self) -> float:
        return self.get_float("control:euler_angle_max")

    @property
    def control_vz_max_mm_s(self) -> float:
        return self.get_float("control:control_vz_max")

    @property
    def control_yaw_rad_s(self) -> float:
        return self.get_float("control:control_yaw")

    @property
    def altitude_max_mm(self) -> int:
        return self.get_int("control:altitude_max")

    @property
    def altitude_min_mm(self) -> int:
        return self.get_int("control:altitude_min")


def _lenient(name: str, text: str) -> Value | tuple[float, ...]:
    """A value from the drone's text: its key's type where the key is known (the drone's word,
    so no range check; a float as the nearest single-precision value, which is the drone's own
    where ``%.7e`` kept enough digits), a vector as a tuple of floats, otherwise the text."""
    key = KEYS_BY_NAME.get(name)
    if key is not None and key.kind is Kind.STRING:
        return text
    if text.startswith("{"):
        try:
            return tuple(float(v) for v in text.strip("{} ").split())
        except ValueError:
            return text
    if key is None:
        return text
    if key.kind is Kind.BOOL:
        return text.upper() == "TRUE"
    try:
        return int(float(text)) if key.kind is Kind.INT else _f32(float(text))
    except (ValueError, OverflowError):  # (not a number, or beyond a 32-bit one)
        return text


def parse_config_text(text: str | bytes) -> dict[str, Value | tuple[float, ...]]:
    """The drone's configuration text (TCP 5559) as {key: value}, keys in lower case: known
    keys typed (as :func:`_lenient` reads them), others as text. Tolerant: NULs, CR or CRLF line
    ends, a vector wrapped over several lines, blank or stray lines, a key given twice (the
    last wins)."""
    if isinstance(text, bytes):
        text = text.decode("latin-1")
    out: dict[str, Value | tuple[float, ...]] = {}
    pending: list[str] | None = None  # [key, text] of a vector still open ("{" without "}")
    for line in text.replace("\0", "").splitlines():
        line = line.strip()
        if pending is not None:
            if "=" not in line or "}" in line:
                pending[1] += f" {line}"
                if "}" in line:
                    out[pending[0]] = _lenient(*pending)
                    pending = None
                continue
            out[pending[0]] = _lenient(*pending)  # never closed: take what came
            pending = None
        name, equals, value = line.partition(" = ") if " = " in line else line.partition("=")
        name, value = name.strip().lower(), value.strip()
        if not equals or ":" not in name:
            continue
        key = KEYS_BY_NAME.get(name)
        if value.startswith("{") and "}" not in value and (
                key is None or key.kind is not Kind.STRING):
            pending = [name, value]
            continue
        out[name] = _lenient(name, value)
    if pending is not None:
        out[pending[0]] = _lenient(*pending)
    return out
