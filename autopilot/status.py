"""Mission status codes, as seed 004's status topic numbered them (and new ones for our step
kinds). One code says what the vehicle is doing for the mission at any moment: logged on
``/mission/status``, shown in the progress line, the report and the goal API.

=====  ==============================  =====  ==============================
code   meaning                         code   meaning
=====  ==============================  =====  ==============================
0      idle (on the ground)            11     area coverage completed
1      takeoff in progress             12     abort (the safe stop: hold, land)
2      takeoff completed               13     following a ball
3      hover (holding, waiting)        14     ball following completed
4      go-to in progress               15     following a marker
5      go-to completed                 16     marker following completed
6      images (orbit) in progress      17     hovering over an image
7      images (orbit) completed        18     image hover completed
8      landing in progress             19     precision landing on a pad
9      landing completed               20     precision landing completed
10     area coverage in progress
=====  ==============================  =====  ==============================
"""

from __future__ import annotations

import enum


class MissionStatus(enum.IntEnum):
    IDLE = 0
    TAKEOFF_IN_PROGRESS = 1
    TAKEOFF_COMPLETED = 2
    HOVER = 3
    GOTO_IN_PROGRESS = 4
    GOTO_COMPLETED = 5
    IMAGES_IN_PROGRESS = 6
    IMAGES_COMPLETED = 7
    LANDING_IN_PROGRESS = 8
    LANDING_COMPLETED = 9
    COVERAGE_IN_PROGRESS = 10
    COVERAGE_COMPLETED = 11
    ABORT = 12
    FOLLOW_BALL_IN_PROGRESS = 13
    FOLLOW_BALL_COMPLETED = 14
    FOLLOW_MARKER_IN_PROGRESS = 15
    FOLLOW_MARKER_COMPLETED = 16
    HOVER_IMAGE_IN_PROGRESS = 17
    HOVER_IMAGE_COMPLETED = 18
    LAND_PAD_IN_PROGRESS = 19
    LAND_PAD_COMPLETED = 20

    @property
    def label(self) -> str:
        return self.name.lower().replace("_", " ")


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
        elif self.code not in (MissionStatus.LANDING_COMPLETED, MissionStatus.LAND_PAD_COMPLETED,
                               MissionStatus.ABORT):
            self.code = MissionStatus.IDLE
        return self.code
