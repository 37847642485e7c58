"""The simulated AR.Drone 2.0's side of its SDK protocol, as a synchronous engine: AT
datagrams in (what a client sends to UDP 5556), navdata packets out (what the drone sends to
UDP 5554), the configuration it serves over TCP 5559, and which camera its one video stream
carries. No sockets and no clock of its own: ``autopilot sim --firmware ardrone`` puts it
behind the drone's ports (:mod:`autopilot.ardrone_server`), and tests drive it datagram by
datagram.

What the drone does with the commands (the SDK 2.0 developer guide, chapters 6–8):

* A command whose sequence number is not above the last one taken is ignored, except that 1
  restarts the count (a new client, or after the watchdog); a malformed command is counted and
  the rest of its datagram still read.
* ``REF``: the takeoff bit's level takes off (landed) or lands (flying); the emergency bit's
  rising edge cuts the motors, or resets the emergency state on the ground.
* ``PCMD`` / ``PCMD_MAG``: a progressive command (its bit 0 set) or the hover.
* ``CONFIG``: applied under the ids of the ``CONFIG_IDS`` before it (a session key only under
  a custom configuration's ids: :meth:`~drivers.ardrone.config.DroneConfig.set`); sets the
  navdata's command-acknowledge bit until ``CTRL 5`` clears it, applied or not.
  ``general:navdata_demo`` ends the bootstrap mode; ``video:video_channel`` switches the
  stream between the front (0) and the bottom (1) camera; ``control:*`` changes the
  firmware's limits.
* ``CTRL 4``: the configuration is sent over TCP 5559 (:meth:`ArdroneFace.config_text`).
* Any command feeds the communication watchdog (no command for 50 ms sets its navdata bit).

The navdata (:meth:`ArdroneFace.navdata`): in bootstrap mode the header alone, at
:data:`DEMO_RATE_HZ`; in demo mode (``general:navdata_demo`` TRUE) at that rate the demo option
and the options ``general:navdata_options`` adds; in full mode (FALSE) at :data:`FULL_RATE_HZ`
the options it selects (:attr:`ArdroneFace.navdata_rate_hz` says which rate is due). The state
bits, and the demo option from the vehicle's telemetry (attitude, its fused height, velocities
in the heading frame) and the firmware's status. Of the other options the simulated drone fills
the time (its clock), the physical measures (gravity's specific force on the accelerometers,
the gyros), the accelerometers' angles, the altitude (the fused height as vision, reference
and raw sonar; its rate) and the magnetometer's headings; the rest — raw ADC words, vision
internals, PWM, pressure, wind — go zeros at their sizes (:data:`~drivers.ardrone.navdata.
OPTION_SIZES`), as no model of them exists here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from drivers.ardrone import at
from drivers.ardrone import navdata as nav
from drivers.ardrone.navdata import State
from drivers.base import VehicleState
from drivers.geometry import euler_from_quat
from drivers.sim.flight.ardrone import FirmwareStatus, Progressive

#: video:video_channel values (ZAP_CHANNEL_HORI, ZAP_CHANNEL_VERT) → our camera names
VIDEO_CHANNELS = {0: "front", 1: "down"}
DEMO_RATE_HZ, FULL_RATE_HZ = nav.RATES_HZ["demo"], nav.RATES_HZ["full"]
CTRL_GET_CONFIG = 4
CTRL_ACK = 5
#: the id a default session, user and application run under (CONFIG_IDS)
DEFAULT_ID = "00000000"
#: the keys the engine acts on (the rest are only kept and listed)
_APPLIED = ("video:video_channel", "control:euler_angle_max", "control:control_vz_max",
            "control:control_yaw", "control:altitude_max", "control:altitude_min")


@dataclass
class FaceCounts:
    """What the engine has seen, for statistics and tests."""

    commands: int = 0
    malformed: int = 0
    stale: int = 0  # sequence numbers not above the last taken
    configs: int = 0
    refused_configs: int = 0


@dataclass
class ArdroneFace:
    """The drone's protocol engine. ``command(name, *args)`` runs a firmware command
    (:class:`~drivers.sim.flight.ardrone.ArdroneFirmware`'s ``ref``, ``pcmd``, ``ftrim``,
    ``alive``); ``limits`` are the firmware's :class:`~drivers.sim.flight.ardrone.ArdroneLimits`
    (``CONFIG control:*`` changes them); ``config`` is the drone's configuration."""

    command: Callable[..., object]
    limits: object
    config: object
    counts: FaceCounts = field(default_factory=FaceCounts)
    bootstrap: bool = True
    ack: bool = False
    #: the camera the video stream carries now (video:video_channel)
    video_camera: str = "front"
    #: the client asked for the configuration (CTRL 4) since the last :meth:`take_config_request`
    config_requested: bool = False
    _last_seq: int = 0
    _ids: tuple[str, ...] = (DEFAULT_ID, DEFAULT_ID, DEFAULT_ID)
    _emergency_bit: bool = False
    _sequence: int = 0
    _frame_index: int = 0

    # -- commands ---------------------------------------------------------------------------

    def on_datagram(self, datagram: bytes) -> None:
        """One datagram to UDP 5556: its commands, in order."""
        try:
            commands = at.parse(datagram)
        except at.AtError:
            self.counts.malformed += 1
            commands = self._salvage(datagram)
        for command in commands:
            self._take(command)

    def _salvage(self, datagram: bytes) -> list[at.AtCommand]:
        """The well-formed commands of a datagram that also holds a malformed one."""
        out = []
        for line in datagram.replace(b"\n", b"\r").split(b"\r"):
            if not line:
                continue
            try:
                out.extend(at.parse(line + b"\r"))
            except at.AtError:
                continue
        return out

    def _take(self, command: at.AtCommand) -> None:
        if command.seq == 1:
            self._last_seq = 0
        if command.seq <= self._last_seq:
            self.counts.stale += 1
            return
        self._last_seq = command.seq
        self.counts.commands += 1
        handler = getattr(self, "_" + command.name.lower(), None)
        if handler is None:
            self.command("alive")
            return
        handler(command)

    def _ref(self, command: at.AtCommand) -> None:
        (bits,) = command.args[:1] or (0,)
        bits = int(bits)
        emergency = bool(bits & at.REF_EMERGENCY)
        edge = emergency and not self._emergency_bit
        self._emergency_bit = emergency
        self.command("ref", bool(bits & at.REF_TAKEOFF), edge)

    def _pcmd(self, command: at.AtCommand) -> None:
        if len(command.args) < 5:
            self.counts.malformed += 1
            return
        flag = int(command.args[0])
        roll, pitch, gaz, yaw = (_clamp(v) for v in command.floats(1)[:4])
        hover = not flag & at.PCMD_PROGRESSIVE
        self.command("pcmd", Progressive(roll, pitch, gaz, yaw, hover=hover))

    _pcmd_mag = _pcmd

    def _ftrim(self, command: at.AtCommand) -> None:
        self.command("ftrim")

    def _ctrl(self, command: at.AtCommand) -> None:
        mode = int(command.args[0]) if command.args else 0
        if mode == CTRL_ACK:
            self.ack = False
        elif mode == CTRL_GET_CONFIG:
            self.config_requested = True
        self.command("alive")

    def _config_ids(self, command: at.AtCommand) -> None:
        self.command("alive")
        if len(command.args) == 3 and all(isinstance(a, str) for a in command.args):
            self._ids = tuple(command.args)

    def _config(self, command: at.AtCommand) -> None:
        self.command("alive")
        self.ack = True  # the drone acknowledges what it received, applied or not
        if len(command.args) != 2 or not all(isinstance(a, str) for a in command.args):
            self.counts.refused_configs += 1
            return
        key, value = command.args
        custom = any(i != DEFAULT_ID for i in self._ids)
        try:
            changed = self.config.set(key, value, custom=custom)
        except (KeyError, ValueError):
            self.counts.refused_configs += 1
            return
        self.counts.configs += 1
        for name in changed:
            self._apply(name)

    def apply_all(self) -> None:
        """Take every key the engine acts on from the configuration (at boot)."""
        for name in _APPLIED:
            self._apply(name)

    def _apply(self, key: str) -> None:
        cfg, lim = self.config, self.limits
        if key == "general:navdata_demo":
            self.bootstrap = False
        elif key == "video:video_channel":
            self.video_camera = VIDEO_CHANNELS.get(cfg.get_int(key), self.video_camera)
        elif key == "control:euler_angle_max":
            lim.euler_angle_max_rad = cfg.euler_angle_max_rad
        elif key == "control:control_vz_max":
            lim.control_vz_max_m_s = cfg.control_vz_max_mm_s / 1000.0
        elif key == "control:control_yaw":
            lim.control_yaw_rad_s = cfg.control_yaw_rad_s
        elif key == "control:altitude_max":
            lim.altitude_max_m = cfg.altitude_max_mm / 1000.0
        elif key == "control:altitude_min":
            lim.altitude_min_m = cfg.altitude_min_mm / 1000.0

    def take_config_request(self) -> bool:
        """Did a client ask for the configuration (CTRL 4) since the last call?"""
        asked, self.config_requested = self.config_requested, False
        return asked

    def config_text(self) -> bytes:
        """The configuration as the drone sends it over TCP 5559."""
        return self.config.to_text().encode("ascii")

    # -- navdata ----------------------------------------------------------------------------

    @property
    def navdata_rate_hz(self) -> float:
        """The rate the navdata is due at: 200 Hz in full mode, 15 Hz otherwise."""
        full = not self.bootstrap and not self.config.get_bool("general:navdata_demo")
        return FULL_RATE_HZ if full else DEMO_RATE_HZ

    def navdata(self, state: VehicleState, status: FirmwareStatus) -> bytes:
        """The navdata packet for one telemetry sample (bootstrap: the header alone)."""
        self._sequence += 1
        bits = State.NAVDATA_THREAD_ON | State.ATCODEC_THREAD_ON | State.VIDEO_THREAD_ON | \
            State.ACQ_THREAD_ON | State.VIDEO | State.ALTITUDE
        for flag, on in ((State.FLY, status.motors_on), (State.COMMAND, self.ack),
                         (State.EMERGENCY, status.emergency),
                         (State.COM_WATCHDOG, status.com_watchdog),
                         (State.COM_LOST, status.com_lost), (State.VBAT_LOW, status.battery_low)):
            if on:
                bits |= flag
        if self.bootstrap:
            return nav.build(bits | State.NAVDATA_BOOTSTRAP, self._sequence)
        tags = set(nav.masked_tags(self.config.get_int("general:navdata_options")))
        if self.config.get_bool("general:navdata_demo"):
            bits |= State.NAVDATA_DEMO
            tags.add(nav.Tag.DEMO)
        roll, pitch, yaw = euler_from_quat(state.attitude_q)
        vn, ve, vd = (float(v) for v in state.velocity_ned_m_s)
        c, s = math.cos(yaw), math.sin(yaw)
        self._frame_index += 1
        theta_mdeg, phi_mdeg = math.degrees(pitch) * 1000.0, math.degrees(roll) * 1000.0
        altitude_mm = max(0, round(state.altitude_m * 1000.0))
        demo = nav.Demo(
            control_state=int(status.control_state) << 16,
            battery_percent=round(100.0 * max(0.0, min(1.0, state.battery.remaining_fraction))),
            theta_mdeg=theta_mdeg, phi_mdeg=phi_mdeg, psi_mdeg=math.degrees(yaw) * 1000.0,
            altitude_mm=altitude_mm,
            vx_mm_s=(c * vn + s * ve) * 1000.0, vy_mm_s=(-s * vn + c * ve) * 1000.0,
            vz_mm_s=vd * 1000.0, frame_index=self._frame_index)
        options: dict[int, bytes] = {}
        for tag in tags - {nav.Tag.DEMO}:
            options[tag] = self._option(tag, state, demo, roll, pitch)
        return nav.build(bits, self._sequence, demo if nav.Tag.DEMO in tags else None,
                         options=options)

    @staticmethod
    def _option(tag: int, state: VehicleState, demo: nav.Demo, roll: float,
                pitch: float) -> bytes:
        """A full-mode option's data (zeros for the ones with no model here)."""
        if tag == nav.Tag.TIME:
            return nav.time_data(state.time_s)
        if tag == nav.Tag.PHYS_MEASURES:
            g = 1000.0  # mg: gravity's specific force on the body axes (FRD)
            accs = (g * math.sin(pitch), -g * math.sin(roll) * math.cos(pitch),
                    -g * math.cos(roll) * math.cos(pitch))
            gyros = tuple(math.degrees(float(w)) for w in state.angular_velocity_frd_rad_s)
            return nav.phys_measures_data(accs, gyros)
        if tag == nav.Tag.EULER_ANGLES:
            return nav.euler_angles_data(demo.theta_mdeg, demo.phi_mdeg)
        if tag == nav.Tag.ALTITUDE:
            return nav.altitude_data(demo.altitude_mm, demo.vz_mm_s, demo.altitude_mm,
                                     demo.altitude_mm)
        if tag == nav.Tag.MAGNETO:
            return nav.magneto_heading_data(demo.psi_mdeg / 1000.0)
        return b""


def _clamp(value: float) -> float:
    return max(-1.0, min(1.0, value)) if math.isfinite(value) else 0.0
