"""What a camera sees of the ground: the outline of its image laid on a level ground plane."""

from __future__ import annotations

import numpy as np

from drivers.base import CameraIntrinsics
from drivers.camera_model import pixel_rays
from drivers.geometry import quat_to_matrix

_PER_SIDE = 8


def image_border_px(intrinsics: CameraIntrinsics, per_side: int = _PER_SIDE) -> np.ndarray:
    """Points around the image's edge (corners included), clockwise from the top left."""
    w, h = intrinsics.width_px - 1.0, intrinsics.height_px - 1.0
    t = np.linspace(0.0, 1.0, per_side, endpoint=False)
    top = np.column_stack([t * w, np.zeros_like(t)])
    right = np.column_stack([np.full_like(t, w), t * h])
    bottom = np.column_stack([w - t * w, np.full_like(t, h)])
    left = np.column_stack([np.zeros_like(t), h - t * h])
    return np.vstack([top, right, bottom, left])


def ground_footprint(intrinsics: CameraIntrinsics, rotation_body_cam: np.ndarray,
                     position_body_m: np.ndarray, vehicle_position_ned_m: np.ndarray,
                     vehicle_attitude_q: np.ndarray, ground_down_m: float = 0.0
                     ) -> np.ndarray | None:
    """The image's outline on the ground plane (NED down = ``ground_down_m``) as (north, east)
    points, lens distortion included; None when part of the image sees the sky."""
    r_wb = quat_to_matrix(np.asarray(vehicle_attitude_q, dtype=float))
    r_wc = r_wb @ np.asarray(rotation_body_cam, dtype=float).reshape(3, 3)
    origin = np.asarray(vehicle_position_ned_m, dtype=float) + r_wb @ np.asarray(
        position_body_m, dtype=float)
    rays = pixel_rays(intrinsics, image_border_px(intrinsics)) @ r_wc.T
    height = ground_down_m - origin[2]
    if height <= 0 or np.any(rays[:, 2] <= 1e-6):
        return None
    scale = height / rays[:, 2]
    return origin[:2] + rays[:, :2] * scale[:, None]


def footprint_width_per_m(intrinsics: CameraIntrinsics, rotation_body_cam: np.ndarray,
                          position_body_m: np.ndarray) -> float:
    """How wide a strip of ground a camera sees under a level vehicle, per metre of height:
    the diameter of the largest circle around the point under the vehicle that lies wholly
    inside the image's outline on the ground (lens and mount included). A circle, because it
    holds at any heading; 0 when the camera does not see the ground under the vehicle.

    For a camera looking straight down this is the image's shorter side on the ground; the
    outline scales with the camera's height, so one metre gives the figure for any height."""
    height_m = 1.0  # of the camera (a camera below the body's origin sees from lower down)
    vehicle = np.array([0.0, 0.0, -height_m - float(np.asarray(position_body_m)[2])])
    outline = ground_footprint(intrinsics, rotation_body_cam, position_body_m, vehicle,
                               np.array([1.0, 0.0, 0.0, 0.0]))
    if outline is None:
        return 0.0
    a, b = outline, np.roll(outline, -1, axis=0)
    # inside: the outline winds the same way round the nadir at every edge
    cross = (b[:, 0] - a[:, 0]) * (-a[:, 1]) - (b[:, 1] - a[:, 1]) * (-a[:, 0])
    if not (np.all(cross > 0) or np.all(cross < 0)):
        return 0.0
    edge = b - a
    t = np.clip(np.einsum("ij,ij->i", -a, edge) / np.einsum("ij,ij->i", edge, edge), 0.0, 1.0)
    nearest = a + edge * t[:, None]
    return 2.0 * float(np.min(np.linalg.norm(nearest, axis=1))) / height_m
