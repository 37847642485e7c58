"""Photos the mission's steps ask for (orbit, survey), taken from the companion computer's own
camera stream, as seed 004's action servers did.

While a step that takes photos runs, :class:`PhotoLane` subscribes to its camera and keeps the
newest few frames and the telemetry of the last seconds. A :class:`PhotoRequest` names the
moment the vehicle passed a photo point; the frame captured nearest that moment becomes the
photo, with the vehicle's pose at the frame's capture time (the telemetry interpolated). Each
photo is logged (``/photos``) and, with a run folder, written to ``photos/`` as a JPEG with its
position (EXIF GPS), time, camera (make, model, focal length) and attitude (XMP), off the event
loop. At the end, ``photos/photos.geojson`` holds every photo's position, pose, time and
footprint on the ground.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as dt
import json
import logging
import math
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from autopilot.behaviors.base import PhotoRequest
from autopilot.config import AppConfig
from autopilot.flightlog import records as ch
from autopilot.flightlog.log import FlightLog
from autopilot.photos import CameraExif, CameraPose, write_geotagged_jpeg
from autopilot.planning.footprint import ground_footprint
from drivers.base import Frame, Vehicle, VehicleState
from drivers.capabilities import OnDemandCameras
from drivers.geometry import euler_from_quat
from drivers.threads import lower_this_thread

log = logging.getLogger(__name__)

_FRAMES_KEPT = 16
_STATES_KEPT = 250  # 5 s of telemetry at 50 Hz


class PhotoLane:
    def __init__(self, vehicle: Vehicle, flight_log: FlightLog, config: AppConfig,
                 folder: Path | None) -> None:
        self.vehicle = vehicle
        self.log = flight_log
        self.config = config
        self.folder = folder
        self.group: asyncio.TaskGroup | None = None
        self.records: list[dict] = []
        self.taken = 0
        self.errors: list[str] = []
        self._camera: str | None = None
        self._task: asyncio.Task | None = None
        self._frames: deque[Frame] = deque(maxlen=_FRAMES_KEPT)
        self._states: deque[VehicleState] = deque(maxlen=_STATES_KEPT)
        self._pending: list[tuple[int, str, PhotoRequest]] = []
        self._writer: ThreadPoolExecutor | None = None
        self._writes: list = []
        #: a camera rendered on demand (the simulator's) is kept running only while a photo
        #: is near; a video stream (its decoder needs every frame) for as long as the step runs
        self._on_demand = isinstance(vehicle, OnDemandCameras) and vehicle.renders_on_demand
        # the clock's epoch on UTC: photo times in EXIF are wall-clock times
        self._utc_offset_s = time.time() - vehicle.clock.now()

    # -- what the runtime calls ---------------------------------------------------------------

    def add_state(self, state: VehicleState) -> None:
        self._states.append(state)

    async def use(self, camera: str | None) -> None:
        """Keep ``camera``'s frames (None: none); photos still waiting are taken from the
        frames there are before the camera changes."""
        if camera == self._camera:
            return
        self._resolve(final=True)
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._task
            self._task = None
        self._camera = camera
        self._frames.clear()
        if camera is not None and camera not in self.vehicle.cameras:
            self.errors.append(f"no camera {camera!r} for photos")
            self._camera = None
            return
        if not self._on_demand:
            self._subscribe()

    def want(self, soon: bool) -> None:
        """Whether a photo is near (a camera rendered on demand runs only then)."""
        if not self._on_demand:
            return
        if soon or self._pending:
            self._subscribe()
        elif self._task is not None:
            self._task.cancel()
            self._task = None

    def _subscribe(self) -> None:
        if self._task is None and self._camera is not None and self.group is not None:
            self._task = self.group.create_task(self._run(self._camera),
                                                name=f"photos-{self._camera}")

    def request(self, step_index: int, step: str, photo: PhotoRequest) -> None:
        self._pending.append((step_index, step, photo))
        self._subscribe()
        self._resolve()

    def close(self) -> None:
        """Take what is still waiting, finish the writes, write ``photos.geojson``."""
        self._resolve(final=True)
        if self._writer is not None:
            self._writer.shutdown(wait=True)
        for future in self._writes:
            with contextlib.suppress(Exception):
                exc = future.exception()
                if exc is not None:
                    self.errors.append(f"photo not written: {exc}")
        if self.folder is not None and self.records:
            self.folder.mkdir(parents=True, exist_ok=True)
            (self.folder / "photos.geojson").write_text(json.dumps(self.geojson(), indent=1))

    # -- internals ----------------------------------------------------------------------------

    async def _run(self, camera: str) -> None:
        async with contextlib.aclosing(self.vehicle.frames(camera)) as frames:
            async for frame in frames:
                self._frames.append(frame)
                self._resolve()

    def _resolve(self, final: bool = False) -> None:
        if not self._pending or not self._frames:
            if final:
                for _step_index, step, req in self._pending:
                    self.errors.append(f"photo {req.index} of step {step}: no frame")
                self._pending.clear()
            return
        newest = self._frames[-1].time_s
        keep = []
        for item in self._pending:
            req = item[2]
            if newest >= req.time_s or final:
                frame = min(self._frames, key=lambda f: abs(f.time_s - req.time_s))
                self._save(item[0], item[1], req, frame)
            else:
                keep.append(item)
        self._pending = keep

    def _state_at(self, time_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        """(position, attitude) at ``time_s`` from the telemetry kept (position interpolated,
        attitude from the nearest sample)."""
        states = self._states
        if not states:
            return None
        after = next((s for s in states if s.time_s >= time_s), None)
        before = next((s for s in reversed(states) if s.time_s <= time_s), None)
        if before is None or after is None or after.time_s <= before.time_s:
            s = after or before
            return np.array(s.position_ned_m), np.array(s.attitude_q)
        f = (time_s - before.time_s) / (after.time_s - before.time_s)
        pos = before.position_ned_m + f * (after.position_ned_m - before.position_ned_m)
        q = (before if f < 0.5 else after).attitude_q
        return np.array(pos), np.array(q)

    def _save(self, step_index: int, step: str, req: PhotoRequest, frame: Frame) -> None:
        pose = self._state_at(frame.time_s)
        if pose is None:
            self.errors.append(f"photo {req.index}: no telemetry")
            return
        pos, q = pose
        cam_cfg = self.config.vehicle.cameras.get(frame.camera.name)
        roll, pitch, yaw = euler_from_quat(q)
        cam_pitch = cam_cfg.pitch_deg if cam_cfg is not None else -90.0
        cam_yaw = cam_cfg.yaw_deg if cam_cfg is not None else 0.0
        yaw_deg = (math.degrees(yaw) + cam_yaw) % 360.0
        home = self.vehicle.home_ned_m
        height = float((home[2] if home is not None else 0.0) - pos[2])
        origin = self.vehicle.global_origin
        lat = lon = alt = None
        if origin is not None:
            lat, lon, alt = origin.to_global(float(pos[0]), float(pos[1]), float(pos[2]))
        taken = dt.datetime.fromtimestamp(frame.time_s + self._utc_offset_s, tz=dt.UTC)
        name = f"photo_{len(self.records):04d}.jpg"
        record = {
            "time_s": frame.time_s, "index": req.index, "step_index": step_index, "step": step,
            "camera": frame.camera.name, "file": name if self.folder is not None else None,
            "requested_s": req.time_s, "lat_deg": lat, "lon_deg": lon, "alt_amsl_m": alt,
            "position_ned_m": pos, "attitude_q": q, "yaw_deg": yaw_deg,
            "planned_ned_m": req.planned_ned_m, "look_at_ned_m": req.look_at_ned_m,
            "height_above_home_m": height, "taken_utc": taken.isoformat()}
        self.records.append(record)
        self.taken += 1
        self.log.write(ch.PHOTOS, frame.time_s, ch.clean(
            {k: v for k, v in record.items() if k != "taken_utc"}))
        if self.folder is None:
            return
        intr = frame.camera.intrinsics
        sensor = self.config.photos.sensor_width_mm
        exif = CameraExif(self.config.photos.make, self.config.photos.model,
                          focal_length_mm=intr.fx * sensor / intr.width_px,
                          focal_length_35mm=round(intr.fx * 36.0 / intr.width_px))
        attitude = CameraPose(yaw_deg, cam_pitch + math.degrees(pitch), math.degrees(roll),
                              height)
        if self._writer is None:
            self._writer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="photos",
                                              initializer=lower_this_thread)
            self.folder.mkdir(parents=True, exist_ok=True)
        self._writes.append(self._writer.submit(
            write_geotagged_jpeg, self.folder / name, frame.image, lat_deg=lat, lon_deg=lon,
            alt_amsl_m=alt, taken_utc=taken, heading_deg=yaw_deg,
            quality=self.config.photos.jpeg_quality, camera=exif, pose=attitude))

    def geojson(self) -> dict:
        """Every photo as a point (its position and pose) and its footprint on the ground
        (from the pose the autopilot knew, at home's height), in WGS-84."""
        origin = self.vehicle.global_origin
        cameras = self.vehicle.cameras
        home = self.vehicle.home_ned_m
        ground = float(home[2]) if home is not None else 0.0
        features = []
        for r in self.records:
            props = {k: v for k, v in ch.clean(r).items()
                     if k not in ("lat_deg", "lon_deg", "alt_amsl_m")}
            if origin is None:
                continue
            features.append({"type": "Feature", "geometry": {
                "type": "Point", "coordinates": [r["lon_deg"], r["lat_deg"], r["alt_amsl_m"]]},
                "properties": dict(props, kind="photo")})
            cam = cameras.get(r["camera"])
            if cam is None:
                continue
            outline = ground_footprint(cam.intrinsics, cam.rotation_body_cam,
                                       cam.position_body_m, r["position_ned_m"],
                                       r["attitude_q"], ground)
            if outline is None:
                continue
            ring = [list(origin.to_global(float(n), float(e), ground)[1::-1])
                    for n, e in outline]
            ring.append(ring[0])
            features.append({"type": "Feature", "geometry": {"type": "Polygon",
                                                             "coordinates": [ring]},
                             "properties": {"kind": "footprint", "file": r["file"],
                                            "index": r["index"], "step": r["step"]}})
        return {"type": "FeatureCollection", "features": features}
