"""Flying one mission: vehicle, runtime, flight log and summary, from a validated plan."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import datetime as dt
import gc
import json
import math
import signal
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from autopilot.api import parse_address
from autopilot.api_server import ApiServer
from autopilot.cameras import camera_setups, parse_camera_options
from autopilot.config import ConfigError, Problem
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import FlightLog
from autopilot.flightlog.metrics import latency_metrics
from autopilot.flightlog.records import clean
from autopilot.flightlog.safety import safety_metrics
from autopilot.goals import GoalManager
from autopilot.mission import MissionPlan
from autopilot.process import StealMeter, release_freed_memory
from autopilot.runtime import Runtime
from autopilot.steps.metrics import mission_metrics
from drivers.base import CameraUnavailable, Vehicle
from drivers.capabilities import DeadReckoning, LinkTimeSync, SimulatorTruth, VideoInput
from drivers.stages import STAGES
from drivers.threads import set_background_nice


def default_out_dir(plan: MissionPlan, root: Path = Path("runs")) -> Path:
    stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    path = root / f"{stamp}-{plan.mission.name}"
    n = 1
    while path.exists():
        n += 1
        path = root / f"{stamp}-{plan.mission.name}-{n}"
    return path




def make_vehicle(plan: MissionPlan, *, realtime: bool = False, connect: str | None = None,
                 video: str | Sequence[str] | None = None,
                 calibration: str | Path | Sequence[str] | None = None,
                 signing_key: Path | None = None,
                 warn: Callable[[str], None] | None = None) -> tuple[Vehicle, int | None]:
    """The vehicle the configuration's ``driver`` names (:mod:`autopilot.vehicle_kinds`), and
    the simulator's seed (if any).

    MAVLink drivers get each camera the mission uses as its own network video stream
    (:mod:`autopilot.cameras`: ``vehicle.cameras.NAME.video``, or ``video``), with the
    intrinsics of its calibration file (``calibration``, or ``vehicle.cameras.NAME.calibration``)
    or, uncalibrated, the nominal ones and a warning (passed to ``warn``). Everything given is
    checked here, before anything opens: a malformed URL or an unreadable key file is an input
    error (:class:`~autopilot.config.ConfigError`) that names the option and what was
    expected."""
    from autopilot.vehicle_kinds import DRIVER_KINDS

    kind = DRIVER_KINDS.get(plan.config.driver)
    if kind is None:
        raise ConfigError([Problem("config", None, "driver",
                                   f"unknown driver {plan.config.driver!r} "
                                   f"({', '.join(DRIVER_KINDS)})")])
    return kind.build(plan, realtime=realtime, connect=connect, video=video,
                      calibration=calibration, signing_key=signing_key, warn=warn)


def make_sim_vehicle(plan: MissionPlan, *, realtime: bool = False, calibration=None,
                     **_unused) -> tuple[Vehicle, int | None]:
    """The simulator in process (lockstep unless ``realtime``)."""
    from autopilot.scenario import build_world  # MuJoCo loads only when the simulator flies

    sim = with_calibrations(plan, calibration) if calibration else plan.config.sim
    sim_config, objects = build_world(plan.mission.scenario, sim, plan.config)
    vehicle_class, options = SIM_VEHICLES[sim_config.firmware](plan)
    return vehicle_class(sim_config, scenario=objects, lockstep=not realtime,
                         **options), sim_config.seed


def _px4_sim_vehicle(plan: MissionPlan) -> tuple[type, dict]:
    from drivers.sim.driver import SimDriver

    return SimDriver, {}


def _ardrone_sim_vehicle(plan: MissionPlan) -> tuple[type, dict]:
    from drivers.sim.ardrone_driver import SimArdroneDriver

    return SimArdroneDriver, {"navdata": plan.config.link.navdata,
                              "drone_config": plan.config.link.ardrone_config}


#: the in-process simulator's vehicle by firmware (``sim.firmware``), with its options: the
#: PX4-like one is the simulator's own driver; an AR.Drone is flown by the AR.Drone driver, in
#: process
def _ardupilot_sim_vehicle(plan: MissionPlan) -> tuple[type, dict]:
    from drivers.sim.arducopter_driver import SimArduCopterDriver

    return SimArduCopterDriver, {}


SIM_VEHICLES = {"px4": _px4_sim_vehicle, "ardupilot": _ardupilot_sim_vehicle,
                "ardrone": _ardrone_sim_vehicle}


def make_mavlink_vehicle(plan: MissionPlan, driver_class: type, *, connect: str | None = None,
                         video: str | Sequence[str] | None = None,
                         calibration: str | Path | Sequence[str] | None = None,
                         signing_key: Path | None = None,
                         warn: Callable[[str], None] | None = None,
                         **_unused) -> tuple[Vehicle, int | None]:
    """A MAVLink vehicle through ``driver_class`` (MAVSDK's or pymavlink's), its cameras as
    network streams."""
    from drivers.mavlink.link import Endpoint, UrlError
    from drivers.mavlink.signing import Signing, SigningKeyError
    from drivers.video import VideoSource

    link = plan.config.link
    url = connect or link.connect
    key = signing_key or (Path(link.signing_key) if link.signing_key else None)
    problems = []
    try:
        Endpoint.parse(url)
    except UrlError as exc:
        problems.append(Problem("command line", None, "--connect", str(exc)))
    used = plan.cameras_used()
    first = used[0] if used else None
    setups = []
    try:
        calibrations = [str(calibration)] if isinstance(calibration, Path) else calibration
        setups = camera_setups(
            plan.config, used,
            videos=parse_camera_options(video, "--video", first),
            calibrations=parse_camera_options(calibrations, "--calibration", first))
    except ConfigError as exc:
        problems += exc.problems
    signing = None
    if key is not None:
        try:
            signing = Signing.load(key)
        except SigningKeyError as exc:
            problems.append(Problem("command line", None, "--signing-key", str(exc)))
    if problems:
        raise ConfigError(problems)
    vehicle = driver_class(url, signing=signing)
    if link.rover_system_id is not None:  # a rover on the same link (land_on_rover)
        vehicle.rover_system_id = link.rover_system_id
        vehicle.rover_latency_s = link.rover_latency_s
    for setup in setups:
        if warn is not None and setup.warning():
            warn(setup.warning())
        vehicle.add_camera(VideoSource(setup.url, setup.info,
                                       to_local=vehicle.vehicle_time_to_local,
                                       clock=vehicle.clock.now,
                                       latency_s=setup.stream_latency_s,
                                       source=setup.video_source))
    vehicle.camera_setups = {setup.name: setup for setup in setups}
    return vehicle, None


def make_ardrone_vehicle(plan: MissionPlan, *, connect: str | None = None,
                         calibration: str | Path | Sequence[str] | None = None,
                         warn: Callable[[str], None] | None = None,
                         **_unused) -> tuple[Vehicle, int | None]:
    """A Parrot AR.Drone 2.0 over its SDK protocol (``ardrone://HOST``): its cameras the
    configuration's, with the intrinsics of their calibration files (``calibration``, or
    ``vehicle.cameras.NAME.calibration``) or, uncalibrated, the nominal ones and a warning."""
    from drivers.ardrone.driver import ArdroneDriver
    from drivers.ardrone.urls import ArdroneUrlError, parse_ardrone_url
    from drivers.calibration import CalibrationError, load_calibration
    from drivers.sim.model import camera_info

    url = connect or plan.config.link.connect
    problems = []
    try:
        parse_ardrone_url(url)
    except ArdroneUrlError as exc:
        problems.append(Problem("command line", None, "--connect", str(exc)))
    cameras = {name: camera_info(name, cam) for name, cam in plan.config.vehicle.cameras.items()
               if cam.enabled}
    used = plan.cameras_used()
    values = [str(calibration)] if isinstance(calibration, (str, Path)) else calibration
    files = {name: cam.calibration for name, cam in plan.config.vehicle.cameras.items()
             if cam.enabled and cam.calibration}
    try:
        files.update(parse_camera_options(values, "--calibration", used[0] if used else None))
    except ConfigError as exc:
        problems += exc.problems
    for name, file in files.items():
        if name not in cameras:
            problems.append(Problem("command line", None, "--calibration",
                                    f"{name}={file}: the AR.Drone has no camera {name!r}"))
            continue
        try:
            cameras[name] = dataclasses.replace(cameras[name],
                                                intrinsics=load_calibration(Path(file)))
        except CalibrationError as exc:
            problems.append(Problem("command line", None, "--calibration", str(exc)))
    if problems:
        raise ConfigError(problems)
    for name in used:
        if name not in files and warn is not None:
            warn(f"camera {name}: uncalibrated: the nominal pinhole of vehicle.cameras.{name} "
                 f"(calibrate it: autopilot calibrate, then --calibration {name}=FILE)")
    return ArdroneDriver(url, cameras=cameras, navdata=plan.config.link.navdata,
                         drone_config=plan.config.link.ardrone_config), None


def check_vehicle_can_fly(plan: MissionPlan, vehicle: Vehicle) -> None:
    """Refuse (:class:`~autopilot.config.ConfigError`, before anything opens or flies) a
    mission with a step that needs what this vehicle does not have (a survey's geotagged
    photos on a vehicle without GNSS), naming the step and the capability."""
    from drivers.capabilities import NEEDS, lacks

    problems = []
    for index, name, need in plan.needs():
        if lacks(vehicle, (need,)):
            problems.append(Problem(str(plan.source), None, f"steps[{index}].{name}", (
                f"needs {NEEDS[need][1]} ({need}), which this vehicle (driver "
                f"{plan.config.driver}) does not have")))
    if problems:
        raise ConfigError(problems)


async def check_vehicle_settings(plan: MissionPlan, vehicle: Vehicle) -> None:
    """Refuse, once connected and before anything flies, a mission with a step that needs what
    this vehicle's own settings keep it from (``vehicle_precland`` on an ArduCopter with
    PLND_ENABLED 0, whose LAND would land anywhere), naming the step and the setting."""
    from drivers.capabilities import settings_problem

    problems, asked = [], {}
    for index, name, need in plan.needs():
        if need not in asked:  # (once per need: a question may be a parameter read)
            asked[need] = await settings_problem(vehicle, need)
        problem = asked[need]
        if problem is not None:
            problems.append(Problem(str(plan.source), None, f"steps[{index}].{name}",
                                    f"needs {need}: {problem}"))
    if problems:
        raise ConfigError(problems)


def with_calibrations(plan: MissionPlan, calibration: str | Path | Sequence[str]):
    """The simulator's configuration with ``--calibration`` files as what its cameras report
    (as a real camera reports its calibration file): each checked now, by its option."""
    from drivers.calibration import CalibrationError, load_calibration

    sim = plan.config.sim
    used = plan.cameras_used()
    values = [str(calibration)] if isinstance(calibration, (str, Path)) else calibration
    cameras, problems = dict(sim.cameras), []
    for name, file in parse_camera_options(values, "--calibration",
                                           used[0] if used else None).items():
        cam = cameras.get(name)
        if cam is None or not cam.enabled:
            known = [n for n, c in cameras.items() if c.enabled]
            problems.append(Problem("command line", None, "--calibration",
                                    f"{name}={file}: the simulated vehicle has no camera "
                                    f"{name!r} (its cameras: {', '.join(known) or 'none'})"))
            continue
        try:
            load_calibration(Path(file))
        except CalibrationError as exc:
            problems.append(Problem("command line", None, "--calibration", str(exc)))
            continue
        cameras[name] = cam.model_copy(update={"calibration": str(file)})
    if problems:
        raise ConfigError(problems)
    return sim.model_copy(update={"cameras": cameras})


async def first_frame(vehicle: Vehicle, camera: str, timeout_s: float, where: str) -> None:
    """Wait for ``camera``'s first frame: a vehicle does not take off blind.
    :class:`~drivers.base.CameraUnavailable` if none comes within ``timeout_s``."""
    async with contextlib.aclosing(vehicle.frames(camera)) as frames:
        try:
            await vehicle.clock.wait_for(anext(frames), timeout_s)
        except (TimeoutError, StopAsyncIteration):
            source = vehicle.video_sources.get(camera) if isinstance(vehicle, VideoInput) \
                else None
            error = getattr(source, "error", None)
            detail = f" (last error: {error})" if error is not None else ""
            raise CameraUnavailable(
                f"no video from the {camera} camera on {where} within {timeout_s:g} s{detail}: "
                f"is the camera streaming to this address? (--video {camera}=URL; a camera on "
                f"another machine: --video {camera}=udp://0.0.0.0:PORT --set "
                f"vehicle.cameras.{camera}.video_source=CAMERA_IP)", "no_video") from None


def logged_cameras(plan: MissionPlan, video_camera: str,
                   cameras: Mapping[str, object]) -> dict[str, float]:
    """Frames logged per second by camera: the cameras the steps use at the configured rate,
    and every frame of the video's camera (``""``: the first step camera)."""
    cfg = plan.config
    used = plan.cameras_used()
    frames = cfg.log.frames
    rate = frames.sim_rate_hz if cfg.driver == "sim" else frames.vehicle_rate_hz
    rates = {camera: rate for camera in used}
    name = video_camera or (used[0] if used else next(iter(cameras), ""))
    if name not in cameras:
        raise ConfigError([Problem("--record-video", None, name,
                                   f"no such camera on this vehicle (it has: "
                                   f"{', '.join(sorted(cameras)) or 'none'})")])
    rates[name] = math.inf
    return rates


def flight_metrics(records: Mapping[str, Sequence[Mapping]], fence) -> dict:
    """The end-of-run metrics of a flight's records: the mission's (per step), the latency
    and the safety groups. Given a closed log's :meth:`FlightLog.read_back`, they read the
    file as they use it: what they hold is columns of the numbers they score, not the
    flight's records."""
    return {"mission": mission_metrics(records), "latency_ms": latency_metrics(records),
            "safety": safety_metrics(records, fence)}


async def fly(plan: MissionPlan, out_dir: Path | None, *, realtime: bool = False,
              progress: Callable[[str], None] | None = None,
              handle_signals: bool = False, connect: str | None = None,
              video: str | Sequence[str] | None = None,
              calibration: str | Path | Sequence[str] | None = None,
              record_video: str | None = None, signing_key: Path | None = None,
              api: str | None = None, api_token: str | None = None,
              on_api: Callable[[object], None] | None = None, console: bool = False,
              api_tls: tuple[str, str] | None = None, stages: bool = False) -> dict:
    """Fly ``plan`` and return its summary (also written to ``out_dir/summary.json``).

    ``stages``: count where the process's CPU time goes (:mod:`drivers.stages`), into the
    summary's ``stages``.

    ``record_video`` names a camera whose every frame is logged (for ``onboard.mp4``; "" is
    the followed camera). ``api`` (``HOST:PORT``) serves the goal API for the flight
    (:mod:`autopilot.api`; ``on_api`` is called with the server once it is created), with the
    operator console (:mod:`autopilot.console`) when ``console``, over HTTPS with ``api_tls``
    (certificate file, key file). Warnings
    (an uncalibrated camera) go to ``progress`` and into the summary."""
    warnings: list[str] = []

    def warn(text: str) -> None:
        warnings.append(text)
        if progress is not None:
            progress(f"warning: {text}")

    for text in plan.warnings:
        warn(text)
    set_background_nice(plan.config.runtime.background_nice)
    vehicle, seed = make_vehicle(plan, realtime=realtime, connect=connect, video=video,
                                 calibration=calibration, signing_key=signing_key, warn=warn)
    check_vehicle_can_fly(plan, vehicle)
    log_cameras = None
    if record_video is not None:
        log_cameras = logged_cameras(plan, record_video, vehicle.cameras)
    if out_dir is not None:
        await asyncio.to_thread(out_dir.mkdir, parents=True, exist_ok=True)
    log = FlightLog(out_dir / "flight.mcap" if out_dir is not None else None)
    if stages:
        STAGES.start()
    wall_start, cpu_start = time.perf_counter(), time.process_time()
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

    if handle_signals:  # from the start: a Ctrl-C while connecting stops the run as cleanly
        for sig in signals:
            loop.add_signal_handler(sig, on_signal, sig.name)
    try:
        await vehicle.connect(plan.config.link.connect_timeout_s if plan.config.driver != "sim"
                              else 10.0)
        await check_vehicle_settings(plan, vehicle)
        setups = vehicle.camera_setups if isinstance(vehicle, VideoInput) else {}
        for camera, setup in setups.items():  # the cameras the mission needs must be
            await first_frame(vehicle, camera,  # streaming before anything takes off
                              plan.config.link.connect_timeout_s, setup.url)
        goals = GoalManager(plan.config) if api is not None else None
        runtime = Runtime(vehicle, plan, log, progress=progress, log_cameras=log_cameras,
                          photos_dir=out_dir / "photos" if out_dir is not None else None,
                          goals=goals)
        if api is not None:
            host, port = parse_address(api)
            server = ApiServer(runtime.desk, host, port, api_token,
                               console=runtime.console if console else None, tls=api_tls)
            runtime.add_service(server)
            if on_api is not None:
                on_api(server)
            if progress is not None:
                scheme = server.scheme
                progress(f"console on {scheme}://{host}:{port}/ (goal API at /api, documented "
                         "at /docs)" if console else
                         f"goal API on {scheme}://{host}:{port}/api (documented at /docs)")
        mapping = asyncio.create_task(_log_time_mapping(vehicle, log), name="time-mapping") \
            if isinstance(vehicle, LinkTimeSync) else None
        try:
            status = await runtime.run()
        finally:
            if mapping is not None:
                mapping.cancel()
                await asyncio.gather(mapping, return_exceptions=True)
        reason = runtime.reason
    except asyncio.CancelledError:
        status, reason = "aborted", (
            f"{' then '.join(received) or 'cancelled'} before the flight started"
            if runtime is None else f"{' then '.join(received) or 'cancelled'}: forced exit")
        with contextlib.suppress(Exception):
            await asyncio.wait_for(vehicle.land(), 2.0)
    finally:
        if handle_signals:
            for sig in signals:
                loop.remove_signal_handler(sig)
        if isinstance(vehicle, LinkTimeSync):  # MAVLink: for scoring against the sim
            _write_time_mapping(vehicle, log)
        sim_time = vehicle.sim_time_s if isinstance(vehicle, SimulatorTruth) else None
        wall_time = time.perf_counter() - wall_start
        await vehicle.close()
        log.close()

    records = await asyncio.to_thread(log.read_back)  # (from the file, as they are used)
    try:
        metrics = await asyncio.to_thread(STAGES.call, "metrics", flight_metrics, records,
                                          plan.config.failsafe.geofence)
    except Exception as exc:  # e.g. a log damaged on disk: the flight still gets its summary
        warn(f"the flight's metrics could not be computed from its log "
             f"({type(exc).__name__}: {exc})")
        metrics = {"mission": {}, "latency_ms": {}, "safety": {}}
    summary = {
        "status": status,
        "reason": reason,
        "mission": plan.mission.name,
        "source": str(plan.source),
        "driver": plan.config.driver,
        "clock": "lockstep" if vehicle.clock.lockstep else "realtime",
        # the simulated world's profile (sim.profile); null: a real vehicle flew
        "sim": {"profile": plan.config.sim.profile} if plan.config.driver == "sim" else None,
        "seed": seed,
        "sim_time_s": sim_time,
        "wall_time_s": wall_time,
        "metrics": {
            **metrics["mission"],
            "sim": {"real_time_factor": sim_time / wall_time if sim_time and wall_time > 0
                    else None,
                    "cpu_steal_pct": steal.percent()},
            "latency_ms": metrics["latency_ms"],
            **({"safety": metrics["safety"]} if metrics["safety"] else {}),
        },
        # the signal that stopped the run (SIGINT: Ctrl-C, SIGTERM), if one did
        "signal": received[0] if received else None,
        # whether the vehicle was ever armed (a run stopped before takeoff flew nothing)
        "flown": runtime is not None and runtime.stats.armed,
        "stats": vars(runtime.stats) if runtime is not None else {},
        "mission_status": int(runtime.status_code) if runtime is not None else None,
        "goals": [g.as_dict() for g in runtime.goals.goals.values()]
        if runtime is not None and runtime.goals is not None else None,
        "photos": ({"taken": runtime.photos.taken, "folder": "photos" if out_dir else None,
                    "errors": runtime.photos.errors}
                   if runtime is not None and (runtime.photos.taken or runtime.photos.errors)
                   else None),
        "warnings": warnings,
        "log": "flight.mcap" if out_dir is not None else None,
    }
    if isinstance(vehicle, DeadReckoning):  # (no GNSS) how far off its position may be
        summary["dead_reckoning"] = {"drift_m": vehicle.drift_m, "path_m": vehicle.path_m}
    sources = vehicle.video_sources if isinstance(vehicle, VideoInput) else {}
    if sources:  # how each network camera's capture times were known, and what arrived
        summary["video"] = {name: {"timing": source.timing.as_dict(),
                                   "stats": dataclasses.asdict(source.stats)}
                            for name, source in sources.items()}
    if stages:
        from autopilot.bench.speed import stage_summary

        counted = STAGES.stop()
        summary["stages"] = stage_summary(counted, STAGES.threads(), sim_time, wall_time,
                                          time.process_time() - cpu_start,
                                          STAGES.run_queue_wait_s())
    if log.error is not None:
        summary["log_error"] = f"{type(log.error).__name__}: {log.error}"
    if runtime is not None:  # frames the log took, and those it had to drop
        summary["stats"]["frames_logged"] = log.images_written
        summary["stats"]["frames_log_dropped"] += log.images_dropped
    summary["stats"] = {k: v for k, v in summary["stats"].items() if not isinstance(v, list)}
    text = json.dumps(clean(summary), indent=2) + "\n"
    if out_dir is not None:
        (out_dir / "summary.json").write_text(text)
    del records, metrics, log, vehicle, summary
    # everything that holds the runtime, its frames or the vehicle (the signal handler's
    # closure too), so that the collection below frees them before the heap is trimmed
    runtime = server = goals = setups = sources = None
    await asyncio.sleep(0)  # (the loop's handle that woke this task still holds the records)
    gc.collect()
    # What outlives the flight is made again now that the flight's objects are freed: built
    # while they were alive, the summary's objects sat among them in Python's 1 MB object
    # arenas, and an arena is given back only when all of it is free: each flight's summary
    # (and what a caller keeps of it) would keep some of them for good.
    summary = json.loads(text)
    release_freed_memory()  # what the flight freed goes back to the system, not to the next
    return summary


#: how often a MAVLink run logs its mapping of the vehicle's clock (for scoring against a
#: simulator's truth, which a vehicle whose clock drifts or lags needs more than once)
TIME_MAPPING_EVERY_S = 1.0


def _write_time_mapping(vehicle, log) -> None:
    now = vehicle.clock.now()
    log.write(ch.TIME_SYNC, now, {"time_s": now, "vehicle_to_local_s": vehicle.vehicle_to_local_s,
                                  "round_trip_s": vehicle.time_sync_round_trip_s})


async def _log_time_mapping(vehicle, log) -> None:
    """The vehicle's clock mapping, every :data:`TIME_MAPPING_EVERY_S` while the run lasts."""
    while True:
        await asyncio.sleep(TIME_MAPPING_EVERY_S)
        if math.isfinite(vehicle.vehicle_to_local_s):
            _write_time_mapping(vehicle, log)
