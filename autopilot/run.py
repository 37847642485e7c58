"""Flying one mission: vehicle, runtime, flight log and summary, from a validated plan."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import datetime as dt
import json
import math
import signal
import time
from collections.abc import Callable, Mapping
from pathlib import Path

from autopilot.config import ConfigError, Problem
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import FlightLog
from autopilot.flightlog.metrics import estimation_metrics, follow_metrics, latency_metrics
from autopilot.flightlog.records import clean
from autopilot.mission import MissionPlan
from autopilot.process import StealMeter
from autopilot.runtime import Runtime
from drivers.base import CameraUnavailable, Vehicle


def default_out_dir(plan: MissionPlan, root: Path = Path("runs")) -> Path:
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    path = root / f"{stamp}-{plan.mission.name}"
    n = 1
    while path.exists():
        n += 1
        path = root / f"{stamp}-{plan.mission.name}-{n}"
    return path




def make_vehicle(plan: MissionPlan, *, realtime: bool = False, connect: str | None = None,
                 video: str | None = None, calibration: Path | None = None,
                 signing_key: Path | None = None) -> tuple[Vehicle, int | None]:
    """The vehicle the configuration's ``driver`` names, and the simulator's seed (if any).

    MAVLink drivers get the forward camera as a network video stream; its intrinsics come from
    ``calibration`` (an OpenCV or ROS calibration file) if given, else from the configuration's
    camera section, which also gives its mounting. Everything given is checked here, before
    anything opens: a malformed URL or an unreadable key file is an input error
    (:class:`~autopilot.config.ConfigError`) that names the option and what was expected."""
    driver = plan.config.driver
    if driver == "sim":
        from autopilot.scenario import build_world  # MuJoCo loads only when the simulator flies
        from drivers.sim.driver import SimDriver

        sim_config, objects = build_world(plan.mission.scenario, plan.config.sim)
        return SimDriver(sim_config, scenario=objects, lockstep=not realtime), sim_config.seed
    if driver in ("pymavlink", "mavsdk"):
        from drivers.mavlink.link import Endpoint, UrlError
        from drivers.mavlink.signing import Signing, SigningKeyError
        from drivers.video import VideoSource, check_video_url

        link = plan.config.link
        url = connect or link.connect
        video_url = video or link.video
        key = signing_key or (Path(link.signing_key) if link.signing_key else None)
        try:
            Endpoint.parse(url)
        except UrlError as exc:
            raise ConfigError([Problem("command line", None, "--connect", str(exc))]) from None
        try:
            check_video_url(video_url)
        except ValueError as exc:
            raise ConfigError([Problem("command line", None, "--video", str(exc))]) from None
        signing = None
        if key is not None:
            try:
                signing = Signing.load(key)
            except SigningKeyError as exc:
                raise ConfigError([Problem("command line", None, "--signing-key",
                                           str(exc))]) from None
        if driver == "mavsdk":
            from drivers.mavlink.mavsdk_driver import MavsdkDriver as Driver
        else:
            from drivers.mavlink.pymavlink_driver import PymavlinkDriver as Driver
        vehicle = Driver(url, signing=signing)
        info = _camera_info(plan, calibration)
        vehicle.add_camera(VideoSource(video_url, info,
                                       to_local=vehicle.vehicle_time_to_local,
                                       clock=vehicle.clock.now,
                                       latency_s=link.camera_latency_s,
                                       source=link.video_source))
        return vehicle, None
    raise ConfigError([Problem("config", None, "driver",
                               f"unknown driver {driver!r} (sim, mavsdk, pymavlink)")])


def _camera_info(plan: MissionPlan, calibration: Path | None):
    from drivers.sim.model import camera_info

    info = camera_info("front", plan.config.sim.cameras["front"])
    if calibration is None:
        return info
    from drivers.calibration import CalibrationError, load_calibration

    try:
        intrinsics = load_calibration(calibration)
    except CalibrationError as exc:
        message = str(exc).removeprefix(f"{calibration}: ")
        raise ConfigError([Problem(str(calibration), None, "calibration", message)]) from None
    return dataclasses.replace(info, intrinsics=intrinsics)


async def first_frame(vehicle: Vehicle, camera: str, timeout_s: float, where: str) -> None:
    """Wait for ``camera``'s first frame: a vehicle does not take off blind.
    :class:`~drivers.base.CameraUnavailable` if none comes within ``timeout_s``."""
    async with contextlib.aclosing(vehicle.frames(camera)) as frames:
        try:
            await vehicle.clock.wait_for(anext(frames), timeout_s)
        except (TimeoutError, StopAsyncIteration):
            source = getattr(vehicle, "video_sources", {}).get(camera)
            error = getattr(source, "error", None)
            detail = f" (last error: {error})" if error is not None else ""
            raise CameraUnavailable(
                f"no video from the {camera} camera on {where} within {timeout_s:g} s{detail}: "
                "is the camera streaming to this address? (--video URL; a camera on another "
                "machine: --video udp://0.0.0.0:5600 --set link.video_source=CAMERA_IP)",
                "no_video") from None


def logged_cameras(plan: MissionPlan, video_camera: str,
                   cameras: Mapping[str, object]) -> dict[str, float]:
    """Frames logged per second by camera: the followed camera at the configured rate, and
    every frame of the video's camera (``""``: the followed one)."""
    cfg = plan.config
    followed = cfg.perception.ball.camera
    frames = cfg.log.frames
    rates = {followed: frames.sim_rate_hz if cfg.driver == "sim" else frames.vehicle_rate_hz}
    name = video_camera or followed
    if name not in cameras:
        raise ConfigError([Problem("--record-video", None, name,
                                   f"no such camera on this vehicle (it has: "
                                   f"{', '.join(sorted(cameras)) or 'none'})")])
    rates[name] = math.inf
    return rates


async def fly(plan: MissionPlan, out_dir: Path | None, *, realtime: bool = False,
              progress: Callable[[str], None] | None = None,
              handle_signals: bool = False, connect: str | None = None,
              video: str | None = None, calibration: Path | None = None,
              record_video: str | None = None, signing_key: Path | None = None) -> dict:
    """Fly ``plan`` and return its summary (also written to ``out_dir/summary.json``).

    ``record_video`` names a camera whose every frame is logged (for ``onboard.mp4``; "" is
    the followed camera)."""
    vehicle, seed = make_vehicle(plan, realtime=realtime, connect=connect, video=video,
                                 calibration=calibration, signing_key=signing_key)
    log_cameras = None
    if record_video is not None:
        log_cameras = logged_cameras(plan, record_video, vehicle.cameras)
    if out_dir is not None:
        await asyncio.to_thread(out_dir.mkdir, parents=True, exist_ok=True)
    log = FlightLog(out_dir / "flight.mcap" if out_dir is not None else None)
    wall_start = time.perf_counter()
    steal = StealMeter()
    runtime: Runtime | None = None
    loop = asyncio.get_running_loop()
    signals = (signal.SIGINT, signal.SIGTERM)
    main_task = asyncio.current_task()
    received: list[str] = []

    def on_signal(name: str) -> None:
        received.append(name)
        if len(received) == 1 and runtime is not None:
            runtime.request_stop(f"{name} received")
        elif main_task is not None:  # a second signal: stop waiting for the safe stop
            main_task.cancel()

    try:
        await vehicle.connect(plan.config.link.connect_timeout_s if plan.config.driver != "sim"
                              else 10.0)
        if plan.config.driver != "sim":  # a real camera must be streaming before takeoff
            camera = plan.config.perception.ball.camera
            await first_frame(vehicle, camera, plan.config.link.connect_timeout_s,
                              video or plan.config.link.video)
        runtime = Runtime(vehicle, plan, log, progress=progress, log_cameras=log_cameras)
        if handle_signals:
            for sig in signals:
                loop.add_signal_handler(sig, on_signal, sig.name)
        status = await runtime.run()
        reason = runtime.reason
    except asyncio.CancelledError:
        status, reason = "aborted", f"{' then '.join(received) or 'cancelled'}: forced exit"
        with contextlib.suppress(Exception):
            await asyncio.wait_for(vehicle.land(), 2.0)
    finally:
        if handle_signals:
            for sig in signals:
                loop.remove_signal_handler(sig)
        if hasattr(vehicle, "vehicle_to_local_s"):  # MAVLink: for scoring against the sim
            log.write(ch.TIME_SYNC, vehicle.clock.now(), {
                "time_s": vehicle.clock.now(), "vehicle_to_local_s": vehicle.vehicle_to_local_s,
                "round_trip_s": vehicle.time_sync_round_trip_s})
        sim_time = getattr(vehicle, "sim_time_s", None)
        wall_time = time.perf_counter() - wall_start
        await vehicle.close()
        log.close()

    summary = {
        "status": status,
        "reason": reason,
        "mission": plan.mission.name,
        "source": str(plan.source),
        "driver": plan.config.driver,
        "clock": "lockstep" if vehicle.clock.lockstep else "realtime",
        "seed": seed,
        "sim_time_s": sim_time,
        "wall_time_s": wall_time,
        "metrics": {
            "follow": follow_metrics(log.records),
            "estimation": estimation_metrics(log.records),
            "sim": {"real_time_factor": sim_time / wall_time if sim_time and wall_time > 0
                    else None,
                    "cpu_steal_pct": steal.percent()},
            "latency_ms": latency_metrics(log.records),
        },
        "stats": vars(runtime.stats) if runtime is not None else {},
        "log": "flight.mcap" if out_dir is not None else None,
    }
    sources = getattr(vehicle, "video_sources", {})
    if sources:  # how each network camera's capture times were known, and what arrived
        summary["video"] = {name: {"timing": source.timing.as_dict(),
                                   "stats": dataclasses.asdict(source.stats)}
                            for name, source in sources.items()}
    if log.error is not None:
        summary["log_error"] = f"{type(log.error).__name__}: {log.error}"
    if runtime is not None:  # frames the log took, and those it had to drop
        summary["stats"]["frames_logged"] = log.images_written
        summary["stats"]["frames_log_dropped"] += log.images_dropped
    summary["stats"] = {k: v for k, v in summary["stats"].items() if not isinstance(v, list)}
    summary = clean(summary)
    if out_dir is not None:
        (out_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
