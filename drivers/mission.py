"""Mission items as a vehicle stores and flies them (MAVLink's mission protocol vocabulary).

A mission is a list of :class:`MissionItem` — MAVLink MISSION_ITEM_INT with its positions
decoded — that the simulator's navigator flies and the MAVLink face transfers. Three lists
exist per vehicle, as in MAVLink: the mission, the geofence and the rally points
(:class:`MissionType`). The command and frame numbers are MAVLink's (``MAV_CMD``,
``MAV_FRAME``), so items pass through unchanged between a ground station and the vehicle.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

NAN = float("nan")


class MissionType(enum.IntEnum):
    MISSION = 0
    FENCE = 1
    RALLY = 2


class Frame(enum.IntEnum):
    """MAV_FRAME values a mission item may use."""

    GLOBAL = 0  # altitude above mean sea level
    LOCAL_NED = 1
    MISSION = 2  # no position
    GLOBAL_RELATIVE_ALT = 3  # altitude above home
    LOCAL_ENU = 4
    GLOBAL_INT = 5
    GLOBAL_RELATIVE_ALT_INT = 6
    LOCAL_OFFSET_NED = 7
    GLOBAL_TERRAIN_ALT = 10
    GLOBAL_TERRAIN_ALT_INT = 11


GLOBAL_FRAMES = frozenset({Frame.GLOBAL, Frame.GLOBAL_INT, Frame.GLOBAL_RELATIVE_ALT,
                           Frame.GLOBAL_RELATIVE_ALT_INT})
RELATIVE_ALT_FRAMES = frozenset({Frame.GLOBAL_RELATIVE_ALT, Frame.GLOBAL_RELATIVE_ALT_INT})


class Cmd(enum.IntEnum):
    """The MAV_CMDs a mission may contain that the simulated vehicle knows."""

    NAV_WAYPOINT = 16
    NAV_LOITER_UNLIM = 17
    NAV_LOITER_TURNS = 18
    NAV_LOITER_TIME = 19
    NAV_RETURN_TO_LAUNCH = 20
    NAV_LAND = 21
    NAV_TAKEOFF = 22
    NAV_LOITER_TO_ALT = 31
    NAV_DELAY = 93
    CONDITION_DELAY = 112
    DO_JUMP = 177
    DO_CHANGE_SPEED = 178
    DO_SET_HOME = 179
    DO_SET_RELAY = 181
    DO_SET_SERVO = 183
    DO_LAND_START = 189
    DO_SET_ROI_LOCATION = 195
    DO_SET_ROI_WPNEXT_OFFSET = 196
    DO_SET_ROI_NONE = 197
    DO_DIGICAM_CONTROL = 203
    DO_MOUNT_CONFIGURE = 204
    DO_MOUNT_CONTROL = 205
    DO_SET_CAM_TRIGG_DIST = 206
    DO_SET_ROI = 201
    DO_SET_CAM_TRIGG_INTERVAL = 214
    DO_GIMBAL_MANAGER_PITCHYAW = 1000
    DO_GIMBAL_MANAGER_CONFIGURE = 1001
    IMAGE_START_CAPTURE = 2000
    IMAGE_STOP_CAPTURE = 2001
    VIDEO_START_CAPTURE = 2500
    VIDEO_STOP_CAPTURE = 2501
    SET_CAMERA_MODE = 530
    SET_CAMERA_ZOOM = 531
    SET_CAMERA_FOCUS = 532
    # geofence and rally items (mission types 1 and 2)
    NAV_FENCE_RETURN_POINT = 5000
    NAV_FENCE_POLYGON_VERTEX_INCLUSION = 5001
    NAV_FENCE_POLYGON_VERTEX_EXCLUSION = 5002
    NAV_FENCE_CIRCLE_INCLUSION = 5003
    NAV_FENCE_CIRCLE_EXCLUSION = 5004
    NAV_RALLY_POINT = 5100


#: Items that move the vehicle (the others take effect at once, between them).
NAV_COMMANDS = frozenset({Cmd.NAV_WAYPOINT, Cmd.NAV_LOITER_UNLIM, Cmd.NAV_LOITER_TURNS,
                          Cmd.NAV_LOITER_TIME, Cmd.NAV_RETURN_TO_LAUNCH, Cmd.NAV_LAND,
                          Cmd.NAV_TAKEOFF, Cmd.NAV_LOITER_TO_ALT, Cmd.NAV_DELAY,
                          Cmd.CONDITION_DELAY})
FENCE_COMMANDS = frozenset({Cmd.NAV_FENCE_RETURN_POINT, Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                            Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
                            Cmd.NAV_FENCE_CIRCLE_INCLUSION, Cmd.NAV_FENCE_CIRCLE_EXCLUSION})
RALLY_COMMANDS = frozenset({Cmd.NAV_RALLY_POINT})
MISSION_COMMANDS = frozenset(Cmd) - FENCE_COMMANDS - RALLY_COMMANDS


@dataclass(frozen=True, slots=True)
class MissionItem:
    """One item, as MISSION_ITEM_INT carries it with its position decoded.

    ``x``/``y`` are latitude/longitude in degrees in global frames and north/east metres in
    local ones; ``z`` is the altitude in metres (above mean sea level or above home, by
    ``frame``; in local frames it is *down*).
    """

    seq: int
    frame: int
    command: int
    param1: float = NAN
    param2: float = NAN
    param3: float = NAN
    param4: float = NAN
    x: float = NAN
    y: float = NAN
    z: float = NAN
    autocontinue: bool = True
    mission_type: int = MissionType.MISSION

    @property
    def is_nav(self) -> bool:
        return self.command in NAV_COMMANDS

    @property
    def has_position(self) -> bool:
        return self.frame != Frame.MISSION and math.isfinite(self.x) and math.isfinite(self.y)


class MissionRejected(ValueError):
    """A mission (or one of its items) the vehicle will not take; ``result`` is the
    MAV_MISSION_RESULT a MAVLink vehicle answers with."""

    def __init__(self, message: str, result: int, seq: int | None = None) -> None:
        super().__init__(message)
        self.result = result
        self.seq = seq


# MAV_MISSION_RESULT
MISSION_ACCEPTED = 0
MISSION_ERROR = 1
MISSION_UNSUPPORTED_FRAME = 2
MISSION_UNSUPPORTED = 3
MISSION_NO_SPACE = 4
MISSION_INVALID = 5
MISSION_INVALID_PARAM1 = 6
MISSION_INVALID_SEQUENCE = 13
MISSION_DENIED = 14
MISSION_OPERATION_CANCELLED = 15

MAX_ITEMS = 2000


def check_items(items: list[MissionItem], mission_type: int) -> None:
    """What the vehicle's mission store refuses outright (PX4 answers these with an error
    MISSION_ACK during the upload): unknown commands, unsupported frames, items of another
    list's kind. Feasibility (distances, geofence) is the navigator's, when a mission starts."""
    if len(items) > MAX_ITEMS:
        raise MissionRejected(f"{len(items)} items: at most {MAX_ITEMS}", MISSION_NO_SPACE)
    allowed = {MissionType.MISSION: MISSION_COMMANDS, MissionType.FENCE: FENCE_COMMANDS,
               MissionType.RALLY: RALLY_COMMANDS}.get(mission_type)
    if allowed is None:
        raise MissionRejected(f"unknown mission type {mission_type}", MISSION_UNSUPPORTED)
    for item in items:
        if item.command not in allowed:
            raise MissionRejected(f"item {item.seq}: command {item.command} is not supported",
                                  MISSION_UNSUPPORTED, item.seq)
        if item.command in NAV_COMMANDS | FENCE_COMMANDS | RALLY_COMMANDS and \
                item.frame not in (*GLOBAL_FRAMES, Frame.LOCAL_NED, Frame.MISSION):
            raise MissionRejected(f"item {item.seq}: frame {item.frame} is not supported "
                                  "(global, global relative-altitude or local NED)",
                                  MISSION_UNSUPPORTED_FRAME, item.seq)
