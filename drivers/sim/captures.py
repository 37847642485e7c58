"""The vehicle's cameras as the simulator runs them: when each captures (its schedule on the
physics step grid, its dropped, delayed and auto-exposed frames: :class:`CaptureModel`), which
frames are shed in real time when the simulator is behind the wall clock, and the photos its
photo camera takes. The pixels are drawn by the :class:`CameraRig` (drivers/sim/camera.py)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from drivers.base import CameraInfo, Frame
from drivers.geo import GlobalOrigin
from drivers.sim.camera import CameraRig, PendingFrame, SimCamera
from drivers.sim.camera_effects import CameraEffects, CaptureModel, VehicleMotion
from drivers.sim.config import SimConfig
from drivers.sim.faults import FaultSchedule
from drivers.sim.flight.navigator import NavEvent
from drivers.sim.model import reported_camera_info
from drivers.sim.schedule import Schedule
from drivers.sim.sensors import EstimatedState

#: The camera that takes the photos of missions and camera commands.
PHOTO_CAMERA = "down"


@dataclass(frozen=True, slots=True, eq=False)
class Photo:
    """A photo the vehicle's camera took (a mission's camera item, a trigger distance, …):
    the image, and where the vehicle was when it was taken (as the estimator had it)."""

    time_s: float
    index: int
    frame: Frame | None  # None: the vehicle has no such camera (disabled)
    position_ned_m: np.ndarray
    attitude_q: np.ndarray
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    height_above_home_m: float


class CameraCaptures:
    def __init__(self, model: mujoco.MjModel, built: Mapping[str, tuple[int, CameraInfo]],
                 config: SimConfig, seed: int, faults: FaultSchedule) -> None:
        cams = config.cameras
        #: the cameras by name
        self.cameras = {name: SimCamera(cam_id, info, cams[name].latency_s,
                                        CameraEffects.from_config(cams[name]),
                                        reported_camera_info(name, cams[name]))
                        for name, (cam_id, info) in built.items()}
        self._models = {name: CaptureModel(name, cams[name], seed) for name in self.cameras}
        #: draws the pixels (on its own thread)
        self.rig = CameraRig(model, seed)
        #: real time, behind the wall clock: every other frame due is skipped, not rendered,
        #: as is any while its camera still draws the last, and a frame not drawn when due is
        #: delivered when it is (the physics and telemetry come first, never waiting for the
        #: rendering; set by the driver)
        self.shed_rendering = False
        rate = config.physics_rate_hz
        #: each camera's captures on the physics step grid
        self.schedules = {name: Schedule(rate / cam.info.rate_hz)
                          for name, cam in self.cameras.items()}
        self._lead_s = config.realtime_render_lead_s
        self._faults = faults

    def capture_due(self, step: int, t: float, data: mujoco.MjData,
                    motion: Callable[[], VehicleMotion],
                    fault_time_s: float | None) -> list[tuple[float, PendingFrame]]:
        """The frames captured at physics step ``step`` (time ``t``; ``fault_time_s`` on the
        faults' clock, where a ``camera_dropout`` keeps its camera from capturing), each with
        its delivery time."""
        out = []
        now = None
        for name, cam in self.cameras.items():
            sched = self.schedules[name]
            if step < sched.next_step:
                continue
            if cam.active and self.shed_rendering and (cam.may_shed or self.rig.rendering(cam)):
                # every other frame (the video goes on at half its rate), and any frame
                # whose camera is still rendering the last one: physics does not wait
                cam.shed += 1
                cam.may_shed = False
            elif cam.active and not (self._faults and self._faults.camera(
                    "camera_dropout", name, fault_time_s)):
                capture = self._models[name].next()
                if capture.dropped:
                    cam.seq += 1  # the autopilot sees the gap in the sequence numbers
                else:
                    due = t + cam.latency_s + capture.delay_s
                    if now is None:
                        now = motion()
                    cam.may_shed = True
                    out.append((due, self.rig.submit(data, cam, t, due - self._lead_s, now,
                                                     capture.gain)))
            sched.advance(step)
        return out

    def next_due_s(self, dt_s: float) -> list[float]:
        """The earliest delivery time of each active camera's next frame."""
        return [self.schedules[name].next_step * dt_s + cam.latency_s
                for name, cam in self.cameras.items() if cam.active]

    def ready(self, pending: PendingFrame) -> bool:
        """May a frame due now be delivered? (Shedding, one still being drawn waits.)"""
        return not self.shed_rendering or pending.image.done()

    def photo(self, data: mujoco.MjData, event: NavEvent, est: EstimatedState,
              origin: GlobalOrigin, home: Sequence[float] | None,
              motion: VehicleMotion) -> tuple[float, str, Photo | tuple[Photo, PendingFrame]]:
        """A photo the navigator's ``event`` takes now with :data:`PHOTO_CAMERA`, geotagged
        with the estimate ``est`` (as PX4's camera feedback does), and its delivery time: the
        photo, or the photo and its frame still to be drawn (no frame: no such camera)."""
        lat, lon, alt = origin.to_global(*(float(v) for v in est.position_ned_m))
        height = float((home[2] if home is not None else 0.0) - est.position_ned_m[2])
        meta = Photo(event.time_s, event.seq, None, est.position_ned_m.copy(),
                     est.q_ned_frd.copy(), lat, lon, alt, height)
        cam = self.cameras.get(PHOTO_CAMERA)
        if cam is None:
            return event.time_s, "photo", meta
        pending = self.rig.submit(data, cam, event.time_s, motion=motion)
        return event.time_s + cam.latency_s, "photo", (meta, pending)

    def capture_now(self, camera: str, data: mujoco.MjData, t: float,
                    motion: VehicleMotion) -> Frame:
        """Render a camera now, synchronously (whether or not it is active)."""
        return self.rig.finish(self.rig.submit(data, self.cameras[camera], t, motion=motion))
