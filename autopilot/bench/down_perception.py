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

from autopilot.bench.perception import (
    BenchOptions,
    DetectorBench,
    _num,
    _percentile,
    register,
)
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
         texture: np.ndarray, width_m: float, detectors: dict) -> dict:
    sim = Simulator(cfg.sim, scenario=[FeatureGround(seed=options.seed),
                                       GroundImage(name, texture, width_m, WHERE, 25.0)])
    rng = np.random.default_rng(options.seed)
    section: dict = {"target": name, "width_m": width_m, "frames_per_height": _frames(options)}
    try:
        camera = sim.camera_infos()[CAMERA]
        samples: dict[str, dict[float, list]] = {d: {h: [] for h in HEIGHTS_M}
                                                 for d in detectors}
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
                    if found is None:
                        samples[label][height].append((False, None, None, ms))
                        continue
                    error = found.position_cam_m - p
                    # across the line of sight: the centre's direction, at the true range
                    direction = found.position_cam_m / np.linalg.norm(found.position_cam_m)
                    lateral = float(np.linalg.norm(direction * np.linalg.norm(p) - p))
                    samples[label][height].append((True, float(np.linalg.norm(error)),
                                                   lateral, ms))
    finally:
        sim.close()
    for label, by_height in samples.items():
        section[label] = {f"at_{h:g}m": _stats(s) for h, s in by_height.items()}
    return section


def _stats(samples: list) -> dict:
    found = [s for s in samples if s[0]]
    return {
        "frames": len(samples),
        "detection_rate": len(found) / len(samples) if samples else None,
        "position_error_m_p50": _percentile([s[1] for s in found], 50),
        "position_error_m_p95": _percentile([s[1] for s in found], 95),
        "lateral_error_m_p50": _percentile([s[2] for s in found], 50),
        "lateral_error_m_p95": _percentile([s[2] for s in found], 95),
        "time_per_frame_ms_p50": _percentile([s[3] for s in samples], 50),
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
        "seed001": Seed001PadDetector("red", size_m)})


def _table(title: str, section: dict) -> list[str]:
    lines = [title,
             f"  {'':<16}{'frames':>7}{'found':>7}{'error p50':>10}{'p95':>7}"
             f"{'lateral p50':>12}{'p95':>7}{'ms p50':>8}{'lateral ÷ ours':>16}"]
    labels = [k for k in section if isinstance(section[k], dict) and "at_1m" in section[k]]
    for h in HEIGHTS_M:
        key = f"at_{h:g}m"
        ours = section[labels[0]][key]["lateral_error_m_p50"]
        for label in labels:
            s = section[label][key]
            ratio = (s["lateral_error_m_p50"] / ours) if ours and \
                s["lateral_error_m_p50"] is not None else None
            lines.append(
                f"  {f'{h:g} m {label}':<16}{s['frames']:>7}"
                f"{_num(s['detection_rate'], '.2f'):>7}"
                f"{_num(s['position_error_m_p50'], '.3f'):>10}"
                f"{_num(s['position_error_m_p95'], '.3f'):>7}"
                f"{_num(s['lateral_error_m_p50'], '.3f'):>12}"
                f"{_num(s['lateral_error_m_p95'], '.3f'):>7}"
                f"{_num(s['time_per_frame_ms_p50'], '.1f'):>8}"
                f"{('' if label == labels[0] else _num(ratio, '.1f') + '×'):>16}")
    return lines


register(DetectorBench("image", _run_image, lambda s: _table(
    f"image (down camera): the generated target, {s['width_m']:g} m; ours vs seed 000's "
    f"pipeline", s)))
register(DetectorBench("pad", _run_pad, lambda s: _table(
    "pad (down camera): red disc 0.8 m; ours vs seed 001's template matching", s)))
