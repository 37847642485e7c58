"""The calibrations the simulated cameras report (``vehicle.cameras.NAME.sim_calibration:
fitted``): the autopilot never sees a simulated camera's true intrinsics, only what
``autopilot calibrate`` fits on simulated views of a ChArUco board seen by that camera (its
lens, noise, blur, rolling shutter and codec), with the fit's residual error — as a real
camera's calibration file.

A fit takes some 20-40 s of rendering and fitting, so it is made once per camera
configuration and cached as an OpenCV calibration YAML, keyed by a hash of everything that
shapes the camera's image (geometry, lens, noise, blur, shutter, codec) and of the fit's own
settings: ``$AUTOPILOT_CACHE_DIR`` (default ``$XDG_CACHE_HOME/autopilot``, else
``~/.cache/autopilot``) ``/calibrations/NAME-HASH.yaml``. The simulator then reports that file
with each frame exactly as a MAVLink vehicle's camera reports its ``calibration`` file (the
camera's ``calibration`` key, which, when set, is used as it is).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from pathlib import Path

from drivers.sim.config import CameraConfig, SimConfig

log = logging.getLogger(__name__)

#: What the fit uses: a ChArUco board, 60 rendered views of which 40 are used (the calibration
#: bench's quick figures: focal error < 0.1 %, RMS 0.2-0.3 px). Bump the version whenever the
#: fitting or rendering changes what a fit gives.
BOARD = "charuco:8x6:0.06:0.045:DICT_5X5_100"
VIEWS = 60
MAX_VIEWS = 40
VERSION = 1

#: Keys of a camera's configuration that do not change its image (hence not its fit).
_NOT_IMAGE = {"enabled", "rate_hz", "position_frd_m", "pitch_deg", "yaw_deg", "latency_s",
              "latency_jitter_s", "drop_fraction", "mount_error_deg", "auto_exposure_step",
              "auto_exposure_interval_s", "sim_calibration", "calibration", "video",
              "video_source", "stream_latency_s"}


def cache_dir() -> Path:
    base = os.environ.get("AUTOPILOT_CACHE_DIR")
    if base:
        return Path(base)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "autopilot"


def config_hash(cam: CameraConfig) -> str:
    """A hash of what shapes the camera's image, and of the fit's settings."""
    image = {k: v for k, v in cam.model_dump(mode="json").items() if k not in _NOT_IMAGE}
    text = json.dumps({"camera": image, "board": BOARD, "views": VIEWS, "max_views": MAX_VIEWS,
                       "version": VERSION}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def fitted_calibration(name: str, sim: SimConfig) -> Path:
    """The cached fitted calibration of camera ``name`` (fitted now if not cached)."""
    cam = sim.cameras[name]
    path = cache_dir() / "calibrations" / f"{name}-{config_hash(cam)}.yaml"
    if path.is_file():
        return path
    from autopilot.bench.calibration import BenchOptions, fit_camera
    from autopilot.calibration import parse_board_spec, write_result

    log.warning("fitting the %s camera's calibration on simulated board views (once; cached "
                "in %s)", name, path.parent)
    # only this camera, posed at the origin; its mount error does not change its intrinsics
    only = {n: c.model_copy(update={"enabled": n == name}) for n, c in sim.cameras.items()}
    board = parse_board_spec(BOARD)
    result, truth, _, elapsed, _ = fit_camera(
        sim.model_copy(update={"cameras": only, "faults": []}), board,
        BenchOptions(boards=(BOARD,), views=VIEWS, max_views=MAX_VIEWS), camera_name=name)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    write_result(result, tmp, tmp.with_name(tmp.name + ".ros.yaml"), name,
                 source=f"simulated {BOARD}, {VIEWS} views")
    tmp.with_name(tmp.name + ".ros.yaml").unlink(missing_ok=True)
    os.replace(tmp, path)  # another process fitting the same camera writes the same file
    fit = result.intrinsics
    log.warning("%s camera: fitted in %.0f s, RMS %.3f px, fx %.2f (truth %.2f, %+.3f %%)",
                name, elapsed, result.reprojection_rms_px, fit.fx, truth.fx,
                100.0 * (fit.fx / truth.fx - 1.0))
    return path


def with_fitted_calibrations(sim: SimConfig) -> SimConfig:
    """``sim`` with each enabled camera that reports a fitted calibration (and has no
    ``calibration`` file of its own) pointed at its cached fit."""
    cameras = dict(sim.cameras)
    changed = False
    for name, cam in sim.cameras.items():
        if cam.enabled and cam.calibration is None and cam.sim_calibration == "fitted":
            cameras[name] = cam.model_copy(update={
                "calibration": str(fitted_calibration(name, sim))})
            changed = True
    return sim.model_copy(update={"cameras": cameras}) if changed else sim
