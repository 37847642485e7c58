"""``autopilot doctor``: the preflight check of a companion computer's setup.

Before a flight (or at boot, from systemd), it checks what a mission will rely on and prints one
line per item with PASS, WARN or FAIL:

* the MAVLink link: a vehicle answers (autopilot, type, ids), its telemetry comes at the rates
  the autopilot needs, TIMESYNC round trips work, the vehicle reports itself armable, and the
  link is signed where it crosses a network;
* each camera: frames arrive at its rate and size, the intrinsics come from a calibration,
  and how capture times are known (the vehicle's clock, RTCP, or arrival minus latency);
* the clock (synchronised to NTP, so that logs and photos carry true times);
* free disk space where runs are written.

It flies nothing and commands nothing. Exit code 0 when nothing failed.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
import shutil
import subprocess
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from autopilot.mission import MissionPlan
from drivers.base import VehicleError
from drivers.capabilities import LinkTimeSync, MavlinkIdentity, VideoInput

#: telemetry the autopilot flies on: position samples per second (PASS at or above, FAIL below
#: the second figure)
POSITION_RATE_HZ = (20.0, 5.0)
TIMESYNC_RTT_S = (0.05, 0.2)
DISK_FREE_B = (5 << 30, 1 << 30)


@dataclass(frozen=True, slots=True)
class Check:
    item: str
    status: str  # PASS | WARN | FAIL
    detail: str

    def line(self) -> str:
        return f"{self.status:<4}  {self.item:<16} {self.detail}"


async def run_doctor(plan: MissionPlan, *, connect: str | None = None,
                     video: str | Sequence[str] | None = None,
                     calibration: str | Path | Sequence[str] | None = None,
                     signing_key: Path | None = None, duration_s: float = 5.0,
                     runs_dir: Path = Path("runs"),
                     report: Callable[[Check], None] = lambda check: None) -> list[Check]:
    """All the checks, each passed to ``report`` as it is made."""
    from autopilot.run import make_vehicle

    checks: list[Check] = []

    def add(item: str, status: str, detail: str) -> None:
        check = Check(item, status, detail)
        checks.append(check)
        report(check)

    add(*_clock_check())
    add(*_disk_check(runs_dir))
    link = plan.config.link
    url = connect or link.connect
    vehicle, _ = make_vehicle(plan, connect=connect, video=video, calibration=calibration,
                              signing_key=signing_key)
    try:
        await vehicle.connect(link.connect_timeout_s)
    except VehicleError as exc:
        add("link", "FAIL", str(exc))
        await vehicle.close()
        return checks
    except OSError as exc:
        add("link", "FAIL", str(exc))
        return checks
    from autopilot.vehicle_kinds import DRIVER_KINDS

    try:
        await DRIVER_KINDS[plan.config.driver].doctor(
            vehicle, plan, url, duration_s, add, signing=bool(signing_key or link.signing_key))
    finally:
        await vehicle.close()
    return checks


async def mavlink_checks(vehicle, plan: MissionPlan, url: str, duration_s: float, add, *,
                         signing: bool) -> None:
    """A MAVLink vehicle's link, telemetry, time sync and health, and its cameras' streams."""
    await _link_checks(vehicle, url, duration_s, add, signing=signing)
    await _param_checks(vehicle, add)
    await _needs_checks(vehicle, plan, add)
    setups = vehicle.camera_setups if isinstance(vehicle, VideoInput) else {}
    for name, setup in setups.items():
        await _camera_checks(vehicle, name, setup.url, duration_s, setup.calibration, add)


async def ardrone_checks(vehicle, plan: MissionPlan, url: str, duration_s: float, add, *,
                         signing: bool) -> None:
    """An AR.Drone 2.0's link (its firmware, read from its configuration), navdata rate,
    battery and state, and each camera the mission uses (the one video stream switched to
    it: its rate, size and delay)."""
    from drivers.ardrone.config import parse_config_text
    from drivers.ardrone.navdata import RATES_HZ

    config = parse_config_text(getattr(vehicle.link, "config_text", b"") or b"")
    version = config.get("general:num_version_soft")
    add("link", "PASS" if version else "WARN",
        f"AR.Drone 2.0 on {url}, firmware {version}" if version else
        f"AR.Drone 2.0 on {url}; no configuration over TCP {vehicle.ports.config} (its "
        "firmware unknown, its default limits assumed)")
    samples = await _samples(vehicle, duration_s)
    rate = len(samples) / duration_s
    mode = getattr(vehicle, "navdata_mode", "demo")
    expected = RATES_HZ[mode]
    add("navdata", "PASS" if rate >= 0.8 * expected else "WARN" if rate >= expected / 3
        else "FAIL", f"{rate:.0f} Hz ({mode} navdata: {expected:.0f} Hz); "
        f"{vehicle.link.bad_packets} bad packets")
    if samples:
        s = samples[-1]
        battery = s.battery.remaining_fraction
        add("battery", "PASS" if battery >= 0.5 else "WARN" if battery >= 0.2 else "FAIL",
            f"{battery * 100:.0f} %")
        where = f"{'flying' if s.in_air else 'on the ground'}, mode {s.mode.value}"
        add("vehicle", "PASS" if s.health.armable else "FAIL", where if s.health.armable else
            f"{where}: cannot take off (its emergency state, or its battery low)")
    for name in plan.cameras_used():
        if name in vehicle.cameras:
            await _camera_checks(vehicle, name, f"{url} (tcp {vehicle.ports.video})",
                                 duration_s, None, add, timing="the drone's PaVE timestamps")
    add("security", "WARN" if "127.0.0.1" not in url and "localhost" not in url else "PASS",
        "the AR.Drone's protocol has no authentication: anyone on its Wi-Fi can fly it")


async def _param_checks(vehicle, add) -> None:
    """The parameters a companion computer depends on, as its firmware names them (both
    MAVLink drivers read parameters)."""
    firmware, get = getattr(vehicle, "firmware", None), getattr(vehicle, "get_param", None)
    if firmware is None:
        return
    estimator = firmware.estimator_check(getattr(vehicle, "ekf_flags", None))
    if estimator is not None:
        add("estimator", *estimator)
    if get is None:
        return
    for check in firmware.companion_params():
        try:
            value = await get(check.name)
        except (KeyError, OSError) as exc:
            add(f"param {check.name}", "WARN", f"not read: {exc}")
            continue
        status, text = check.judge(value)
        add(f"param {check.name}", status, f"{value:g}: {text}")


async def _needs_checks(vehicle, plan: MissionPlan, add) -> None:
    """What the mission's steps need of the vehicle that its own settings may deny (a landing
    handed to ArduCopter with PLND_ENABLED 0): FAIL, as ``autopilot run`` would refuse it."""
    from drivers.capabilities import NEEDS, SETTINGS, lacks, settings_problem

    for need in dict.fromkeys(need for _, _, need in plan.needs()):
        steps = ", ".join(f"steps[{i}].{name}" for i, name, n in plan.needs() if n == need)
        if lacks(vehicle, (need,)):
            add(need, "FAIL", f"{steps} need {NEEDS[need][1]}, which this driver does not have")
        elif need in SETTINGS:
            problem = await settings_problem(vehicle, need)
            add(need, "FAIL" if problem else "PASS", f"{steps}: {problem}" if problem else
                f"{steps}: {NEEDS[need][1]}, its settings allow it")


async def _samples(vehicle, duration_s: float) -> list:
    samples = []
    async with contextlib.aclosing(vehicle.telemetry(buffer=256)) as stream:
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(duration_s):
                async for state in stream:
                    samples.append(state)
    return samples


async def _link_checks(vehicle, url: str, duration_s: float, add, *, signing: bool) -> None:
    from drivers.base import FlightMode
    from drivers.mavlink.firmware import FIRMWARE_PROFILES, firmware_profile

    known = isinstance(vehicle, MavlinkIdentity)
    number = vehicle.autopilot if known else None
    autopilot = firmware_profile(number).title if number in FIRMWARE_PROFILES else "MAVLink"
    target = vehicle.target_ids if known else None
    ids = f"system {target[0]} component {target[1]}" if target else "ids unknown"
    add("link", "PASS", f"{autopilot} vehicle, {ids}, on {url}")
    samples, attitudes = [], set()
    async with contextlib.aclosing(vehicle.telemetry(buffer=256)) as stream:
        end = time.monotonic() + duration_s
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(duration_s):
                async for state in stream:
                    samples.append(state)
                    attitudes.add(state.attitude_time_s)
                    if time.monotonic() > end:
                        break
    rate = len(samples) / duration_s
    lo_pass, lo_fail = POSITION_RATE_HZ
    status = "PASS" if rate >= lo_pass else "WARN" if rate >= lo_fail else "FAIL"
    add("telemetry", status, f"position {rate:.0f} Hz, attitude updates "
        f"{len(attitudes) / duration_s:.0f} Hz (the autopilot wants ≥ {lo_pass:g} Hz)")
    rtt = vehicle.time_sync_round_trip_s if isinstance(vehicle, LinkTimeSync) else math.inf
    good, bad = TIMESYNC_RTT_S
    if math.isfinite(rtt):
        status = "PASS" if rtt <= good else "WARN" if rtt <= bad else "FAIL"
        add("time sync", status, f"TIMESYNC round trip {rtt * 1e3:.1f} ms; vehicle clock "
            f"mapped with ±{rtt * 5e2:.1f} ms")
    else:
        add("time sync", "WARN", "no TIMESYNC answer: capture times use telemetry arrival "
            "(less exact)")
    if samples:
        s = samples[-1]
        health = s.health
        problems = ", ".join(health.problems())
        add("vehicle", "PASS" if health.armable else "WARN",
            f"mode {s.mode.value}, {'armed' if s.armed else 'disarmed'}, "
            f"battery {s.battery.remaining_fraction * 100:.0f} %, "
            + ("armable" if health.armable else f"not armable: {problems}"))
        if s.mode is FlightMode.UNKNOWN:
            add("modes", "WARN", "the vehicle's flight mode is not one this autopilot knows")
    network = not (url.startswith("serial:") or "127.0.0.1" in url or "localhost" in url)
    if signing:
        add("signing", "PASS", "MAVLink 2 signing on (unsigned messages are dropped)")
    else:
        add("signing", "WARN" if network else "PASS",
            "unsigned, on a network address: anyone on that network can command the vehicle"
            if network else "unsigned (local link)")


async def _camera_checks(vehicle, name: str, url: str, duration_s: float,
                         calibration: str | None, add, timing: str | None = None) -> None:
    info = vehicle.cameras[name]
    frames = []
    subscribed = vehicle.clock.now()
    async with contextlib.aclosing(vehicle.frames(name)) as stream:
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(duration_s):
                async for frame in stream:
                    frames.append((frame, vehicle.clock.now()))
    if not frames:
        source = vehicle.video_sources.get(name) if isinstance(vehicle, VideoInput) else None
        error = getattr(source, "error", None)
        add(f"camera {name}", "FAIL", f"no frame from {url} in {duration_s:g} s"
            + (f" ({error})" if error else ""))
        return
    # the stream's rate from its first frame on: a decoder starts at a key frame, so the wait
    # for the first one (up to the sender's key-frame interval) is said on its own
    first_s = frames[0][1] - subscribed
    span_s = frames[-1][1] - frames[0][1]
    rate = (len(frames) - 1) / span_s if len(frames) > 1 and span_s > 0.5 else \
        len(frames) / duration_s
    height, width = frames[-1][0].image.shape[:2]
    intr = info.intrinsics
    size_ok = (width, height) == (intr.width_px, intr.height_px)
    status = "PASS" if rate >= 0.8 * info.rate_hz and size_ok else "WARN"
    add(f"camera {name}", status, f"{rate:.1f} fps of {info.rate_hz:g}, {width}×{height}"
        + ("" if size_ok else f" (intrinsics are for {intr.width_px}×{intr.height_px})")
        + f", first frame after {first_s:.1f} s")
    add(f"calibration {name}", "PASS" if calibration else "WARN",
        f"from {calibration}" if calibration else "none: the nominal pinhole of "
        f"vehicle.cameras.{name} (not this camera's, no lens distortion): calibrate it "
        f"(autopilot calibrate) and pass --calibration {name}=FILE")
    delays = sorted(arrived - frame.time_s for frame, arrived in frames)
    source = vehicle.video_sources.get(name) if isinstance(vehicle, VideoInput) else None
    mode = timing or str(getattr(getattr(source, "timing", None), "mode", "arrival"))
    detail = f"capture times from {mode}; capture → arrival p50 " \
             f"{delays[len(delays) // 2] * 1e3:.0f} ms"
    add("capture times", "PASS" if "arrival" not in mode else "WARN",
        detail + ("" if "arrival" not in mode else
                  f" (assumed: vehicle.cameras.{name}.stream_latency_s; measure it, see "
                  "docs/companion.md)"))


def _clock_check() -> tuple[str, str, str]:
    synced = None
    if shutil.which("timedatectl"):
        with contextlib.suppress(OSError, subprocess.SubprocessError):
            out = subprocess.run(["timedatectl", "show", "-p", "NTPSynchronized", "--value"],
                                 capture_output=True, text=True, timeout=5).stdout.strip()
            synced = {"yes": True, "no": False}.get(out)
    if synced is None and Path("/run/systemd/timesync/synchronized").exists():
        synced = True
    wall = time.strftime("%Y-%m-%d %H:%M:%S %Z")
    if synced:
        return "clock", "PASS", f"{wall}, synchronised (NTP)"
    return "clock", "WARN", (f"{wall}, not known to be synchronised: logs and photos carry "
                             "this machine's time (enable NTP, or a GPS time source)")


def _disk_check(runs_dir: Path) -> tuple[str, str, str]:
    where = runs_dir if runs_dir.exists() else Path.cwd()
    free = shutil.disk_usage(where).free
    good, bad = DISK_FREE_B
    status = "PASS" if free >= good else "WARN" if free >= bad else "FAIL"
    minutes = free / (50 << 20)  # a flight log with frames: ~50 MB a minute
    return "disk", status, (f"{free / (1 << 30):.1f} GB free at {where.resolve()} "
                            f"(~{minutes:.0f} min of flight logs with frames)")


def summary_line(checks: list[Check]) -> str:
    counts = {s: sum(c.status == s for c in checks) for s in ("PASS", "WARN", "FAIL")}
    return f"{counts['PASS']} passed, {counts['WARN']} warnings, {counts['FAIL']} failed"


def as_dicts(checks: list[Check]) -> list[dict]:
    return [dataclasses.asdict(c) for c in checks]
