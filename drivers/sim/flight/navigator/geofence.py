"""The geofence PX4's navigator keeps: GF_MAX_HOR_DIST and GF_MAX_VER_DIST from home (0: off),
and the uploaded fence (MAVLink mission type 1, :class:`Fence`): the horizontal position must
be inside at least one inclusion polygon or circle (if there is any) and outside every
exclusion polygon and circle. NAV_FENCE_RETURN_POINT is stored but not used (RTL returns
home)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely

from drivers.geo import GlobalOrigin
from drivers.mission import GLOBAL_FRAMES, MISSION_ERROR, Cmd, Frame, MissionItem, MissionRejected
from drivers.sim.flight.params import Parameters


def geofence_breach(params: Parameters, home: np.ndarray | None, fence: Fence | None,
                    position_ned_m: np.ndarray) -> str | None:
    """Why ``position_ned_m`` is outside the geofence (None: inside, or no fence)."""
    if home is None:
        return None
    horizontal = float(np.hypot(*(position_ned_m[:2] - home[:2])))
    height = float(home[2] - position_ned_m[2])
    max_h, max_v = params["GF_MAX_HOR_DIST"], params["GF_MAX_VER_DIST"]
    if max_h > 0 and horizontal > max_h:
        return f"{horizontal:.0f} m from home, GF_MAX_HOR_DIST {max_h:g} m"
    if max_v > 0 and height > max_v:
        return f"{height:.0f} m above home, GF_MAX_VER_DIST {max_v:g} m"
    return fence.breach(float(position_ned_m[0]), float(position_ned_m[1])) \
        if fence is not None else None


@dataclass(frozen=True, slots=True, eq=False)
class FenceArea:
    """One inclusion or exclusion area of an uploaded geofence, in local NED (north, east)."""

    inclusion: bool
    shape: str  # "polygon" | "circle"
    #: the area's number among the fence's polygons (or circles), in upload order
    index: int
    #: the mission items it was made of (sequence numbers)
    seqs: tuple[int, ...]
    #: polygons: a prepared shapely geometry (a self-intersecting outline is made valid with
    #: the even-odd rule, as PX4's crossing-number test sees it)
    geometry: shapely.Geometry | None = None
    center_ne_m: tuple[float, float] = (0.0, 0.0)
    radius_m: float = 0.0

    @property
    def name(self) -> str:
        return f"{'inclusion' if self.inclusion else 'exclusion'} {self.shape} {self.index}"

    def contains(self, north_m: float, east_m: float) -> bool:
        """Whether the point is in the area. The boundary counts as allowed: inside an
        inclusion area, outside an exclusion area."""
        if self.geometry is None:
            inside = math.hypot(north_m - self.center_ne_m[0], east_m - self.center_ne_m[1])
            return inside <= self.radius_m if self.inclusion else inside < self.radius_m
        if self.inclusion:
            return bool(shapely.intersects_xy(self.geometry, north_m, east_m))
        return bool(shapely.contains_xy(self.geometry, north_m, east_m))


class Fence:
    """An uploaded geofence (MAVLink mission type 1), built once per upload: the horizontal
    position is inside when it is in at least one inclusion area (or there is none) and in no
    exclusion area, as PX4's ``Geofence::isInsidePolygonOrCircle``."""

    def __init__(self, areas: Sequence[FenceArea]) -> None:
        self.areas = tuple(areas)
        self.inclusions = tuple(a for a in self.areas if a.inclusion)
        self.exclusions = tuple(a for a in self.areas if not a.inclusion)

    @classmethod
    def from_items(cls, items: Sequence[MissionItem], origin: GlobalOrigin) -> Fence | None:
        """The fence of a list of fence items (sorted by seq); None if it has no area.
        Raises :class:`MissionRejected` (MISSION_ERROR) for a malformed list."""
        areas: list[FenceArea] = []
        counts = {"polygon": 0, "circle": 0}
        i = 0
        while i < len(items):
            item = items[i]
            cmd = item.command
            if cmd in (Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                       Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION):
                group = _polygon_group(items, i)
                vertices = [_fence_point(v, origin) for v in group]
                areas.append(FenceArea(cmd == Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, "polygon",
                                       counts["polygon"], tuple(v.seq for v in group),
                                       geometry=_polygon_geometry(vertices, group[0].seq)))
                counts["polygon"] += 1
                i += len(group)
                continue
            if cmd in (Cmd.NAV_FENCE_CIRCLE_INCLUSION, Cmd.NAV_FENCE_CIRCLE_EXCLUSION):
                radius = item.param1
                if not (math.isfinite(radius) and radius > 0):
                    raise MissionRejected(f"fence item {item.seq}: circle radius (param1) must "
                                          f"be positive, got {radius:g}", MISSION_ERROR,
                                          item.seq)
                areas.append(FenceArea(cmd == Cmd.NAV_FENCE_CIRCLE_INCLUSION, "circle",
                                       counts["circle"], (item.seq,),
                                       center_ne_m=_fence_point(item, origin),
                                       radius_m=float(radius)))
                counts["circle"] += 1
            elif cmd != Cmd.NAV_FENCE_RETURN_POINT:  # the return point is not used
                raise MissionRejected(f"fence item {item.seq}: command {cmd} is not a fence "
                                      "item", MISSION_ERROR, item.seq)
            i += 1
        return cls(areas) if areas else None

    def breach(self, north_m: float, east_m: float) -> str | None:
        """Why the horizontal position is outside the fence (None: inside)."""
        if self.inclusions and not any(a.contains(north_m, east_m) for a in self.inclusions):
            if len(self.inclusions) == 1:
                return f"outside the {self.inclusions[0].name}"
            return "outside every inclusion area (" + ", ".join(
                a.name.removeprefix("inclusion ") for a in self.inclusions) + ")"
        for area in self.exclusions:
            if area.contains(north_m, east_m):
                return f"inside the {area.name}"
        return None


def _polygon_group(items: Sequence[MissionItem], start: int) -> list[MissionItem]:
    """The vertices of the polygon that starts at ``items[start]`` (param1: vertex count)."""
    first = items[start]
    count = first.param1
    if not (math.isfinite(count) and count == int(count) and count >= 3):
        raise MissionRejected(f"fence item {first.seq}: a polygon needs at least 3 vertices "
                              f"(param1 = {count:g})", MISSION_ERROR, first.seq)
    group = list(items[start:start + int(count)])
    for vertex in group:
        if vertex.command != first.command or vertex.param1 != count:
            raise MissionRejected(f"fence item {vertex.seq}: polygon from item {first.seq} "
                                  f"should have {int(count)} vertices of command "
                                  f"{first.command}", MISSION_ERROR, vertex.seq)
    if len(group) < count:
        raise MissionRejected(f"fence item {first.seq}: polygon of {int(count)} vertices has "
                              f"only {len(group)}", MISSION_ERROR, first.seq)
    return group


def _fence_point(item: MissionItem, origin: GlobalOrigin) -> tuple[float, float]:
    """(north, east) of a fence item's position."""
    if not item.has_position:
        raise MissionRejected(f"fence item {item.seq}: no position", MISSION_ERROR, item.seq)
    if item.frame in GLOBAL_FRAMES:
        north, east, _ = origin.to_ned(item.x, item.y, origin.alt_amsl_m)
        return north, east
    if item.frame == Frame.LOCAL_NED:
        return float(item.x), float(item.y)
    raise MissionRejected(f"fence item {item.seq}: frame {item.frame} is not supported",
                          MISSION_ERROR, item.seq)


def _polygon_geometry(vertices: list[tuple[float, float]], seq: int) -> shapely.Geometry:
    geometry = shapely.make_valid(shapely.Polygon(vertices))
    if not geometry.geom_type.endswith("Polygon"):  # e.g. lines left of a degenerate outline
        parts = [g for g in shapely.get_parts(geometry) if g.geom_type == "Polygon"]
        geometry = shapely.MultiPolygon(parts) if parts else shapely.Polygon()
    if geometry.is_empty or geometry.area <= 1e-6:
        raise MissionRejected(f"fence item {seq}: the polygon encloses no area",
                              MISSION_ERROR, seq)
    shapely.prepare(geometry)
    return geometry
