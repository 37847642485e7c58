"""The vehicle's cameras as a MAVLink driver gets them: each its own video stream
(``vehicle.cameras.NAME.video``), with the intrinsics and distortion of its calibration file
(``vehicle.cameras.NAME.calibration``, or ``--calibration``) — or, for an uncalibrated camera, the
nominal pinhole of its configured geometry and a warning (ranges and bearings are then off by
the lens's distortion: a few per cent at the image edges for a typical small-drone lens).

Command-line options name a camera or default to the first camera the mission uses:
``--video URL`` / ``--video down=udp://0.0.0.0:5601``, ``--calibration FILE`` /
``--calibration down=down.yaml``.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from autopilot.config import AppConfig, ConfigError, Problem
from drivers.base import CameraInfo

_NAMED = re.compile(r"^([A-Za-z_][A-Za-z0-9_-]*)=(.+)$")


@dataclass(frozen=True, slots=True)
class CameraSetup:
    name: str
    url: str  # its video stream
    info: CameraInfo  # intrinsics (calibrated or nominal) and mounting
    calibration: str | None  # the file its intrinsics came from (None: nominal)
    video_source: str | None
    stream_latency_s: float

    @property
    def calibrated(self) -> bool:
        return self.calibration is not None

    def warning(self) -> str | None:
        if self.calibrated:
            return None
        return (f"camera {self.name} is uncalibrated: using the nominal pinhole of "
                f"vehicle.cameras.{self.name} ({self.info.intrinsics.width_px}×"
                f"{self.info.intrinsics.height_px}, {_hfov_deg(self.info):.0f}° wide, no lens "
                "distortion); ranges and bearings will be off by the lens's distortion. "
                f"Calibrate it (autopilot calibrate) and pass --calibration {self.name}=FILE or "
                f"set vehicle.cameras.{self.name}.calibration")


def parse_camera_options(values: Sequence[str] | str | None, option: str,
                         default_camera: str | None) -> dict[str, str]:
    """``--video``/``--calibration`` values (``VALUE`` or ``CAMERA=VALUE``) by camera."""
    if values is None:
        return {}
    if isinstance(values, str):
        values = [values]
    out: dict[str, str] = {}
    for value in values:
        named = _NAMED.match(value)
        if named and "://" not in named.group(1):
            camera, value = named.group(1), named.group(2)
        elif default_camera is None:
            raise ConfigError([Problem("command line", None, option,
                                       f"{value!r}: this mission uses no camera; name one "
                                       f"({option} CAMERA=VALUE)")])
        else:
            camera = default_camera
        if camera in out:
            raise ConfigError([Problem("command line", None, option,
                                       f"given twice for camera {camera!r}")])
        out[camera] = value
    return out


def camera_setups(config: AppConfig, cameras: Sequence[str], *,
                  videos: Mapping[str, str] = {}, calibrations: Mapping[str, str] = {}
                  ) -> list[CameraSetup]:
    """The streams, intrinsics and mounting of ``cameras`` (checked: every problem is a
    :class:`~autopilot.config.ConfigError` naming the key or option)."""
    from drivers.calibration import CalibrationError, load_calibration
    from drivers.sim.model import camera_info
    from drivers.video import check_video_url

    problems: list[Problem] = []
    known = config.vehicle.cameras
    for name in list(videos) + list(calibrations):
        if name not in known:
            problems.append(Problem("command line", None, name,
                                    f"no such camera (vehicle.cameras has: "
                                    f"{', '.join(known) or 'none'})"))
    setups = []
    for name in cameras:
        cam = known.get(name)
        if cam is None:
            problems.append(Problem("config", None, f"vehicle.cameras.{name}",
                                    "the mission uses this camera; define it"))
            continue
        url = videos.get(name) or cam.video
        where = "--video" if name in videos else f"vehicle.cameras.{name}.video"
        if not url:
            problems.append(Problem("config", None, where,
                                    f"camera {name} has no video stream (the mission uses it)"))
            continue
        try:
            check_video_url(url)
        except ValueError as exc:
            problems.append(Problem("command line" if name in videos else "config", None,
                                    where, str(exc)))
            continue
        # the nominal geometry, without the simulated lens's distortion
        info = camera_info(name, cam.model_copy(update={"realistic": False}))
        calibration = calibrations.get(name) or cam.calibration
        if calibration is not None:
            try:
                intrinsics = load_calibration(Path(calibration))
            except CalibrationError as exc:
                message = str(exc).removeprefix(f"{calibration}: ")
                problems.append(Problem(str(calibration), None,
                                        "--calibration" if name in calibrations else
                                        f"vehicle.cameras.{name}.calibration", message))
                continue
            info = dataclasses.replace(info, intrinsics=intrinsics)
        setups.append(CameraSetup(name, url, info, calibration, cam.video_source,
                                  cam.stream_latency_s))
    if problems:
        raise ConfigError(problems)
    return setups


def _hfov_deg(info: CameraInfo) -> float:
    import math

    return math.degrees(info.intrinsics.hfov_rad)
