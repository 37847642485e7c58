"""The simulated vehicle's geofence (MAVLink mission type 1) without an event loop: the fence
geometry built from uploaded items, its breach reasons, what an upload refuses, and the
mission feasibility check against it."""

import math

import numpy as np
import pytest
import shapely

from drivers.geo import GlobalOrigin
from drivers.mission import (
    MISSION_ERROR,
    Cmd,
    Frame,
    MissionItem,
    MissionRejected,
    MissionType,
)
from drivers.sim.flight.navigator import Fence, Navigator
from drivers.sim.flight.params import Parameters

ORIGIN = GlobalOrigin(47.397742, 8.545594, 488.0)
INCL, EXCL = Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION
C_INCL, C_EXCL = Cmd.NAV_FENCE_CIRCLE_INCLUSION, Cmd.NAV_FENCE_CIRCLE_EXCLUSION


def latlon(north_m: float, east_m: float) -> tuple[float, float]:
    lat, lon, _ = ORIGIN.to_global(north_m, east_m, 0.0)
    return lat, lon


def polygon(cmd: Cmd, corners_ne, first_seq: int = 0, frame: Frame = Frame.GLOBAL_INT,
            count: float | None = None) -> list[MissionItem]:
    items = []
    for k, (n, e) in enumerate(corners_ne):
        x, y = latlon(n, e) if frame != Frame.LOCAL_NED else (n, e)
        items.append(MissionItem(first_seq + k, frame, cmd, param1=len(corners_ne)
                                 if count is None else count, x=x, y=y, z=0.0,
                                 mission_type=MissionType.FENCE))
    return items


def circle(cmd: Cmd, center_ne, radius: float, seq: int = 0) -> MissionItem:
    x, y = latlon(*center_ne)
    return MissionItem(seq, Frame.GLOBAL_INT, cmd, param1=radius, x=x, y=y, z=0.0,
                       mission_type=MissionType.FENCE)


def square(half: float, center=(0.0, 0.0)):
    n, e = center
    return [(n - half, e - half), (n - half, e + half), (n + half, e + half),
            (n + half, e - half)]


def navigator() -> Navigator:
    nav = Navigator(Parameters(), ORIGIN, request_mode=lambda mode: None,
                    complete=lambda mode, then: None, event=lambda text: None)
    nav.home = np.zeros(3)
    return nav


def test_no_fence_items_no_fence():
    assert Fence.from_items([], ORIGIN) is None
    # a return point alone is no area (it is not used: RTL returns home)
    ret = MissionItem(0, Frame.GLOBAL_INT, Cmd.NAV_FENCE_RETURN_POINT, x=47.4, y=8.5, z=10.0)
    assert Fence.from_items([ret], ORIGIN) is None


def test_inclusion_polygon_in_global_coordinates():
    fence = Fence.from_items(polygon(INCL, square(20.0)), ORIGIN)
    assert fence.breach(0.0, 0.0) is None
    assert fence.breach(19.9, -19.9) is None
    assert fence.breach(20.5, 0.0) == "outside the inclusion polygon 0"
    assert fence.breach(0.0, -25.0) == "outside the inclusion polygon 0"


def test_local_ned_vertices():
    fence = Fence.from_items(polygon(INCL, [(0, 0), (0, 10), (10, 0)], frame=Frame.LOCAL_NED),
                             ORIGIN)
    assert fence.breach(2.0, 2.0) is None
    assert fence.breach(8.0, 8.0) is not None


def test_circles_and_exclusions():
    items = [circle(C_INCL, (0.0, 0.0), 50.0, seq=0),
             *polygon(EXCL, square(5.0, center=(20.0, 0.0)), first_seq=1),
             circle(C_EXCL, (-20.0, 0.0), 5.0, seq=5)]
    fence = Fence.from_items(items, ORIGIN)
    assert fence.breach(0.0, 0.0) is None
    assert fence.breach(0.0, 49.0) is None
    assert fence.breach(0.0, 51.0) == "outside the inclusion circle 0"
    assert fence.breach(20.0, 1.0) == "inside the exclusion polygon 0"
    assert fence.breach(-21.0, 1.0) == "inside the exclusion circle 1"
    assert fence.breach(-20.0, 6.0) is None


def test_any_inclusion_area_is_enough():
    items = [*polygon(INCL, square(10.0)), circle(C_INCL, (100.0, 0.0), 10.0, seq=4)]
    fence = Fence.from_items(items, ORIGIN)
    assert fence.breach(0.0, 0.0) is None
    assert fence.breach(105.0, 0.0) is None
    assert fence.breach(50.0, 0.0) == ("outside every inclusion area (polygon 0, circle 0)")


def test_only_exclusions_allow_everything_else():
    fence = Fence.from_items([circle(C_EXCL, (0.0, 30.0), 10.0)], ORIGIN)
    assert fence.breach(0.0, 0.0) is None
    assert fence.breach(1000.0, -1000.0) is None
    assert fence.breach(0.0, 35.0) == "inside the exclusion circle 0"


def test_two_polygons_back_to_back_with_the_same_count():
    items = [*polygon(INCL, [(0, 0), (0, 10), (10, 0)]),
             *polygon(INCL, [(100, 100), (100, 110), (110, 100)], first_seq=3)]
    fence = Fence.from_items(items, ORIGIN)
    assert [a.seqs for a in fence.areas] == [(0, 1, 2), (3, 4, 5)]
    assert fence.breach(101.0, 101.0) is None
    assert fence.breach(50.0, 50.0) is not None


def test_self_intersecting_outline_uses_the_even_odd_rule():
    # a bow tie: two triangles meeting at (5, 5) (PX4's crossing-number test sees the same)
    fence = Fence.from_items(polygon(INCL, [(0, 0), (10, 10), (10, 0), (0, 10)]), ORIGIN)
    assert fence.breach(1.0, 5.0) is None
    assert fence.breach(9.0, 5.0) is None
    assert fence.breach(5.0, 1.0) is not None
    assert fence.breach(5.0, 9.0) is not None


@pytest.mark.parametrize(("items", "match"), [
    (polygon(INCL, [(0, 0), (0, 10)]), "at least 3 vertices"),
    (polygon(INCL, square(5.0), count=5), "has only 4"),
    (polygon(INCL, square(5.0))[:3] + polygon(INCL, square(5.0), count=3)[3:],
     "should have 4 vertices"),
    (polygon(INCL, square(5.0))[:2] + polygon(EXCL, square(5.0))[2:], "should have 4"),
    (polygon(INCL, square(5.0), count=float("nan")), "at least 3 vertices"),
    (polygon(INCL, [(0, 0), (5, 5), (10, 10)]), "encloses no area"),
    ([circle(C_INCL, (0, 0), 0.0)], "radius"),
    ([circle(C_EXCL, (0, 0), float("nan"))], "radius"),
    ([MissionItem(0, Frame.MISSION, C_INCL, param1=5.0)], "no position"),
])
def test_malformed_fences_are_refused(items, match):
    with pytest.raises(MissionRejected, match=match) as info:
        Fence.from_items(items, ORIGIN)
    assert info.value.result == MISSION_ERROR


def test_a_refused_upload_keeps_the_previous_fence():
    nav = navigator()
    good = polygon(INCL, square(20.0))
    nav.set_items(good, MissionType.FENCE)
    fence_id = nav.status.fence_id
    assert fence_id != 0
    with pytest.raises(MissionRejected):
        nav.set_items(polygon(INCL, [(0, 0), (0, 10)]), MissionType.FENCE)
    assert nav.items(MissionType.FENCE) == good
    assert nav.fence is not None
    assert nav.geofence_breach(np.array([30.0, 0.0, -5.0])) == "outside the inclusion polygon 0"
    nav.set_items([], MissionType.FENCE)  # cleared
    assert nav.fence is None
    assert nav.geofence_breach(np.array([30.0, 0.0, -5.0])) is None


def test_distance_limits_come_first_and_only_when_set():
    nav = navigator()
    nav.set_items(polygon(INCL, square(100.0)), MissionType.FENCE)
    assert nav.geofence_breach(np.array([50.0, 0.0, -10.0])) is None
    nav.params.set("GF_MAX_HOR_DIST", 40.0)
    assert "GF_MAX_HOR_DIST 40 m" in nav.geofence_breach(np.array([50.0, 0.0, -10.0]))
    nav.params.set("GF_MAX_VER_DIST", 8.0)
    assert "GF_MAX_VER_DIST 8 m" in nav.geofence_breach(np.array([0.0, 0.0, -10.0]))


def test_a_mission_outside_the_fence_cannot_start():
    nav = navigator()
    lat, lon = latlon(30.0, 0.0)
    mission = [MissionItem(0, Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_WAYPOINT, x=lat, y=lon,
                           z=5.0)]
    nav.set_items(mission)
    assert nav.mission_problem(landed=True) is None
    nav.set_items(polygon(INCL, square(20.0)), MissionType.FENCE)
    problem = nav.mission_problem(landed=True)
    assert problem.startswith("Geofence violation for waypoint 1")
    nav.set_items(polygon(INCL, square(40.0)), MissionType.FENCE)
    assert nav.mission_problem(landed=True) is None


def test_geometry_is_built_once_at_upload():
    """geofence_breach runs every position-loop tick: the polygons are prepared at upload."""
    nav = navigator()
    corners = [(30 * math.cos(a), 30 * math.sin(a)) for a in np.linspace(0, 2 * math.pi, 50,
                                                                           endpoint=False)]
    nav.set_items([*polygon(INCL, corners), circle(C_EXCL, (10.0, 0.0), 3.0, seq=50)],
                  MissionType.FENCE)
    fence = nav.fence
    area = fence.areas[0]
    assert shapely.is_prepared(area.geometry)
    assert nav.geofence_breach(np.array([1.0, 2.0, -5.0])) is None
    assert nav.fence is fence
    assert fence.areas[0].geometry is area.geometry
    assert nav.geofence_breach(np.array([10.0, 1.0, -5.0])) == "inside the exclusion circle 0"
