"""Onboard cameras: headless MuJoCo rendering on a schedule, only while someone watches.

Rendering overlaps the physics: :meth:`CameraRig.submit` snapshots the scene as it is at capture
time (``mjv_updateScene``, CPU only, on the simulator's thread) and hands it to a dedicated render
thread, which draws and reads the pixels back (MuJoCo releases the GIL while it renders, and
Mesa's llvmpipe rasterises on worker threads of its own); :meth:`CameraRig.finish` collects the
image when the frame is due (capture time + camera latency). The image content is fixed at
capture, so this changes nothing but speed, and lockstep runs stay deterministic.

In real time, a render can also be held back (``render_gate``) until shortly before its frame
is due. A real camera's exposure and readout cost the companion computer nothing; here the
rendering takes both cores for a few milliseconds. Started at capture, it would land on the
autopilot's processing of the previous frame (which is delivered 30 ms after its capture, 3 ms
before the next capture); held back, it runs while the autopilot is idle between frames.

The OpenGL context lives on the render thread, the only thread that touches it. In real time
that thread (and Mesa's rasteriser threads, which inherit it) runs at a lower CPU priority
(``background``): on a real vehicle the camera is its own hardware, so rendering should not
take the CPU from the autopilot's detector when both are busy. In lockstep it keeps normal
priority: there the render is what the simulation waits for, while the physics stepping
alongside it has time to spare (lowered, it cost 10-15 % of the real-time factor). Each camera
has its own MuJoCo render context (offscreen framebuffer) and scene; :meth:`CameraRig.prepare`
makes them before flight. Pixels are read back as BGRA
(llvmpipe's native layout, cheaper than MuJoCo's RGB read-back); wherever nothing was drawn
(alpha 0: MuJoCo clears to transparent black) the sky is painted in the world's haze colour.
Frames are delivered top-down BGR, as OpenCV expects.

A ``realistic`` camera (``CameraConfig.realistic``, the default) delivers what a small drone's
camera would, not MuJoCo's ideal pinhole; after the read-back, on a thread of its own (the
camera model's: the render thread draws the next frame meanwhile, one frame at a time and in
order, so a seed's frames are the same), in order:

* **lens distortion** (OpenCV's k1 k2 p1 p2 k3, reported in the frame's intrinsics so the
  autopilot can undistort with them; see drivers/camera_model.py): MuJoCo renders an ideal
  pinhole with the frame's focal length, larger by what the barrel pulls in at the edges
  (front camera: 726×546 for 640×480, down: 680×512), and ``cv2.remap`` distorts it through
  maps built once per camera (the vertical flip of OpenGL's bottom-up rows is folded into
  them). The larger render costs about 1.1 ms CPU a frame; rendering at the frame's size with
  a shorter focal length instead (``render_intrinsics(fit=True)``) saves that, but follow_ball
  flew worse on the magnified render (RMS image error 14.0 px instead of 11.2 px; ideal camera:
  11.8 px);
* **rolling shutter** (``rolling_shutter_s`` > 0): row *i* is exposed ``(i / (H − 1) − ½) ·
  rolling_shutter_s`` after the frame's time stamp (the middle row's), so each row is shifted
  by the image motion over that time (per-frame maps);
* **motion blur**: the image motion over the exposure (``exposure_s``, centred on the time
  stamp), applied as a line kernel (``cv2.filter2D``); nothing when it is under 0.5 px;
* **read noise**: Gaussian, ``noise_std_dn`` in 8-bit digital numbers, rounded and clipped:
  a window of a bank of noise (two frames' worth, drawn once per camera from the simulator's
  seed and the camera's name) at an offset drawn for each frame from (seed, camera, frame
  number), so frames stay deterministic whatever order the cameras render in.

* **exposure steps**: the frame's auto-exposure gain (:class:`CaptureModel`), applied before
  the noise;
* **codec**: a JPEG round trip (``codec: jpeg``, ``codec_quality``; about 2 ms a frame) or an
  H.264 one as the network stream's (``codec: h264``, ``codec_bitrate_bps``; stateful, one
  encoder per camera), the artefacts of a compressed stream.

Between capture and delivery (:class:`CaptureModel`, drawn on the simulator's thread in capture
order, so lockstep runs stay deterministic): dropped frames (``drop_fraction``; never rendered),
latency jitter (``latency_jitter_s``, frames keep their order) and the auto-exposure's steps.
The camera renders with its true mount (off nominal by ``mount_error_deg``) and intrinsics;
its frames report :attr:`SimCamera.reported`, the nominal mount and the intrinsics of its
calibration file (see autopilot/sim_calibration.py).

The image motion for blur and rolling shutter is that of the image centre, from the vehicle's
true angular and linear velocity at capture (:class:`VehicleMotion`): rotation, plus translation
over the distance along the boresight to the ground (the translation of a camera looking at
or above the horizon is ignored). Rotation about the optical axis, which blurs only towards
the edges, and the scene's own motion (a moving ball) are not blurred.

Cost on the 2-core development machine, 640×480, CPU time of one thread: 1.0-1.4 ms a frame
(sky 0.1, remap 0.7, noise 0.1 ms), plus 0.45-0.9 ms for a frame that is blurred (about 5 % of
follow_ball's), plus 1 ms with a rolling shutter while moving; the larger render 1.1 ms. The
maps (0.1 s) and the noise bank (20 ms) are made by ``prepare``.
"""

from __future__ import annotations

import contextlib
import math
import os
import threading
import zlib
from collections.abc import Callable, Iterable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import mujoco
import numpy as np

from drivers import camera_model
from drivers.base import CameraInfo, Frame

if TYPE_CHECKING:
    pass
from drivers.sim.camera_effects import (
    MAX_RATE_RAD_S,
    CameraEffects,
    H264RoundTrip,
    RenderingUnavailable,
    VehicleMotion,
    blur_kernel,
    image_motion_px_s,
)
from drivers.stages import STAGES


class SimCamera:
    def __init__(self, cam_id: int, info: CameraInfo, latency_s: float,
                 effects: CameraEffects | None = None,
                 reported: CameraInfo | None = None) -> None:
        self.cam_id = cam_id
        #: The camera as it is (rendered so) ...
        self.info = info
        #: ... and as its frames describe it (nominal mount, calibrated intrinsics).
        self.reported = reported or info
        self.latency_s = latency_s
        #: None: the ideal pinhole image (then ``info`` has no distortion either).
        self.effects = effects
        #: Rendered only while active (someone subscribed to the frames).
        self.active = False
        self.seq = 0
        self.rendered = 0
        #: frames skipped, not rendered, to keep real time (``CameraCaptures.shed_rendering``)
        self.shed = 0
        #: the last frame due was rendered: the next may be shed
        self.may_shed = True


@dataclass(eq=False, slots=True)
class PendingFrame:
    """A frame captured (scene snapshot taken) whose pixels may still be rendering."""

    camera: SimCamera
    time_s: float
    seq: int
    image: Future[np.ndarray]
    #: done once the scene is drawn and read back (the snapshot may then be overwritten); a
    #: realistic camera's model and codec may still be working on the pixels
    drawn: Future | None = None
    frame: Frame | None = None


class _CameraTarget:
    """A camera's MuJoCo scene, and its render context (made on the render thread); for a
    realistic camera, what its post-processing needs (made on the camera model's thread)."""

    def __init__(self, model: mujoco.MjModel, cam: SimCamera, seed: int) -> None:
        intr = cam.info.intrinsics
        effects = cam.effects
        self.cam = cam
        #: Does the ideal render go through cv2.remap (distortion, rolling shutter)?
        self.warp = effects is not None and (camera_model.is_distorted(intr)
                                             or effects.rolling_shutter_s > 0)
        if self.warp:
            shift = math.ceil(max(intr.fx, intr.fy) * MAX_RATE_RAD_S
                              * effects.rolling_shutter_s / 2.0)
            source = camera_model.render_intrinsics(intr, margin_px=2 + shift)
        else:
            source = intr
        #: The ideal pinhole MuJoCo renders (the frame's focal length, larger when warped).
        self.source = source
        self.scene = mujoco.MjvScene(model, maxgeom=2000)
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self.camera.fixedcamid = cam.cam_id
        #: The model's camera has the frame's vertical field of view; the render's is wider.
        self.frustum_scale = (source.height_px / source.fy) / (intr.height_px / intr.fy)
        self.rect = mujoco.MjrRect(0, 0, source.width_px, source.height_px)
        self.bgra = np.empty((source.height_px, source.width_px, 4), dtype=np.uint8)
        self.sky = np.empty((source.height_px, source.width_px, 3), dtype=np.uint8)
        self.sky[:] = np.round(np.asarray(model.vis.rgba.haze[2::-1]) * 255).astype(np.uint8)
        self.sky_bgra = cv2.cvtColor(self.sky, cv2.COLOR_BGR2BGRA) if self.warp else None
        self.context: mujoco.MjrContext | None = None
        self.pending: PendingFrame | None = None
        #: Noise streams: (simulator seed, camera), the same whatever the camera's id.
        self.noise_key = (seed, zlib.crc32(cam.info.name.encode()))
        self.maps: tuple[np.ndarray, np.ndarray] | None = None
        self.row_times_s: np.ndarray | None = None
        self.noise: tuple[np.ndarray, np.ndarray] | None = None
        self.h264: H264RoundTrip | None = None


class CameraRig:
    def __init__(self, model: mujoco.MjModel, seed: int = 0) -> None:
        self._model = model
        #: The simulator's seed: realistic cameras' noise derives from it.
        self.seed = seed
        #: Called on the render thread with the time (simulator clock) at which a scheduled
        #: frame may start rendering; returns when that time has come. None: render at once.
        self.render_gate: Callable[[float], None] | None = None
        #: Render at a lower CPU priority (set before the first render; see the module notes).
        self.background = False
        self._gl = None
        self._targets: dict[int, _CameraTarget] = {}
        self._option = mujoco.MjvOption()
        # onboard cameras render geom groups 0-1: the airframe's own geoms (groups 2-4) are
        # out of their view, so skipping them only saves time
        self._option.geomgroup[2:] = 0
        self._thread: ThreadPoolExecutor | None = None
        #: a realistic camera's model and codec, on a thread of their own: the next frame is
        #: drawn while this one is post-processed (in order, one frame at a time)
        self._post_thread: ThreadPoolExecutor | None = None

    def prepare(self, data: mujoco.MjData, cams: Iterable[SimCamera]) -> None:
        """Make the OpenGL and render contexts of ``cams`` now and draw each once, so that a
        missing OpenGL fails before flight (:class:`RenderingUnavailable`) and the first frames
        do not pay for context creation and Mesa's shader compilation (about 0.3 s)."""
        for cam in cams:
            target = self._snapshot(data, cam)
            drawn = self._executor().submit(self._draw_stage, target, None)
            if cam.effects is None:
                drawn.result()
            else:
                self._post_executor().submit(self._post_stage, target, drawn, None, cam.seq,
                                             1.0).result()

    def submit(self, data: mujoco.MjData, cam: SimCamera, time_s: float,
               render_from_s: float | None = None,
               motion: VehicleMotion | None = None, gain: float = 1.0) -> PendingFrame:
        """Capture what ``cam`` sees now; the image is collected by :meth:`finish`. With a
        ``render_gate``, rendering waits until ``render_from_s`` (if given). ``motion``: the
        vehicle's at capture, for a realistic camera's motion blur and rolling shutter (None:
        at rest); ``gain``: its auto-exposure's brightness factor."""
        target = self._snapshot(data, cam)
        drawn = self._executor().submit(self._draw_stage, target, render_from_s)
        if cam.effects is None:
            image = drawn
        else:
            image = self._post_executor().submit(self._post_stage, target, drawn, motion,
                                                 cam.seq, gain)
        pending = PendingFrame(cam, time_s, cam.seq, image, drawn)
        cam.seq += 1
        cam.rendered += 1
        target.pending = pending
        return pending

    def rendering(self, cam: SimCamera) -> bool:
        """Is ``cam``'s last frame still being drawn? (Capturing the next would wait for it.)"""
        target = self._targets.get(cam.cam_id)
        return target is not None and target.pending is not None \
            and not target.pending.drawn.done()

    def _snapshot(self, data: mujoco.MjData, cam: SimCamera) -> _CameraTarget:
        """Update ``cam``'s scene from ``data`` (after collecting a frame still rendering it)."""
        target = self._targets.get(cam.cam_id)
        if target is None:
            target = self._targets[cam.cam_id] = _CameraTarget(self._model, cam, self.seed)
        if target.pending is not None:  # the scene is about to be overwritten
            target.pending.drawn.result()
        mujoco.mjv_updateScene(self._model, data, self._option, None, target.camera,
                               mujoco.mjtCatBit.mjCAT_ALL.value, target.scene)
        if target.frustum_scale != 1.0:  # the render's wider field of view
            for gl_camera in target.scene.camera:
                gl_camera.frustum_bottom *= target.frustum_scale
                gl_camera.frustum_top *= target.frustum_scale
        return target

    def _executor(self) -> ThreadPoolExecutor:
        if self._thread is None:
            self._thread = ThreadPoolExecutor(max_workers=1, thread_name_prefix="render")
        return self._thread

    def _post_executor(self) -> ThreadPoolExecutor:
        if self._post_thread is None:
            self._post_thread = ThreadPoolExecutor(
                max_workers=1, thread_name_prefix="camera-model",
                initializer=lower_thread_priority if self.background else None)
        return self._post_thread

    def finish(self, pending: PendingFrame) -> Frame:
        """The captured frame (waits for the render if it is not done; once per frame)."""
        if pending.frame is None:
            image, jpeg = pending.image.result()
            pending.frame = Frame(camera=pending.camera.reported, time_s=pending.time_s,
                                  seq=pending.seq, image=image, jpeg=jpeg)
            target = self._targets[pending.camera.cam_id]
            if target.pending is pending:
                target.pending = None
        return pending.frame

    def _draw_stage(self, target: _CameraTarget, render_from_s: float | None
                    ) -> tuple[np.ndarray, bytes | None] | np.ndarray:
        """On the render thread: draw the snapshot and read it back. An ideal camera's image,
        top-down BGR, with no JPEG; a realistic camera's, rows still bottom-up (a copy: the
        read-back buffer is the next frame's), for :meth:`_post_stage`."""
        if render_from_s is not None and self.render_gate is not None:
            self.render_gate(render_from_s)
        if self._gl is None:
            if self.background:
                lower_thread_priority()
            self._gl = _make_gl_context(self._model)
        if target.context is None:
            offscreen = self._model.vis.global_  # the render context's framebuffer size
            offscreen.offwidth = max(offscreen.offwidth, target.rect.width)
            offscreen.offheight = max(offscreen.offheight, target.rect.height)
            try:
                target.context = mujoco.MjrContext(self._model,
                                                   mujoco.mjtFontScale.mjFONTSCALE_50.value)
            except Exception as exc:  # mujoco.FatalError and friends
                raise _unavailable(exc) from exc
            _fast_texture_filtering(target.context)
        with STAGES.stage(f"render.{target.cam.info.name}"):
            bgr = self._draw(target, target.context)
            if target.cam.effects is None:
                image = cv2.flip(bgr, 0)  # OpenGL rows run bottom-up
                image.flags.writeable = False
                return image, None
            return bgr.copy() if bgr is target.bgra else bgr

    def _post_stage(self, target: _CameraTarget, drawn: Future, motion: VehicleMotion | None,
                    seq: int, gain: float) -> tuple[np.ndarray, bytes | None]:
        """On the camera-model thread (once ``drawn`` is): make a realistic camera's render
        look like a real camera's; with the JPEG it was decoded from, if its codec's round trip
        was the last thing done to it."""
        bgr = drawn.result()
        effects = target.cam.effects
        if effects is None:
            return bgr
        name = target.cam.info.name
        with STAGES.stage(f"camera model.{name}"):
            image = self._realistic(target, effects, bgr, motion, seq, gain)
        with STAGES.stage(f"codec.{name}"):
            image, jpeg = self._codec(target, effects, image)
        image.flags.writeable = False
        return image, jpeg

    @staticmethod
    def _draw(target: _CameraTarget, context: mujoco.MjrContext) -> np.ndarray:
        """Draw the snapshot and read it back (rows bottom-up, the sky painted)."""
        # every camera has its own render context and framebuffer on the one OpenGL context;
        # the bound framebuffer is OpenGL state, so bind this camera's before drawing (else a
        # second camera draws into the first one's buffer and each reads the other's image)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, context)
        mujoco.mjr_render(target.rect, target.scene, context)
        if context.offSamples:  # multisampled buffers need MuJoCo's resolve; no sky painting
            rgb = np.empty(target.sky.shape, dtype=np.uint8)
            mujoco.mjr_readPixels(rgb, None, target.rect, context)
            bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
        else:
            gl = _gl()
            gl.glBindFramebuffer(gl.GL_READ_FRAMEBUFFER, context.offFBO)
            gl.glReadPixels(0, 0, target.rect.width, target.rect.height, gl.GL_BGRA,
                            gl.GL_UNSIGNED_BYTE, target.bgra)
            background = cv2.compare(cv2.extractChannel(target.bgra, 3), 0, cv2.CMP_EQ)
            if target.warp:  # stays BGRA through the remap (cheaper: 4-byte pixels)
                cv2.copyTo(target.sky_bgra, background, target.bgra)
                bgr = target.bgra
            else:
                bgr = cv2.cvtColor(target.bgra, cv2.COLOR_BGRA2BGR)
                cv2.copyTo(target.sky, background, bgr)
        return bgr

    @staticmethod
    def _realistic(target: _CameraTarget, effects: CameraEffects, bottom_up: np.ndarray,
                   motion: VehicleMotion | None, seq: int, gain: float = 1.0) -> np.ndarray:
        """Distortion (and rolling shutter), motion blur, exposure and read noise; see the
        module notes."""
        info = target.cam.info
        rate_u, rate_v = image_motion_px_s(info, motion) if motion is not None else (0.0, 0.0)
        if target.warp:
            if target.maps is None:
                target.maps = _warp_maps(info.intrinsics, target.source)
                rows = np.arange(info.intrinsics.height_px, dtype=np.float32)
                target.row_times_s = ((rows / max(rows.size - 1, 1) - 0.5)
                                      * effects.rolling_shutter_s).reshape(-1, 1)
            map_x, map_y = target.maps
            if effects.rolling_shutter_s > 0 and (rate_u or rate_v):
                # row i sees the scene as it was t_i later: displaced by the image motion
                t = target.row_times_s
                to_source = target.source.fx / info.intrinsics.fx  # render pixels per frame's
                map_x = map_x - np.float32(rate_u * to_source) * t
                map_y = map_y + np.float32(rate_v * to_source) * t  # source rows bottom-up
            # float maps on BGRA pixels: OpenCV's fastest bilinear remap (SIMD), 1 ms
            image = cv2.remap(bottom_up, map_x, map_y, cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REPLICATE)
            if image.shape[2] == 4:
                image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
        else:
            image = cv2.flip(bottom_up, 0)
        if effects.exposure_s > 0:
            kernel = blur_kernel(rate_u * effects.exposure_s, rate_v * effects.exposure_s)
            if kernel is not None:
                image = cv2.filter2D(image, -1, kernel, borderType=cv2.BORDER_REPLICATE)
        if gain != 1.0:
            image = cv2.convertScaleAbs(image, alpha=gain)
        if effects.noise_std_dn > 0:
            n = image.size
            if target.noise is None:  # two frames' worth, drawn once
                rng = np.random.default_rng((*target.noise_key, 0))
                noise = np.rint(rng.standard_normal(2 * n, dtype=np.float32)
                                * effects.noise_std_dn)
                # as its positive and negative parts: two saturating uint8 operations add it
                target.noise = (np.clip(noise, 0, 255).astype(np.uint8),
                                np.clip(-noise, 0, 255).astype(np.uint8))
            offset = int(np.random.default_rng((*target.noise_key, 1, seq)).integers(0, n + 1))
            up, down = (part[offset:offset + n].reshape(image.shape) for part in target.noise)
            image = cv2.add(image, up)
            cv2.subtract(image, down, dst=image)
        return image

    @staticmethod
    def _codec(target: _CameraTarget, effects: CameraEffects, image: np.ndarray
               ) -> tuple[np.ndarray, bytes | None]:
        """The codec's round trip (JPEG or H.264), with the JPEG the image was decoded from."""
        jpeg = None
        if effects.jpeg_quality:
            _, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY,
                                                   effects.jpeg_quality])
            image = cv2.imdecode(data, cv2.IMREAD_COLOR)
            jpeg = data.tobytes()
        if effects.h264_bitrate_bps:
            if target.h264 is None:
                intr = target.cam.info.intrinsics
                target.h264 = H264RoundTrip(intr.width_px, intr.height_px, effects.rate_hz,
                                            effects.h264_bitrate_bps)
            image, jpeg = target.h264(image), None
        return image, jpeg

    def _release(self) -> None:
        for target in self._targets.values():
            if target.context is not None:
                target.context.free()
        if self._gl is not None:
            self._gl.free()
            self._gl = None

    def close(self) -> None:
        STAGES.sample_threads()  # (they end with the OpenGL context and the pool)
        for target in self._targets.values():
            if target.pending is not None:
                target.pending.image.cancel()
                target.pending.drawn.cancel()
        if self._post_thread is not None:
            self._post_thread.shutdown(wait=True, cancel_futures=True)
            self._post_thread = None
        if self._thread is not None:
            self._thread.submit(self._release).result()
            self._thread.shutdown(wait=True)
            self._thread = None
        self._targets.clear()


def _warp_maps(intrinsics, source) -> tuple[np.ndarray, np.ndarray]:
    """``cv2.remap`` maps (``float32``) from the ideal render as read back (rows bottom-up) to
    the distorted frame (top-down)."""
    map_x, map_y = camera_model.distortion_maps(intrinsics, source)
    map_y = (source.height_px - 1) - map_y  # OpenGL rows run bottom-up
    return map_x, map_y


def lower_thread_priority(niceness: int = 10) -> None:
    """Lower this thread's scheduling priority (Linux: niceness is per thread, and threads
    started from here inherit it). Elsewhere, or if not permitted, nothing changes."""
    with contextlib.suppress(AttributeError, OSError):  # not Linux, or not permitted
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(),
                       os.getpriority(os.PRIO_PROCESS, 0) + niceness)


def _make_gl_context(model: mujoco.MjModel):
    """An OpenGL context for the backend ``MUJOCO_GL`` names (EGL by default), chosen here
    rather than when mujoco was imported, so that importing mujoco first does not matter."""
    backend = os.environ.get("MUJOCO_GL", "egl").lower()
    try:
        if backend == "egl":
            from mujoco.egl import GLContext
        elif backend == "osmesa":
            from mujoco.osmesa import GLContext
        elif backend == "glfw":
            from mujoco.glfw import GLContext
        else:
            raise RuntimeError(f"unknown MUJOCO_GL backend {backend!r} (egl, osmesa, glfw)")
        ctx = GLContext(model.vis.global_.offwidth, model.vis.global_.offheight)
        ctx.make_current()
        return ctx
    except Exception as exc:
        raise _unavailable(exc) from exc


def _unavailable(exc: Exception) -> RenderingUnavailable:
    backend = os.environ.get("MUJOCO_GL", "egl")
    return RenderingUnavailable(
        f"cannot render headless with MUJOCO_GL={backend!r}: {exc}. Install Mesa's EGL "
        "(Debian: apt install libegl1 libgl1-mesa-dri) or disable the cameras "
        "(--set vehicle.cameras.front.enabled=false --set vehicle.cameras.down.enabled=false).")


def _gl():
    """PyOpenGL (it ships with mujoco), imported once MuJoCo has chosen the platform (EGL)."""
    from OpenGL import GL

    return GL


def _fast_texture_filtering(context: mujoco.MjrContext) -> None:
    """Bilinear filtering within the nearest mipmap level (GL_LINEAR_MIPMAP_NEAREST) instead of
    MuJoCo's trilinear: 10-15 % faster frames on llvmpipe, at the cost of a faint seam where the
    mipmap level changes far away on textured ground."""
    GL = _gl()
    for i in range(context.ntexture):
        if context.textureType[i] == mujoco.mjtTexture.mjTEXTURE_2D:
            GL.glBindTexture(GL.GL_TEXTURE_2D, int(context.texture[i]))
            GL.glTexParameteri(GL.GL_TEXTURE_2D, GL.GL_TEXTURE_MIN_FILTER,
                               GL.GL_LINEAR_MIPMAP_NEAREST)
    GL.glBindTexture(GL.GL_TEXTURE_2D, 0)
