"""Flies an uploaded mission plan: one `step` per control tick on sim time gives the setpoint, the arm/gripper
actions and the hand-over to landing. Pure (the mode manager owns it while in Mission mode).

Positions: LOCAL_NED items are NED metres (x/y stored * 1e4); global items are projected around the global
origin (navig8_fc.mission.geo); altitudes: GLOBAL_RELATIVE_ALT[_INT] z is above home (NED z = home_z - z),
GLOBAL[_INT] z is AMSL (NED z = alt0 - z); LOCAL_NED z is NED down.

Items (docs/gcs.md, "Mission execution"):
- NAV_TAKEOFF: climb above where the vehicle is at `climb_rate_m_s` to the item's altitude; done within
  `takeoff_tol_m`.
- NAV_WAYPOINT / NAV_LOITER_TIME / NAV_LOITER_UNLIM: fly to the position (the setpoint steps there, as the
  paper's Eq. 25 commands do, unless DO_CHANGE_SPEED set a speed: then it moves along the straight line at that
  speed); reached within the acceptance radius (p2 of a waypoint, else `acceptance_m`); then hold p1 s (waypoint
  hold, loiter time) or forever (LOITER_UNLIM). Yaw p4 (deg, NaN keep) is commanded from the item's start.
- NAV_LAND: fly to x/y (x = y = 0 in a global frame: where the vehicle is) at the current altitude, then hand
  over to landing (`ExecStep.land`); the plan is finished.
- NAV_RETURN_TO_LAUNCH: choose the destination as PX4's RTL_TYPE 0 (navig8_fc.mission.rally: home, or the closest
  rally point more than 10 m from home), climb to `rtl_alt_m` above it if lower, fly there, hand over to landing.
- DO_CHANGE_SPEED (p2 m/s, -1 keep), DO_GRIPPER, NAVIG8_ARM_JOINTS: act and continue at once.
- DO_JUMP: jump to p1, p2 times (-1: forever), then continue.
- CONDITION_DELAY: hold p1 s. CONDITION_YAW: command yaw p1 deg (absolute, or relative with p3 direction when
  p4 = 1); done within `yaw_tol_rad` (or after `yaw_timeout_s`).
- NAVIG8_PITCH_HOLD: command pitch p1 deg from now on (the paper's pitched hover) and hold p2 s.
The end of the plan (no LAND/RTL last): `finished`, the mode manager holds where the last item left it.
Every completed item is reported reached, in order (`Progress.reached_log`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import (
    LOCAL_XY_SCALE,
    RELATIVE_ALT_FRAMES,
    Cmd,
    Frame,
    MissionItem,
    Plan,
    Progress,
)
from navig8_fc.mission.rally import Destination, RallyPoint, return_destination

Vec3 = tuple[float, float, float]
REACHED_LOG_LEN = 32
EPS_S = 1e-6  # timers compare sim times that are sums of 10 ms steps: 2.5 s must not read 2.4999999 s


@dataclass(frozen=True)
class ExecConfig:
    climb_rate_m_s: float = 1.0
    takeoff_tol_m: float = 0.2
    acceptance_m: float = 0.2  # waypoint acceptance radius when the item's p2 is 0
    rtl_alt_m: float = 2.5  # return altitude above the return's destination (RTL_RETURN_ALT)
    yaw_tol_rad: float = 0.1
    yaw_timeout_s: float = 10.0


class ExecStep(NamedTuple):
    setpoint: Setpoint
    actions: tuple[tuple[str, object], ...]  # ("gripper", "grab"|"release") / ("joints", (q1, q2, q3) rad)
    land: bool  # hand over to landing (NAV_LAND, the end of NAV_RETURN_TO_LAUNCH)
    events: tuple[str, ...]


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def item_position(it: MissionItem, origin: GeoOrigin, home_ned_m: Vec3, here: Vec3) -> Vec3:
    """An item's position in local NED (m): LOCAL_NED as is; a global frame around the origin, x = y = 0 meaning
    `here`, the altitude above home (RELATIVE_ALT frames) or AMSL."""
    if it.frame == Frame.LOCAL_NED:
        return it.x / LOCAL_XY_SCALE, it.y / LOCAL_XY_SCALE, it.z
    if it.x == 0 and it.y == 0:
        n, e = here[0], here[1]  # no position given: here
    else:
        n, e = origin.to_ned_xy(it.x * 1e-7, it.y * 1e-7)
    if it.frame in RELATIVE_ALT_FRAMES:
        d = home_ned_m[2] - it.z
    else:
        d = origin.alt_amsl_m - it.z
    return n, e, d


_AT_POSITION = (Cmd.NAV_WAYPOINT, Cmd.NAV_LOITER_TIME, Cmd.NAV_LOITER_UNLIM)


def planned_path(plan: Plan, origin: GeoOrigin, home_ned_m: Vec3) -> list[Vec3]:
    """The positions a plan flies through in item order, starting at home (for display: the executor's targets
    without its timing, DO_JUMP loops shown once): takeoff climbs where the vehicle is, waypoints and loiters go to
    their position, a landing descends at its x/y, return to launch ends at home."""
    here = home_ned_m
    path = [here]
    for it in plan.items:
        cmd = it.command
        if cmd == Cmd.NAV_TAKEOFF:
            here = (here[0], here[1], item_position(it, origin, home_ned_m, here)[2])
        elif cmd in _AT_POSITION:
            here = item_position(it, origin, home_ned_m, here)
        elif cmd == Cmd.NAV_LAND:
            p = item_position(it, origin, home_ned_m, here)
            path.append((p[0], p[1], here[2]))
            here = (p[0], p[1], home_ned_m[2])
        elif cmd == Cmd.NAV_RETURN_TO_LAUNCH:
            here = home_ned_m
        else:
            continue
        path.append(here)
    return path


class MissionExecutor:
    def __init__(self, plan: Plan, origin: GeoOrigin, home_ned_m: Vec3, start_sp: Setpoint,
                 config: ExecConfig | None = None, reached_count: int = 0,
                 rally: Callable[[], tuple[RallyPoint, ...]] | None = None) -> None:
        self._plan = plan
        self._rally = rally  # the rally points in force, read when a return starts
        self._dest = Destination(-1, home_ned_m)  # where the last return went
        self._origin = origin
        self._home = home_ned_m
        self._cfg = config or ExecConfig()
        self._idx = plan.current if 0 <= plan.current < len(plan.items) else 0
        self._pos: Vec3 = start_sp.pos_ned_m  # the position setpoint
        self._pitch = start_sp.pitch_rad
        self._yaw = start_sp.yaw_rad
        self._speed = 0.0  # 0: step the setpoint to the target
        self._jumps: dict[int, int] = {}
        self._entered = False
        self._phase = 0
        self._target: Vec3 = self._pos
        self._t_start = 0.0
        self._hold_since: float | None = None
        self._finished = False
        self._reached = -1
        self._count = reached_count
        self._log: tuple[tuple[int, int], ...] = ()

    @property
    def progress(self) -> Progress:
        n = len(self._plan.items)
        return Progress(min(self._idx, n - 1) if n else 0, self._reached, True, self._finished, self._log)

    @property
    def reached_count(self) -> int:
        return self._count

    @property
    def finished(self) -> bool:
        return self._finished

    @property
    def destination(self) -> Destination:
        """Where the last NAV_RETURN_TO_LAUNCH went (home until one started)."""
        return self._dest

    # --- positions ---------------------------------------------------------------------------------------
    def _item_pos(self, it: MissionItem, here: Vec3) -> Vec3:
        return item_position(it, self._origin, self._home, here)

    def _setpoint(self) -> Setpoint:
        return Setpoint(self._pos, self._pitch, self._yaw)

    def _move(self, target: Vec3, dt: float) -> None:
        if self._speed <= 0.0:
            self._pos = target
            return
        d = [t - p for t, p in zip(target, self._pos, strict=True)]
        dist = math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
        step = self._speed * dt
        if dist <= step:
            self._pos = target
        else:
            self._pos = tuple(p + di * step / dist for p, di in zip(self._pos, d, strict=True))  # type: ignore[assignment]

    # --- the step ----------------------------------------------------------------------------------------
    def step(self, t_s: float, pos_ned_m: Vec3, yaw_rad: float, dt: float) -> ExecStep:
        actions: list[tuple[str, object]] = []
        events: list[str] = []
        land = False
        for _ in range(len(self._plan.items) + 1):  # instant items run in the same step, bounded (DO_JUMP loops)
            if self._finished or self._idx >= len(self._plan.items):
                if not self._finished:
                    self._finished = True
                    events.append("Mission complete")
                break
            it = self._plan.items[self._idx]
            if not self._entered:
                self._enter(it, t_s, pos_ned_m, events)
            done, land_now = self._run(it, t_s, pos_ned_m, yaw_rad, dt, actions)
            if not done:
                break
            self._complete(events)
            if land_now:
                land = True
                self._finished = True
                break
            if it.command == Cmd.DO_JUMP:
                self._jump(it)
        return ExecStep(self._setpoint(), tuple(actions), land, tuple(events))

    def _complete(self, events: list[str]) -> None:
        self._count += 1
        self._reached = self._idx
        self._log = (*self._log[-(REACHED_LOG_LEN - 1):], (self._count, self._idx))
        self._idx += 1
        self._entered = False

    def _jump(self, it: MissionItem) -> None:
        key = self._idx - 1
        done = self._jumps.get(key, 0)
        repeats = int(it.param2)
        if repeats < 0 or done < repeats:
            self._jumps[key] = done + 1
            self._idx = int(it.param1)

    def _enter(self, it: MissionItem, t_s: float, here: Vec3, events: list[str]) -> None:
        self._entered = True
        self._t_start = t_s
        self._hold_since = None
        self._phase = 0
        cmd = it.command
        if cmd in (Cmd.NAV_WAYPOINT, Cmd.NAV_LOITER_TIME, Cmd.NAV_LOITER_UNLIM, Cmd.NAV_TAKEOFF, Cmd.NAV_LAND):
            if math.isfinite(it.param4):
                self._yaw = _wrap(math.radians(it.param4))
        if cmd == Cmd.NAV_TAKEOFF:
            self._target = (self._pos[0], self._pos[1], self._item_pos(it, here)[2])
            self._pos = (self._pos[0], self._pos[1], here[2]) if self._pos[2] > here[2] else self._pos
        elif cmd in (Cmd.NAV_WAYPOINT, Cmd.NAV_LOITER_TIME, Cmd.NAV_LOITER_UNLIM):
            self._target = self._item_pos(it, here)
        elif cmd == Cmd.NAV_LAND:
            p = self._item_pos(it, here)
            self._target = (p[0], p[1], self._pos[2])
        elif cmd == Cmd.NAV_RETURN_TO_LAUNCH:
            dest = self._dest = return_destination(here, self._home, self._rally() if self._rally else ())
            self._target = (self._pos[0], self._pos[1], min(self._pos[2], dest.pos_ned_m[2] - self._cfg.rtl_alt_m))
            events.append("Mission: returning to launch" if dest.is_home else
                          f"Mission: returning to rally point {dest.seq}")
        elif cmd == Cmd.CONDITION_YAW:
            if int(it.param4) == 1:
                direction = -1.0 if int(it.param3) == -1 else 1.0
                self._yaw = _wrap(self._yaw + direction * math.radians(it.param1))
            else:
                self._yaw = _wrap(math.radians(it.param1))
        elif cmd == Cmd.NAVIG8_PITCH_HOLD:
            self._pitch = math.radians(it.param1)

    def _run(self, it: MissionItem, t_s: float, here: Vec3, yaw_rad: float, dt: float,
             actions: list[tuple[str, object]]) -> tuple[bool, bool]:
        """(done, land) for the current item."""
        cmd = it.command
        cfg = self._cfg
        if cmd == Cmd.NAV_TAKEOFF:
            x, y, z = self._pos
            tz = self._target[2]
            step = cfg.climb_rate_m_s * dt
            z = tz if abs(tz - z) <= step else z + math.copysign(step, tz - z)
            self._pos = (x, y, z)
            return z == tz and abs(here[2] - tz) < cfg.takeoff_tol_m, False
        if cmd in (Cmd.NAV_WAYPOINT, Cmd.NAV_LOITER_TIME, Cmd.NAV_LOITER_UNLIM):
            self._move(self._target, dt)
            radius = it.param2 if cmd == Cmd.NAV_WAYPOINT and it.param2 > 0 else cfg.acceptance_m
            if self._hold_since is None:
                if self._pos != self._target or math.dist(here, self._target) > radius:
                    return False, False
                self._hold_since = t_s
            if cmd == Cmd.NAV_LOITER_UNLIM:
                return False, False
            return t_s - self._hold_since >= it.param1 - EPS_S, False
        if cmd == Cmd.NAV_LAND:
            self._move(self._target, dt)
            return self._pos == self._target and math.dist(here[:2], self._target[:2]) <= cfg.acceptance_m, True
        if cmd == Cmd.NAV_RETURN_TO_LAUNCH:
            if self._phase == 0:  # climb
                self._move(self._target, dt)
                if self._pos == self._target and abs(here[2] - self._target[2]) < cfg.takeoff_tol_m:
                    self._phase = 1
                    dest = self._dest.pos_ned_m
                    self._target = (dest[0], dest[1], self._target[2])
                return False, False
            self._move(self._target, dt)
            return self._pos == self._target and math.dist(here, self._target) <= cfg.acceptance_m, True
        if cmd == Cmd.DO_CHANGE_SPEED:
            if it.param2 > 0:
                self._speed = it.param2
            return True, False
        if cmd == Cmd.DO_GRIPPER:
            actions.append(("gripper", "grab" if int(it.param2) == 1 else "release"))
            return True, False
        if cmd == Cmd.NAVIG8_ARM_JOINTS:
            actions.append(("joints", (math.radians(it.param1), math.radians(it.param2), math.radians(it.param3))))
            return True, False
        if cmd == Cmd.DO_JUMP:
            return True, False
        if cmd == Cmd.CONDITION_DELAY:
            return t_s - self._t_start >= it.param1 - EPS_S, False
        if cmd == Cmd.CONDITION_YAW:
            return abs(_wrap(yaw_rad - self._yaw)) < cfg.yaw_tol_rad or t_s - self._t_start >= cfg.yaw_timeout_s, False
        if cmd == Cmd.NAVIG8_PITCH_HOLD:
            return t_s - self._t_start >= it.param2 - EPS_S, False
        return True, False  # a command the plan checks let through but nothing to do here
