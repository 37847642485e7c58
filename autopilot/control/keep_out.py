"""The keep-out guard: every setpoint streamed to the vehicle, whoever made it, kept out of the
keep-out zones seen so far (:mod:`autopilot.perception.keep_out_map`). A
:class:`~autopilot.watch.SetpointGuard`, passed every setpoint before the geofence checks it
(:mod:`autopilot.runtime.commands`).

All of it in the horizontal plane (a zone is a column over its disc; heights, vertical
velocities and the heading are never touched), each zone its disc's radius (or
``radius_m``) plus ``margin_m``:

* **inside a zone** (the vehicle is: a zone first seen under it, an overshoot): pushed out —
  a position setpoint becomes the zone's edge nearest the vehicle; a velocity setpoint keeps
  its tangential part and moves outwards at ``push_out_speed_m_s`` at least;
* **a position setpoint inside a zone** (the vehicle outside): moved to the zone's edge, where
  the ray from the zone's centre through it leaves the zone;
* **motion into a zone within** ``lookahead_s``: a velocity setpoint, or the motion a position
  setpoint implies (``position_gain_per_s`` × the way to it, plus its feed-forward; at most
  ``max_speed_m_s``), whose straight line enters a zone within the distance it covers in that
  time, is turned onto the zone's tangent from the vehicle (the side it was already heading
  for; kept while the intervention lasts): the inward component goes, the tangential one stays,
  at the speed asked, so that the vehicle goes round instead of stopping at the edge. A
  position setpoint is turned with its feed-forward about the vehicle (the way to it keeps its
  length: the vehicle's controller flies it at the speed it would have). If the turned motion
  runs into another zone, the other side is tried; if both do, the horizontal motion stops.

Zones the vehicle is already inside are never deflected around, only pushed out of. Only in the
air (a landed vehicle is not pushed about).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from autopilot.perception.keep_out_map import KeepOutZone
from autopilot.watch import Guarded
from drivers.base import Setpoint, SetpointFrame, VehicleState
from drivers.geometry import wrap_pi, yaw_from_quat

#: edge points a little outside the zone (so that a setpoint put there counts as outside)
EDGE_EPS_M = 0.02
#: a turn onto a tangent goes this much beyond it (the tangent only grazes the zone)
TANGENT_EXTRA_RAD = math.radians(3.0)


@dataclass(frozen=True, slots=True)
class GuardSettings:
    margin_m: float = 0.5  # beyond each disc's radius
    radius_m: float | None = None  # every zone's radius; None: each disc's as measured
    lookahead_s: float = 1.0
    position_gain_per_s: float = 1.0  # how fast a position setpoint is taken to be flown
    max_speed_m_s: float = 5.0  # ... at most
    push_out_speed_m_s: float = 0.5  # out of a zone the vehicle is inside, at least
    side_memory_s: float = 1.0  # the side a zone is passed on is kept this long


def _rot(angle_rad: float, v: np.ndarray) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def entry_distance(p: np.ndarray, direction: np.ndarray, centre: np.ndarray,
                   radius_m: float) -> float:
    """How far along the unit ``direction`` from ``p`` (outside the circle) the line enters
    it (inf: it does not)."""
    m = centre - p
    b = float(m @ direction)
    disc = b * b - (float(m @ m) - radius_m ** 2)
    if b <= 0.0 or disc < 0.0:
        return math.inf
    return b - math.sqrt(disc)


class KeepOutGuard:
    """See the module's notes. ``zones``: the zones that count now (the map's)."""

    def __init__(self, name: str, zones: Callable[[], Sequence[KeepOutZone]],
                 settings: GuardSettings = GuardSettings()) -> None:
        self.name = name
        self.zones = zones
        self.settings = settings
        self._sides: dict[int, tuple[int, float]] = {}  # zone → (side, when last used)

    def radius(self, zone: KeepOutZone) -> float:
        s = self.settings
        return (s.radius_m if s.radius_m is not None else zone.radius_m) + s.margin_m

    def guard(self, setpoint: Setpoint, state: VehicleState) -> Guarded:
        zones = self.zones()
        if not zones or not state.in_air:
            return Guarded(setpoint)
        p = np.asarray(state.position_ned_m, float)[:2]
        body = setpoint.frame is SetpointFrame.BODY_FRD
        yaw = yaw_from_quat(np.asarray(state.attitude_q, float)) if body else 0.0
        target = np.asarray(setpoint.position_ned_m, float)[:2]
        vel = np.asarray(setpoint.velocity_m_s, float)[:2]
        if body:
            vel = _rot(yaw, vel)
        has_pos, has_vel = bool(np.isfinite(target).all()), bool(np.isfinite(vel).all())
        if not has_pos and not has_vel:
            return Guarded(setpoint)  # (one horizontal axis only: not a motion it can judge)
        circles = [(z, np.array(z.centre_ne_m, float), self.radius(z)) for z in zones]
        inside = [(r - float(np.linalg.norm(p - c)), z, c, r) for z, c, r in circles
                  if float(np.linalg.norm(p - c)) < r]
        if inside:
            _, zone, c, r = max(inside, key=lambda item: item[0])
            new_target, new_vel = self._push_out(p, target, vel, has_pos, has_vel, c, r)
            return self._out(setpoint, state, zone, c, r, "pushed out", new_target, new_vel,
                             yaw, body)
        moved: tuple[KeepOutZone, np.ndarray, float] | None = None
        if has_pos:
            for z, c, r in circles:
                off = target - c
                dist = float(np.linalg.norm(off))
                if dist < r:
                    way = off / dist if dist > 1e-6 else (p - c) / float(np.linalg.norm(p - c))
                    target = c + (r + EDGE_EPS_M) * way
                    moved = (z, c, r)
        ff = vel if has_vel else np.zeros(2)
        u = self.settings.position_gain_per_s * (target - p) + ff if has_pos else vel
        speed = float(np.linalg.norm(u))
        if speed > 1e-6:
            reach = min(speed, self.settings.max_speed_m_s) * self.settings.lookahead_s
            if has_pos:
                reach = min(reach, float(np.linalg.norm(target - p))
                            + float(np.linalg.norm(ff)) * self.settings.lookahead_s)
            turn = self._turn(p, u / speed, reach, circles, state.time_s)
            if turn is not None:
                angle, zone, c, r = turn
                if angle is None:  # both sides blocked: the horizontal motion stops
                    new_target = p.copy() if has_pos else target
                    new_vel = np.zeros(2) if has_vel else vel
                    action = "stopped"
                else:
                    new_target = p + _rot(angle, target - p) if has_pos else target
                    new_vel = _rot(angle, vel) if has_vel else vel
                    action = "deflected"
                return self._out(setpoint, state, zone, c, r, action, new_target, new_vel,
                                 yaw, body)
        if moved is not None:
            zone, c, r = moved
            return self._out(setpoint, state, zone, c, r, "moved to edge", target, vel, yaw,
                             body)
        return Guarded(setpoint)

    # -- the parts ---------------------------------------------------------------------------

    def _push_out(self, p, target, vel, has_pos, has_vel, c, r):
        d = float(np.linalg.norm(p - c))
        if d > 1e-6:
            n = (p - c) / d
        elif has_vel and float(np.linalg.norm(vel)) > 1e-6:
            n = vel / float(np.linalg.norm(vel))
        else:
            n = np.array([1.0, 0.0])
        new_vel = vel
        if has_vel:
            radial = float(vel @ n)
            tangential = vel - radial * n
            outward = max(radial, self.settings.push_out_speed_m_s) if not has_pos \
                else max(radial, 0.0)
            new_vel = tangential + outward * n
        new_target = c + (r + EDGE_EPS_M) * n if has_pos else target
        return new_target, new_vel

    def _hits(self, p, direction, reach, circles, skip=None):
        """The first zone the line from ``p`` along ``direction`` enters within ``reach``."""
        best = None
        for z, c, r in circles:
            if z is skip:
                continue
            s = entry_distance(p, direction, c, r)
            if s <= reach and (best is None or s < best[0]):
                best = (s, z, c, r)
        return best

    def _turn(self, p, direction, reach, circles, now_s):
        """The turn (rad) that takes the motion round the first zone it runs into (None: it
        runs into none; an angle of None: both sides are blocked), with that zone."""
        hit = self._hits(p, direction, reach, circles)
        if hit is None:
            return None
        _, zone, c, r = hit
        m = c - p
        d = float(np.linalg.norm(m))
        alpha = math.asin(min(1.0, r / d))
        heading = math.atan2(direction[1], direction[0])
        to_centre = math.atan2(m[1], m[0])
        beta = wrap_pi(heading - to_centre)
        remembered = self._sides.get(zone.index)
        side = remembered[0] if remembered is not None and \
            now_s - remembered[1] <= self.settings.side_memory_s else (1 if beta >= 0 else -1)
        for s in (side, -side):
            angle = wrap_pi(to_centre + s * (alpha + TANGENT_EXTRA_RAD) - heading)
            turned = _rot(angle, direction)
            if self._hits(p, turned, reach, circles, skip=zone) is None:
                self._sides[zone.index] = (s, now_s)
                return angle, zone, c, r
        return None, zone, c, r

    def _out(self, setpoint: Setpoint, state: VehicleState, zone: KeepOutZone, c: np.ndarray,
             r: float, action: str, target: np.ndarray, vel: np.ndarray, yaw: float,
             body: bool) -> Guarded:
        pos = np.array(setpoint.position_ned_m, float)
        v = np.array(setpoint.velocity_m_s, float)
        if not body:
            pos[:2] = target
        v[:2] = _rot(-yaw, vel) if body else vel
        acc = np.array(setpoint.acceleration_m_s2, float)
        acc[:2] = math.nan  # (a trajectory's curvature no longer fits the motion)
        out = Setpoint(position_ned_m=pos, velocity_m_s=v, yaw_rad=setpoint.yaw_rad,
                       yaw_rate_rad_s=setpoint.yaw_rate_rad_s, frame=setpoint.frame,
                       time_s=setpoint.time_s, acceleration_m_s2=acc)
        d = float(np.linalg.norm(np.asarray(state.position_ned_m, float)[:2] - c))
        text = (f"keep-out zone {zone.index}: setpoint {action} (the vehicle {d:.2f} m from "
                f"its centre, the zone {r:.2f} m)")
        record = {"zone": zone.index, "centre_ne_m": list(zone.centre_ne_m), "radius_m": r,
                  "distance_m": d, "position_before_ned_m": setpoint.position_ned_m,
                  "velocity_before_m_s": setpoint.velocity_m_s,
                  "position_after_ned_m": out.position_ned_m,
                  "velocity_after_m_s": out.velocity_m_s}
        return Guarded(out, action, f"zone {zone.index}", text, record)
