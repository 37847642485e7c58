"""The camera model shared by the simulator and the autopilot: a pinhole with OpenCV's lens
distortion (``k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tx ty]]]]``, the "plumb bob" model and
its extensions), as :class:`~drivers.base.CameraIntrinsics` describes it.

Frames and conventions:

* optical frame: x right, y down, z forward (metres; only directions matter here);
* *normalised* image coordinates: ``(x, y) = (X / Z, Y / Z)`` of a point ``(X, Y, Z)`` in the
  optical frame, unitless (the tangent of the angle off the optical axis, per axis).
  *Ideal* normalised coordinates are those of the pinhole; *distorted* ones are where the lens
  puts the point, before the camera matrix: ``(u, v) = (fx·x_d + cx, fy·y_d + cy)``;
* pixels: OpenCV's convention, ``u`` right and ``v`` down, pixel centres at integer coordinates
  (the top-left pixel's centre is (0, 0), the image spans −0.5 … width − 0.5).

A detection found in a distorted image is turned into a bearing with :func:`undistort_points`
(ideal normalised coordinates: the direction ``(x, y, 1)`` in the optical frame) or
:func:`pixel_rays` (unit vectors). Points are projected into a distorted image with
:func:`project_points`. The simulator renders an ideal pinhole image (:func:`render_intrinsics`)
and distorts it with ``cv2.remap`` through :func:`distortion_maps`.

These are pure functions (the map builders are cached per intrinsics); inputs may be a single
point or an ``(N, 2)`` / ``(N, 3)`` array, outputs are ``float64`` arrays shaped alike (one
point in, one point out).
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from drivers.base import CameraIntrinsics

#: Undistortion iterates to this: OpenCV's default (5 fixed-point iterations) leaves errors of
#: a few thousandths of a pixel in the corners of a wide-angle lens; this leaves < 1e-6 px.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)
_NO_ROTATION = np.zeros(3)


def pinhole(width_px: int, height_px: int, hfov_deg: float,
            distortion=(0.0, 0.0, 0.0, 0.0, 0.0)) -> CameraIntrinsics:
    """A camera with square pixels and the principal point at the image centre
    (``((width − 1) / 2, (height − 1) / 2)`` in OpenCV's convention), whose ideal pinhole spans
    ``hfov_deg`` horizontally (edge to edge of the image), with the given distortion."""
    f = (width_px / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
    return CameraIntrinsics(width_px, height_px, f, f, (width_px - 1) / 2.0,
                            (height_px - 1) / 2.0, tuple(float(c) for c in distortion))


def distortion_problem(intrinsics: CameraIntrinsics) -> str | None:
    """Why the distortion cannot describe a real lens over this image (None if it can): the
    image must stay one-to-one out to its corners (the radial polynomial rising), and
    undistortion must converge there."""
    if not is_distorted(intrinsics):
        return None
    w, h = intrinsics.width_px, intrinsics.height_px
    corners = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [-0.5, h - 0.5], [w - 0.5, h - 0.5]])
    limit = _monotonic_radius(tuple(distortion_coefficients(intrinsics).tolist()))
    with np.errstate(all="ignore"):
        ideal = undistort_points(intrinsics, corners)
        back = project_points(intrinsics, np.column_stack([ideal, np.ones(4)]))
    radius = float(np.max(np.hypot(ideal[:, 0], ideal[:, 1]), initial=0.0))
    if not np.all(np.isfinite(back)) or np.max(np.abs(back - corners)) > 0.01 \
            or radius >= limit:
        return ("the lens model folds over (the distortion stops increasing with the angle) "
                "within the image; use smaller coefficients")
    return None


def is_distorted(intrinsics: CameraIntrinsics) -> bool:
    """Does the camera have any lens distortion (a non-zero coefficient)?"""
    return any(intrinsics.distortion)


def distortion_coefficients(intrinsics: CameraIntrinsics) -> np.ndarray:
    """OpenCV's ``distCoeffs`` (at least 4, zero-padded to 5)."""
    d = np.asarray(intrinsics.distortion, dtype=np.float64).ravel()
    return np.pad(d, (0, 5 - d.size)) if d.size < 5 else d


def distort_points(intrinsics: CameraIntrinsics, points_norm) -> np.ndarray:
    """Ideal normalised coordinates → distorted normalised coordinates (both unitless, the
    distorted ones before the camera matrix). Only the distortion coefficients are used."""
    pts, shape = _as_points(points_norm, 2)
    if not is_distorted(intrinsics):
        return pts.reshape(shape)
    xyz = np.concatenate([pts, np.ones((len(pts), 1))], axis=1)
    out, _ = cv2.projectPoints(xyz, _NO_ROTATION, _NO_ROTATION, np.eye(3),
                               distortion_coefficients(intrinsics))
    return out.reshape(shape)


def undistort_points(intrinsics: CameraIntrinsics, points_px, *,
                     to_pixels: bool = False) -> np.ndarray:
    """Observed pixel coordinates (in the distorted image) → ideal normalised coordinates
    ``(x, y)``, so that ``(x, y, 1)`` is the point's direction in the optical frame; or, with
    ``to_pixels``, ideal pixel coordinates (where an ideal pinhole with the same camera matrix
    would have seen it). Inverse of :func:`project_points` to better than 1e-6 px within the
    image (OpenCV's ``undistortPoints``, iterated to convergence)."""
    pts, shape = _as_points(points_px, 2)
    k = intrinsics.matrix
    if not is_distorted(intrinsics):
        out = pts if to_pixels else (pts - (intrinsics.cx, intrinsics.cy)) / (intrinsics.fx,
                                                                               intrinsics.fy)
        return out.reshape(shape)
    out = cv2.undistortPoints(pts.reshape(-1, 1, 2), k, distortion_coefficients(intrinsics),
                              None, None, k if to_pixels else None, _UNDISTORT_CRITERIA)
    return out.reshape(shape)


def pixel_rays(intrinsics: CameraIntrinsics, points_px) -> np.ndarray:
    """Observed pixel coordinates → unit direction vectors in the optical frame, ``(N, 3)``
    (or ``(3,)`` for one point)."""
    xy = np.atleast_2d(undistort_points(intrinsics, points_px))
    rays = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    return rays[0] if np.ndim(points_px) == 1 else rays


def project_points(intrinsics: CameraIntrinsics, points_cam) -> np.ndarray:
    """Points in the optical frame (m) → pixel coordinates in the distorted image, as
    ``cv2.projectPoints`` computes them. Points behind the camera (z ≤ 0), and points so far
    off-axis that the distortion polynomial no longer increases with the angle (where it would
    fold them back into the image), come back as NaN."""
    pts, shape = _as_points(points_cam, 3)
    out = np.full((len(pts), 2), np.nan)
    front = pts[:, 2] > 1e-9
    if front.any():
        p = pts[front]
        r = np.hypot(p[:, 0], p[:, 1]) / p[:, 2]
        ok = r < _monotonic_radius(tuple(distortion_coefficients(intrinsics).tolist()))
        if ok.any():
            uv, _ = cv2.projectPoints(p[ok], _NO_ROTATION, _NO_ROTATION, intrinsics.matrix,
                                      distortion_coefficients(intrinsics))
            idx = np.flatnonzero(front)[ok]
            out[idx] = uv.reshape(-1, 2)
    return out.reshape((*shape[:-1], 2))


@functools.lru_cache(maxsize=64)
def _monotonic_radius(distortion: tuple[float, ...]) -> float:
    """The ideal normalised radius up to which the radial distortion keeps increasing
    (``r·radial(r)`` strictly rising), searched to r = 20 (87° off-axis); inf if throughout."""
    d = np.pad(np.asarray(distortion, dtype=np.float64), (0, max(0, 8 - len(distortion))))
    k1, k2, _p1, _p2, k3, k4, k5, k6 = d[:8]
    r = np.linspace(0.0, 20.0, 20001)
    r2 = r * r
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    rd = r * radial
    bad = np.flatnonzero((np.diff(rd) <= 0) | (radial[1:] <= 0))
    return float(r[bad[0]]) if bad.size else math.inf


def render_intrinsics(intrinsics: CameraIntrinsics, margin_px: int = 2,
                      fit: bool = False) -> CameraIntrinsics:
    """The ideal pinhole an image is rendered with before it is distorted into
    ``intrinsics``' image: no distortion, principal point at its centre (as MuJoCo renders),
    covering the ideal position of every pixel (centre) of the distorted image with
    ``margin_px`` to spare on each side (for interpolation and small shifts).

    With the same focal lengths (``fit`` False) the render is larger than the frame and has its
    resolution everywhere; its width and height grow by even numbers. With ``fit``, the focal
    lengths are scaled down until the render has the frame's size (plus margins): cheaper to
    render, at a slightly lower resolution than the frame's near the centre."""
    w, h = intrinsics.width_px, intrinsics.height_px
    # the frame's outermost pixel centres, as ideal normalised coordinates
    u = np.arange(w, dtype=np.float64)
    v = np.arange(h, dtype=np.float64)
    outline = np.concatenate([np.column_stack([u, np.zeros_like(u)]),
                              np.column_stack([u, np.full_like(u, h - 1)]),
                              np.column_stack([np.zeros_like(v), v]),
                              np.column_stack([np.full_like(v, w - 1), v])])
    xy = undistort_points(intrinsics, outline)
    reach_x = max(-xy[:, 0].min(), xy[:, 0].max())
    reach_y = max(-xy[:, 1].min(), xy[:, 1].max())
    scale = 1.0
    if fit:
        scale = min(1.0, (w - 1) / 2.0 / (reach_x * intrinsics.fx),
                    (h - 1) / 2.0 / (reach_y * intrinsics.fy))
    fx, fy = float(scale * intrinsics.fx), float(scale * intrinsics.fy)

    def size(n: int, reach_px: float) -> int:
        """The smallest n + 2k (k ≥ 0) whose centre is at least reach + margin from the
        outermost pixel centres ((n − 1) / 2 from the centre); a hair of slack for rounding."""
        return n + 2 * max(0, math.ceil((2.0 * (reach_px + margin_px) + 1.0 - n) / 2.0 - 1e-6))

    width, height = size(w, reach_x * fx), size(h, reach_y * fy)
    return CameraIntrinsics(width, height, fx, fy, (width - 1) / 2.0, (height - 1) / 2.0)


@functools.lru_cache(maxsize=16)
def distortion_maps(intrinsics: CameraIntrinsics,
                    source: CameraIntrinsics) -> tuple[np.ndarray, np.ndarray]:
    """``cv2.remap`` maps that turn an ideal pinhole image ``source`` (no distortion; usually
    :func:`render_intrinsics`) into ``intrinsics``' distorted image: for every pixel (u, v) of
    the distorted image, the ideal pixel of ``source`` that it sees (``float32``, height × width,
    read-only; cached, built once per pair of intrinsics)."""
    if is_distorted(source):
        raise ValueError("the source image must be an ideal pinhole (no distortion)")
    w, h = intrinsics.width_px, intrinsics.height_px
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    xy = undistort_points(intrinsics, np.column_stack([u.ravel(), v.ravel()]))
    map_x = (xy[:, 0] * source.fx + source.cx).reshape(h, w).astype(np.float32)
    map_y = (xy[:, 1] * source.fy + source.cy).reshape(h, w).astype(np.float32)
    map_x.flags.writeable = False
    map_y.flags.writeable = False
    return map_x, map_y


def _as_points(points, dim: int) -> tuple[np.ndarray, tuple[int, ...]]:
    arr = np.asarray(points, dtype=np.float64)
    if arr.shape[-1:] != (dim,):
        raise ValueError(f"expected points of shape (..., {dim}), got {arr.shape}")
    return arr.reshape(-1, dim), arr.shape
