"""What a real camera does to its image, as the simulated camera does it: capture-time jitter
and dropped frames, motion blur from the vehicle's motion during the exposure, rolling
shutter, read noise, exposure steps and the H.264 codec's round trip."""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from drivers.base import CameraInfo
from drivers.geometry import quat_to_matrix

if TYPE_CHECKING:
    from drivers.sim.config import CameraConfig

#: Blur shorter than this (pixels over the exposure) is not applied: it would barely change
#: the image, for 0.5 ms of filtering (in follow_ball, 40 % of frames blur by 0.3-0.5 px while
#: the vehicle turns slowly, about 5 % by more).


#: Blur shorter than this (pixels over the exposure) is not applied: it would barely change
#: the image, for 0.5 ms of filtering (in follow_ball, 40 % of frames blur by 0.3-0.5 px while
#: the vehicle turns slowly, about 5 % by more).
MIN_BLUR_PX = 0.5
#: Rolling shutter: the ideal render's margin covers row shifts up to this rotation rate.
MAX_RATE_RAD_S = 3.0
#: Depth used for the translational image motion is at least this (m).
MIN_DEPTH_M = 0.3


class RenderingUnavailable(RuntimeError):
    pass


@dataclass(frozen=True, slots=True)
class CameraEffects:
    """What a realistic camera adds to the ideal render (the distortion is the intrinsics')."""

    noise_std_dn: float = 0.0
    exposure_s: float = 0.0
    rolling_shutter_s: float = 0.0
    #: JPEG round trip at this quality (0: none)
    jpeg_quality: int = 0
    #: H.264 round trip at this bit rate (0: none)
    h264_bitrate_bps: int = 0
    rate_hz: float = 30.0

    @classmethod
    def from_config(cls, cfg: CameraConfig) -> CameraEffects | None:
        """None for an ideal camera (``realistic: false``)."""
        if not cfg.realistic:
            return None
        return cls(cfg.noise_std_dn, cfg.exposure_s, cfg.rolling_shutter_s,
                   cfg.codec_quality if cfg.codec == "jpeg" else 0,
                   cfg.codec_bitrate_bps if cfg.codec == "h264" else 0, cfg.rate_hz)


class H264RoundTrip:
    """A camera's frames through libx264 and back, as the network stream encodes them
    (drivers/video.py's settings; one thread, so the output is deterministic). With no
    B-frames and zero latency each frame comes out as it goes in."""

    def __init__(self, width_px: int, height_px: int, rate_hz: float, bitrate_bps: int) -> None:
        from fractions import Fraction

        import av

        enc = av.CodecContext.create("libx264", "w")
        enc.width, enc.height = width_px, height_px
        enc.pix_fmt = "yuv420p"
        enc.time_base = Fraction(1, 90_000)
        enc.framerate = Fraction(rate_hz).limit_denominator(1001)
        enc.bit_rate = bitrate_bps
        enc.thread_count = 1
        enc.options = {"preset": "ultrafast", "tune": "zerolatency",
                       "x264-params": "keyint=30:bframes=0:repeat-headers=1:annexb=1"}
        enc.open()
        self._enc = enc
        self._dec = av.CodecContext.create("h264", "r")
        self._dec.thread_count = 1
        self._pts = 0

    def __call__(self, image: np.ndarray) -> np.ndarray:
        import av

        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="bgr24")
        frame.pts = self._pts
        self._pts += 3000
        out = None
        for packet in self._enc.encode(frame):
            for decoded in self._dec.decode(packet):
                out = decoded.to_ndarray(format="bgr24")
        return image if out is None else out


@dataclass(frozen=True, slots=True)
class Capture:
    """What happens to one frame between its capture and its delivery."""

    dropped: bool
    delay_s: float  # beyond the camera's latency
    gain: float  # the auto-exposure's brightness factor


class CaptureModel:
    """A camera's frame-to-frame imperfections: dropped frames, latency jitter (frames keep
    their order) and auto-exposure steps. One random stream per (seed, camera), drawn in
    capture order, so a lockstep run stays deterministic."""

    def __init__(self, name: str, cfg: CameraConfig, seed: int) -> None:
        on = cfg.realistic
        self.drop_fraction = cfg.drop_fraction if on else 0.0
        self.jitter_s = cfg.latency_jitter_s if on else 0.0
        self.step = cfg.auto_exposure_step if on else 0.0
        self.step_probability = -math.expm1(-1.0 / (cfg.rate_hz * cfg.auto_exposure_interval_s))
        self.gain = 1.0
        self._last_delay_s = 0.0
        self._period_s = 1.0 / cfg.rate_hz
        self._rng = np.random.default_rng((seed, zlib.crc32(name.encode()), 3))

    def next(self) -> Capture:
        rng = self._rng
        u_drop, u_step, u_dir, z = rng.random(), rng.random(), rng.random(), rng.standard_normal()
        if self.step > 0.0 and u_step < self.step_probability:
            # a bounded walk: at most two steps from the nominal exposure
            up = u_dir < 0.5
            if self.gain >= 1.0 + 1.5 * self.step:
                up = False
            elif self.gain <= 1.0 - 1.5 * self.step:
                up = True
            self.gain += self.step if up else -self.step
        # the previous frame's delay less a period: the next frame cannot overtake it
        delay = max(abs(z) * self.jitter_s, self._last_delay_s - self._period_s)
        self._last_delay_s = delay
        return Capture(u_drop < self.drop_fraction, delay, self.gain)


@dataclass(frozen=True, slots=True, eq=False)
class VehicleMotion:
    """The vehicle's true state at a frame's capture (local NED, body FRD), for motion blur
    and rolling shutter. The ground is the plane z = 0."""

    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    attitude_q: np.ndarray  # body FRD → NED
    angular_velocity_frd_rad_s: np.ndarray


def image_motion_px_s(info: CameraInfo, motion: VehicleMotion) -> tuple[float, float]:
    """How fast the scene moves across the image centre (pixels per second, u right, v down)
    as the vehicle moves: rotation, plus translation over the distance along the boresight to
    the ground (ignored for a boresight at or above the horizon).

    A static point seen by a camera turning at ω and moving at v (optical frame) moves at
    ``ẋ = −ω_y − v_x / Z``, ``ẏ = ω_x − v_y / Z`` in normalised coordinates at the centre."""
    r_world_body = quat_to_matrix(np.asarray(motion.attitude_q, dtype=float))
    r_body_cam = info.rotation_body_cam
    rates_body = np.asarray(motion.angular_velocity_frd_rad_s, dtype=float)
    w_cam = r_body_cam.T @ rates_body
    v_body = r_world_body.T @ np.asarray(motion.velocity_ned_m_s, dtype=float) \
        + np.cross(rates_body, info.position_body_m)
    v_cam = r_body_cam.T @ v_body
    boresight_down = float((r_world_body @ r_body_cam[:, 2])[2])
    height = -float(motion.position_ned_m[2] + (r_world_body @ info.position_body_m)[2])
    inv_depth = 0.0
    if boresight_down > 0.05 and height > 0.0:
        inv_depth = 1.0 / max(height / boresight_down, MIN_DEPTH_M)
    intr = info.intrinsics
    return (intr.fx * float(-w_cam[1] - v_cam[0] * inv_depth),
            intr.fy * float(w_cam[0] - v_cam[1] * inv_depth))


def blur_kernel(du_px: float, dv_px: float) -> np.ndarray | None:
    """A line kernel (``float32``, odd square, sums to 1) for a uniform motion of
    ``(du_px, dv_px)`` over the exposure, centred; None if the motion is under
    :data:`MIN_BLUR_PX`. The line is sampled finely and splatted bilinearly, so sub-pixel
    lengths and any direction come out right."""
    length = math.hypot(du_px, dv_px)
    if length < MIN_BLUR_PX:
        return None
    half = math.ceil(max(abs(du_px), abs(dv_px)) / 2.0 + 0.5)  # room for the bilinear splat
    size = 2 * half + 1
    s = np.linspace(-0.5, 0.5, max(16, math.ceil(length * 16)))
    x, y = half + s * du_px, half + s * dv_px
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    kernel = np.zeros((size, size), np.float64)
    np.add.at(kernel, (y0, x0), (1 - fx) * (1 - fy))
    np.add.at(kernel, (y0, x0 + 1), fx * (1 - fy))
    np.add.at(kernel, (y0 + 1, x0), (1 - fx) * fy)
    np.add.at(kernel, (y0 + 1, x0 + 1), fx * fy)
    return (kernel / kernel.sum()).astype(np.float32)
