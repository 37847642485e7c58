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
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable, Iterable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import mujoco
import numpy as np

from drivers.base import CameraInfo, Frame


class RenderingUnavailable(RuntimeError):
    pass


class SimCamera:
    def __init__(self, cam_id: int, info: CameraInfo, latency_s: float) -> None:
        self.cam_id = cam_id
        self.info = info
        self.latency_s = latency_s
        #: Rendered only while active (someone subscribed to the frames).
        self.active = False
        self.seq = 0
        self.rendered = 0


@dataclass(eq=False, slots=True)
class PendingFrame:
    """A frame captured (scene snapshot taken) whose pixels may still be rendering."""

    camera: SimCamera
    time_s: float
    seq: int
    image: Future[np.ndarray]
    frame: Frame | None = None


class _CameraTarget:
    """A camera's MuJoCo scene, and its render context (made on the render thread)."""

    def __init__(self, model: mujoco.MjModel, cam: SimCamera) -> None:
        intr = cam.info.intrinsics
        self.scene = mujoco.MjvScene(model, maxgeom=2000)
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self.camera.fixedcamid = cam.cam_id
        self.rect = mujoco.MjrRect(0, 0, intr.width_px, intr.height_px)
        self.bgra = np.empty((intr.height_px, intr.width_px, 4), dtype=np.uint8)
        self.sky = np.empty((intr.height_px, intr.width_px, 3), dtype=np.uint8)
        self.sky[:] = np.round(np.asarray(model.vis.rgba.haze[2::-1]) * 255).astype(np.uint8)
        self.context: mujoco.MjrContext | None = None
        self.pending: PendingFrame | None = None


class CameraRig:
    def __init__(self, model: mujoco.MjModel) -> None:
        self._model = model
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

    def prepare(self, data: mujoco.MjData, cams: Iterable[SimCamera]) -> None:
        """Make the OpenGL and render contexts of ``cams`` now and draw each once, so that a
        missing OpenGL fails before flight (:class:`RenderingUnavailable`) and the first frames
        do not pay for context creation and Mesa's shader compilation (about 0.3 s)."""
        for cam in cams:
            self._executor().submit(self._render, self._snapshot(data, cam)).result()

    def submit(self, data: mujoco.MjData, cam: SimCamera, time_s: float,
               render_from_s: float | None = None) -> PendingFrame:
        """Capture what ``cam`` sees now; the image is collected by :meth:`finish`. With a
        ``render_gate``, rendering waits until ``render_from_s`` (if given)."""
        target = self._snapshot(data, cam)
        pending = PendingFrame(cam, time_s, cam.seq,
                               self._executor().submit(self._render, target, render_from_s))
        cam.seq += 1
        cam.rendered += 1
        target.pending = pending
        return pending

    def _snapshot(self, data: mujoco.MjData, cam: SimCamera) -> _CameraTarget:
        """Update ``cam``'s scene from ``data`` (after collecting a frame still rendering it)."""
        target = self._targets.get(cam.cam_id)
        if target is None:
            target = self._targets[cam.cam_id] = _CameraTarget(self._model, cam)
        if target.pending is not None:  # the scene is about to be overwritten
            self.finish(target.pending)
        mujoco.mjv_updateScene(self._model, data, self._option, None, target.camera,
                               mujoco.mjtCatBit.mjCAT_ALL.value, target.scene)
        return target

    def _executor(self) -> ThreadPoolExecutor:
        if self._thread is None:
            self._thread = ThreadPoolExecutor(max_workers=1, thread_name_prefix="render")
        return self._thread

    def finish(self, pending: PendingFrame) -> Frame:
        """The captured frame (waits for the render if it is not done; once per frame)."""
        if pending.frame is None:
            image = pending.image.result()
            pending.frame = Frame(camera=pending.camera.info, time_s=pending.time_s,
                                  seq=pending.seq, image=image)
            target = self._targets[pending.camera.cam_id]
            if target.pending is pending:
                target.pending = None
        return pending.frame

    def _render(self, target: _CameraTarget, render_from_s: float | None = None) -> np.ndarray:
        """On the render thread: draw the snapshot, read it back top-down BGR."""
        if render_from_s is not None and self.render_gate is not None:
            self.render_gate(render_from_s)
        if self._gl is None:
            if self.background:
                lower_thread_priority()
            self._gl = _make_gl_context(self._model)
        if target.context is None:
            try:
                target.context = mujoco.MjrContext(self._model,
                                                   mujoco.mjtFontScale.mjFONTSCALE_50.value)
            except Exception as exc:  # mujoco.FatalError and friends
                raise _unavailable(exc) from exc
            mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, target.context)
            _fast_texture_filtering(target.context)
        context = target.context
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
            bgr = cv2.cvtColor(target.bgra, cv2.COLOR_BGRA2BGR)
            cv2.copyTo(target.sky, background, bgr)
        image = cv2.flip(bgr, 0)  # OpenGL rows run bottom-up
        image.flags.writeable = False
        return image

    def _release(self) -> None:
        for target in self._targets.values():
            if target.context is not None:
                target.context.free()
        if self._gl is not None:
            self._gl.free()
            self._gl = None

    def close(self) -> None:
        for target in self._targets.values():
            if target.pending is not None:
                target.pending.image.cancel()
        if self._thread is not None:
            self._thread.submit(self._release).result()
            self._thread.shutdown(wait=True)
            self._thread = None
        self._targets.clear()


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
        "(--set sim.cameras.front.enabled=false --set sim.cameras.down.enabled=false).")


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
