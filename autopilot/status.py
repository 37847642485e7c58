"""Mission status codes, as seed 004's status topic numbered them (and new ones for our step
kinds). One code says what the vehicle is doing for the mission at any moment: logged on
``/mission/status``, shown in the progress line, the report and the goal API.

The codes are registered, not listed in one place: the mission-wide ones here (0 idle, 3
hover, 12 abort, and the takeoff and landing codes every flight has), a step kind's own in its
module (:func:`register_status`), a plugin's in its package. A step kind
names the two it reports (:attr:`autopilot.steps.registry.StepKind.status`: while it runs, once
it has succeeded).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar


@dataclass(frozen=True, slots=True)
class _Info:
    label: str
    #: a code that stays when the vehicle is on the ground with nothing running (a landing
    #: completed is still that, not "idle")
    stays_landed: bool


class MissionStatus(int):
    """A registered status code: an ``int`` with its ``label`` (one instance per code, so
    ``is`` compares as ``==``). ``MissionStatus(13)`` is the code registered as 13 (ValueError
    for a code nobody registered)."""

    __slots__ = ()
    _registered: ClassVar[dict[int, MissionStatus]] = {}
    _info: ClassVar[dict[int, _Info]] = {}

    IDLE: ClassVar[MissionStatus]
    TAKEOFF_IN_PROGRESS: ClassVar[MissionStatus]
    TAKEOFF_COMPLETED: ClassVar[MissionStatus]
    HOVER: ClassVar[MissionStatus]
    LANDING_IN_PROGRESS: ClassVar[MissionStatus]
    LANDING_COMPLETED: ClassVar[MissionStatus]
    ABORT: ClassVar[MissionStatus]

    def __new__(cls, code: int) -> MissionStatus:
        try:
            return cls._registered[int(code)]
        except KeyError:
            raise ValueError(f"no mission status code {int(code)} is registered (known: "
                             f"{', '.join(map(str, sorted(cls._registered)))})") from None

    @property
    def value(self) -> int:
        return int(self)

    @property
    def label(self) -> str:
        return self._info[int(self)].label

    @property
    def stays_landed(self) -> bool:
        return self._info[int(self)].stays_landed

    def __repr__(self) -> str:
        return f"MissionStatus({int(self)}: {self.label})"


def register_status(code: int, label: str, *, stays_landed: bool = False) -> MissionStatus:
    """Register a status code (once; the same label again returns it)."""
    known = MissionStatus._info.get(code)
    if known is not None:
        if known.label != label:
            raise ValueError(f"status code {code} is registered as {known.label!r}")
        return MissionStatus._registered[code]
    instance = int.__new__(MissionStatus, code)
    MissionStatus._info[code] = _Info(label, stays_landed)
    MissionStatus._registered[code] = instance
    return instance


def status_codes() -> dict[int, str]:
    """Every registered code and its label."""
    return {code: MissionStatus._info[code].label for code in sorted(MissionStatus._registered)}


MissionStatus.IDLE = register_status(0, "idle")
MissionStatus.TAKEOFF_IN_PROGRESS = register_status(1, "takeoff in progress")
MissionStatus.TAKEOFF_COMPLETED = register_status(2, "takeoff completed")
MissionStatus.HOVER = register_status(3, "hover")
MissionStatus.LANDING_IN_PROGRESS = register_status(8, "landing in progress")
MissionStatus.LANDING_COMPLETED = register_status(9, "landing completed", stays_landed=True)
MissionStatus.ABORT = register_status(12, "abort", stays_landed=True)


class StatusTracker:
    """The status code from the mission's events (step started / succeeded, fallback, abort)
    and the vehicle's state (on the ground or flying when nothing runs)."""

    def __init__(self) -> None:
        self.code = MissionStatus.IDLE
        self._stopping = False

    def step_started(self, codes: tuple[int, int]) -> MissionStatus:
        if not self._stopping:
            self.code = MissionStatus(codes[0])
        return self.code

    def step_succeeded(self, codes: tuple[int, int]) -> MissionStatus:
        if not self._stopping:
            self.code = MissionStatus(codes[1])
        return self.code

    def abort(self) -> MissionStatus:
        self._stopping = True
        self.code = MissionStatus.ABORT
        return self.code

    def resume(self) -> None:
        """A new goal after an abort or a finished mission (the goal API)."""
        self._stopping = False

    def idle(self, in_air: bool) -> MissionStatus:
        """Nothing runs: hovering in the air, or idle on the ground (a landing completed
        stays so)."""
        if in_air:
            self.code = MissionStatus.HOVER
        elif not self.code.stays_landed:
            self.code = MissionStatus.IDLE
        return self.code
