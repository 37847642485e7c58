"""``autopilot bench sitl``: the simulator's speed and the flight stack's accuracy.

Takes off to 2 m, makes a 2 m position step north in OFFBOARD, hovers for 10 s and lands, with
the forward camera rendering throughout. Scores the step response and the hover against the
vehicle's own navigation (what the flight stack controls: its accuracy), and separately the
hover against ground truth (where the vehicle really is: the navigation's error included, a
few centimetres on RTK, decimetres on GNSS); reports rendering throughput and real-time factor.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from dataclasses import asdict, dataclass

import numpy as np

from autopilot.flight_ops import stream_setpoints, wait_for_state
from autopilot.process import StealMeter
from drivers.base import FlightMode, Setpoint
from drivers.sim.config import SimConfig
from drivers.sim.driver import SimDriver

TAKEOFF_ALTITUDE_M = 2.0
STEP_M = 2.0
SETTLE_BAND_M = 0.05
STEP_OBSERVE_S = 5.0  # after the step, before the hover window
HOVER_S = 10.0
SETPOINT_RATE_HZ = 50.0
CAMERA = "front"


@dataclass(frozen=True, slots=True)
class StepResponse:
    rise_time_s: float  # 10 % → 90 % of the step
    overshoot_pct: float  # beyond the target along the step, % of the step
    settle_time_s: float  # from the step until the error stays within SETTLE_BAND_M


@dataclass(frozen=True, slots=True)
class SitlBenchResult:
    lockstep: bool
    real_time_factor: float
    sim_time_s: float
    wall_time_s: float
    step_response: StepResponse
    hover_rms_m: float  # 3-D distance of the navigation's position from the setpoint (hover)
    hover_max_m: float
    hover_rms_truth_m: float  # ... of the true position (the navigation's error included)
    navigation_rms_m: float  # the navigation's 3-D error against truth over the hover
    camera: str | None  # None when the forward camera is disabled
    camera_resolution: str | None
    camera_frames: int
    camera_fps: float  # frames rendered and delivered per wall-clock second
    camera_fps_sim: float  # frames per simulated second (the camera's own rate)
    physics_rate_hz: int
    seed: int
    cpu_steal_pct: float | None  # CPU time the hypervisor took during the run (None: unknown)

    def to_dict(self) -> dict:
        return asdict(self)


def step_response(times_s: np.ndarray, along_m: np.ndarray, step_m: float,
                  band_m: float) -> StepResponse:
    """Metrics of a step from 0 to ``step_m`` starting at ``times_s[0]``.

    ``along_m`` is the displacement along the step direction. Crossing times are interpolated
    linearly between samples.
    """
    t = times_s - times_s[0]
    frac = along_m / step_m

    def crossing(level: float) -> float:
        idx = np.flatnonzero(frac >= level)
        if len(idx) == 0:
            return math.inf
        i = int(idx[0])
        if i == 0:
            return 0.0
        f0, f1 = frac[i - 1], frac[i]
        return float(t[i - 1] + (level - f0) / (f1 - f0) * (t[i] - t[i - 1]))

    rise = crossing(0.9) - crossing(0.1)
    overshoot = max(0.0, float(np.max(frac)) - 1.0) * 100.0
    outside = np.flatnonzero(np.abs(along_m - step_m) > band_m)
    if len(outside) == 0:
        settle = 0.0
    elif outside[-1] == len(t) - 1:
        settle = math.inf  # never settled within the observation window
    else:
        settle = float(t[outside[-1] + 1])
    return StepResponse(rise, overshoot, settle)


async def run_sitl_bench(config: SimConfig, *, lockstep: bool = True,
                         log=lambda message: None) -> SitlBenchResult:
    steal = StealMeter()
    driver = SimDriver(config, lockstep=lockstep)
    await driver.connect()
    clock = driver.clock
    truth: list[tuple[float, np.ndarray]] = []
    navigation: list[tuple[float, np.ndarray]] = []  # the vehicle's own estimate
    frames = 0
    cam = config.cameras.get(CAMERA)
    rendering = cam is not None and cam.enabled

    async def count_frames() -> None:
        nonlocal frames
        async with contextlib.aclosing(driver.frames(CAMERA)) as stream:
            async for _ in stream:
                frames += 1

    async def record_truth() -> None:
        async with contextlib.aclosing(driver.ground_truth()) as stream:
            async for sample in stream:
                truth.append((sample.time_s, sample.vehicle.position_ned_m))

    async def record_navigation() -> None:
        async with contextlib.aclosing(driver.telemetry(buffer=64)) as stream:
            async for state in stream:
                navigation.append((state.time_s, np.array(state.position_ned_m, dtype=float)))

    setpoint: Setpoint | None = None  # the bench's trivial "controller": a fixed target

    try:
        async with asyncio.TaskGroup() as tasks:
            background = [
                tasks.create_task(record_truth()),
                tasks.create_task(record_navigation()),
                tasks.create_task(stream_setpoints(driver, lambda: setpoint, SETPOINT_RATE_HZ)),
            ]
            if rendering:
                background.append(tasks.create_task(count_frames()))
            try:
                log("waiting for the vehicle to be armable")
                await wait_for_state(driver, lambda s: s.health.armable, 30.0, "armable")
                await driver.arm()
                log(f"armed; taking off to {TAKEOFF_ALTITUDE_M} m")
                await driver.takeoff(TAKEOFF_ALTITUDE_M)
                await wait_for_state(driver, lambda s: s.mode is FlightMode.HOLD and s.in_air,
                                     30.0, "takeoff to finish")
                await clock.sleep(2.0)
                start = driver.latest_state
                p0 = np.array(start.position_ned_m)
                yaw0 = start.yaw_rad
                setpoint = Setpoint.position(*p0, yaw_rad=yaw0)
                await clock.sleep(0.3)
                await driver.start_offboard()
                log("OFFBOARD; holding")
                await clock.sleep(2.0)
                target = p0 + np.array([STEP_M, 0.0, 0.0])
                t_step = clock.now()
                setpoint = Setpoint.position(*target, yaw_rad=yaw0)
                log(f"step {STEP_M} m north")
                await clock.sleep(STEP_OBSERVE_S + HOVER_S)
                t_end = clock.now()
                setpoint = None
                log("landing")
                await driver.land()
                await wait_for_state(driver, lambda s: not s.armed, 60.0, "landing and disarm")
            finally:
                for task in background:
                    task.cancel()
    finally:
        sim_time, wall_time = driver.sim_time_s, driver.wall_time_s
        await driver.close()

    # control is scored in the vehicle's own (estimated) frame, where its setpoints live
    times = np.array([t for t, _ in navigation])
    positions = np.array([p for _, p in navigation])
    sel = (times >= t_step) & (times <= t_end)
    along = positions[sel, 0] - p0[0]
    response = step_response(times[sel], along, STEP_M, SETTLE_BAND_M)
    hover = (times >= t_end - HOVER_S) & (times <= t_end)
    err = np.linalg.norm(positions[hover] - target, axis=1)
    true_t = np.array([t for t, _ in truth])
    true_p = np.array([p for _, p in truth])
    true_hover = (true_t >= t_end - HOVER_S) & (true_t <= t_end)
    err_truth = np.linalg.norm(true_p[true_hover] - target, axis=1)
    nav_at_truth = np.stack([np.interp(true_t[true_hover], times, positions[:, i])
                             for i in range(3)], axis=1)
    nav_err = np.linalg.norm(nav_at_truth - true_p[true_hover], axis=1)
    return SitlBenchResult(
        lockstep=lockstep,
        real_time_factor=sim_time / wall_time,
        sim_time_s=sim_time,
        wall_time_s=wall_time,
        step_response=response,
        hover_rms_m=float(np.sqrt(np.mean(err ** 2))),
        hover_max_m=float(np.max(err)),
        hover_rms_truth_m=float(np.sqrt(np.mean(err_truth ** 2))),
        navigation_rms_m=float(np.sqrt(np.mean(nav_err ** 2))),
        camera=CAMERA if rendering else None,
        camera_resolution=f"{cam.width_px}x{cam.height_px}" if rendering else None,
        camera_frames=frames,
        camera_fps=frames / wall_time,
        camera_fps_sim=frames / sim_time,
        physics_rate_hz=config.physics_rate_hz,
        seed=config.seed,
        cpu_steal_pct=steal.percent(),
    )


def format_table(result: SitlBenchResult) -> str:
    r = result
    s = r.step_response
    rows = [
        ("clock", "lockstep" if r.lockstep else "real time", ""),
        ("real-time factor", f"{r.real_time_factor:.2f}", "× (target ≥ 5, lockstep)"),
        ("simulated / wall time", f"{r.sim_time_s:.1f} / {r.wall_time_s:.1f}", "s"),
        ("step rise time (10–90 %)", f"{s.rise_time_s:.2f}", "s"),
        ("step overshoot", f"{s.overshoot_pct:.1f}", "% (target ≤ 10)"),
        ("step settle time (±5 cm)", f"{s.settle_time_s:.2f}", "s (target ≤ 3)"),
        ("hover RMS error", f"{r.hover_rms_m * 100:.1f}",
         "cm, against its navigation (target ≤ 5)"),
        ("hover max error", f"{r.hover_max_m * 100:.1f}", "cm"),
        ("hover RMS error, truth", f"{r.hover_rms_truth_m * 100:.1f}",
         "cm (the navigation's error included)"),
        ("navigation RMS error", f"{r.navigation_rms_m * 100:.1f}", "cm, over the hover"),
    ]
    if r.camera is None:
        rows.append(("camera", "off", ""))
    else:
        rows.append((f"camera {r.camera} {r.camera_resolution}", f"{r.camera_fps:.0f}",
                     f"frames per wall second ({r.camera_frames} frames, "
                     f"{r.camera_fps_sim:.1f}/sim s)"))
    if r.cpu_steal_pct is not None:
        rows.append(("hypervisor steal", f"{r.cpu_steal_pct:.1f}",
                     "% of CPU time (speed figures drop when this is above ~2 %)"))
    width = max(len(name) for name, _, _ in rows)
    return "\n".join(f"{name:<{width}}  {value:>10}  {unit}" for name, value, unit in rows)
