"""Fault injection in the simulated vehicle, as PX4 SITL's ``failure`` commands and ``SIM_*``
parameters do for PX4: seeded, on the simulator's clock, so a faulted run replays exactly.

A fault is a window of scenario time: it starts ``start_s`` after the vehicle first arms (when
the scenario's scripted motion starts) and lasts ``duration_s`` (omitted: to the end of the
flight). Where it acts:

=====================  ===========================================================================
kind                   what happens while it is active (parameters, defaults)
=====================  ===========================================================================
camera_dropout         the camera delivers no frames (``camera``: one camera's name; omitted: all)
camera_freeze          the camera repeats the last image from before the fault with new stamps
                       (``camera``)
camera_corrupt         ``mode`` ``black`` (black frames), ``noise`` (decoder garbage: smeared,
                       shifted and grey macroblock bands, as a lost H.264 slice gives) or
                       ``exposure`` (brightness × ``gain``, 3.0: clipped highlights; < 1 dark)
                       (``camera``)
telemetry_dropout      no telemetry reaches the autopilot; the vehicle flies on
telemetry_delay        every telemetry sample arrives ``delay_s`` (0.5) later
link_loss              the link to the vehicle loses ``fraction`` (0.3) of what crosses it: in the
                       simulator driver telemetry samples and setpoints; on a MAVLink link
                       (``autopilot sim``) also ``duplicate`` (0) and ``reorder`` (0) fractions,
                       ``latency_s`` (0) more delay, and ``video_fraction`` (0) of the RTP packets
                       of the camera streams (H.264 slices lost: corrupt frames)
ekf_glitch             the vehicle's position estimate jumps ``magnitude_m`` (3) towards
                       ``direction_deg`` (0: north; NED, clockwise) and drifts ``drift_m_s`` (0)
                       further that way; it jumps back at the end (an EKF reset)
gps_loss               the position estimate dead-reckons: it drifts ``drift_m_s`` (0.3) in a
                       seeded direction, and after ``invalid_after_s`` (5, PX4's
                       ``EKF2_NOAID_TOUT``) the vehicle reports no local position (PX4 then lands)
rangefinder_dropout    the downward rangefinder reads nothing (NaN)
motor_failure          motor ``motor`` (0) gives ``efficiency`` (0.6) of its thrust (an ESC or
                       propeller failing partly); counted from 0 in PX4's quad-X order (PX4's
                       motor 1 is 0): 0 front-right, 1 rear-left, 2 front-left, 3 rear-right
battery_sag            the battery's remaining charge drops to ``remaining_fraction`` (0.12: under
                       PX4's BAT_LOW_THR 0.15; 0.06 is under BAT_CRIT_THR 0.07) and drains on from
                       there (charge does not come back: ``duration_s`` is ignored)
wind_step              a steady wind of ``speed_m_s`` (8) blowing towards ``direction_deg`` (90:
                       east), with gusts of ``gust_mps`` (0) RMS on top, up to 10 m/s and beyond
rover_stop             the rover (land_on_rover) stops dead (``mode: stop``) or drives back along
                       its path (``mode: reverse``; no further than where it started), then
                       drives on
decoy_crossing         a second ball like the followed one (or of ``color``) crosses behind it,
                       ``behind_m`` (1.5) further from the vehicle's start, at ``speed_m_s`` (1.0),
                       passing behind the ball halfway through the window
=====================  ===========================================================================

The models are validated with the mission (``scenario.faults``) or from ``--fault KIND:k=v,...``
(:func:`parse_fault`). :class:`FaultSchedule` answers "which faults are active now" for the
simulator (and for the MAVLink face's link impairments).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Annotated, ClassVar, Literal, Union

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

Fraction = Annotated[float, Field(ge=0, le=1)]


class _Fault(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    #: seconds after the vehicle first arms
    start_s: Annotated[float, Field(ge=0, le=86400)] = 0.0
    #: how long it lasts (omitted: to the end of the flight)
    duration_s: Annotated[float, Field(gt=0, le=86400)] | None = None
    #: the scenario section (target kind) it acts on, when it needs one
    needs_target: ClassVar[str | None] = None

    def active_at(self, scenario_time_s: float | None) -> bool:
        if scenario_time_s is None or scenario_time_s < self.start_s:
            return False
        return self.duration_s is None or scenario_time_s < self.start_s + self.duration_s

    @property
    def end_s(self) -> float:
        return math.inf if self.duration_s is None else self.start_s + self.duration_s


class CameraDropout(_Fault):
    kind: Literal["camera_dropout"]
    camera: str | None = None


class CameraFreeze(_Fault):
    kind: Literal["camera_freeze"]
    camera: str | None = None


class CameraCorrupt(_Fault):
    kind: Literal["camera_corrupt"]
    camera: str | None = None
    mode: Literal["black", "noise", "exposure"] = "noise"
    gain: Annotated[float, Field(ge=0, le=20)] = 3.0


class TelemetryDropout(_Fault):
    kind: Literal["telemetry_dropout"]


class TelemetryDelay(_Fault):
    kind: Literal["telemetry_delay"]
    delay_s: Annotated[float, Field(gt=0, le=10)] = 0.5


class LinkLoss(_Fault):
    kind: Literal["link_loss"]
    fraction: Fraction = 0.3
    duplicate: Fraction = 0.0
    reorder: Fraction = 0.0
    latency_s: Annotated[float, Field(ge=0, le=10)] = 0.0
    video_fraction: Fraction = 0.0


class EkfGlitch(_Fault):
    kind: Literal["ekf_glitch"]
    magnitude_m: Annotated[float, Field(ge=0, le=100)] = 3.0
    direction_deg: Annotated[float, Field(ge=-360, le=360)] = 0.0
    drift_m_s: Annotated[float, Field(ge=0, le=10)] = 0.0


class GpsLoss(_Fault):
    kind: Literal["gps_loss"]
    drift_m_s: Annotated[float, Field(ge=0, le=10)] = 0.3
    invalid_after_s: Annotated[float, Field(ge=0, le=600)] = 5.0


class RangefinderDropout(_Fault):
    kind: Literal["rangefinder_dropout"]


class MotorFailure(_Fault):
    kind: Literal["motor_failure"]
    motor: Annotated[int, Field(ge=0, le=7)] = 0
    efficiency: Fraction = 0.6


class BatterySag(_Fault):
    kind: Literal["battery_sag"]
    remaining_fraction: Fraction = 0.12


class WindStep(_Fault):
    kind: Literal["wind_step"]
    speed_m_s: Annotated[float, Field(ge=0, le=20)] = 8.0
    direction_deg: Annotated[float, Field(ge=-360, le=360)] = 90.0
    gust_mps: Annotated[float, Field(ge=0, le=10)] = 0.0


class RoverStop(_Fault):
    kind: Literal["rover_stop"]
    needs_target: ClassVar[str | None] = "rover"
    mode: Literal["stop", "reverse"] = "stop"


class DecoyCrossing(_Fault):
    kind: Literal["decoy_crossing"]
    needs_target: ClassVar[str | None] = "ball"
    duration_s: Annotated[float, Field(gt=0, le=600)] = 6.0
    speed_m_s: Annotated[float, Field(gt=0, le=10)] = 1.0
    behind_m: Annotated[float, Field(ge=-5, le=20)] = 1.5
    color: str | None = None


Fault = Annotated[Union[CameraDropout, CameraFreeze, CameraCorrupt, TelemetryDropout,  # noqa: UP007
                        TelemetryDelay, LinkLoss, EkfGlitch, GpsLoss, RangefinderDropout,
                        MotorFailure, BatterySag, WindStep, RoverStop, DecoyCrossing],
                  Field(discriminator="kind")]
FAULT_KINDS = ("camera_dropout", "camera_freeze", "camera_corrupt", "telemetry_dropout",
               "telemetry_delay", "link_loss", "ekf_glitch", "gps_loss", "rangefinder_dropout",
               "motor_failure", "battery_sag", "wind_step", "rover_stop", "decoy_crossing")
_ADAPTER: TypeAdapter = TypeAdapter(Fault)
CAMERA_FAULTS = ("camera_dropout", "camera_freeze", "camera_corrupt")


def fault_model(kind: str) -> type[_Fault]:
    """The model of a fault kind (its parameters are its fields)."""
    return next(cls for cls in Fault.__origin__.__args__
                if cls.model_fields["kind"].annotation.__args__ == (kind,))


class FaultError(ValueError):
    """A ``--fault`` that does not parse or validate."""


def parse_fault(text: str) -> dict:
    """``KIND[:key=value,...]`` (values as YAML scalars) → the fault's mapping, validated.
    E.g. ``camera_dropout:start_s=12,duration_s=3`` or ``link_loss:fraction=0.3``."""
    kind, _, rest = text.strip().partition(":")
    from autopilot.suggest import did_you_mean

    kind = kind.strip()
    if kind not in FAULT_KINDS:
        raise FaultError(f"--fault {text!r}: unknown kind {kind!r}"
                         f"{did_you_mean(kind, FAULT_KINDS)} (expected one of "
                         f"{', '.join(FAULT_KINDS)})")
    fields = [name for name in fault_model(kind).model_fields if name != "kind"]
    item: dict = {"kind": kind}
    for part in filter(None, (p.strip() for p in rest.split(","))):
        key, sep, value = part.partition("=")
        if not sep or not key.strip():
            raise FaultError(f"--fault {text!r}: expected KEY=VALUE, got {part!r} ({kind}'s "
                             f"parameters: {', '.join(fields)})")
        if key.strip() not in fields:
            raise FaultError(f"--fault {text!r}: {kind} has no parameter {key.strip()!r}"
                             f"{did_you_mean(key.strip(), fields)} (its parameters: "
                             f"{', '.join(fields)})")
        try:
            item[key.strip()] = yaml.safe_load(value) if value.strip() else None
        except yaml.YAMLError:
            item[key.strip()] = value
    try:
        return _ADAPTER.validate_python(item).model_dump(exclude_unset=True) | {"kind": kind}
    except ValidationError as exc:
        problems = "; ".join(f"{'.'.join(str(p) for p in e['loc'][1:]) or 'kind'}: {e['msg']}"
                             for e in exc.errors())
        raise FaultError(f"--fault {text!r}: {problems}") from None


def fault_override(texts: Sequence[str]) -> str:
    """``--fault`` items as one ``--set`` override of ``scenario.faults`` (JSON is YAML)."""
    import json

    return "scenario.faults=" + json.dumps([parse_fault(t) for t in texts])


class FaultSchedule:
    """The faults of a flight, asked by kind at a scenario time (None: not armed yet)."""

    def __init__(self, faults: Sequence[_Fault], seed: int = 0) -> None:
        self.faults = tuple(faults)
        self._by_kind: dict[str, tuple[_Fault, ...]] = {}
        for f in self.faults:
            self._by_kind[f.kind] = (*self._by_kind.get(f.kind, ()), f)
        # one generator per thread that draws: the simulator's, the MAVLink face's (the event
        # loop) and the video encoder's
        self.rng = np.random.default_rng((seed, 6151))
        self.link_rng = np.random.default_rng((seed, 6153))
        self.video_rng = np.random.default_rng((seed, 6154))

    def __bool__(self) -> bool:
        return bool(self.faults)

    def of(self, kind: str) -> tuple[_Fault, ...]:
        return self._by_kind.get(kind, ())

    def active(self, kind: str, scenario_time_s: float | None) -> list[_Fault]:
        return [f for f in self._by_kind.get(kind, ()) if f.active_at(scenario_time_s)]

    def camera(self, kind: str, camera: str, scenario_time_s: float | None) -> _Fault | None:
        for f in self.active(kind, scenario_time_s):
            if f.camera is None or f.camera == camera:
                return f
        return None

    def lost(self, scenario_time_s: float | None, rng: np.random.Generator | None = None,
             field: str = "fraction") -> bool:
        """One message across the link: lost to a ``link_loss`` now (seeded draw)?"""
        active = self.active("link_loss", scenario_time_s)
        if not active:
            return False
        keep = 1.0
        for f in active:
            keep *= 1.0 - getattr(f, field)
        return bool((rng or self.rng).random() >= keep)

    def video_lost(self, scenario_time_s: float | None) -> bool:
        """One RTP packet of a camera stream: lost to a ``link_loss`` (``video_fraction``)?"""
        return self.lost(scenario_time_s, self.video_rng, "video_fraction")


class TimeWarp:
    """A scripted path's clock under ``rover_stop`` faults: stopped (time stands still) or
    reversed (time runs back, no further than the path's start, where the rover waits) within
    each window, running on afterwards; ``rate`` is d(warped)/dt, which scales the path's
    velocity (and its square the acceleration). Where windows overlap, the one that started
    first acts; a later one acts on what is left of its window."""

    def __init__(self, faults: Sequence[RoverStop]) -> None:
        self.faults = sorted(faults, key=lambda f: f.start_s)

    def __call__(self, t: float) -> tuple[float, float]:
        warped, cursor = 0.0, 0.0  # path time reached at scenario time ``cursor``
        for f in self.faults:
            start = max(f.start_s, cursor)
            if t < start:
                break
            warped += start - cursor  # driving normally up to the window
            cursor = start
            if f.end_s <= cursor:
                continue
            span = min(t, f.end_s) - cursor
            rate = 0.0 if f.mode == "stop" else -1.0
            warped += rate * span
            if warped < 0.0:  # reversed all the way to the start: it waits there
                warped, rate = 0.0, 0.0
            cursor += span
            if t < f.end_s:
                return warped, rate
        return warped + (t - cursor), 1.0


class WarpedPath:
    """A rover's path (:class:`~drivers.sim.rover.RoverPath`) on a :class:`TimeWarp`."""

    def __init__(self, path, warp: TimeWarp) -> None:
        self.path = path
        self.warp = warp

    def __call__(self, time_s: float):
        pos, vel, yaw, _, _ = self.motion(time_s)
        return pos, vel, yaw

    def motion(self, time_s: float):
        warped, rate = self.warp(time_s)
        pos, vel, yaw, acc, yaw_rate = self.path.motion(warped)
        return pos, vel * rate, yaw, acc * (rate * rate), yaw_rate * rate


def corrupt_image(image: np.ndarray, fault: CameraCorrupt, rng: np.random.Generator
                  ) -> np.ndarray:
    """What a corrupt frame looks like (see the module's table)."""
    if fault.mode == "black":
        return np.zeros_like(image)
    if fault.mode == "exposure":
        return np.clip(image.astype(np.float32) * fault.gain, 0, 255).astype(np.uint8)
    out = image.copy()
    h, w = out.shape[:2]
    block = 16
    rows = h // block
    start = int(rng.integers(0, max(rows, 1)))
    count = int(rng.integers(1, max(rows // 2, 2)))
    for r in range(start, min(rows, start + count)):  # from a lost slice down: garbage
        y = r * block
        band = out[y:y + block]
        choice = int(rng.integers(3))
        if choice == 0:
            band[:] = 128  # grey: the decoder's concealment of a missing macroblock row
        elif choice == 1:
            band[:] = np.roll(band, int(rng.integers(-w // 4, w // 4)), axis=1)
        else:
            band[:] = np.repeat(band[:1], band.shape[0], axis=0)  # smeared
    noise = rng.integers(0, 40, size=out.shape, dtype=np.uint16)
    return np.minimum(out + noise, 255).astype(np.uint8)
