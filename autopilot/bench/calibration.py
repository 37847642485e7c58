"""``autopilot bench calibration``: ``autopilot calibrate``'s code on views of a calibration
board the simulator renders, against the simulated camera's true intrinsics.

The camera is the front camera as configured (``config.yaml``: realistic — lens distortion,
read noise, motion blur from the vehicle's motion during the exposure); its true intrinsics and
distortion are the simulator's (``Simulator.camera_infos()``). A board
(:class:`drivers.sim.scenario.CalibrationBoard`: ChArUco, then a chessboard) stands still; the
vehicle is posed (teleported) for every view so that the board appears at a chosen place in the
image (the whole image, corners included: there the distortion matters most; a ChArUco board
may be partly outside it, a chessboard must be whole), at a chosen distance and tilt (up to
50°, any direction) and camera roll, moving slightly as a hand-held or hovering camera does.
Every tenth view is taken while the vehicle turns fast (motion blur of several pixels): the
view selection should leave those out. The rendered frames go through
:func:`autopilot.calibration.calibrate_frames` exactly as an image folder's would.

Reported per board and, as the headline, the worse of the boards: ``focal_error_pct`` (the
larger of fx's and fy's relative errors; both, and their mean, are given too),
``principal_point_error_px``, ``reprojection_rms_px``, and the lens model against the truth
over the whole image: ``distortion_max_difference_px`` (the distortion alone: both models with
the true camera matrix) and ``model_max_error_px`` (everything: a pixel's ray as the estimate
has it, seen through the true camera). The required figures (issue 11): focal error ≤ 0.5 %,
reprojection RMS ≤ 0.5 px. Every random choice comes from fixed seeds.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from autopilot.bench import perception
from autopilot.calibration import (
    BoardSpec,
    CalibrationOptions,
    CalibrationResult,
    SourceFrame,
    calibrate_frames,
    parse_board_spec,
)
from autopilot.config import AppConfig, load_config
from autopilot.process import StealMeter
from drivers.base import CameraInfo, CameraIntrinsics
from drivers.camera_model import project_points, undistort_points
from drivers.sim.config import SimConfig
from drivers.sim.scenario import CalibrationBoard
from drivers.sim.simulator import Simulator

CAMERA = "front"
#: The issue's required figures.
FOCAL_ERROR_MAX_PCT = 0.5
REPROJECTION_RMS_MAX_PX = 0.5
#: The board's centre stands this high above the ground, facing north (m).
_BOARD_HEIGHT_M = 3.0
#: The image divided into this many cells (columns, rows); views cycle through them (the
#: corner cells twice).
_CELLS = (4, 3)


@dataclass(frozen=True, slots=True)
class BenchOptions:
    """Which boards, how many views of each, and how they are taken."""

    boards: tuple[str, ...] = ("charuco:8x6:0.06:0.045:DICT_5X5_100", "chessboard:9x7:0.05")
    views: int = 120  # rendered per board
    max_views: int = 40  # used by the calibration (autopilot calibrate's default)
    distance_m: tuple[float, float] = (0.35, 0.85)  # camera to board centre
    max_tilt_deg: float = 50.0  # between the board's normal and the line of sight
    max_roll_deg: float = 30.0  # the camera about its line of sight
    #: The camera's motion during an exposure (σ per axis), as a hand-held or hovering one.
    rate_std_rad_s: float = 0.05
    speed_std_m_s: float = 0.05
    #: Every n-th view (0: none) is taken turning fast: several pixels of motion blur.
    blurred_every: int = 10
    blurred_rate_std_rad_s: float = 3.0
    seed: int = 0


DEFAULT_OPTIONS = BenchOptions()
#: For the test suite: the ChArUco board only, fewer views (about 15 s).
QUICK_OPTIONS = BenchOptions(boards=DEFAULT_OPTIONS.boards[:1], views=40, max_views=30)


def run_bench(log: Callable[[str], None] = lambda message: None, quick: bool = False,
              config: AppConfig | None = None, options: BenchOptions | None = None,
              save_dir: Path | None = None) -> dict:
    """Render, calibrate and score each board; one JSON-ready dict. With ``save_dir``, the
    rendered views are also written there, one folder per board (``charuco/``,
    ``chessboard/``), as ``autopilot calibrate`` would read them."""
    cfg = config or load_config()
    opts = options or (QUICK_OPTIONS if quick else DEFAULT_OPTIONS)
    boards = [parse_board_spec(text) for text in opts.boards]
    cam = cfg.sim.cameras[CAMERA]
    steal = StealMeter()
    started = time.perf_counter()
    result: dict = {
        "bench": "calibration",
        "quick": quick,
        "options": asdict(opts),
        "camera": {"name": CAMERA, "width_px": cam.width_px, "height_px": cam.height_px,
                   "hfov_deg": cam.hfov_deg, "realistic": cam.realistic,
                   "distortion": list(cam.distortion), "noise_std_dn": cam.noise_std_dn,
                   "exposure_s": cam.exposure_s, "rolling_shutter_s": cam.rolling_shutter_s},
        "boards": {},
    }
    for i, board in enumerate(boards):
        folder = None
        if save_dir is not None:
            folder = Path(save_dir) / board.pattern
            folder.mkdir(parents=True, exist_ok=True)
        section = _run_board(cfg, board, opts, i, log, folder)
        result["boards"][board.pattern if board.pattern not in result["boards"]
                         else f"{board.pattern}_{i}"] = section
        result.setdefault("truth", section.pop("truth"))
    sections = list(result["boards"].values())
    for key in ("focal_error_pct", "principal_point_error_px", "reprojection_rms_px",
                "distortion_max_difference_px", "model_max_error_px"):
        result[key] = max(s[key] for s in sections)
    result["views_used"] = {name: s["views_used"] for name, s in result["boards"].items()}
    result["required"] = {
        "focal_error_pct": {"max": FOCAL_ERROR_MAX_PCT, "value": result["focal_error_pct"],
                            "met": result["focal_error_pct"] <= FOCAL_ERROR_MAX_PCT},
        "reprojection_rms_px": {"max": REPROJECTION_RMS_MAX_PX,
                                "value": result["reprojection_rms_px"],
                                "met": result["reprojection_rms_px"] <= REPROJECTION_RMS_MAX_PX},
    }
    result["wall_time_s"] = time.perf_counter() - started
    result["cpu_steal_pct"] = steal.percent()
    return result


def _run_board(cfg: AppConfig, board: BoardSpec, opts: BenchOptions, index: int,
               log: Callable[[str], None], folder: Path | None) -> dict:
    calibrated, truth, rendered, elapsed, blurred = fit_camera(cfg.sim, board, opts, index,
                                                               folder)
    section = _score(calibrated, truth, board, opts, blurred)
    section["render_time_s"] = rendered
    section["calibrate_time_s"] = elapsed - rendered
    log(f"{board.pattern}: {section['views_used']} views of {section['views_found']} found, "
        f"focal error {section['focal_error_pct']:.3f} %, RMS "
        f"{section['reprojection_rms_px']:.3f} px")
    return section


def fit_camera(sim_config: SimConfig, board: BoardSpec, opts: BenchOptions, index: int = 0,
               folder: Path | None = None, camera_name: str = CAMERA
               ) -> tuple[CalibrationResult, CameraIntrinsics, float, float, set[str]]:
    """``autopilot calibrate``'s fit on rendered views of ``board`` seen by the simulated
    camera ``camera_name``: the result, the true intrinsics, the render time and the whole
    time (s), and the names of the views taken turning fast."""
    target = CalibrationBoard(
        "calibration_board", (0.0, 0.0, -_BOARD_HEIGHT_M), pattern=board.pattern,
        squares=(board.columns, board.rows), square_m=board.square_m,
        marker_m=board.marker_m, dictionary=board.dictionary or "DICT_5X5_100")
    sim = Simulator(sim_config, scenario=[target])
    blurred: set[str] = set()
    rendered = [0.0]
    try:
        camera = sim.camera_infos()[camera_name]
        truth = camera.intrinsics
        sim.capture(camera_name)  # warm-up: the renderer's first frame costs more

        def frames() -> Iterator[SourceFrame]:
            rng = np.random.default_rng((opts.seed, 7, index))
            still = perception.BenchOptions(rate_std_rad_s=opts.rate_std_rad_s,
                                            speed_std_m_s=opts.speed_std_m_s)
            shaken = perception.BenchOptions(rate_std_rad_s=opts.blurred_rate_std_rad_s,
                                             speed_std_m_s=opts.speed_std_m_s)
            for n in range(opts.views):
                t0 = time.perf_counter()
                r_ned_cam, position = _view(rng, camera, target, board, n, opts)
                fast = opts.blurred_every > 0 and n % opts.blurred_every == opts.blurred_every - 1
                name = f"view_{n:03d}.png"
                if fast:
                    blurred.add(name)
                perception._pose_camera(sim, camera, r_ned_cam, position, rng,
                                        shaken if fast else still)
                image = cv2.cvtColor(sim.capture(camera_name).image, cv2.COLOR_RGB2BGR)
                if folder is not None:
                    cv2.imwrite(str(folder / name), image)
                rendered[0] += time.perf_counter() - t0
                yield SourceFrame(name, image)

        t0 = time.perf_counter()
        calibrated = calibrate_frames(frames(), board, CalibrationOptions(
            max_views=opts.max_views))
        elapsed = time.perf_counter() - t0
    finally:
        sim.close()
    return calibrated, truth, rendered[0], elapsed, blurred


def _view(rng: np.random.Generator, camera: CameraInfo, target: CalibrationBoard,
          board: BoardSpec, n: int, opts: BenchOptions) -> tuple[np.ndarray, np.ndarray]:
    """A camera pose (``R_ned_cam``, position NED) seeing the board in the ``n``-th cell of
    the image, at a random distance, tilt and roll. The point of the board put at the chosen
    pixel is as far from the board's centre as the pixel is from the image's (towards the
    same side), so that near the image's corners the board reaches into them. A chessboard
    must be seen whole (with a margin): poses that cut it are drawn again."""
    intr = camera.intrinsics
    r_ned_pattern = target.rotation_ned_pattern()
    normal = -r_ned_pattern[:, 2]  # out of the face, towards a camera that reads it
    right, up = r_ned_pattern[:, 0], -r_ned_pattern[:, 1]
    centre = np.asarray(target.position_ned_m, dtype=float)
    outline = centre + (board.outline_m() - board.centre_m()) @ r_ned_pattern.T
    cx, cy = _CELLS
    corners = [0, cx - 1, cx * (cy - 1), cx * cy - 1]
    cycle = list(range(cx * cy)) + corners  # the corners twice: the lens bends most there
    cell = cycle[n % len(cycle)]
    lo = (cell % cx / cx * intr.width_px, cell // cx / cy * intr.height_px)
    for attempt in range(400):
        # corner cells cannot always hold a whole chessboard: widen the search as it fails
        spread = 1.0 + attempt / 100.0
        u = float(np.clip(lo[0] + rng.uniform(-0.5 * spread + 0.5, 0.5 * spread + 0.5)
                          * intr.width_px / cx, 0.0, intr.width_px - 1.0))
        v = float(np.clip(lo[1] + rng.uniform(-0.5 * spread + 0.5, 0.5 * spread + 0.5)
                          * intr.height_px / cy, 0.0, intr.height_px - 1.0))
        distance = rng.uniform(*opts.distance_m)
        tilt = math.radians(opts.max_tilt_deg) * math.sqrt(rng.uniform())  # uniform on a cap
        psi = rng.uniform(0.0, 2.0 * math.pi)
        roll = math.radians(rng.uniform(-opts.max_roll_deg, opts.max_roll_deg))
        towards = math.cos(tilt) * normal + math.sin(tilt) * (math.cos(psi) * right
                                                              + math.sin(psi) * up)
        anchor = centre + 0.45 * board.square_m * (
            (2.0 * u / intr.width_px - 1.0) * board.columns * r_ned_pattern[:, 0]
            + (2.0 * v / intr.height_px - 1.0) * board.rows * r_ned_pattern[:, 1])
        position = anchor + distance * towards
        r_ned_cam = perception._looking(-towards, roll) @ perception._rotation_onto(
            perception._ray(camera, u, v), np.array([0.0, 0.0, 1.0]))
        if board.pattern != "chessboard" or _whole(intr, r_ned_cam, position, outline):
            return r_ned_cam, position
    raise RuntimeError(f"no pose shows the whole {board.describe()} in cell {cell}")


def _whole(intr: CameraIntrinsics, r_ned_cam: np.ndarray, position: np.ndarray,
           outline_ned: np.ndarray, margin_px: float = 6.0) -> bool:
    """Is the board's pattern (its outline) inside the image, with a margin?"""
    uv = project_points(intr, (outline_ned - position) @ r_ned_cam)
    return bool(np.all(np.isfinite(uv)) and uv[:, 0].min() >= margin_px
                and uv[:, 1].min() >= margin_px and uv[:, 0].max() <= intr.width_px - 1
                - margin_px and uv[:, 1].max() <= intr.height_px - 1 - margin_px)


def _score(result: CalibrationResult, truth: CameraIntrinsics, board: BoardSpec,
           opts: BenchOptions, blurred: set[str]) -> dict:
    est = result.intrinsics
    fx_pct = 100.0 * abs(est.fx - truth.fx) / truth.fx
    fy_pct = 100.0 * abs(est.fy - truth.fy) / truth.fy
    distortion_px, model_px = lens_differences(truth, est)
    used = {v.name for v in result.views}
    rejected_names = {r.name for r in result.rejected}
    d = result.as_dict()
    return {
        "board": board.text,
        "description": board.describe(),
        "views_rendered": opts.views,
        "views_found": result.frames_with_board,
        "views_used": len(result.views),
        "rejected": result.rejected_counts(),
        "blurred_rendered": len(blurred),
        "blurred_found": len(blurred & (used | rejected_names)),
        "blurred_used": len(blurred & used),
        "focal_error_pct": max(fx_pct, fy_pct),
        "fx_error_pct": fx_pct,
        "fy_error_pct": fy_pct,
        "focal_error_pct_mean": 0.5 * (fx_pct + fy_pct),
        "principal_point_error_px": math.hypot(est.cx - truth.cx, est.cy - truth.cy),
        "reprojection_rms_px": result.reprojection_rms_px,
        "view_rms_px_max": max(v.rms_px for v in result.views),
        "distortion_max_difference_px": float(distortion_px.max()),
        "model_max_error_px": float(model_px.max()),
        "model_p95_error_px": float(np.percentile(model_px, 95)),
        "estimate": {"fx": est.fx, "fy": est.fy, "cx": est.cx, "cy": est.cy,
                     "distortion": list(est.distortion), "std_px": d["std_px"]},
        "truth": {"fx": truth.fx, "fy": truth.fy, "cx": truth.cx, "cy": truth.cy,
                  "distortion": list(truth.distortion)},
        "coverage": d["coverage"],
        "warnings": list(result.warnings),
    }


def lens_differences(truth: CameraIntrinsics, est: CameraIntrinsics,
                     step_px: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Over a grid of the image's pixels (every ``step_px``, the border included): how far
    apart the two lens models put each pixel (px). First the distortion alone (both with the
    true camera matrix: where each says the pixel's undistorted position is); then the whole
    model (the pixel's ray as ``est`` has it, projected through ``truth``)."""
    w, h = truth.width_px, truth.height_px
    u = np.unique(np.r_[np.arange(0, w, step_px), w - 1]).astype(float)
    v = np.unique(np.r_[np.arange(0, h, step_px), h - 1]).astype(float)
    grid = np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 2)
    mixed = CameraIntrinsics(w, h, truth.fx, truth.fy, truth.cx, truth.cy, est.distortion)
    distortion = np.linalg.norm(undistort_points(truth, grid, to_pixels=True)
                                - undistort_points(mixed, grid, to_pixels=True), axis=1)
    rays = undistort_points(est, grid)
    back = project_points(truth, np.column_stack([rays, np.ones(len(rays))]))
    model = np.linalg.norm(back - grid, axis=1)
    return distortion, model


def format_table(result: dict) -> str:
    cam = result["camera"]
    truth = result["truth"]
    lines = [f"camera {cam['name']} {cam['width_px']}×{cam['height_px']} {cam['hfov_deg']:g}° "
             f"({'realistic' if cam['realistic'] else 'ideal'}: noise {cam['noise_std_dn']:g} "
             f"DN, exposure {cam['exposure_s'] * 1e3:g} ms){', quick' if result['quick'] else ''}",
             f"truth: fx {truth['fx']:.2f} fy {truth['fy']:.2f} cx {truth['cx']:.2f} "
             f"cy {truth['cy']:.2f} px, distortion "
             + " ".join(f"{x:+.4f}" for x in truth["distortion"])]
    for name, s in result["boards"].items():
        est = s["estimate"]
        c = s["coverage"]
        rej = s["rejected"]
        lines += [
            "",
            f"{name}: {s['description']}",
            f"  views: {s['views_rendered']} rendered ({s['blurred_rendered']} blurred), "
            f"{s['views_found']} with the board found, {s['views_used']} used; not used: "
            f"{rej['blurry']} blurry, {rej['duplicate']} near-duplicates, {rej['outlier']} "
            f"outliers, {rej['not_needed']} not needed; blurred ones used: {s['blurred_used']}",
            f"  coverage: {c['cells_fraction']:.0%} of cells, {c['border_cells_fraction']:.0%} "
            f"of border cells, {c['area_fraction']:.0%} of the area; tilted "
            f"{c['tilt_deg_min']:.0f}-{c['tilt_deg_max']:.0f}° off the optical axis",
            f"  estimate: fx {est['fx']:.2f} fy {est['fy']:.2f} cx {est['cx']:.2f} "
            f"cy {est['cy']:.2f} px, distortion "
            + " ".join(f"{x:+.4f}" for x in est["distortion"]),
            f"  focal error {s['focal_error_pct']:.3f} % (fx {s['fx_error_pct']:.3f}, fy "
            f"{s['fy_error_pct']:.3f}), principal point {s['principal_point_error_px']:.2f} px,"
            f" reprojection RMS {s['reprojection_rms_px']:.3f} px (worst view "
            f"{s['view_rms_px_max']:.3f})",
            f"  lens model against truth over the image: distortion alone max "
            f"{s['distortion_max_difference_px']:.2f} px; whole model max "
            f"{s['model_max_error_px']:.2f} px, p95 {s['model_p95_error_px']:.2f} px",
            f"  time: render {s['render_time_s']:.1f} s, detect and calibrate "
            f"{s['calibrate_time_s']:.1f} s",
        ]
    lines.append("")
    for key, req in result["required"].items():
        unit = "%" if key.endswith("pct") else "px"
        lines.append(f"required: {key} ≤ {req['max']:g} {unit}: {req['value']:.3f} {unit}, "
                     f"{'met' if req['met'] else 'NOT MET'}")
    steal = result.get("cpu_steal_pct")
    lines.append(f"{result['wall_time_s']:.0f} s"
                 + ("" if steal is None else f"; hypervisor steal {steal:.1f} %"))
    return "\n".join(lines)
