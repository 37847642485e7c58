"""``autopilot bench perception``: each detector on frames the simulator renders from known
poses, scored against ground truth.

The camera is the front camera as configured (``config.yaml``: realistic — lens distortion,
read noise, motion blur from the vehicle's motion during the exposure), and each detector is
built from the configuration exactly as the autopilot builds it
(:func:`autopilot.perception.ball_pipeline.detector_settings`,
:func:`autopilot.perception.marker_pipeline.detector_settings`). The scene stands still; the
vehicle is posed (teleported) for every frame so that the target appears at a chosen distance,
place in the image and, for a marker, obliquity, and is given a random angular and linear
velocity (the motion blur a hovering, tracking vehicle sees; ``BenchOptions``). Every random
choice comes from fixed seeds: two runs give the same figures, apart from the times.

* ``marker``: the configured marker (seed 002: ArUco ``DICT_ARUCO_ORIGINAL`` id 36, 16 cm) at
  1, 3 and 5 m, each at obliquities 0, 20, 40 and 60° (the angle between the marker's normal
  and the line of sight; the tilt's direction random), the camera rolled at random (±45°: every
  direction of the marker's edges) and the marker anywhere in the image. Per distance, and per
  obliquity within it: detection rate, position error (and its parts along the line of sight,
  ``range``, and across it, ``lateral``), orientation error, and the time per frame searching
  the whole frame and a window around where a tracker would expect the marker (here: the true
  position). The project's figure: median position error at 3 m ≤ 1 cm.
* ``ball``: the configured ball at 1-8 m anywhere in the image, the camera level within ±10°:
  centre error against the true centre projected through the lens
  (:func:`drivers.camera_model.project_points`), range error, detection rate, time per frame.

Times are this machine's (one detection at a time, OpenCV's own threads as configured) and
vary with its load; the hypervisor's share of the CPU during the run is reported with them.
Detectors are registered in :data:`BENCHES`; a new one adds a :class:`DetectorBench`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from autopilot.bench.detectors import (
    BENCHES,
    DEFAULT_OPTIONS,
    QUICK_OPTIONS,
    BenchOptions,
    DetectorBench,
    num,
    percentile,
    register,
)
from autopilot.config import AppConfig, load_config
from autopilot.perception import ball_pipeline, marker_pipeline
from autopilot.perception.ball import BallDetector
from autopilot.perception.colors import COLORS
from autopilot.perception.marker import MarkerDetector, MarkerHint, rotation_angle
from autopilot.process import StealMeter
from drivers.base import CameraInfo
from drivers.camera_model import project_points, undistort_points
from drivers.geometry import matrix_to_quat, quat_from_euler, quat_to_matrix
from drivers.sim.scenario import (
    Geom,
    MarkerBoard,
    MocapBody,
    Static,
    marker_in_camera,
    marker_rotation_ned,
)
from drivers.sim.simulator import Simulator

CAMERA = "front"
MARKER_DISTANCES_M = (1.0, 3.0, 5.0)
MARKER_OBLIQUITIES_DEG = (0, 20, 40, 60)
BALL_DISTANCES_M = (1.0, 2.0, 4.0, 6.0, 8.0)
#: The project's required figure: median marker position error at 3 m.
MARKER_AT_3M_MAX_POSITION_ERROR_M = 0.01
#: The camera is never posed lower than this above the ground (m).
_MIN_CAMERA_HEIGHT_M = 0.5
#: The scene: the marker's centre and the ball this high above the ground (m).
_MARKER_HEIGHT_M = 3.0
_BALL_HEIGHT_M = 2.0


def run_bench(log: Callable[[str], None] = lambda message: None, quick: bool = False,
              detectors: Sequence[str] | None = None, config: AppConfig | None = None,
              options: BenchOptions | None = None) -> dict:
    """Run the detectors' benches (all registered ones by default) and return one JSON-ready
    dict: the camera, the options, and a section per detector (``ball``, ``marker``)."""
    cfg = config or load_config()
    opts = options or (QUICK_OPTIONS if quick else DEFAULT_OPTIONS)
    names = list(BENCHES) if detectors is None else list(detectors)
    unknown = [n for n in names if n not in BENCHES]
    if unknown:
        raise ValueError(f"no perception bench {unknown[0]!r} (known: {', '.join(BENCHES)})")
    cam = cfg.sim.cameras[CAMERA]
    steal = StealMeter()
    started = time.perf_counter()
    result: dict = {
        "bench": "perception",
        "quick": quick,
        "options": asdict(opts),
        "camera": {"name": CAMERA, "width_px": cam.width_px, "height_px": cam.height_px,
                   "hfov_deg": cam.hfov_deg, "realistic": cam.realistic,
                   "distortion": list(cam.distortion), "noise_std_dn": cam.noise_std_dn,
                   "exposure_s": cam.exposure_s, "rolling_shutter_s": cam.rolling_shutter_s},
    }
    for name in names:
        t0 = time.perf_counter()
        section = BENCHES[name].run(cfg, opts, log)
        section["wall_time_s"] = time.perf_counter() - t0
        result[name] = section
    result["wall_time_s"] = time.perf_counter() - started
    result["cpu_steal_pct"] = steal.percent()
    return result


def format_table(result: dict) -> str:
    cam = result["camera"]
    lines = [f"camera {cam['name']} {cam['width_px']}×{cam['height_px']} "
             f"{cam['hfov_deg']:g}° ({'realistic' if cam['realistic'] else 'ideal'}: "
             f"noise {cam['noise_std_dn']:g} DN, exposure {cam['exposure_s'] * 1e3:g} ms)"
             f"{', quick' if result.get('quick') else ''}"]
    for name, bench in BENCHES.items():
        if name in result:
            lines.append("")
            lines.extend(bench.table(result[name]))
    steal = result.get("cpu_steal_pct")
    lines.append("")
    lines.append(f"{result['wall_time_s']:.0f} s"
                 + ("" if steal is None else f"; hypervisor steal {steal:.1f} %"))
    return "\n".join(lines)


# -- shared ------------------------------------------------------------------------------------


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _ray(camera: CameraInfo, u_px: float, v_px: float) -> np.ndarray:
    """The unit direction (optical frame) of a pixel of the distorted image."""
    x, y = undistort_points(camera.intrinsics, (u_px, v_px))
    return _unit(np.array([x, y, 1.0]))


def _rotation_onto(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The shortest rotation taking unit vector ``a`` onto unit vector ``b``."""
    axis = np.cross(a, b)
    s, c = float(np.linalg.norm(axis)), float(a @ b)
    if s < 1e-12:
        return np.eye(3)
    k = axis / s
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + s * kx + (1.0 - c) * kx @ kx


def _looking(direction_ned: np.ndarray, roll_rad: float) -> np.ndarray:
    """``R_ned_cam`` of a camera looking along ``direction_ned``, its image's x axis
    horizontal, then rolled about the line of sight."""
    z = _unit(direction_ned)
    x = np.cross((0.0, 0.0, 1.0), z)
    x = _unit(x) if np.linalg.norm(x) > 1e-9 else np.array([0.0, 1.0, 0.0])
    y = np.cross(z, x)
    c, s = math.cos(roll_rad), math.sin(roll_rad)
    return np.column_stack((x, y, z)) @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _pose_camera(sim: Simulator, camera: CameraInfo, r_ned_cam: np.ndarray,
                 camera_ned_m: np.ndarray, rng: np.random.Generator,
                 options: BenchOptions) -> None:
    """Put the vehicle where its camera has this pose, moving as ``options`` say."""
    r_ned_body = r_ned_cam @ camera.rotation_body_cam.T
    body = camera_ned_m - r_ned_body @ camera.position_body_m
    sim.set_vehicle_pose(body, matrix_to_quat(r_ned_body))
    rates_frd = rng.normal(0.0, options.rate_std_rad_s, 3)
    velocity_ned = rng.normal(0.0, options.speed_std_m_s, 3)
    # the free joint's velocity: linear in the world (ENU), angular in the body (FLU)
    free = int(np.flatnonzero(sim.model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)[0])
    dof = sim.model.jnt_dofadr[free]
    sim.data.qvel[dof:dof + 3] = (velocity_ned[1], velocity_ned[0], -velocity_ned[2])
    sim.data.qvel[dof + 3:dof + 6] = (rates_frd[0], -rates_frd[1], -rates_frd[2])


def _timed(call: Callable[[], object]) -> tuple[object, float]:
    t0 = time.perf_counter()
    out = call()
    return out, (time.perf_counter() - t0) * 1e3


# -- marker ------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _MarkerSample:
    obliquity_deg: int
    detected: bool
    position_error_m: float = math.nan
    range_error_m: float = math.nan  # signed: measured minus true distance
    lateral_error_m: float = math.nan
    orientation_error_deg: float = math.nan
    ambiguous: bool = False
    time_ms: float = math.nan
    window_time_ms: float = math.nan
    window_detected: bool = False
    size_px: float = math.nan


def _marker_view(rng: np.random.Generator, camera: CameraInfo, distance_m: float,
                 obliquity_deg: float, size_m: float, marker_ned_m: np.ndarray,
                 r_ned_marker: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A camera pose (``R_ned_cam``, position NED) seeing the marker at ``distance_m``, at
    ``obliquity_deg`` in a random direction, anywhere in the image, rolled at random."""
    intr = camera.intrinsics
    margin = 0.75 * intr.fx * size_m / distance_m + 8.0  # half the diagonal, and some
    u = rng.uniform(margin, intr.width_px - 1 - margin)
    v = rng.uniform(margin, intr.height_px - 1 - margin)
    roll = math.radians(rng.uniform(-45.0, 45.0))
    theta = math.radians(obliquity_deg)
    normal, right, up = r_ned_marker[:, 2], r_ned_marker[:, 0], r_ned_marker[:, 1]
    for _ in range(1000):
        psi = rng.uniform(0.0, 2.0 * math.pi)
        towards_camera = math.cos(theta) * normal + math.sin(theta) * (
            math.cos(psi) * right + math.sin(psi) * up)
        position = marker_ned_m + distance_m * towards_camera
        if -position[2] >= _MIN_CAMERA_HEIGHT_M:
            break
    else:  # pragma: no cover - the marker stands high enough for every distance benched
        raise RuntimeError("no camera position above the ground")
    ray = _ray(camera, u, v)
    # the level camera looking at the marker, turned so that the marker is seen along the ray
    r_ned_cam = _looking(-towards_camera, roll) @ _rotation_onto(ray, np.array([0.0, 0.0, 1.0]))
    return r_ned_cam, position


def _run_marker(cfg: AppConfig, options: BenchOptions, log: Callable[[str], None]) -> dict:
    settings = marker_pipeline.detector_settings(cfg)
    detector = MarkerDetector(settings)
    board = MarkerBoard("marker", settings.marker_id,
                        Static((0.0, 0.0, -_MARKER_HEIGHT_M)), dictionary=settings.dictionary,
                        size_m=settings.size_m, facing="fixed", yaw_deg=0.0)
    sim = Simulator(cfg.sim, scenario=[board])
    section: dict = {"detector": {"marker_id": settings.marker_id, "size_m": settings.size_m,
                                  "dictionary": settings.dictionary,
                                  "backend": settings.backend,
                                  "corner_refinement": settings.corner_refinement}}
    try:
        camera = sim.camera_infos()[CAMERA]
        truth0 = sim.ground_truth().bodies["marker"]
        r_ned_marker = marker_rotation_ned(truth0.attitude_q)
        marker_ned = np.asarray(truth0.position_ned_m, dtype=float)
        detector.detect(sim.capture(CAMERA).image, camera, 0.0)  # warm-up (not scored)
        for distance in MARKER_DISTANCES_M:
            samples: list[_MarkerSample] = []
            for obliquity in MARKER_OBLIQUITIES_DEG:
                rng = np.random.default_rng((options.seed, 1, int(distance * 1000), obliquity))
                for _ in range(options.marker_frames):
                    r_ned_cam, position = _marker_view(rng, camera, distance, obliquity,
                                                       settings.size_m, marker_ned,
                                                       r_ned_marker)
                    _pose_camera(sim, camera, r_ned_cam, position, rng, options)
                    frame = sim.capture(CAMERA)
                    truth = sim.ground_truth()
                    samples.append(_score_marker(detector, frame, truth, camera, obliquity,
                                                 settings.size_m))
            key = f"at_{distance:g}m"
            section[key] = {"distance_m": distance, **_marker_stats(samples),
                            "by_obliquity": {
                                str(o): _marker_stats([s for s in samples
                                                       if s.obliquity_deg == o])
                                for o in MARKER_OBLIQUITIES_DEG}}
            s = section[key]
            log(f"marker at {distance:g} m: detected {s['detection_rate']:.2f}, position "
                f"error p50 {_mm(s['position_error_m_p50'])} mm")
    finally:
        sim.close()
    p50 = section["at_3m"]["position_error_m_p50"]
    section["required"] = {
        "at_3m.position_error_m_p50": {
            "max": MARKER_AT_3M_MAX_POSITION_ERROR_M, "value": p50,
            "met": p50 is not None and p50 <= MARKER_AT_3M_MAX_POSITION_ERROR_M}}
    return section


def _score_marker(detector: MarkerDetector, frame, truth, camera: CameraInfo,
                  obliquity: int, size_m: float) -> _MarkerSample:
    position, rotation = marker_in_camera(truth.bodies["marker"], truth.vehicle, camera)
    det, ms = _timed(lambda: detector.detect(frame.image, camera, frame.time_s))
    centre = project_points(camera.intrinsics, position)
    hint = MarkerHint((float(centre[0]), float(centre[1])),
                      camera.intrinsics.fx * size_m / float(np.linalg.norm(position)))
    windowed, window_ms = _timed(lambda: detector.detect(frame.image, camera, frame.time_s,
                                                         hint))
    if det is None:
        return _MarkerSample(obliquity, False, time_ms=ms, window_time_ms=window_ms,
                             window_detected=windowed is not None)
    error = det.position_cam_m - position
    along = _unit(position)
    return _MarkerSample(
        obliquity, True,
        position_error_m=float(np.linalg.norm(error)),
        range_error_m=float(np.linalg.norm(det.position_cam_m) - np.linalg.norm(position)),
        lateral_error_m=float(np.linalg.norm(error - (error @ along) * along)),
        orientation_error_deg=math.degrees(rotation_angle(det.rotation_cam_marker, rotation)),
        ambiguous=det.ambiguous, time_ms=ms, window_time_ms=window_ms,
        window_detected=windowed is not None and windowed.window is not None,
        size_px=det.size_px)


def _marker_stats(samples: Sequence[_MarkerSample]) -> dict:
    found = [s for s in samples if s.detected]
    pos = [s.position_error_m for s in found]
    rng = [s.range_error_m for s in found]
    lat = [s.lateral_error_m for s in found]
    ori = [s.orientation_error_deg for s in found]
    return {
        "frames": len(samples),
        "detected": len(found),
        "detection_rate": len(found) / len(samples) if samples else None,
        "position_error_m_p50": percentile(pos, 50),
        "position_error_m_p95": percentile(pos, 95),
        "range_error_m_p50": percentile(np.abs(rng), 50),
        "range_error_m_p95": percentile(np.abs(rng), 95),
        "range_bias_m": percentile(rng, 50),
        "lateral_error_m_p50": percentile(lat, 50),
        "lateral_error_m_p95": percentile(lat, 95),
        "orientation_error_deg_p50": percentile(ori, 50),
        "orientation_error_deg_p95": percentile(ori, 95),
        "ambiguous_rate": (sum(s.ambiguous for s in found) / len(found)) if found else None,
        "size_px_p50": percentile([s.size_px for s in found], 50),
        "time_per_frame_ms_p50": percentile([s.time_ms for s in samples], 50),
        "time_per_frame_ms_p95": percentile([s.time_ms for s in samples], 95),
        "window_time_per_frame_ms_p50": percentile([s.window_time_ms for s in samples], 50),
        "window_detection_rate": (sum(s.window_detected for s in samples) / len(samples))
        if samples else None,
    }


def _mm(value: float | None) -> str:
    return "—" if value is None else f"{value * 1e3:.1f}"


def _marker_table(section: dict) -> list[str]:
    d = section["detector"]
    lines = [f"marker: {d['dictionary']} id {d['marker_id']}, {d['size_m'] * 100:g} cm, "
             f"{d['backend']} / {d['corner_refinement']}",
             f"  {'':<10}{'frames':>7}{'found':>7}{'px':>6}{'pos p50':>9}{'p95':>7}"
             f"{'range':>7}{'lat.':>6}{'orient p50':>11}{'p95':>6}{'ms':>6}{'window':>7}",
             f"  {'':<10}{'':>7}{'':>7}{'':>6}{'mm':>9}{'mm':>7}{'mm':>7}{'mm':>6}"
             f"{'°':>11}{'°':>6}{'p50':>6}{'ms':>7}"]

    def row(label: str, s: dict) -> str:
        return (f"  {label:<10}{s['frames']:>7}{num(s['detection_rate'], '.2f'):>7}"
                f"{num(s['size_px_p50'], '.0f'):>6}"
                f"{_mm(s['position_error_m_p50']):>9}{_mm(s['position_error_m_p95']):>7}"
                f"{_mm(s['range_error_m_p50']):>7}{_mm(s['lateral_error_m_p50']):>6}"
                f"{num(s['orientation_error_deg_p50'], '.2f'):>11}"
                f"{num(s['orientation_error_deg_p95'], '.1f'):>6}"
                f"{num(s['time_per_frame_ms_p50'], '.1f'):>6}"
                f"{num(s['window_time_per_frame_ms_p50'], '.1f'):>7}")

    for distance in MARKER_DISTANCES_M:
        s = section.get(f"at_{distance:g}m")
        if s is None:
            continue
        lines.append(row(f"{distance:g} m", s))
        for obliquity, sub in s["by_obliquity"].items():
            lines.append(row(f"  {obliquity}°", sub))
    req = section["required"]["at_3m.position_error_m_p50"]
    lines.append(f"  required: median position error at 3 m ≤ {req['max'] * 1e3:g} mm: "
                 f"{_mm(req['value'])} mm, {'met' if req['met'] else 'NOT MET'}")
    return lines


# -- ball --------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _BallSample:
    detected: bool
    centre_error_px: float = math.nan
    range_error_m: float = math.nan  # signed
    range_m: float = math.nan
    time_ms: float = math.nan


def _run_ball(cfg: AppConfig, options: BenchOptions, log: Callable[[str], None]) -> dict:
    settings = ball_pipeline.detector_settings(cfg)
    detector = BallDetector(settings)
    ball = cfg.perception.ball
    rgba = COLORS[ball.color][0] if ball.color in COLORS else (1.0, 0.42, 0.0, 1.0)
    ball_ned = np.array([0.0, 0.0, -_BALL_HEIGHT_M])
    sim = Simulator(cfg.sim, scenario=[
        MocapBody("ball", [Geom("sphere", (settings.diameter_m / 2.0,), rgba)],
                  Static(tuple(ball_ned)))])
    section: dict = {"detector": {"color": ball.color, "diameter_m": settings.diameter_m}}
    try:
        camera = sim.camera_infos()[CAMERA]
        intr = camera.intrinsics
        detector.detect(sim.capture(CAMERA).image, camera, 0.0)  # warm-up (not scored)
        everything: list[_BallSample] = []
        for distance in BALL_DISTANCES_M:
            rng = np.random.default_rng((options.seed, 2, int(distance * 1000)))
            samples = []
            radius_px = intr.fx * settings.diameter_m / 2.0 / distance
            margin = radius_px + 4.0
            for _ in range(options.ball_frames):
                for _ in range(1000):
                    u = rng.uniform(margin, intr.width_px - 1 - margin)
                    v = rng.uniform(margin, intr.height_px - 1 - margin)
                    r_ned_cam = _looking(
                        np.array([1.0, 0.0, 0.0]), 0.0)  # level, looking north; then turned:
                    turn = quat_to_matrix(quat_from_euler(*np.radians(
                        [rng.uniform(-10, 10), rng.uniform(-10, 10), rng.uniform(-180, 180)])))
                    r_ned_cam = turn @ r_ned_cam
                    position = ball_ned - r_ned_cam @ (distance * _ray(camera, u, v))
                    if -position[2] >= _MIN_CAMERA_HEIGHT_M:
                        break
                _pose_camera(sim, camera, r_ned_cam, position, rng, options)
                frame = sim.capture(CAMERA)
                truth = sim.ground_truth()
                samples.append(_score_ball(detector, frame, truth, camera, ball_ned))
            everything.extend(samples)
            section[f"at_{distance:g}m"] = {"distance_m": distance, **_ball_stats(samples)}
            s = section[f"at_{distance:g}m"]
            log(f"ball at {distance:g} m: detected {s['detection_rate']:.2f}, centre error "
                f"p50 {num(s['centre_error_px_p50'], '.2f')} px")
        section["all"] = _ball_stats(everything)
    finally:
        sim.close()
    return section


def _score_ball(detector: BallDetector, frame, truth, camera: CameraInfo,
                ball_ned: np.ndarray) -> _BallSample:
    r_ned_body = quat_to_matrix(truth.vehicle.attitude_q)
    p_cam = camera.rotation_body_cam.T @ (
        r_ned_body.T @ (ball_ned - truth.vehicle.position_ned_m) - camera.position_body_m)
    u, v = project_points(camera.intrinsics, p_cam)
    det, ms = _timed(lambda: detector.detect(frame.image, camera, frame.time_s))
    distance = float(np.linalg.norm(p_cam))
    if det is None:
        return _BallSample(False, range_m=distance, time_ms=ms)
    return _BallSample(True, centre_error_px=math.hypot(det.u_px - u, det.v_px - v),
                       range_error_m=det.range_m - distance, range_m=distance, time_ms=ms)


def _ball_stats(samples: Sequence[_BallSample]) -> dict:
    found = [s for s in samples if s.detected]
    centre = [s.centre_error_px for s in found]
    rng = np.abs([s.range_error_m for s in found])
    pct = [100.0 * abs(s.range_error_m) / s.range_m for s in found]
    return {
        "frames": len(samples),
        "detected": len(found),
        "detection_rate": len(found) / len(samples) if samples else None,
        "centre_error_px_p50": percentile(centre, 50),
        "centre_error_px_p95": percentile(centre, 95),
        "range_error_m_p50": percentile(rng, 50),
        "range_error_m_p95": percentile(rng, 95),
        "range_error_pct_p50": percentile(pct, 50),
        "range_error_pct_p95": percentile(pct, 95),
        "range_bias_m": percentile([s.range_error_m for s in found], 50),
        "time_per_frame_ms_p50": percentile([s.time_ms for s in samples], 50),
        "time_per_frame_ms_p95": percentile([s.time_ms for s in samples], 95),
    }


def _ball_table(section: dict) -> list[str]:
    d = section["detector"]
    lines = [f"ball: {d['color']}, {d['diameter_m'] * 100:g} cm",
             f"  {'':<10}{'frames':>7}{'found':>7}{'centre p50':>11}{'p95':>6}"
             f"{'range p50':>10}{'p95':>6}{'p50':>7}{'p95':>6}{'ms':>6}",
             f"  {'':<10}{'':>7}{'':>7}{'px':>11}{'px':>6}{'m':>10}{'m':>6}{'%':>7}{'%':>6}"
             f"{'p50':>6}"]

    def row(label: str, s: dict) -> str:
        return (f"  {label:<10}{s['frames']:>7}{num(s['detection_rate'], '.2f'):>7}"
                f"{num(s['centre_error_px_p50'], '.2f'):>11}"
                f"{num(s['centre_error_px_p95'], '.2f'):>6}"
                f"{num(s['range_error_m_p50'], '.3f'):>10}"
                f"{num(s['range_error_m_p95'], '.3f'):>6}"
                f"{num(s['range_error_pct_p50'], '.1f'):>7}"
                f"{num(s['range_error_pct_p95'], '.1f'):>6}"
                f"{num(s['time_per_frame_ms_p50'], '.1f'):>6}")

    for distance in BALL_DISTANCES_M:
        s = section.get(f"at_{distance:g}m")
        if s is not None:
            lines.append(row(f"{distance:g} m", s))
    lines.append(row("all", section["all"]))
    return lines


register(DetectorBench("ball", _run_ball, _ball_table))
register(DetectorBench("marker", _run_marker, _marker_table))

# the down camera's detectors (image, pad) register themselves
import autopilot.bench.down_perception  # noqa: E402, F401  (it imports the registry, not this)
