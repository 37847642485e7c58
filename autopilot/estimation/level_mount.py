"""A down camera's mount tilt, learned in flight from a target known to lie level.

A camera bracket is off its nominal angles by a degree or so (``camera_mount_std_deg``); seen
from 2 m, 1° of tilt puts a target 3.5 cm from where the autopilot believes it is, the same
on every frame, so no filter averages it away. A flat target on level ground (hover_image's
image) measures it: its pose from the camera (PnP) gives the ground's normal in the camera's
frame, and the vehicle's attitude with the nominal mount says where that normal should be.
The difference, averaged over many frames, is the mount's tilt (about the optical x and y
axes; a turn about the line of sight is not seen). It also takes in the navigation's tilt
error of the moment, which drifts over a minute (PX4's EKF), so the correction removes that
too while it lasts.

Each frame's tilt is noisy (PnP's rotation of a small planar target: ~1° here), so nothing is
corrected before ``min_frames``; a frame implying more than ``max_tilt_deg`` (a flipped planar
pose) is not used. The correction's own uncertainty is the mean's standard error with a floor
(``residual_std_deg``) for the pose's bias (calibration residuals). The navigation's tilt
is not in it: it is the attitude term the estimate's σ carries anyway (the part learned
with the mount drifts away again over the attitude error's minute), so it is counted once.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import cv2
import numpy as np

from drivers.base import CameraInfo

_DOWN = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True, slots=True)
class LevelMountSettings:
    min_frames: int = 30  # frames before the learned tilt is applied
    max_tilt_deg: float = 5.0  # a frame implying more is a bad pose, not the mount
    residual_std_deg: float = 0.1  # floor of the learned tilt's σ (the pose's bias)


@dataclass(frozen=True, slots=True, eq=False)
class MountEstimate:
    tilt_deg: tuple[float, float]  # the mount's turn about the optical x and y axes
    frames: int
    std_deg: float  # σ of each tilt component as applied

    @property
    def rotation(self) -> np.ndarray:
        """Nominal optical frame → the true one (as :func:`drivers.sim.model.mount_error`)."""
        rvec = np.radians([self.tilt_deg[0], self.tilt_deg[1], 0.0])
        return cv2.Rodrigues(rvec)[0]


def frame_tilt_rad(r_world_cam_nominal: np.ndarray, r_cam_target: np.ndarray) -> np.ndarray:
    """The mount's tilt (rotation vector, optical frame, radians; its component along the
    world's down is not observable and is 0) that one frame of a level target implies:
    the target's normal seen by the camera is the true mount's view of the world's down,
    ``n = δᵀ d`` with ``d`` the down seen through the nominal mount, so ``n − d ≈ d × θ``."""
    d = r_world_cam_nominal.T @ _DOWN
    n = np.asarray(r_cam_target, dtype=float)[:, 2]
    n = n if n @ d >= 0.0 else -n
    skew = np.array([[0.0, -d[2], d[1]], [d[2], 0.0, -d[0]], [-d[1], d[0], 0.0]])
    theta, *_ = np.linalg.lstsq(skew, n - d, rcond=None)  # the least-norm θ: ⟂ d
    return theta


class LevelMountEstimator:
    """Running mean of the tilt that frames of a level target imply (see the module)."""

    def __init__(self, settings: LevelMountSettings = LevelMountSettings()) -> None:
        self.settings = settings
        self.frames = 0
        self.rejected = 0
        self._sum = np.zeros(3)
        self._sum2 = np.zeros(3)

    def add(self, r_world_body: np.ndarray, camera: CameraInfo,
            r_cam_target: np.ndarray) -> bool:
        """One frame (the vehicle's attitude at capture, the camera as nominally mounted, the
        target's rotation in the camera frame); False when it was not used."""
        theta = frame_tilt_rad(r_world_body @ camera.rotation_body_cam, r_cam_target)
        if not np.all(np.isfinite(theta)) or \
                np.linalg.norm(theta) > math.radians(self.settings.max_tilt_deg):
            self.rejected += 1
            return False
        self.frames += 1
        self._sum += theta
        self._sum2 += theta * theta
        return True

    def estimate(self) -> MountEstimate | None:
        if self.frames < self.settings.min_frames:
            return None
        n = self.frames
        mean = self._sum / n
        var = np.maximum(self._sum2 / n - mean * mean, 0.0)
        std_err = math.sqrt(float(np.max(var[:2])) / n)
        std = math.hypot(std_err, math.radians(self.settings.residual_std_deg))
        return MountEstimate((math.degrees(mean[0]), math.degrees(mean[1])), n,
                             math.degrees(std))

    def corrected(self, camera: CameraInfo) -> CameraInfo:
        """``camera`` with its mount turned by the learned tilt (as it is once learned)."""
        est = self.estimate()
        if est is None:
            return camera
        return dataclasses.replace(camera,
                                   rotation_body_cam=camera.rotation_body_cam @ est.rotation)
