"""Follow a tracked target at a standoff distance, keeping it centred in a camera.

The vehicle aims for the point ``standoff_m`` back from the target along the camera's line of
sight (so a camera pitched down δ puts the vehicle standoff·sin δ above the target, which then
sits in the image centre), and flies there with a velocity command: the target's velocity as
feed-forward, plus its acceleration times ``accel_lead_s`` (the vehicle's velocity loop lags its
command by about that much, so the command leads the target's motion), plus a proportional
correction, limited in speed and acceleration. Leading, rather than correcting harder later,
keeps the vehicle's pitch — and so the target's place in a body-fixed camera — calm. Two modes
(seed 001):

* ``yaw`` — turn to face the target; the standoff point lies behind it on the bearing line.
* ``lateral`` — keep the heading the vehicle had when following began; translate so the target
  stays straight ahead.
* ``face`` — for a target with a face (a marker): the standoff point lies in front of the face,
  along its direction (``TargetEstimate.heading_rad``), and the vehicle turns to the target
  (so it ends up square to the face, the target centred). Without a known face direction it
  flies as ``yaw``.

Yaw: an absolute heading setpoint — the bearing to the target, led by the bearing's rate times
``yaw_lead_s`` (the flight stack's yaw loop lags its setpoint by about that much). A heading,
not a yaw rate: the flight stack integrates a yaw-rate command into its own heading setpoint,
and a rate loop closed on top of that winds it up and overshoots when the target swerves.
An altitude floor bounds the descent. Synchronous; called by the follow behaviour.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from autopilot.estimation.target import TargetEstimate
from drivers.base import CameraInfo, Setpoint, VehicleState
from drivers.geometry import wrap_pi

_MIN_BEARING_DISTANCE_M = 0.4  # closer than this (horizontally) the bearing is meaningless


@dataclass(frozen=True, slots=True)
class FollowSettings:
    mode: Literal["yaw", "lateral", "face"]
    standoff_m: float
    position_gain: float  # 1/s
    max_speed_m_s: float
    max_vertical_speed_m_s: float
    max_accel_m_s2: float
    max_yaw_rate_rad_s: float  # bound on the bearing rate the heading is led by
    altitude_floor_m: float
    accel_lead_s: float = 0.0  # feed-forward of the target's acceleration
    accel_filter_s: float = 0.2  # time constant of the target-acceleration estimate
    yaw_lead_s: float = 0.3  # the heading setpoint leads the bearing by its rate × this
    #: yaw mode: share of the target's velocity across the line of sight flown as well (1:
    #: the vehicle translates with the target and the yaw only turns; 0: the yaw alone follows
    #: sideways motion, as seed 001's yaw following did)
    sideways_feedforward: float = 0.0
    #: yaw mode: the bearing rate the yaw alone follows; the part of the target's sideways
    #: velocity beyond it (a target passing close and fast) is flown too, or it gets away
    yaw_tracked_bearing_rate_rad_s: float = math.radians(60.0)
    #: yaw mode, fallen behind: head for where the target will be when the gap is closed, at
    #: most this far ahead (0: always straight at it)
    intercept_horizon_s: float = 1.0


def camera_depression_rad(camera: CameraInfo) -> float:
    """How far below the body's horizontal plane the camera looks (positive: down)."""
    boresight = camera.rotation_body_cam[:, 2]
    return math.asin(max(-1.0, min(1.0, boresight[2])))


class FollowController:
    def __init__(self, settings: FollowSettings, camera: CameraInfo) -> None:
        self.settings = settings
        self._depression = camera_depression_rad(camera)
        self._heading: float | None = None
        self._yaw_target = 0.0
        self._last_cmd: np.ndarray | None = None
        self._last_time: float | None = None
        self._target_vel: np.ndarray | None = None
        self._target_acc = np.zeros(3)
        self._target_time = 0.0
        #: Where the controller wants the vehicle (NED), for logging.
        self.desired_position_ned_m = np.full(3, np.nan)

    def reset(self, state: VehicleState) -> None:
        """Start following from the vehicle's current motion and heading."""
        self._heading = state.yaw_rad
        self._yaw_target = state.yaw_rad
        self._last_cmd = np.array(state.velocity_ned_m_s)
        self._last_time = state.time_s
        self._target_vel = None
        self._target_acc = np.zeros(3)

    def update(self, now_s: float, state: VehicleState, target: TargetEstimate) -> Setpoint:
        s = self.settings
        if self._heading is None:
            self.reset(state)
        p_v = np.asarray(state.position_ned_m)
        p_t, v_t = target.position_ned_m, target.velocity_ned_m_s
        rel = p_t - p_v
        horizontal = math.hypot(rel[0], rel[1])
        facing = s.mode == "face" and target.heading_rad is not None
        turning = s.mode in ("yaw", "face")

        if turning:
            if horizontal > _MIN_BEARING_DISTANCE_M:
                self._yaw_target = math.atan2(rel[1], rel[0])
            yaw_des = self._yaw_target
        else:
            yaw_des = self._heading

        # the standoff point: back from the target along the camera's line of sight (or out
        # along the target's face)
        back = s.standoff_m * math.cos(self._depression)
        away = target.heading_rad + math.pi if facing else yaw_des
        desired = p_t - back * np.array([math.cos(away), math.sin(away), 0.0])
        desired[2] = min(p_t[2] - s.standoff_m * math.sin(self._depression),
                         -s.altitude_floor_m)
        self.desired_position_ned_m = desired

        acc_t = self._target_acceleration(now_s, v_t)
        lead = v_t + s.accel_lead_s * acc_t
        if facing:
            # the standoff point moves round the target as its face turns
            h, omega = target.heading_rad, target.heading_rate_rad_s
            lead = lead + omega * back * np.array([-math.sin(h), math.cos(h), 0.0])
            cmd = lead + s.position_gain * (desired - p_v)
        elif s.mode == "yaw" and horizontal > _MIN_BEARING_DISTANCE_M:
            # facing the target, only the line of sight matters: move along it to hold the
            # range, and let the yaw follow sideways motion (no orbiting). Fallen behind (a
            # target faster or turning harder than the vehicle can), head for where it will be
            # by the time the gap is closed rather than where it is: a chasing vehicle then
            # cuts inside its turns instead of trailing it round them
            u = np.array([rel[0] / horizontal, rel[1] / horizontal, 0.0])
            gap = horizontal - back
            speed_t = math.hypot(v_t[0], v_t[1])
            if gap > 0.0 and speed_t > 0.1 and s.intercept_horizon_s > 0.0:
                ahead = rel + v_t * min(gap / max(speed_t, 1.0), s.intercept_horizon_s)
                reach = math.hypot(ahead[0], ahead[1])
                if reach > _MIN_BEARING_DISTANCE_M:
                    u = np.array([ahead[0] / reach, ahead[1] / reach, 0.0])
            radial = float(lead @ u) + s.position_gain * (horizontal - back)
            if gap > 0.0:
                # chasing a target that turns: the line of sight turns with it, and at the
                # acceleration limit the vehicle turns at that rate only this slowly; faster,
                # it would be carried round outside the turn and never close the gap
                rel_v = v_t - np.asarray(state.velocity_ned_m_s)
                turn = abs(rel[0] * rel_v[1] - rel[1] * rel_v[0]) / (horizontal * horizontal)
                if turn > 1e-3:
                    radial = min(radial, 0.8 * s.max_accel_m_s2 / turn)
            sideways = lead - float(lead @ u) * u
            sideways[2] = 0.0
            side_speed = float(np.linalg.norm(sideways))
            followed = s.yaw_tracked_bearing_rate_rad_s * horizontal
            beyond = max(0.0, side_speed - followed) / side_speed if side_speed > 1e-6 else 0.0
            share = s.sideways_feedforward + (1.0 - s.sideways_feedforward) * beyond
            cmd = radial * u + share * sideways
            cmd[2] = lead[2] + s.position_gain * (desired[2] - p_v[2])
        else:
            cmd = lead + s.position_gain * (desired - p_v)
        cmd = self._limit(now_s, cmd)
        if cmd[2] > 0.0 and p_v[2] > -s.altitude_floor_m - 0.1:
            # near the floor: no descending feed-forward, only the correction towards the
            # (floor-limited) desired altitude; applied after the smoothing, which must not
            # carry a descent through the floor
            cmd[2] = max(0.0, min(cmd[2], s.position_gain * (desired[2] - p_v[2])))
            self._last_cmd[2] = cmd[2]

        yaw_sp = yaw_des
        if turning and horizontal > _MIN_BEARING_DISTANCE_M:
            rel_v = v_t - np.asarray(state.velocity_ned_m_s)
            bearing_rate = (rel[0] * rel_v[1] - rel[1] * rel_v[0]) / (horizontal * horizontal)
            bearing_rate = max(-s.max_yaw_rate_rad_s, min(s.max_yaw_rate_rad_s, bearing_rate))
            yaw_sp = wrap_pi(yaw_des + s.yaw_lead_s * bearing_rate)
        return Setpoint.velocity_ned(*cmd, yaw_rad=yaw_sp, time_s=now_s)

    def _target_acceleration(self, now_s: float, v_t: np.ndarray) -> np.ndarray:
        """Low-passed derivative of the target's estimated velocity."""
        if self._target_vel is not None:
            dt = now_s - self._target_time
            if dt > 1e-6:
                alpha = dt / (dt + self.settings.accel_filter_s)
                self._target_acc += alpha * ((v_t - self._target_vel) / dt - self._target_acc)
        if self._target_vel is None or now_s > self._target_time:
            self._target_vel = np.array(v_t)
            self._target_time = now_s
        return self._target_acc

    def _limit(self, now_s: float, cmd: np.ndarray) -> np.ndarray:
        s = self.settings
        speed = math.hypot(cmd[0], cmd[1])
        if speed > s.max_speed_m_s:
            cmd[:2] *= s.max_speed_m_s / speed
        cmd[2] = max(-s.max_vertical_speed_m_s, min(s.max_vertical_speed_m_s, cmd[2]))
        if self._last_cmd is not None and self._last_time is not None:
            dt = max(now_s - self._last_time, 0.0)
            step = cmd - self._last_cmd
            max_step = s.max_accel_m_s2 * dt
            norm = float(np.linalg.norm(step))
            if norm > max_step:
                cmd = self._last_cmd + step * (max_step / norm)
        self._last_cmd = cmd.copy()
        self._last_time = now_s
        return cmd
