"""The console bridge: what the operator console (:mod:`autopilot.console`) asks of a flight —
what to show (the frames with their detections, the map, the values), and what the keys do
(manual flight, the follow mode, take off, land, the emergency stop), acted on at the next
control tick."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from autopilot.behaviors.base import BehaviorInputs, FollowModes, RequestKind, VehicleRequest
from autopilot.behaviors.manual import ACTIONS, HeldKeys, ManualFlight, ManualSettings
from autopilot.console.view import pose_record, vehicle_map
from autopilot.mission import MissionOutput
from autopilot.runtime.commands import SetpointStream, VehicleCommands
from autopilot.runtime.failsafes import Failsafes
from autopilot.runtime.flight import Flight, ProcessedFrame
from autopilot.runtime.goal_desk import GoalDesk
from autopilot.runtime.perception import PerceptionLanes
from autopilot.runtime.recorder import MissionRecorder
from autopilot.runtime.telemetry import TelemetryIntake
from drivers.base import FlightMode, Frame, VehicleError, VehicleState

#: what each console action will do, as the answer says
_WILL = {"follow_mode": "switching follow mode", "takeoff": "taking off", "land": "landing"}


class ConsoleBridge:
    """Implements :class:`autopilot.runtime.ports.ConsolePort` for a flight."""

    def __init__(self, flight: Flight, recorder: MissionRecorder, desk: GoalDesk,
                 perception: PerceptionLanes, telemetry: TelemetryIntake,
                 setpoints: SetpointStream, commands: VehicleCommands, failsafes: Failsafes,
                 spawn: Callable, planned_path: Callable[[], tuple[int, list]]) -> None:
        self.flight = flight
        self.vehicle, self.clock, self.config = flight.vehicle, flight.clock, flight.config
        self.events, self.values = flight.events, flight.values
        self.recorder, self.desk, self.perception = recorder, desk, perception
        self.telemetry, self.setpoints = telemetry, setpoints
        self.commands, self.failsafes = commands, failsafes
        self.spawn = spawn  # a task of the run (the console's video)
        self._planned_path = planned_path
        c = flight.config.console
        self._settings = ManualSettings(
            c.speed_m_s, c.vertical_speed_m_s, math.radians(c.yaw_rate_deg_s), c.key_timeout_s,
            c.min_altitude_m, takeoff_altitude_m=c.takeoff_altitude_m)
        self.held_keys = HeldKeys(c.key_timeout_s)
        #: the keys' clock: the wall clock (a person's keys, whatever the simulated clock
        #: does); tests that drive the keys on the lockstep clock swap it
        self.key_clock: Callable[[], float] = time.monotonic
        self._manual = ManualFlight(self._settings)
        self.manual = False  # the console's Y: the mission waits, the keys fly
        self._enter = False
        self._from_air = False
        self._offboard_asked_s = -math.inf
        self._actions: list[str] = []
        self._requests: tuple[VehicleRequest, ...] = ()
        #: set when Y hands the vehicle back to the step (the control loop resumes it)
        self.resume: Callable[[], None] = lambda: None

    # -- what the console shows ------------------------------------------------------------

    @property
    def planned_path(self) -> tuple[int, list]:
        return self._planned_path()

    def api_status(self) -> dict:
        return self.desk.api_status()

    async def processed_frame(self, camera: str, seq: int, timeout_s: float
                              ) -> ProcessedFrame | None:
        return await self.perception.processed_frame(camera, seq, timeout_s)

    def take_frame(self, camera: str) -> bool:
        """Draw this frame of ``camera``? (Not all while the loop runs late: see
        :mod:`autopilot.runtime.governor`.)"""
        governor = self.perception.governor
        return governor is None or governor.take(f"console:{camera}")

    def overlay_records(self, camera: str, frame: Frame) -> dict:
        """What the console draws over ``frame``, as the flight log's records (for
        :func:`autopilot.report.video.overlay_from`): the detections in it when a step's
        pipelines processed it, the pose now, the target estimate, the newest setpoint."""
        det, est = self.perception.overlay(camera, frame, self.clock.now())
        cursor = self.flight.cursor
        return {"det": det, "pose": pose_record(self.flight.state), "est": est,
                "setpoint": self.setpoints.intent_record,
                "step": cursor.step, "phase": cursor.phase}

    def map_snapshot(self) -> dict:
        """The console's mini-map: where the vehicle is and faces, home, the target."""
        s = self.flight.state
        out = vehicle_map(s, self.vehicle.home_ned_m, self._planned_path()[0])
        track = self.perception.first_track()
        if s is None or track is None:
            return out
        target = track.pipeline.target(self.clock.now())
        if target is not None and not target.stale:
            out["target_ne_m"] = [round(float(target.position_ned_m[0]), 3),
                                  round(float(target.position_ned_m[1]), 3)]
            out["target_sigma_m"] = round(float(np.sqrt(np.mean(
                np.diag(target.covariance)[:2]))), 3)
        return out

    def console_about(self) -> dict:
        """What the console's page is told first: the mission, the camera to show, whether
        it may fly and send goals, and the clock."""
        camera = next((p.camera for p in self.perception.pipelines.values() if p.camera),
                      next(iter(self.vehicle.cameras), ""))
        return {"mission": self.flight.plan.mission.name, "camera": camera, "can_fly": True,
                "track_ne_m": list(self.telemetry.track_ne_m),
                "takes_goals": self.desk.goals is not None,
                "clock": "lockstep" if self.clock.lockstep else "realtime"}

    # -- what the keys do ------------------------------------------------------------------

    def console_keys(self, held: Sequence[str], source: object = None) -> None:
        """The movement keys a console page (``source``) holds now (renewed while held)."""
        self.held_keys.report(held, self.key_clock(), source)

    def console_release(self, source: object = None) -> None:
        """A console page went away: what it held is let go at once."""
        self.held_keys.release(source)

    def console_action(self, action: str, confirm: bool = False) -> str:
        """One of the console's keys (:data:`~autopilot.behaviors.manual.ACTIONS`); acted on
        at the next control tick. Returns what will happen (ValueError: refused now)."""
        f = self.flight
        if action not in ACTIONS:
            raise ValueError(f"unknown action {action!r}; actions: {list(ACTIONS)}")
        if f.executor is None or f.control_ended:
            raise ValueError("the mission is not flying: the console's keys are off")
        if action == "emergency":  # (the kill switch works during a safe stop too)
            if not confirm:
                raise ValueError("the emergency stop needs confirming (it stops the motors, in "
                                 "the air too)")
            self.failsafes.emergency = self.failsafes.emergency or \
                "emergency stop from the console"
            f.nudge()  # act now, not at the next tick
            return "emergency stop: the motors stop"
        if f.stop_requested.is_set() or self.failsafes.stale or self.failsafes.emergency:
            raise ValueError("the mission is stopping (a safe stop flies): only the emergency "
                             "stop (R) acts now")
        if action == "takeoff" and not self.manual:
            raise ValueError("T acts in manual flight only (Y hands the vehicle to the keys)")
        self._actions.append(action)
        f.nudge()
        if action == "autopilot":
            return "manual flight" if not self.manual else "autopilot on"
        return _WILL[action]

    def hand_back(self) -> None:
        """A failsafe or the safe stop takes control: the keys let go of the vehicle, and the
        actions not yet acted on are dropped."""
        self.manual = False
        self._actions.clear()

    def tick(self, inputs: BehaviorInputs) -> MissionOutput | None:
        """The console's actions since the last tick, and the keys' setpoint while manual;
        None: the mission runs this tick as usual."""
        f = self.flight
        actions, self._actions = self._actions, []
        s, now = inputs.state, inputs.now_s
        requests: list[VehicleRequest] = []
        for action in actions:
            if action == "autopilot":
                self._toggle_manual(s, now)
            elif action == "follow_mode":
                behavior = f.executor.current
                if not isinstance(behavior, FollowModes):
                    self.recorder.console(now, "follow_mode", "F: the running step does not "
                                          "follow a target")
                else:
                    mode = behavior.toggle_follow_mode()
                    self.recorder.console(now, "follow_mode", f"following by {mode}",
                                          {"mode": mode})
            elif action == "land":
                if not self.manual:
                    self.desk.abort("land requested from the console")
                    return None
                self.recorder.console(now, "land", "landing (manual)")
                requests.append(VehicleRequest(RequestKind.LAND))
            elif action == "takeoff":
                if s.in_air or s.armed:
                    self.recorder.console(now, "takeoff", "T: already armed or flying")
                else:
                    self.recorder.console(now, "takeoff", "taking off (manual)")
                    self._manual.reset()
                    requests += [VehicleRequest(RequestKind.ARM), VehicleRequest(
                        RequestKind.TAKEOFF, altitude_m=self._settings.takeoff_altitude_m)]
        self._requests = tuple(requests)
        if not self.manual or f.stop_requested.is_set():
            return None
        held = self.held_keys.held(self.key_clock())
        setpoint = self._manual.setpoint(held, s, now) if s.in_air else None
        if s.in_air and s.armed and s.mode is not FlightMode.OFFBOARD and not requests and \
                (held or self._enter) and now - self._offboard_asked_s > 2.0:
            self._offboard_asked_s = now
            self._requests += (VehicleRequest(RequestKind.START_OFFBOARD),)
        self._enter = False
        return MissionOutput(setpoint, (), (), False, "running", f.cursor.step, "manual",
                             f.cursor.index)

    async def perform(self) -> None:
        """The console's vehicle commands (T, L, entering OFFBOARD): one refused is reported,
        it fails no step (the step never asked for it)."""
        requests, self._requests = self._requests, ()
        for request in requests:
            try:
                await self.commands.perform(request)
            except VehicleError as exc:
                self.recorder.console(self.clock.now(), "refused",
                                      f"{request.kind.value} refused: {exc}")
                return

    def _toggle_manual(self, s: VehicleState, now: float) -> None:
        if not self.manual:
            self.manual = True
            self._manual.reset()
            self.held_keys.release_all()
            self._enter = s.in_air
            self._from_air = s.in_air
            self.recorder.console(now, "autopilot", "autopilot off: manual flight (keys)",
                                  {"autopilot": False})
            return
        self.held_keys.release_all()
        if not s.in_air and self._from_air:
            self.manual = False
            self.recorder.console(now, "autopilot", "autopilot on: landed under manual "
                                  "control, so the mission ends", {"autopilot": True})
            self.flight.request_stop("landed under manual control")
            return
        self.manual = False
        self.resume()
        self.recorder.console(now, "autopilot", f"autopilot on: "
                              f"{self.flight.cursor.step or 'mission'} resumes",
                              {"autopilot": True})
