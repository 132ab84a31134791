"""Mission plans as the vehicle stores them: items, their validation and the plan's identity (opaque_id).

Pure data and checks (no MAVLink import: the numbers below are the MAVLink values, checked against pymavlink's
common.xml in tests/unit/test_mission_protocol.py), so the mission executor in the flight stack can read plans too.

Items are kept in the MISSION_ITEM_INT form: x/y are int32, latitude/longitude in degE7 for global frames and
metres * 1e4 for MAV_FRAME_LOCAL_NED (the spec's scaling for *_INT items in local frames), z is float (m).
A legacy MISSION_ITEM (float x/y) is converted on receipt and back on download (`from_float_xy`/`to_float_xy`).

Validation (`check_item`, `check_plan`) names the problem with the MAV_MISSION_RESULT the spec defines for it:
an unsupported command -> MAV_MISSION_UNSUPPORTED, a frame the command cannot use -> UNSUPPORTED_FRAME, a
parameter that is not finite or out of range -> INVALID_PARAM1..7 (5..7 = x, y, z), a DO_JUMP to no item ->
INVALID_PARAM1; `reason` is the STATUSTEXT. NaN is accepted where the spec gives it a meaning ("keep the
current value": the yaw of NAV_WAYPOINT/NAV_LOITER_*/NAV_TAKEOFF/NAV_LAND) and in every parameter the command does
not use ("not given": MAVSDK sends NAV_RETURN_TO_LAUNCH with p1..p4 NaN; PX4 stores them unchecked); a parameter the
command uses must be a number.

Commands (docs/gcs.md has the parameter table):
- MISSION: NAV_WAYPOINT (p1 hold s, p2 acceptance radius m, p4 yaw deg), NAV_LOITER_UNLIM (p4 yaw),
  NAV_LOITER_TIME (p1 time s, p4 yaw), NAV_RETURN_TO_LAUNCH, NAV_LAND (x/y where, p4 yaw), NAV_TAKEOFF (z
  altitude, p4 yaw), DO_JUMP (p1 target seq, p2 repeats, -1 = forever), DO_CHANGE_SPEED (p2 m/s, -1 = no
  change), CONDITION_DELAY (p1 s), CONDITION_YAW (p1 deg 0..360, p2 deg/s, p3 direction -1/0/1, p4 relative
  0/1), DO_GRIPPER (p1 instance 0/1, p2 0 release / 1 grab), NAVIG8_ARM_JOINTS (31010 = MAV_CMD_USER_1: p1..p3
  joint targets deg, p4 = 1), NAVIG8_PITCH_HOLD (31011 = MAV_CMD_USER_2: p1 pitch deg, p2 hold time s: the
  paper's pitched hover).
- FENCE: NAV_FENCE_POLYGON_VERTEX_INCLUSION / _EXCLUSION (p1 vertex count >= 3, x/y lat/lon; consecutive items of
  the same command and count form one polygon), NAV_FENCE_CIRCLE_INCLUSION / _EXCLUSION (p1 radius m >= 0, x/y
  centre), NAV_FENCE_RETURN_POINT (stored, not used: Return flies home). As PX4, an area is stored whatever its
  place; the fence does not enforce an area on the wrong side of home (mission.fence).
- RALLY: NAV_RALLY_POINT (x/y lat/lon, z altitude: AMSL in GLOBAL[_INT], above home in GLOBAL_RELATIVE_ALT[_INT];
  params unused). As PX4 (mavlink_mission.cpp), MAV_FRAME_MISSION is MAV_MISSION_UNSUPPORTED, every other non-global
  frame UNSUPPORTED_FRAME; Return picks among them (mission.rally).
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass
from enum import IntEnum

INT32_MAX = 2**31 - 1
LOCAL_XY_SCALE = 1e4  # MISSION_ITEM_INT x/y in MAV_FRAME_LOCAL_NED: metres * 1e4
GLOBAL_XY_SCALE = 1e7  # degE7
PITCH_HOLD_MAX_DEG = 60.0  # the attitude item's pitch limit (the paper flies 45 deg)


class MissionType(IntEnum):
    MISSION = 0
    FENCE = 1
    RALLY = 2
    ALL = 255


class Result(IntEnum):
    """MAV_MISSION_RESULT."""

    ACCEPTED = 0
    ERROR = 1
    UNSUPPORTED_FRAME = 2
    UNSUPPORTED = 3
    NO_SPACE = 4
    INVALID = 5
    INVALID_PARAM1 = 6
    INVALID_PARAM2 = 7
    INVALID_PARAM3 = 8
    INVALID_PARAM4 = 9
    INVALID_PARAM5_X = 10
    INVALID_PARAM6_Y = 11
    INVALID_PARAM7 = 12
    INVALID_SEQUENCE = 13
    DENIED = 14
    OPERATION_CANCELLED = 15


class Frame(IntEnum):
    GLOBAL = 0
    LOCAL_NED = 1
    MISSION = 2
    GLOBAL_RELATIVE_ALT = 3
    GLOBAL_INT = 5
    GLOBAL_RELATIVE_ALT_INT = 6


class Cmd(IntEnum):
    NAV_WAYPOINT = 16
    NAV_LOITER_UNLIM = 17
    NAV_LOITER_TIME = 19
    NAV_RETURN_TO_LAUNCH = 20
    NAV_LAND = 21
    NAV_TAKEOFF = 22
    CONDITION_DELAY = 112
    CONDITION_YAW = 115
    DO_JUMP = 177
    DO_CHANGE_SPEED = 178
    DO_GRIPPER = 211
    NAV_FENCE_RETURN_POINT = 5000
    NAV_FENCE_POLYGON_VERTEX_INCLUSION = 5001
    NAV_FENCE_POLYGON_VERTEX_EXCLUSION = 5002
    NAV_FENCE_CIRCLE_INCLUSION = 5003
    NAV_FENCE_CIRCLE_EXCLUSION = 5004
    NAV_RALLY_POINT = 5100
    NAVIG8_ARM_JOINTS = 31010  # MAV_CMD_USER_1 (navig8.xml)
    NAVIG8_PITCH_HOLD = 31011  # MAV_CMD_USER_2 (navig8.xml)


GLOBAL_FRAMES = frozenset({Frame.GLOBAL, Frame.GLOBAL_RELATIVE_ALT, Frame.GLOBAL_INT, Frame.GLOBAL_RELATIVE_ALT_INT})
RELATIVE_ALT_FRAMES = frozenset({Frame.GLOBAL_RELATIVE_ALT, Frame.GLOBAL_RELATIVE_ALT_INT})
POSITION_FRAMES = GLOBAL_FRAMES | {Frame.LOCAL_NED}
# Items without a position ignore x/y/z: QGC sends them in MAV_FRAME_MISSION, older tools in a global frame.
NON_POSITION_FRAMES = POSITION_FRAMES | {Frame.MISSION}

NAV_COMMANDS = frozenset({Cmd.NAV_WAYPOINT, Cmd.NAV_LOITER_UNLIM, Cmd.NAV_LOITER_TIME, Cmd.NAV_LAND,
                          Cmd.NAV_TAKEOFF})  # items with a position (x, y, z)
MISSION_COMMANDS = NAV_COMMANDS | {
    Cmd.NAV_RETURN_TO_LAUNCH, Cmd.CONDITION_DELAY, Cmd.CONDITION_YAW, Cmd.DO_JUMP, Cmd.DO_CHANGE_SPEED,
    Cmd.DO_GRIPPER, Cmd.NAVIG8_ARM_JOINTS, Cmd.NAVIG8_PITCH_HOLD,
}  # fmt: skip
FENCE_POLYGON_COMMANDS = frozenset({Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION})
FENCE_CIRCLE_COMMANDS = frozenset({Cmd.NAV_FENCE_CIRCLE_INCLUSION, Cmd.NAV_FENCE_CIRCLE_EXCLUSION})
FENCE_COMMANDS = FENCE_POLYGON_COMMANDS | FENCE_CIRCLE_COMMANDS | {Cmd.NAV_FENCE_RETURN_POINT}
RALLY_COMMANDS = frozenset({Cmd.NAV_RALLY_POINT})
# storage per type (NO_SPACE above); rally: PX4's DM_KEY_SAFE_POINTS_MAX
MAX_ITEMS = {MissionType.MISSION: 500, MissionType.FENCE: 64, MissionType.RALLY: 32}
# Yaw (p4) may be NaN = keep the current heading.
_YAW_P4 = frozenset({Cmd.NAV_WAYPOINT, Cmd.NAV_LOITER_UNLIM, Cmd.NAV_LOITER_TIME, Cmd.NAV_LAND, Cmd.NAV_TAKEOFF})
# The parameters (0-based p1..p4) each command uses: the executor and the fence read these and nothing else, so
# the others may be anything finite or NaN ("not given").
_USED_PARAMS: dict[int, frozenset[int]] = {
    Cmd.NAV_WAYPOINT: frozenset({0, 1, 3}), Cmd.NAV_LOITER_UNLIM: frozenset({3}),
    Cmd.NAV_LOITER_TIME: frozenset({0, 3}), Cmd.NAV_LAND: frozenset({3}), Cmd.NAV_TAKEOFF: frozenset({3}),
    Cmd.NAV_RETURN_TO_LAUNCH: frozenset(), Cmd.CONDITION_DELAY: frozenset({0}),
    Cmd.CONDITION_YAW: frozenset({0, 1, 2, 3}), Cmd.DO_JUMP: frozenset({0, 1}), Cmd.DO_CHANGE_SPEED: frozenset({1}),
    Cmd.DO_GRIPPER: frozenset({0, 1}), Cmd.NAVIG8_ARM_JOINTS: frozenset({0, 1, 2, 3}),
    Cmd.NAVIG8_PITCH_HOLD: frozenset({0, 1}), Cmd.NAV_FENCE_RETURN_POINT: frozenset(),
    Cmd.NAV_RALLY_POINT: frozenset(),
    **{c: frozenset({0}) for c in (Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
                                   Cmd.NAV_FENCE_CIRCLE_INCLUSION, Cmd.NAV_FENCE_CIRCLE_EXCLUSION)},
}  # fmt: skip


@dataclass(frozen=True)
class MissionItem:
    """One stored item (MISSION_ITEM_INT form: x/y int32, see the module docstring)."""

    frame: int
    command: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float

    @property
    def params(self) -> tuple[float, float, float, float]:
        return (self.param1, self.param2, self.param3, self.param4)


@dataclass(frozen=True)
class Plan:
    """The items of one mission type in force, the start item (`current`, from the item marked current on
    upload) and its identity (CRC32 of the items, never 0; 0 = no plan)."""

    mission_type: int
    items: tuple[MissionItem, ...] = ()
    current: int = 0

    @property
    def opaque_id(self) -> int:
        return plan_crc(self.items) if self.items else 0


@dataclass(frozen=True)
class Progress:
    """What the mission executor reports: the item being flown, the last item reached (-1: none yet), whether the
    vehicle is in Mission mode, whether the plan has been flown to its end, and the last reached items as
    (running count, seq) so that every one is announced (MISSION_ITEM_REACHED) even when several complete
    between two polls."""

    current: int = 0
    reached: int = -1
    active: bool = False
    finished: bool = False
    reached_log: tuple[tuple[int, int], ...] = ()


@dataclass(frozen=True)
class Problem:
    """Why an item (or a plan) is refused: the MAV_MISSION_RESULT and the STATUSTEXT."""

    result: Result
    reason: str


_ALLOWED = {MissionType.MISSION: MISSION_COMMANDS, MissionType.FENCE: FENCE_COMMANDS,
            MissionType.RALLY: RALLY_COMMANDS}


def plan_crc(items: tuple[MissionItem, ...]) -> int:
    """CRC32 over each item's frame, command, autocontinue, params 1-4, x, y, z (PX4's crc32_for_mission_item
    fields) as the plan's opaque_id; never 0 (0 means "no plan" in the spec)."""
    crc = 0
    for it in items:
        crc = zlib.crc32(struct.pack("<BHBffffiif", it.frame & 0xFF, it.command & 0xFFFF, it.autocontinue & 0xFF,
                                     it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z), crc)
    return crc or 1


def from_float_xy(frame: int, x: float, y: float) -> tuple[int, int] | None:
    """x/y of a legacy MISSION_ITEM (degrees or metres) in the stored int form; None when not representable."""
    scale = LOCAL_XY_SCALE if frame == Frame.LOCAL_NED else GLOBAL_XY_SCALE
    if not (math.isfinite(x) and math.isfinite(y)):
        return None
    xi, yi = round(x * scale), round(y * scale)
    if max(abs(xi), abs(yi)) > INT32_MAX:
        return None
    return int(xi), int(yi)


def to_float_xy(frame: int, x: int, y: int) -> tuple[float, float]:
    scale = LOCAL_XY_SCALE if frame == Frame.LOCAL_NED else GLOBAL_XY_SCALE
    return x / scale, y / scale


def _finite(v: float) -> bool:
    return math.isfinite(v)


def check_item(item: MissionItem, mission_type: int, count: int) -> Problem | None:
    """None when `item` can be stored in a plan of `count` items of `mission_type`, else the problem."""
    cmd = item.command
    allowed = _ALLOWED.get(int(mission_type), frozenset())
    if cmd not in allowed:
        kind = {0: "mission", 1: "fence", 2: "rally plan"}.get(int(mission_type), f"type {int(mission_type)}")
        return Problem(Result.UNSUPPORTED, f"Mission item: command {cmd} not supported in a {kind}")
    name = Cmd(cmd).name
    positional = cmd in NAV_COMMANDS or cmd in FENCE_COMMANDS or cmd in RALLY_COMMANDS
    global_only = cmd in FENCE_COMMANDS or cmd in RALLY_COMMANDS
    frames = (GLOBAL_FRAMES if global_only else POSITION_FRAMES) if positional else NON_POSITION_FRAMES
    if cmd in RALLY_COMMANDS and item.frame == Frame.MISSION:  # PX4: MAV_FRAME_MISSION -> UNSUPPORTED
        return Problem(Result.UNSUPPORTED, f"{name}: frame {item.frame} (MISSION) not supported")
    if item.frame not in frames:
        return Problem(Result.UNSUPPORTED_FRAME, f"{name}: frame {item.frame} not supported")
    if item.autocontinue not in (0, 1):
        return Problem(Result.INVALID, f"{name}: autocontinue must be 0 or 1")
    p = item.params
    used = _USED_PARAMS[cmd]
    for i, v in enumerate(p):
        if _finite(v) or (math.isnan(v) and (i not in used or (i == 3 and cmd in _YAW_P4))):
            continue
        return Problem(Result(Result.INVALID_PARAM1 + i), f"{name}: param{i + 1} must be a number")
    if positional:
        if not _finite(item.z):
            return Problem(Result.INVALID_PARAM7, f"{name}: z must be a number")
        if item.frame in GLOBAL_FRAMES:
            if abs(item.x) > 90 * GLOBAL_XY_SCALE:
                return Problem(Result.INVALID_PARAM5_X, f"{name}: latitude {item.x / 1e7:g} outside +-90 deg")
            if abs(item.y) > 180 * GLOBAL_XY_SCALE:
                return Problem(Result.INVALID_PARAM6_Y, f"{name}: longitude {item.y / 1e7:g} outside +-180 deg")
    return _check_params(item, Cmd(cmd), count)


def _range(item: MissionItem, index: int, lo: float, hi: float, what: str) -> Problem | None:
    v = item.params[index]
    if lo <= v <= hi:
        return None
    return Problem(Result(Result.INVALID_PARAM1 + index),
                   f"{Cmd(item.command).name}: param{index + 1} ({what}) {v:g} outside [{lo:g}, {hi:g}]")


def _check_params(item: MissionItem, cmd: Cmd, count: int) -> Problem | None:
    inf = math.inf
    checks: list[tuple[int, float, float, str]] = []
    if cmd == Cmd.NAV_WAYPOINT:
        checks = [(0, 0, 3600, "hold time s"), (1, 0, 1000, "acceptance radius m")]
    elif cmd == Cmd.NAV_LOITER_TIME:
        checks = [(0, 0, 86400, "time s")]
    elif cmd == Cmd.NAV_TAKEOFF and not 0 < item.z <= 1000 and item.frame in RELATIVE_ALT_FRAMES:
        return Problem(Result.INVALID_PARAM7, f"NAV_TAKEOFF: altitude {item.z:g} m above home must be > 0")
    elif cmd == Cmd.DO_JUMP:
        checks = [(0, 0, count - 1, "target item"), (1, -1, 1e6, "repeat count, -1 = forever")]
    elif cmd == Cmd.DO_CHANGE_SPEED:
        if item.param2 != -1 and not 0 < item.param2 <= 20:
            return Problem(Result.INVALID_PARAM2, f"DO_CHANGE_SPEED: speed {item.param2:g} m/s outside (0, 20] "
                           "(-1 = no change)")
    elif cmd == Cmd.CONDITION_DELAY:
        checks = [(0, 0, 86400, "delay s")]
    elif cmd == Cmd.CONDITION_YAW:
        checks = [(0, 0, 360, "angle deg"), (1, 0, inf, "rate deg/s"), (2, -1, 1, "direction"),
                  (3, 0, 1, "relative")]
    elif cmd == Cmd.DO_GRIPPER:
        checks = [(0, 0, 1, "instance"), (1, 0, 1, "action 0 release / 1 grab")]
    elif cmd == Cmd.NAVIG8_ARM_JOINTS:
        checks = [(0, -180, 180, "q1 deg"), (1, -180, 180, "q2 deg"), (2, -180, 180, "q3 deg"), (3, 1, 1, "apply")]
    elif cmd == Cmd.NAVIG8_PITCH_HOLD:
        checks = [(0, -PITCH_HOLD_MAX_DEG, PITCH_HOLD_MAX_DEG, "pitch deg"), (1, 0, 86400, "hold time s")]
    elif cmd in FENCE_POLYGON_COMMANDS:
        checks = [(0, 3, 64, "vertex count")]
    elif cmd in FENCE_CIRCLE_COMMANDS:
        checks = [(0, 0.0, 1e5, "radius m")]  # 0: the empty circle MAVSDK's geofence example sends (never enforced)
    for index, lo, hi, what in checks:
        problem = _range(item, index, lo, hi, what)
        if problem is not None:
            return problem
    if cmd == Cmd.DO_JUMP and item.param1 != int(item.param1):
        return Problem(Result.INVALID_PARAM1, f"DO_JUMP: target {item.param1:g} is not an item number")
    return None


def check_plan(items: tuple[MissionItem, ...], mission_type: int) -> Problem | None:
    """Whole-plan rules once every item is in: fence polygons have as many vertices as they announce."""
    if mission_type != MissionType.FENCE:
        return None
    i = 0
    while i < len(items):
        it = items[i]
        if it.command in FENCE_POLYGON_COMMANDS:
            n = int(it.param1)
            group = items[i:i + n]
            if len(group) < n or any(g.command != it.command or int(g.param1) != n for g in group):
                return Problem(Result.INVALID_PARAM1, f"Fence polygon at item {i}: fewer than {n} vertices")
            i += n
        else:
            i += 1
    return None
