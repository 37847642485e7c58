"""The keep-out zones the autopilot has seen: blue discs (:mod:`autopilot.perception.keep_out`)
placed on the ground and merged into a small map, and the watcher that keeps it
(:class:`KeepOutWatcher`, a :class:`~autopilot.watch.Watcher`: it runs on every frame the
running step's cameras deliver, whatever the step).

Only frames and telemetry go in: a disc is placed with the vehicle's estimated pose at the
frame's capture time, so a zone lives in the frame the vehicle navigates in (its GNSS errors
included, which is what the setpoints it guards are in too). The ground plane is NED down 0
(the take-off point's level), or — better, as the barometer's height wanders by decimetres —
the level the rangefinder measures under the vehicle near the frame's time
(:func:`~autopilot.perception.pad_pipeline.ground_level`, the median of the nearest readings).

The same disc seen again refines its zone: its centre and radius are averages weighted by how
well each view places it (the slant range² over the height: a disc far ahead on the ground is
placed coarsely by a degree of pointing error, one below finely) with a slow forgetting, so
that the zone follows the navigation's slow drift. A zone counts (the guard respects it) once
it has been seen ``confirm_after`` times; a candidate not confirmed within a few seconds is
forgotten (one odd blob is not a zone).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from autopilot.estimation.pose_history import PoseHistory
from autopilot.perception.keep_out import (
    DiscAcceptance,
    DiscDetection,
    DiscDetector,
    GroundCircle,
    accept,
    ground_circle,
)
from autopilot.perception.pad_pipeline import ground_level
from autopilot.watch import WatchReport
from drivers.base import CameraInfo, VehicleState


@dataclass(frozen=True, slots=True)
class KeepOutZone:
    """A keep-out zone as the guard reads it: a disc on the ground (local NED)."""

    index: int
    centre_ne_m: tuple[float, float]
    radius_m: float  # the disc's, as measured
    observations: int


@dataclass(frozen=True, slots=True)
class MapSettings:
    confirm_after: int = 3  # views before a zone counts
    #: a view whose circle lies within this of a zone's edge is that disc seen again
    merge_gap_m: float = 0.5
    #: each older view's weight is multiplied by this at every new view of its zone
    memory: float = 0.95
    forget_unconfirmed_s: float = 3.0  # a candidate not confirmed within this is dropped
    max_zones: int = 32


class _Zone:
    __slots__ = ("centre", "count", "first_s", "index", "last_s", "radius", "weight")

    def __init__(self, index: int, circle: GroundCircle, weight: float, time_s: float) -> None:
        self.index = index
        self.centre = np.array(circle.centre_ne_m, float)
        self.radius = circle.radius_m
        self.weight = weight
        self.count = 1
        self.first_s = self.last_s = time_s


class KeepOutMap:
    """The zones seen so far (see the module's notes); synchronous, on the loop."""

    def __init__(self, settings: MapSettings = MapSettings()) -> None:
        self.settings = settings
        self._zones: list[_Zone] = []
        self._next_index = 0
        self.version = 0  # changes whenever the confirmed zones do

    def observe(self, circle: GroundCircle, time_s: float) -> tuple[int, str | None]:
        """One view of a disc: the zone it refines or starts (its index; -1: the map is full)
        and a note when that makes a new zone count."""
        s = self.settings
        self._zones = [z for z in self._zones if z.count >= s.confirm_after
                       or time_s - z.first_s <= s.forget_unconfirmed_s]
        weight = 1.0 / circle.std_m ** 2
        zone, best = None, math.inf
        for z in self._zones:
            gap = float(np.linalg.norm(z.centre - circle.centre_ne_m)) \
                - max(z.radius, circle.radius_m)
            if gap <= s.merge_gap_m and gap < best:
                zone, best = z, gap
        if zone is None:
            if len(self._zones) >= s.max_zones:
                return -1, None
            zone = _Zone(self._next_index, circle, weight, time_s)
            self._next_index += 1
            self._zones.append(zone)
        else:
            zone.weight = s.memory * zone.weight + weight
            share = weight / zone.weight
            zone.centre = zone.centre + share * (np.asarray(circle.centre_ne_m) - zone.centre)
            zone.radius += share * (circle.radius_m - zone.radius)
            zone.count += 1
            zone.last_s = time_s
        if zone.count >= s.confirm_after:
            self.version += 1
        if zone.count == s.confirm_after:
            n, e = zone.centre
            return zone.index, (f"keep-out zone {zone.index} seen at ({n:.2f}, {e:.2f}) m, "
                                f"radius {zone.radius:.2f} m")
        return zone.index, None

    def zones(self) -> tuple[KeepOutZone, ...]:
        """The zones that count (confirmed), oldest first."""
        c = self.settings.confirm_after
        return tuple(KeepOutZone(z.index, (float(z.centre[0]), float(z.centre[1])),
                                 float(z.radius), z.count)
                     for z in self._zones if z.count >= c)

    def record(self, time_s: float) -> dict:
        """The flight log's record of the zones that count."""
        return {"time_s": time_s, "zones": [
            {"index": z.index, "centre_ne_m": list(z.centre_ne_m), "radius_m": z.radius_m,
             "observations": z.observations} for z in self.zones()]}


@dataclass(frozen=True, slots=True)
class WatcherSettings:
    every_n_frames: int = 1
    use_rangefinder: bool = True  # the ground's level from it (else NED down 0)


class KeepOutWatcher:
    """Blue discs in every frame the running step's cameras deliver, placed on the ground
    and merged into :attr:`map` (a :class:`~autopilot.watch.Watcher`)."""

    def __init__(self, name: str, detector: DiscDetector, rules: DiscAcceptance,
                 zone_map: KeepOutMap, settings: WatcherSettings, *, observations_topic: str,
                 zones_topic: str) -> None:
        self.name = self.kind = name
        self.detector = detector
        self.rules = rules
        self.map = zone_map
        self.settings = settings
        self.observations_topic = observations_topic
        self.zones_topic = zones_topic
        self.history = PoseHistory()
        self._levels: deque[tuple[float, float]] = deque(maxlen=200)  # (time, ground level)
        self._last_reading = math.nan

    def add_state(self, state: VehicleState) -> None:
        self.history.add(state)
        r = state.distance_to_ground_m
        if math.isfinite(r) and r != self._last_reading:  # (telemetry repeats a reading)
            level = ground_level(state)
            if math.isfinite(level):
                self._levels.append((state.time_s, level))
        self._last_reading = r

    def ground_at(self, time_s: float, max_gap_s: float = 0.5, count: int = 5) -> float:
        """The ground's level (NED down) near ``time_s``: the median of the nearest
        rangefinder readings (an outlier is voted out); 0 (the take-off point's level) when
        there are none or they are not to be used."""
        if not self.settings.use_rangefinder:
            return 0.0
        near = sorted((abs(t - time_s), level) for t, level in self._levels
                      if abs(t - time_s) <= max_gap_s)
        return float(np.median([level for _, level in near[:count]])) if near else 0.0

    def looks_at(self, camera: str, seq: int) -> bool:
        return seq % self.settings.every_n_frames == 0

    def detect(self, image_bgr: np.ndarray, camera: CameraInfo, time_s: float,
               hint: object | None = None) -> DiscDetection | None:
        return self.detector.detect(image_bgr, camera, time_s)

    def update(self, time_s: float, seq: int, camera: CameraInfo,
               detection: DiscDetection | None) -> WatchReport:
        if detection is None:
            return WatchReport()
        pose = self.history.pose_at(time_s)
        ground = self.ground_at(time_s)
        version = self.map.version
        seen, notes = [], []
        for blob in detection.blobs:
            circle = ground_circle(blob, camera, pose, ground) if pose is not None else None
            why = "no pose at its time" if pose is None else \
                "not on the ground" if circle is None else accept(circle, self.rules)
            zone = -1
            if why is None:
                zone, note = self.map.observe(circle, time_s)
                if note is not None:
                    notes.append(note)
            u, v = blob.center_px
            seen.append({"u_px": u, "v_px": v, "area_px": blob.area_px, "clipped": blob.clipped,
                         "accepted": why is None, "why": why or "", "zone": zone,
                         **({} if circle is None else {
                             "centre_ne_m": circle.centre_ne_m, "radius_m": circle.radius_m,
                             "fit_error": circle.fit_error, "arc_deg": circle.arc_deg,
                             "range_m": circle.range_m})})
        records = [(self.observations_topic, {"time_s": time_s, "seq": seq,
                                              "camera": camera.name, "ground_down_m": ground,
                                              "blobs": seen})]
        if self.map.version != version:
            records.append((self.zones_topic, self.map.record(time_s)))
        return WatchReport(tuple(records), tuple(notes))
