"""The AR.Drone 2.0's video clock mapped onto ours (:class:`VideoClock`) and its nominal
cameras (:func:`ardrone_cameras`)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from drivers.base import (
    CameraInfo,
)
from drivers.camera_model import pinhole

# --------------------------------------------------------------------------------------------
# Video: the drone's clock onto ours, the cameras
# --------------------------------------------------------------------------------------------


class VideoClock:
    """PaVE timestamps (the drone's clock) onto ours: ``ours = drone + offset``, the offset
    the smallest ``arrival − drone − latency_s`` seen (the frame that came fastest bounds it,
    as a clock mapping does). An arrival more than :data:`RESTART_S` after its mapped time
    means the drone's clock restarted (a reboot): the offset is taken afresh."""

    RESTART_S = 2.0

    def __init__(self, latency_s: float = 0.05) -> None:
        self.latency_s = latency_s
        self.offset_s: float | None = None

    def map(self, drone_time_s: float, arrival_s: float) -> float:
        offset = arrival_s - drone_time_s - self.latency_s
        if self.offset_s is None or offset < self.offset_s or \
                offset - self.offset_s > self.RESTART_S:
            self.offset_s = offset
        return drone_time_s + self.offset_s


#: the AR.Drone 2.0's cameras as autopilot/vehicles/ardrone.yaml describes them (its specs):
#: (width, height, horizontal FOV °, rate Hz, position FRD m, pitch °, distortion)
_CAMERAS = {
    "front": (640, 360, 84.1, 30.0, (0.17, 0.0, 0.0), 0.0, (-0.12, 0.02, 0.0, 0.0, 0.0)),
    "down": (320, 240, 53.1, 30.0, (0.0, 0.0, 0.03), -90.0, (-0.04, 0.004, 0.0, 0.0, 0.0)),
}
#: video:video_channel for each camera (ZAP_CHANNEL_HORI, ZAP_CHANNEL_VERT)
VIDEO_CHANNELS = {"front": 0, "down": 1}


def _rotation_body_cam(pitch_deg: float) -> np.ndarray:
    """Optical frame → body FRD for a camera looking forward, pitched by ``pitch_deg``
    (−90: straight down, image up towards the nose), as the simulator mounts it."""
    p = math.radians(pitch_deg)
    z = np.array([math.cos(p), 0.0, -math.sin(p)])
    x = np.array([0.0, 1.0, 0.0])
    return np.column_stack((x, np.cross(z, x), z))


def ardrone_cameras() -> dict[str, CameraInfo]:
    """The AR.Drone 2.0's two cameras, nominal (the driver's default; a calibration's
    ``CameraInfo`` can be passed to it instead)."""
    out = {}
    for name, (w, h, hfov, rate, position, pitch, distortion) in _CAMERAS.items():
        out[name] = CameraInfo(name, pinhole(w, h, hfov, distortion), _rotation_body_cam(pitch),
                               np.array(position), rate)
    return out


def streamed_cameras(cameras: Mapping[str, CameraInfo]) -> dict[str, CameraInfo]:
    """``cameras``, checked to be ones the drone streams (ValueError otherwise)."""
    unknown = set(cameras) - set(VIDEO_CHANNELS)
    if unknown:
        raise ValueError(f"the AR.Drone streams the cameras {sorted(VIDEO_CHANNELS)}, "
                         f"not {sorted(unknown)}")
    return dict(cameras)


def camera_of_frame(width_px: int, height_px: int, cameras: Mapping[str, CameraInfo],
                    channel_camera: str) -> str:
    """Which camera a decoded frame of this size came from: the one selected, unless only
    another camera has this size (a frame from before a channel switch)."""
    selected = cameras.get(channel_camera)
    if selected is not None and (selected.intrinsics.width_px,
                                 selected.intrinsics.height_px) == (width_px, height_px):
        return channel_camera
    for name, info in cameras.items():
        if (info.intrinsics.width_px, info.intrinsics.height_px) == (width_px, height_px):
            return name
    return channel_camera
