"""The console for ``autopilot sim --console HOST:PORT``: the simulated vehicle itself, as a
PX4 SITL vehicle would be watched — its cameras (with its own state drawn over them, there is
no autopilot in this process), its telemetry as ``name::value`` pairs, a map of its track and
its status messages. It only watches: the vehicle is flown by whatever client talks MAVLink to
it (an autopilot, QGroundControl, MAVSDK), and two pilots at once would be one too many.
``POST /api/abort`` lands it, as a safety switch."""

from __future__ import annotations

import asyncio
import contextlib
import time

from autopilot import values
from autopilot.config import AppConfig
from autopilot.console.view import pose_record, publish_vehicle, vehicle_map, vehicle_status
from autopilot.goals import GoalError
from autopilot.hooks import Event, EventHub
from drivers.base import VehicleError, VehicleState
from drivers.sim.driver import SimDriver


class _Keys:
    def held(self, now_s: float) -> frozenset[str]:
        return frozenset()


class SimConsoleSource:
    """What :class:`autopilot.console.Console` and the goal API's routes ask of a runtime,
    for the simulator alone."""

    manual = False
    goals = None
    waiting_for_goals = False

    def __init__(self, vehicle: SimDriver, config: AppConfig, name: str) -> None:
        self.vehicle = vehicle
        self.config = config
        self.clock = vehicle.clock
        self.name = name
        self.events = EventHub()
        self.values = values.board()
        self.held_keys = _Keys()
        self.key_clock = time.monotonic
        self._tasks: list[asyncio.Task] = []
        self._state: VehicleState | None = None
        self.planned_path: tuple[int, list] = (0, [])

    # -- lifecycle -------------------------------------------------------------------------

    def start(self) -> None:
        loop = asyncio.get_running_loop()
        self._tasks += [loop.create_task(self._telemetry(), name="console-telemetry"),
                        loop.create_task(self._status_texts(), name="console-status")]

    async def close(self) -> None:
        self.events.close()
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)

    def spawn(self, coro, name: str) -> asyncio.Task:
        task = asyncio.get_running_loop().create_task(coro, name=name)
        self._tasks.append(task)
        return task

    async def _telemetry(self) -> None:
        async with contextlib.aclosing(self.vehicle.telemetry()) as samples:
            async for s in samples:
                previous, self._state = self._state, s
                if previous is not None and s.mode is not previous.mode:
                    self.events.emit(Event("mode", s.mode.value, s.time_s,
                                           f"mode {s.mode.value}"))
                if previous is not None and s.armed != previous.armed:
                    name = "armed" if s.armed else "disarmed"
                    self.events.emit(Event("armed", name, s.time_s, name))
                publish_vehicle(self.values, s)
                self.values.publish("failsafe", s.failsafe)

    async def _status_texts(self) -> None:
        async with contextlib.aclosing(self.vehicle.events()) as texts:
            async for time_s, text in texts:
                self.events.emit(Event("status_text", "status_text", time_s, text))

    # -- what the console and the API ask ------------------------------------------------

    def console_about(self) -> dict:
        return {"mission": f"{self.name} (simulated vehicle)",
                "camera": next(iter(self.vehicle.cameras), ""), "can_fly": False,
                "takes_goals": False, "clock": "realtime"}

    def console_keys(self, held, source=None) -> None:
        return None

    def console_release(self, source=None) -> None:
        return None

    def console_action(self, action: str, confirm: bool = False) -> str:
        raise ValueError("this console watches the simulated vehicle; fly it from the client "
                         "that talks MAVLink to it (autopilot run --driver mavsdk, "
                         "QGroundControl, …)")

    def goal_site(self):
        return None  # (no goal is taken: nothing to check a goal's reach against)

    def submit_goal(self, step):
        raise GoalError(409, "the simulator takes no goals: send them to 'autopilot run "
                        "--console/--api'")

    def abort(self, reason: str) -> None:
        async def land() -> None:
            with contextlib.suppress(VehicleError):
                await self.vehicle.land()
        self.spawn(land(), "console-abort")

    def api_status(self) -> dict:
        s = self._state
        out = {"status_code": None, "status": "simulated vehicle", "step": "", "phase": "",
               "goal_id": None, "time_s": self.clock.now(), "progress": None,
               "waiting_for_goals": False, "control": "external", "photos": 0}
        return {**out, **vehicle_status(s)}

    async def processed_frame(self, camera: str, seq: int, timeout_s: float) -> None:
        return None  # (no pipelines here: the frames as they come)

    def take_frame(self, camera: str) -> bool:
        return True  # (the simulator's own console: no flight to yield to)

    def overlay_records(self, camera: str, frame) -> dict:
        return {"det": None, "pose": pose_record(self._state), "est": None, "setpoint": None,
                "step": "simulated vehicle", "phase": ""}

    def map_snapshot(self) -> dict:
        return vehicle_map(self._state, self.vehicle.home_ned_m)
