"""What the goal API and the console ask of a flight: small interfaces, so that they depend on
the goal desk and the console bridge, not on the runtime (``autopilot sim --console`` serves
them from the simulated vehicle alone: :class:`autopilot.console.sim.SimConsoleSource`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    import asyncio

    from autopilot.behaviors.base import BehaviorInputs
    from autopilot.config import AppConfig
    from autopilot.goals import Goal, GoalManager
    from autopilot.hooks import EventHub
    from autopilot.mission import Step
    from autopilot.values import ValueBoard
    from drivers.base import Frame, Vehicle
    from drivers.clock import Clock


class GoalDeskPort(Protocol):
    """The goal API's side of a flight (:class:`autopilot.runtime.goal_desk.GoalDesk`)."""

    config: AppConfig
    goals: GoalManager | None

    def api_status(self) -> dict: ...

    def goal_site(self) -> BehaviorInputs | None: ...

    def submit_goal(self, step: Step) -> Goal: ...

    def abort(self, reason: str) -> None: ...


class ConsolePort(Protocol):
    """The operator console's side of a flight
    (:class:`autopilot.runtime.console_bridge.ConsoleBridge`)."""

    vehicle: Vehicle
    clock: Clock
    config: AppConfig
    events: EventHub
    values: ValueBoard
    manual: bool
    key_clock: Callable[[], float]

    @property
    def planned_path(self) -> tuple[int, list]: ...

    @property
    def held_keys(self): ...

    def spawn(self, coro, name: str) -> asyncio.Task: ...

    def api_status(self) -> dict: ...

    def console_about(self) -> dict: ...

    async def processed_frame(self, camera: str, seq: int, timeout_s: float): ...

    def take_frame(self, camera: str) -> bool: ...

    def overlay_records(self, camera: str, frame: Frame) -> dict: ...

    def map_snapshot(self) -> dict: ...

    def console_keys(self, held: Sequence[str], source: object = None) -> None: ...

    def console_release(self, source: object = None) -> None: ...

    def console_action(self, action: str, confirm: bool = False) -> str: ...
