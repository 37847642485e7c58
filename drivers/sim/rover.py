"""The rover: a ground vehicle carrying a landing deck, and the sensors that relate it to the drone.

**The body.** A real dynamic MuJoCo body (not a mocap body: those are kinematic, and a drone
standing on one would not be carried). It moves in the plane on two slide joints and a hinge
about the vertical, pushed along its scripted path by a stiff PD servo with acceleration
feed-forward (generalised forces on its joints, as a rover's own speed and steering loops would
push it), so a drone on its deck rides along on the contact forces and friction. Its geoms
collide with the drone's skids but not with the ground (contact bits: the rover's are 2, the
ground's 1, the skids' both).

**Its paths** (:func:`rover_path`): ``straight``, ``circle``, ``random_turns`` (straight runs
and turns of random angle and radius) and ``stop_and_go`` (straight, stopping and pulling away
again), each a unicycle integrated once on a fine grid (speed within ``accel_m_s2``, turns
within the rover's yaw-rate limit), so position is a pure function of time.

**The deck** is a box ``deck_size_m`` (length along the rover, width) whose top is
``deck_height_m`` above the ground, carrying a printed tag (the nested marker pad, its top
towards the rover's front). The rover's reference point — what its own position reports and its
UWB anchors are placed from — is on the ground under the deck's centre, body FRD.

**Sensors** (:class:`UwbModel`, :class:`RoverLinkModel`): UWB ranges between anchors on the
rover and a tag on the drone (Gaussian noise, non-line-of-sight outliers that only lengthen a
range, anchors dropping out); the rover's own state as its autopilot reports it over MAVLink
(position with a slowly wandering GNSS error, velocity, compass heading). Ground truth feeds
them; the autopilot only ever sees their outputs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import cv2
import mujoco
import numpy as np

from drivers.base import RoverState, UwbRanges
from drivers.geometry import quat_from_euler, quat_to_matrix
from drivers.geometry import rot_z as _yaw_matrix
from drivers.sim.scenario import BodyTruth, ScenarioObject, WorldFrame
from drivers.sim.sensors import GaussMarkov

RoverPathName = Literal["straight", "circle", "random_turns", "stop_and_go", "static"]
ROVER_PATHS: tuple[str, ...] = ("straight", "circle", "random_turns", "stop_and_go", "static")

#: contact bits: rover geoms collide with what has bit 2 (the drone's skids), not the ground
ROVER_CONTACT = 2


class RoverPath:
    """A rover's scripted motion: a unicycle (speed, yaw rate) integrated on a fine grid.

    ``__call__(t)`` gives ``(position_ned_m, velocity_ned_m_s, yaw_rad)`` of the rover's
    reference point; :meth:`motion` adds the acceleration and yaw rate (the servo's
    feed-forward)."""

    def __init__(self, start_ned_m, heading_rad: float, speed_m_s: np.ndarray,
                 yaw_rate_rad_s: np.ndarray, dt_s: float) -> None:
        n = len(speed_m_s)
        yaw = heading_rad + np.concatenate(([0.0], np.cumsum(yaw_rate_rad_s[:-1]) * dt_s))
        vel = np.column_stack((speed_m_s * np.cos(yaw), speed_m_s * np.sin(yaw)))
        pos = np.concatenate(([[0.0, 0.0]], np.cumsum(vel[:-1], axis=0) * dt_s))
        self._start = np.asarray(start_ned_m, dtype=float)
        self._pos, self._vel, self._yaw = pos, vel, yaw
        self._acc = np.gradient(vel, dt_s, axis=0)
        self._rate = np.asarray(yaw_rate_rad_s, dtype=float)
        self._dt = dt_s
        self._n = n

    @property
    def duration_s(self) -> float:
        return (self._n - 1) * self._dt

    def _index(self, time_s: float) -> tuple[int, float]:
        k = min(max(time_s / self._dt, 0.0), self._n - 1.000001)
        i = int(k)
        return i, k - i

    def __call__(self, time_s: float) -> tuple[np.ndarray, np.ndarray, float]:
        pos, vel, yaw, _, _ = self.motion(time_s)
        return pos, vel, yaw

    def motion(self, time_s: float) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, float]:
        """Position, velocity, yaw, acceleration (NED) and yaw rate at ``time_s``."""
        i, f = self._index(time_s)
        xy = self._pos[i] * (1.0 - f) + self._pos[i + 1] * f
        v = self._vel[i] * (1.0 - f) + self._vel[i + 1] * f
        a = self._acc[i] * (1.0 - f) + self._acc[i + 1] * f
        yaw = self._yaw[i] + f * (self._yaw[i + 1] - self._yaw[i])
        rate = self._rate[i]
        if time_s > self.duration_s:  # beyond the script: it coasts on at its last velocity
            extra = time_s - self.duration_s
            xy = self._pos[-1] + self._vel[-1] * extra
        return (self._start + np.array([xy[0], xy[1], 0.0]), np.array([v[0], v[1], 0.0]),
                float(yaw), np.array([a[0], a[1], 0.0]), float(rate))


def _ramp(speed: np.ndarray, accel: float, dt: float) -> np.ndarray:
    """A speed profile whose changes stay within ``accel`` (forwards, then backwards, so that
    it slows down in time for every stop)."""
    out = speed.copy()
    step = accel * dt
    for k in range(1, len(out)):
        out[k] = min(out[k], out[k - 1] + step)
    for k in range(len(out) - 2, -1, -1):
        out[k] = min(out[k], out[k + 1] + step)
    return out


def rover_path(path: RoverPathName, start_ned_m, heading_rad: float, speed_m_s: float, *,
               size_m: float = 20.0, accel_m_s2: float = 1.0, seed: int = 0,
               duration_s: float = 600.0, dt_s: float = 0.01) -> RoverPath:
    """A named path from ``start_ned_m`` along ``heading_rad``, pulling away at ``accel_m_s2``
    to ``speed_m_s``. ``size_m``: the circle's diameter; the random turns' largest radius ×2.
    ``circle`` turns left (counter-clockwise seen from above); ``random_turns`` alternates
    straight runs (3–10 s) with turns of 30–120° at radii from 4 m to ``size_m``/2;
    ``stop_and_go`` drives 4–9 s, stops for 1–3 s, and drives on."""
    n = int(duration_s / dt_s) + 1
    t = np.arange(n) * dt_s
    rng = np.random.default_rng(seed + 9001)
    cruise = np.full(n, float(speed_m_s))
    rate = np.zeros(n)
    if path == "static" or speed_m_s == 0.0:
        cruise[:] = 0.0
    elif path == "circle":
        radius = max(size_m / 2.0, 1.0)
        speed = _ramp(np.concatenate(([0.0], cruise[1:])), accel_m_s2, dt_s)
        return RoverPath(start_ned_m, heading_rad, speed, -speed / radius, dt_s)
    elif path == "stop_and_go":
        k = 0
        while k < n:
            go = int(rng.uniform(4.0, 9.0) / dt_s)
            stop = int(rng.uniform(1.0, 3.0) / dt_s)
            cruise[k + go:k + go + stop] = 0.0
            k += go + stop
    elif path == "random_turns":
        k = int(rng.uniform(3.0, 10.0) / dt_s)
        while k < n:
            radius = float(rng.uniform(4.0, max(4.0, size_m / 2.0)))
            angle = math.radians(float(rng.uniform(30.0, 120.0)))
            turn = int(angle * radius / max(speed_m_s, 1e-3) / dt_s)
            sign = 1.0 if rng.random() < 0.5 else -1.0
            rate[k:k + turn] = sign * speed_m_s / radius
            k += turn + int(rng.uniform(3.0, 10.0) / dt_s)
        # turns are entered and left over half a second (a steering rate limit)
        width = max(1, int(0.5 / dt_s))
        rate = np.convolve(rate, np.ones(width) / width, mode="same")
    elif path != "straight":
        raise ValueError(f"unknown rover path {path!r} (known: {', '.join(ROVER_PATHS)})")
    cruise[0] = 0.0  # it starts at rest
    speed = _ramp(cruise, accel_m_s2, dt_s)
    if path == "random_turns":  # the yaw rate scales with the speed (a fixed turn radius)
        rate = rate * speed / max(speed_m_s, 1e-9)
    del t
    return RoverPath(start_ned_m, heading_rad, speed, rate, dt_s)


@dataclass
class Rover(ScenarioObject):
    """The rover (see the module's notes). ``deck_texture_bgr`` is printed on the deck,
    ``tag_size_m`` square, centred, its top towards the rover's front."""

    name: str
    path: RoverPath
    deck_size_m: tuple[float, float] = (1.0, 0.8)
    deck_height_m: float = 0.45
    deck_texture_bgr: np.ndarray | None = None
    tag_size_m: float = 0.7
    mass_kg: float = 150.0
    #: the servo's natural frequency (rad/s), critically damped
    servo_omega_rad_s: float = 10.0
    #: UWB anchors to draw (rover FRD from its reference point), for the picture only
    anchors_frd_m: Sequence[Sequence[float]] = ()
    _qpos: int = field(default=-1, init=False)
    _qvel: int = field(default=-1, init=False)
    _body: int = field(default=-1, init=False)
    _origin: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), init=False)
    _inertia_z: float = field(default=1.0, init=False)

    moves = True

    def build(self, spec: mujoco.MjSpec, frame: WorldFrame) -> None:
        length, width = self.deck_size_m
        h = self.deck_height_m
        ox, oy, _ = frame.origin_enu_m
        body = spec.worldbody.add_body(name=self.name, pos=[ox, oy, 0.0])
        for axis, jname in (([1, 0, 0], "x"), ([0, 1, 0], "y")):
            body.add_joint(name=f"{self.name}/{jname}", type=mujoco.mjtJoint.mjJNT_SLIDE,
                           axis=axis)
        body.add_joint(name=f"{self.name}/yaw", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
        izz = self.mass_kg * (length ** 2 + width ** 2) / 12.0
        self._inertia_z = izz
        body.mass = self.mass_kg
        body.inertia = [izz, izz, izz]
        body.ipos = [0.0, 0.0, h / 2.0]
        body.explicitinertial = True
        contact = {"contype": ROVER_CONTACT, "conaffinity": ROVER_CONTACT}
        none = {"contype": 0, "conaffinity": 0, "mass": 0}
        # the deck (what a drone lands on) over a chassis, on four wheels; FLU body axes
        body.add_geom(name=f"{self.name}/deck", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[length / 2.0, width / 2.0, 0.02], pos=[0.0, 0.0, h - 0.02],
                      rgba=[0.55, 0.56, 0.58, 1.0], friction=[1.0, 0.01, 0.001], mass=0,
                      **contact)
        body.add_geom(name=f"{self.name}/chassis", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[length / 2.0 * 0.9, width / 2.0 * 0.8, (h - 0.2) / 2.0],
                      pos=[0.0, 0.0, 0.16 + (h - 0.2) / 2.0], rgba=[0.75, 0.55, 0.1, 1.0],
                      **none)
        for sx in (-1.0, 1.0):
            for sy in (-1.0, 1.0):
                body.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.16, 0.05, 0.0],
                              pos=[sx * length * 0.33, sy * (width / 2.0 + 0.05), 0.16],
                              quat=[math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0],
                              rgba=[0.1, 0.1, 0.1, 1.0], **none)
        for a in self.anchors_frd_m:  # UWB anchors: small white boxes (and a mast if raised)
            x, y, z = float(a[0]), -float(a[1]), -float(a[2])
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.02, 0.02, 0.02],
                          pos=[x, y, z], rgba=[0.95, 0.95, 0.95, 1.0], **none)
            if z > h + 0.05:
                body.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                              size=[0.01, (z - h) / 2.0, 0.0], pos=[x, y, (z + h) / 2.0],
                              rgba=[0.3, 0.3, 0.3, 1.0], **none)
        if self.deck_texture_bgr is not None:
            image = np.ascontiguousarray(cv2.cvtColor(self.deck_texture_bgr, cv2.COLOR_BGR2RGB))
            th, tw = image.shape[:2]
            spec.add_texture(name=f"{self.name}/tag", type=mujoco.mjtTexture.mjTEXTURE_2D,
                             width=tw, height=th, nchannel=3).data = image.tobytes()
            material = spec.add_material(name=f"{self.name}/tag", specular=0.0, shininess=0.0,
                                         reflectance=0.0, rgba=[1.0, 1.0, 1.0, 1.0])
            material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"{self.name}/tag"
            # the texture's top (the geom's +y) towards the rover's front (body +x)
            half = self.tag_size_m / 2.0
            body.add_geom(name=f"{self.name}/tag", type=mujoco.mjtGeom.mjGEOM_BOX,
                          size=[half, half, 0.001], pos=[0.0, 0.0, h + 0.001],
                          quat=[math.sqrt(0.5), 0.0, 0.0, -math.sqrt(0.5)],
                          material=f"{self.name}/tag", **none)

    def bind(self, model: mujoco.MjModel, data: mujoco.MjData, frame: WorldFrame) -> None:
        jid = model.joint(f"{self.name}/x").id
        self._qpos = int(model.jnt_qposadr[jid])
        self._qvel = int(model.jnt_dofadr[jid])
        self._body = model.body(self.name).id
        self._origin = tuple(frame.origin_enu_m.tolist())
        (n, e, _), _, yaw = self.path(0.0)
        data.qpos[self._qpos:self._qpos + 3] = (e, n, 0.5 * math.pi - yaw)
        data.qvel[self._qvel:self._qvel + 3] = 0.0

    def update(self, time_s: float, data: mujoco.MjData) -> None:
        """The servo: generalised forces that keep the rover on its script."""
        pos, vel, yaw, acc, rate = self.path.motion(time_s)
        q = data.qpos[self._qpos:self._qpos + 3]
        dq = data.qvel[self._qvel:self._qvel + 3]
        w = self.servo_omega_rad_s
        kp, kd = w * w, 2.0 * w
        theta_ref = 0.5 * math.pi - yaw
        err_theta = math.remainder(theta_ref - float(q[2]), 2.0 * math.pi)
        ax = acc[1] + kp * (pos[1] - float(q[0])) + kd * (vel[1] - float(dq[0]))
        ay = acc[0] + kp * (pos[0] - float(q[1])) + kd * (vel[0] - float(dq[1]))
        alpha = kp * err_theta + kd * (-rate - float(dq[2]))
        data.qfrc_applied[self._qvel:self._qvel + 3] = (self.mass_kg * ax, self.mass_kg * ay,
                                                        self._inertia_z * alpha)

    def state(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, float, float]:
        """The reference point's true position and velocity (NED), heading and yaw rate."""
        e, n, theta = data.qpos[self._qpos:self._qpos + 3].tolist()
        ve, vn, w = data.qvel[self._qvel:self._qvel + 3].tolist()
        return (np.array([n, e, 0.0]), np.array([vn, ve, 0.0]),
                math.remainder(0.5 * math.pi - theta, 2.0 * math.pi), -w)

    def truth(self, time_s: float, data: mujoco.MjData) -> BodyTruth:
        """The deck's top centre, the rover's velocity, its heading."""
        pos, vel, yaw, _ = self.state(data)
        pos[2] = -self.deck_height_m
        return BodyTruth(pos, vel, quat_from_euler(0.0, 0.0, yaw))


# --------------------------------------------------------------------------------------------
# Sensors
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class UwbSettings:
    anchors_frd_m: tuple[tuple[float, float, float], ...]  # on the rover, from its reference
    tag_frd_m: tuple[float, float, float]  # on the drone, from its body origin
    range_noise_m: float
    dropout: float  # each anchor's reading is missing with this probability
    nlos_fraction: float  # readings lengthened by a non-line-of-sight path
    nlos_max_m: float
    max_range_m: float


class UwbModel:
    """Two-way-ranging UWB: the drone's tag ranges to every anchor on the rover at once."""

    def __init__(self, settings: UwbSettings, rng: np.random.Generator) -> None:
        self.s = settings
        self._rng = rng
        self._anchors = np.array(settings.anchors_frd_m, dtype=float).reshape(-1, 3)
        self._tag = np.array(settings.tag_frd_m, dtype=float)

    def true_ranges(self, rover_pos: np.ndarray, rover_yaw: float, drone_pos: np.ndarray,
                    drone_q: np.ndarray) -> np.ndarray:
        tag = drone_pos + quat_to_matrix(drone_q) @ self._tag
        anchors = rover_pos + self._anchors @ _yaw_matrix(rover_yaw).T
        return np.linalg.norm(anchors - tag, axis=1)

    def measure(self, time_s: float, rover_pos: np.ndarray, rover_yaw: float,
                drone_pos: np.ndarray, drone_q: np.ndarray) -> UwbRanges | None:
        s, rng = self.s, self._rng
        true = self.true_ranges(rover_pos, rover_yaw, drone_pos, drone_q)
        noise = rng.standard_normal(len(true)) * s.range_noise_m
        nlos = rng.random(len(true)) < s.nlos_fraction
        extra = rng.uniform(0.0, s.nlos_max_m, len(true)) * nlos
        keep = (rng.random(len(true)) >= s.dropout) & (true <= s.max_range_m)
        if not keep.any():
            return None
        ids = tuple(int(i) for i in np.flatnonzero(keep))
        ranges = tuple(float(max(0.0, r)) for r in (true + noise + extra)[keep])
        return UwbRanges(time_s, ids, ranges)


@dataclass(frozen=True, slots=True)
class RoverLinkSettings:
    position_error_m: tuple[float, float, float]  # its GNSS error (Gauss–Markov std)
    position_error_time_constant_s: float
    velocity_noise_m_s: float
    heading_noise_deg: float  # compass noise, each reading
    heading_bias_deg: float  # compass bias (Gauss–Markov std, same time constant)
    system_id: int = 2


class RoverLinkModel:
    """The rover's state as its own autopilot reports it (its position from its GNSS in the
    drone's local frame, velocity, compass heading)."""

    def __init__(self, settings: RoverLinkSettings, rng: np.random.Generator) -> None:
        self.s = settings
        self._rng = rng
        tau = settings.position_error_time_constant_s
        self._errors = GaussMarkov(
            rng, np.array([*settings.position_error_m, math.radians(settings.heading_bias_deg)]),
            tau)
        self._last_s: float | None = None

    def measure(self, time_s: float, pos: np.ndarray, vel: np.ndarray,
                yaw: float) -> RoverState:
        s, rng = self.s, self._rng
        if self._last_s is not None:
            self._errors.step(max(time_s - self._last_s, 0.0))
        self._last_s = time_s
        err = self._errors.value
        heading = yaw + err[3] + math.radians(s.heading_noise_deg) * float(rng.standard_normal())
        return RoverState(
            time_s=time_s, position_ned_m=pos + err[:3],
            velocity_ned_m_s=vel + s.velocity_noise_m_s * rng.standard_normal(3) * (1, 1, 0),
            heading_rad=math.remainder(heading, 2.0 * math.pi),
            position_std_m=float(max(s.position_error_m[:2])),
            velocity_std_m_s=s.velocity_noise_m_s,
            heading_std_rad=math.radians(math.hypot(s.heading_noise_deg, s.heading_bias_deg)),
            system_id=s.system_id)
