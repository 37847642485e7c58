"""``autopilot sim``: the simulator as a stand-alone vehicle that speaks MAVLink like PX4 SITL.

Runs the MuJoCo simulator in real time, with a mission's scenario in its world if one is
given, behind :class:`~drivers.mavlink.face.MavlinkFace`. It runs until Ctrl-C / SIGTERM; if
a client is still flying it, the vehicle is landed first (as stopping PX4 SITL would not do,
but as a safe state demands).

It runs at normal CPU priority (in process the simulator yields the CPU to the autopilot, and
its world slows as a whole; here its clock runs against other processes'). When the machine
cannot run it in real time, the physics and telemetry come first: rendering is shed (frames
skipped, and never waited for) while it is behind, and a warning says so every
:data:`SLOW_WARNING_EVERY_S` (its boot clock then lags the wall clock, as no real flight
controller's does). It prints :data:`READY` when the vehicle becomes armable, as PX4 SITL's
commander does, so that scripts can wait for that line.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as dt
import math
import signal
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from autopilot.config import AppConfig
from autopilot.flight_ops import wait_for_state
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import FlightLog
from autopilot.mission import Scenario
from autopilot.photos import PhotoIndex
from autopilot.scenario import build_world
from drivers.base import FlightMode, VehicleError
from drivers.calibration import write_calibration
from drivers.geometry import yaw_from_quat
from drivers.mavlink.common import cancel_all
from drivers.mavlink.face import MavlinkFace
from drivers.mavlink.signing import Signing
from drivers.sim.config import SimConfig
from drivers.sim.driver import SimDriver
from drivers.video import VideoSender

LAND_ON_EXIT_TIMEOUT_S = 60.0
#: below real time, the warning is repeated this often (wall seconds) while it lasts
SLOW_WARNING_EVERY_S = 10.0
#: printed when the vehicle becomes armable (PX4 SITL's commander: "Ready for takeoff!")
READY = "Ready for takeoff!"


TRUTH_LOG = "truth.mcap"
PHOTOS = "photos"
#: ``serve``'s default: each camera to the address its ``vehicle.cameras.NAME.video`` listens on
FROM_CONFIG: Mapping[str, str] = {}


def video_destinations(config: AppConfig) -> dict[str, str]:
    """Where each enabled camera streams by default: the address the autopilot listens on for
    it (``vehicle.cameras.NAME.video``; a wildcard listen address means this host)."""
    out = {}
    for name, cam in config.vehicle.cameras.items():
        if cam.enabled and cam.video and cam.video.startswith("udp://"):
            host, _, port = cam.video.removeprefix("udp://").rpartition(":")
            host = "127.0.0.1" if host in ("", "0.0.0.0", "[::]", "::") else host
            out[name] = f"udp://{host}:{port}"
    return out


async def serve(config: AppConfig, scenario: Scenario | None, *, instance: int = 0,
                videos: Mapping[str, str] | None = FROM_CONFIG, out_dir: Path | None = None,
                log: Callable[[str], None] = print,
                stop: asyncio.Event | None = None, host: str = "127.0.0.1",
                signing: Signing | None = None, console: str | None = None,
                console_token: str | None = None,
                on_console: Callable[[object], None] | None = None,
                title: str = "empty world", face_class: type[MavlinkFace] = MavlinkFace) -> None:
    """Serve the simulated vehicle until ``stop`` is set (or SIGINT / SIGTERM when None),
    streaming each camera in ``videos`` (camera → URL; by default every enabled camera to its
    :func:`video_destinations`; None: no video). The MAVLink ports listen on ``host``; with
    ``signing``, only signed MAVLink is accepted. ``console`` (``HOST:PORT``) serves a console
    that watches the vehicle (:mod:`autopilot.console.sim`; ``on_console`` gets its server)."""
    if videos is FROM_CONFIG:
        videos = video_destinations(config)
    sim = with_instance_id(config.sim, instance, face_class)
    sim_config, objects = build_world(scenario, sim, config)
    vehicle = SimDriver(sim_config, scenario=objects, lockstep=False,
                        warn_every_s=SLOW_WARNING_EVERY_S, shed_rendering=True,
                        background=False)
    await vehicle.connect()
    face = face_class(vehicle, instance=instance, events=vehicle.events(), host=host,
                       signing=signing)
    loop = asyncio.get_running_loop()
    handle_signals = stop is None
    stop = stop or asyncio.Event()
    streams: list[asyncio.Task] = []

    def console_line(time_s: float, text: str) -> None:
        wall = time.time()  # to line up with other processes' logs
        stamp = time.strftime("%H:%M:%S", time.localtime(wall)) + f"{wall % 1:.3f}"[1:]
        log(f"[{time_s:8.2f} s | {stamp}] {text}")

    async def log_events() -> None:  # the vehicle's console, as PX4's shell prints it
        async with contextlib.aclosing(vehicle.events()) as events:
            async for time_s, text in events:
                console_line(time_s, text)

    events = loop.create_task(log_events(), name="sim-events")
    ready = loop.create_task(announce_ready(vehicle, console_line), name="sim-ready")
    truth_log: FlightLog | None = None
    truth: asyncio.Task | None = None
    photos: asyncio.Task | None = None
    if out_dir is not None:  # ground truth, on the vehicle's boot clock, for `autopilot score`
        truth_log, truth = await record_truth(vehicle, out_dir, log)
        photos = loop.create_task(save_photos(vehicle, out_dir / PHOTOS, log), name="sim-photos")
        log(f"photos → {out_dir / PHOTOS}/ (JPEG, geotagged; photos.jsonl)")
        for name, info in vehicle.cameras.items():  # as a factory calibration would come
            calibration = out_dir / f"{name}_calibration.yaml"
            write_calibration(calibration, info.intrinsics)
            log(f"{name} camera calibration → {calibration}")
    console_source = console_server = console_task = None
    if console is not None:
        from autopilot.api import parse_address
        from autopilot.api_server import ApiServer
        from autopilot.console.sim import SimConsoleSource

        console_source = SimConsoleSource(vehicle, config, title)
        console_host, console_port = parse_address(console)
        console_server = ApiServer(console_source, console_host, console_port, console_token,
                                   console=console_source)
        console_source.start()
        console_task = loop.create_task(console_server.run(), name="sim-console")
        await console_server.started.wait()
        if on_console is not None:
            on_console(console_server)
        log(f"console on http://{console_host}:{console_server.bound_port}/ (watching)")
    try:
        await face.start()
        for name, url in (videos or {}).items():
            if name not in vehicle.cameras:
                log(f"no camera {name!r} on this vehicle (it has: "
                    f"{', '.join(vehicle.cameras) or 'none'}): not streamed")
                continue
            streams.append(loop.create_task(stream_video(vehicle, name, url, log),
                                            name=f"video-{name}"))
            log(f"{name} camera: H.264 over RTP to {url} "
                "(RTP timestamps are capture times on the vehicle's boot clock)")
        if handle_signals:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, stop.set)
        log(face.describe(host))
        await stop.wait()
        log("stopping")
        await _land_if_flying(vehicle, log)
    finally:
        if handle_signals:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)
        if console_server is not None:
            await console_server.stop(graceful=False)
            await console_source.close()
        await cancel_all(t for t in (*streams, events, ready, truth, photos, console_task)
                         if t is not None)
        await face.close()
        await vehicle.close()
        if truth_log is not None:
            truth_log.close()


async def record_truth(vehicle: SimDriver, out_dir: Path,
                       log: Callable[[str], None]) -> tuple[FlightLog, asyncio.Task]:
    """Record the vehicle's ground truth and its true cameras into ``out_dir/truth.mcap`` (on
    its boot clock, for ``autopilot score``) until the returned task is cancelled; close the
    log after it."""
    await asyncio.to_thread(out_dir.mkdir, parents=True, exist_ok=True)
    truth_log = FlightLog(out_dir / TRUTH_LOG)
    # the cameras as they really are (the realistic world's calibration and mount errors), so
    # that a detection is scored where the target truly appeared, not where the nominal
    # camera the autopilot was given would put it
    for camera in vehicle.true_cameras().values():
        truth_log.write(ch.CAMERA_TRUTH, vehicle.sim_time_s, ch.camera_info_record(camera))

    async def log_truth() -> None:
        async with contextlib.aclosing(vehicle.ground_truth()) as samples:
            async for gt in samples:
                truth_log.write(ch.GROUND_TRUTH, gt.time_s, ch.ground_truth_record(gt))

    task = asyncio.get_running_loop().create_task(log_truth(), name="sim-truth")
    log(f"ground truth → {out_dir / TRUTH_LOG}")
    return truth_log, task


async def announce_ready(vehicle: SimDriver, say: Callable[[float, str], None]) -> None:
    """Say :data:`READY` each time the vehicle becomes armable (its preflight checks pass)
    while disarmed: at boot, and again after a failure that stopped it from arming cleared."""
    was_ready = False
    async with contextlib.aclosing(vehicle.telemetry(buffer=1)) as states:
        async for state in states:
            ready = state.health.armable and not state.armed
            if ready and not was_ready:
                say(state.time_s, READY)
            was_ready = ready or state.armed


def with_instance_id(sim: SimConfig, instance: int,
                     face_class: type[MavlinkFace] = MavlinkFace) -> SimConfig:
    """The parameters instance ``instance`` boots with (PX4 SITL: MAV_SYS_ID i + 1;
    ArduCopter SITL: SYSID_THISMAV stays 1), unless configured."""
    given = face_class.instance_params(instance)
    return sim.model_copy(update={"params": {**given, **sim.params}})


async def save_photos(vehicle: SimDriver, folder: Path, log: Callable[[str], None]) -> None:
    """Write each photo the vehicle takes (mission camera items, trigger distance, camera
    commands) into ``folder``, geotagged, off the event loop."""
    index = PhotoIndex(folder)
    boot_wall = time.time() - vehicle.clock.now()  # the vehicle's boot clock on the calendar
    async with contextlib.aclosing(vehicle.photos()) as stream:
        async for photo in stream:
            record = {
                "index": photo.index, "time_s": photo.time_s, "lat_deg": photo.lat_deg,
                "lon_deg": photo.lon_deg, "alt_amsl_m": photo.alt_amsl_m,
                "height_above_home_m": photo.height_above_home_m,
                "position_ned_m": [float(v) for v in photo.position_ned_m],
                "attitude_q": [float(v) for v in photo.attitude_q],
                "yaw_deg": math.degrees(yaw_from_quat(photo.attitude_q)) % 360.0,
                "camera": photo.frame.camera.name if photo.frame is not None else None}
            taken = dt.datetime.fromtimestamp(boot_wall + photo.time_s, dt.UTC)
            image = photo.frame.image if photo.frame is not None else None
            try:
                path = await asyncio.to_thread(index.add, image, record, taken)
            except OSError as exc:  # a full disk stops the photos, not the vehicle
                log(f"photos stopped: {exc}")
                return
            where = f"{photo.lat_deg:.7f}, {photo.lon_deg:.7f}, {photo.alt_amsl_m:.1f} m AMSL"
            log(f"photo {photo.index} → {path.name if path else '(no camera)'} ({where})")


async def stream_video(vehicle: SimDriver, camera: str, url: str,
                       log: Callable[[str], None]) -> None:
    """Encode and send ``camera``'s frames as they come; a frame that arrives while the
    previous one is still encoding replaces any older waiting one (newest only)."""
    loop = asyncio.get_running_loop()
    info = vehicle.cameras[camera]
    executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="video-encode")
    intr = info.intrinsics
    sender: VideoSender | None = None
    sim = vehicle.simulator

    def drop() -> bool:  # a link_loss fault's video_fraction
        return bool(sim.faults) and sim.faults.video_lost(sim.fault_time_s())

    try:
        sender = await loop.run_in_executor(
            executor, lambda: VideoSender(url, intr.width_px, intr.height_px, info.rate_hz,
                                          capture_clock=vehicle.clock.now, drop=drop))
        async with contextlib.aclosing(vehicle.frames(camera)) as frames:
            async for frame in frames:
                await loop.run_in_executor(executor, sender.send, frame.image, frame.time_s)
    except VehicleError:
        return
    except Exception as exc:  # the vehicle flies on without video
        log(f"video stream stopped: {type(exc).__name__}: {exc}")
    finally:
        if sender is not None:
            await asyncio.shield(loop.run_in_executor(executor, sender.close))
        executor.shutdown(wait=False)


async def _land_if_flying(vehicle: SimDriver, log: Callable[[str], None]) -> None:
    state = vehicle.latest_state
    if state is None or not state.armed:
        return
    log("vehicle still armed: landing before exit")
    with contextlib.suppress(VehicleError):
        if state.in_air and state.mode is not FlightMode.LAND:
            await vehicle.land()

    try:
        await wait_for_state(vehicle, lambda s: not s.armed, LAND_ON_EXIT_TIMEOUT_S, "disarm")
    except TimeoutError:
        log(f"not disarmed within {LAND_ON_EXIT_TIMEOUT_S:g} s; stopping the motors")
        with contextlib.suppress(VehicleError):
            await vehicle.disarm(force=True)
