"""``autopilot bench perception`` for the down camera: the image detector (hover_image) and the
pad detector (land_pad), ours against the seed reports' (seed 000: ORB 300 + FLANN +
solvePnPRansac; seed 001: multi-scale TM_CCOEFF template matching), on frames the simulator
renders with the realistic down camera from known poses over gravel and grass.

The vehicle is posed 1, 3 and 8 m above the target (``image``: the generated default target,
1 m wide; ``pad``: the red disc, 0.8 m), offset from it by up to 15 % of the height each way,
tilted by up to 5°, at any heading; the same poses for both detectors. Per height and
detector: detection rate, position error of the target's centre in the camera frame against
the truth (the whole error, and across the line of sight: what a landing or a hover lives
with), and the time per frame. Registered in :data:`autopilot.bench.perception.BENCHES`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from autopilot.bench.detectors import BenchOptions, DetectorBench, num, percentile, register
from autopilot.config import AppConfig
from drivers.geometry import quat_from_euler, quat_to_matrix
from drivers.sim.scenario import FeatureGround, GroundImage
from drivers.sim.simulator import Simulator

HEIGHTS_M = (1.0, 3.0, 8.0)
CAMERA = "down"
WHERE = (2.0, 1.0)


def _frames(options: BenchOptions) -> int:
    return max(2, options.ball_frames // 2)


def _run(cfg: AppConfig, options: BenchOptions, log: Callable[[str], None], *, name: str,
         texture: np.ndarray, width_m: float, detectors: dict,
         with_range: str | None = None) -> dict:
    """``with_range``: also score that detector's circle laid on the ground with the true
    attitude and a rangefinder reading (what the pad pipeline flies on), as
    ``<name>+rangefinder`` (the reading: the true range, without noise)."""
    sim = Simulator(cfg.sim, scenario=[FeatureGround(seed=options.seed),
                                       GroundImage(name, texture, width_m, WHERE, 25.0)])
    rng = np.random.default_rng(options.seed)
    section: dict = {"target": name, "width_m": width_m, "frames_per_height": _frames(options)}
    try:
        camera = sim.camera_infos()[CAMERA]
        labels = [*detectors] + ([f"{with_range}+rangefinder"] if with_range else [])
        samples: dict[str, dict[float, list]] = {d: {h: [] for h in HEIGHTS_M}
                                                 for d in labels}
        for height in HEIGHTS_M:
            log(f"{name}: {height:g} m …")
            for _ in range(_frames(options)):
                offset = rng.uniform(-0.15, 0.15, 2) * height
                tilt = np.radians(rng.uniform(-5.0, 5.0, 2))
                sim.set_vehicle_pose(
                    np.array([WHERE[0] + offset[0], WHERE[1] + offset[1], -height]),
                    quat_from_euler(tilt[0], tilt[1], rng.uniform(-math.pi, math.pi)))
                frame = sim.capture(CAMERA)
                truth = sim.ground_truth()
                r = quat_to_matrix(truth.vehicle.attitude_q)
                p = camera.rotation_body_cam.T @ (
                    r.T @ (np.asarray(truth.bodies[name].position_ned_m)
                           - np.asarray(truth.vehicle.position_ned_m))
                    - camera.position_body_m)
                for label, detector in detectors.items():
                    t0 = time.perf_counter()
                    found = detector.detect(frame.image, camera, frame.time_s)
                    ms = (time.perf_counter() - t0) * 1e3
                    samples[label][height].append(_score(found, p, ms))
                    if label == with_range:
                        position = _on_ground(found, camera, truth, r, name)
                        samples[f"{label}+rangefinder"][height].append(_score(
                            None if position is None else _Found(position), p, ms))
    finally:
        sim.close()
    for label, by_height in samples.items():
        section[label] = {f"at_{h:g}m": _stats(s) for h, s in by_height.items()}
    return section


class _Found:
    def __init__(self, position_cam_m: np.ndarray) -> None:
        self.position_cam_m = position_cam_m


def _score(found, truth_cam: np.ndarray, ms: float) -> tuple:
    if found is None:
        return (False, None, None, ms)
    error = float(np.linalg.norm(found.position_cam_m - truth_cam))
    # across the line of sight: the centre's direction, at the true range
    direction = found.position_cam_m / np.linalg.norm(found.position_cam_m)
    lateral = float(np.linalg.norm(direction * np.linalg.norm(truth_cam) - truth_cam))
    return (True, error, lateral, ms)


def _on_ground(found, camera, truth, r_ned_body: np.ndarray, name: str) -> np.ndarray | None:
    """A circle detection laid on the ground (the rangefinder's range along the body's z
    axis), back in the camera frame."""
    from autopilot.estimation.pose_history import Pose
    from autopilot.perception.pad_pipeline import ground_fit

    if found is None:
        return None
    vehicle = np.asarray(truth.vehicle.position_ned_m)
    ground = float(truth.bodies[name].position_ned_m[2])
    pose = Pose(truth.time_s, vehicle, truth.vehicle.attitude_q)
    fit = ground_fit(found, camera, pose, (ground - vehicle[2]) / r_ned_body[2, 2])
    if fit is None:
        return None
    cam = vehicle + r_ned_body @ camera.position_body_m
    return camera.rotation_body_cam.T @ (r_ned_body.T @ (fit.centre_ned_m - cam))


def _stats(samples: list) -> dict:
    found = [s for s in samples if s[0]]
    return {
        "frames": len(samples),
        "detection_rate": len(found) / len(samples) if samples else None,
        "position_error_m_p50": percentile([s[1] for s in found], 50),
        "position_error_m_p95": percentile([s[1] for s in found], 95),
        "lateral_error_m_p50": percentile([s[2] for s in found], 50),
        "lateral_error_m_p95": percentile([s[2] for s in found], 95),
        "time_per_frame_ms_p50": percentile([s[3] for s in samples], 50),
    }


def _run_image(cfg: AppConfig, options: BenchOptions, log: Callable[[str], None]) -> dict:
    from autopilot.perception.baselines import Seed000ImageDetector
    from autopilot.perception.image_pipeline import detector_settings
    from autopilot.perception.image_target import ImageTargetDetector, default_target_image

    image = default_target_image()
    size_m = 1.0
    return _run(cfg, options, log, name="image", texture=image, width_m=size_m, detectors={
        "ours": ImageTargetDetector(image, detector_settings(cfg, size_m)),
        "seed000": Seed000ImageDetector(image, size_m)})


def _run_pad(cfg: AppConfig, options: BenchOptions, log: Callable[[str], None]) -> dict:
    from autopilot.perception.baselines import Seed001PadDetector
    from autopilot.perception.pad import pad_texture
    from autopilot.perception.pad_pipeline import make_detector, pad_target

    size_m = 0.8
    texture, width = pad_texture("circle", size_m, color="red")
    return _run(cfg, options, log, name="pad", texture=texture, width_m=width, detectors={
        "ours": make_detector(cfg, pad_target("circle", "red"), size_m, detector="ours"),
        "seed001": Seed001PadDetector("red", size_m)}, with_range="ours")


def _mm(value: float | None) -> str:
    return "—" if value is None else f"{value * 1e3:.1f}"


def _table(title: str, section: dict) -> list[str]:
    labels = [k for k in section if isinstance(section[k], dict) and "at_1m" in section[k]]
    width = max(16, max(len(k) for k in labels) + 7)
    lines = [title + " (errors in mm)",
             f"  {'':<{width}}{'frames':>7}{'found':>7}{'error p50':>10}{'p95':>7}"
             f"{'lateral p50':>12}{'p95':>7}{'ms p50':>8}{'error ÷ ours':>14}"
             f"{'lateral ÷ ours':>16}"]
    for h in HEIGHTS_M:
        key = f"at_{h:g}m"
        ours = section[labels[0]][key]
        for label in labels:
            s = section[label][key]
            ratios = [(s[k] / ours[k]) if ours[k] and s[k] is not None else None
                      for k in ("position_error_m_p50", "lateral_error_m_p50")]
            lines.append(
                f"  {f'{h:g} m {label}':<{width}}{s['frames']:>7}"
                f"{num(s['detection_rate'], '.2f'):>7}"
                f"{_mm(s['position_error_m_p50']):>10}"
                f"{_mm(s['position_error_m_p95']):>7}"
                f"{_mm(s['lateral_error_m_p50']):>12}"
                f"{_mm(s['lateral_error_m_p95']):>7}"
                f"{num(s['time_per_frame_ms_p50'], '.1f'):>8}"
                + "".join(f"{('' if label.startswith(labels[0]) else num(x, '.1f') + '×'):>{w}}"
                          for x, w in zip(ratios, (14, 16), strict=True)))
    return lines


register(DetectorBench("image", _run_image, lambda s: _table(
    f"image (down camera): the generated target, {s['width_m']:g} m; ours vs seed 000's "
    f"pipeline", s)))
register(DetectorBench("pad", _run_pad, lambda s: _table(
    "pad (down camera): red disc 0.8 m; ours vs seed 001's template matching", s)))
