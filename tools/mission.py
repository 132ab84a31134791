"""navig8-mission: a pymavlink ground-station client for mission plans.

    navig8-mission upload PLAN [--connect udpin:127.0.0.1:14550]    # .plan (QGroundControl JSON) or waypoint text
    navig8-mission download OUT.waypoints [--connect ...]  # the mission as waypoint text
    navig8-mission download OUT.plan [--connect ...]       # mission, fence and rally points as a QGC .plan
    navig8-mission clear [--connect ...]
    navig8-mission fly PLAN [--connect ...] [--timeout S]      # upload, Mission, arm, progress, summary
    navig8-mission from-scenario paper OUT.waypoints           # a scenario's script + arm schedule as a plan

Plan files:
- QGroundControl `.plan` JSON (fileType "Plan"): `mission.items` SimpleItems (command, frame, params[7],
  autoContinue; params 5/6 are latitude/longitude in degrees for global frames, x/y in metres for
  MAV_FRAME_LOCAL_NED; null = NaN; DO_JUMP param1 is the target's doJumpId, converted to its item number as QGC
  does on upload), `geoFence` circles/polygons (inclusion and exclusion) and its `breachReturn` point -> the FENCE
  plan, and `rallyPoints` `points` ([lat, lon, alt above home]) -> the RALLY plan (NAV_RALLY_POINT,
  MAV_FRAME_GLOBAL_RELATIVE_ALT, as QGC and MAVSDK's import_qgroundcontrol_mission send them).
  `upload` sends each plan the file has.
- `download` to a `.plan` path writes all three plans the vehicle holds in that format (`write_qgc_plan`: fence
  vertices grouped back into polygons, DO_JUMP targets as doJumpIds, NaN parameters as null), which reads back
  equal; to any other path the mission alone as waypoint text.
- MAVLink waypoint text ("QGC WPL 110"): one item per line, `seq current frame command p1 p2 p3 p4 x y z
  autocontinue`, tab-separated; every line is an item (no home line is skipped: this vehicle does not take
  item 0 as home, like PX4).

`fly` uploads the plan, selects Mission (SET_MODE, custom_mode AUTO.MISSION), arms unless the vehicle is armed
already (an air-started scenario), prints the progress (current item, distance from home, wall time) and
ends with a summary line (items reached, wall time, path length, distance from home at the end) when the
mission is complete (MISSION_CURRENT COMPLETE), the vehicle disarmed after flying, or the timeout passed.

`from-scenario` turns a scenario's flight-controller script (Eq. 25 steps) and arm schedule (Eq. 26 square
wave, its initial ramp as 0.25 s joint-target steps) into a plan: one NAV_WAYPOINT (LOCAL_NED, acceptance
radius 1000 m, so it is done the step it is commanded, as a step setpoint is) per setpoint step,
NAVIG8_PITCH_HOLD for pitch steps, NAVIG8_ARM_JOINTS for arm targets, CONDITION_DELAY between events and up to
the scenario's duration (a command at the very end is left out: the scripted run ends there). Flown on the
`paper_plan` world (the paper's world without a script: the FC starts hovering and the plan commands
everything), it reproduces the paper run (docs/gcs.md).

The client side of the mission protocol lives here (`upload`, `download`), used by the SITL tests too: the vehicle
requests each item; the client answers whatever seq is requested (a repeated request gets the item again) and
finishes on MISSION_ACK. Every wait is bounded (`timeout_s` without a message from the vehicle ends it).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pymavlink import mavutil

from navig8_fc.mission.plan import Cmd, Frame, MissionItem, MissionType, from_float_xy, to_float_xy

WPL_HEADER = "QGC WPL 110"
_TIMEOUT_S = 5.0


@dataclass(frozen=True)
class PlanFile:
    mission: tuple[MissionItem, ...]
    fence: tuple[MissionItem, ...] = ()
    rally: tuple[MissionItem, ...] = ()


def _item(frame: int, command: int, autocontinue: int, p: list[float], x: float, y: float, z: float) -> MissionItem:
    xy = from_float_xy(frame, x, y) if math.isfinite(x) and math.isfinite(y) else (0, 0)
    if xy is None:
        raise ValueError(f"command {command}: x/y {x}, {y} out of range")
    return MissionItem(int(frame), int(command), int(autocontinue), *(float(v) for v in p[:4]), xy[0], xy[1],
                       float(z))


def _num(v: Any) -> float:
    return math.nan if v is None else float(v)


def read_qgc_plan(doc: dict) -> PlanFile:
    if doc.get("fileType") != "Plan":
        raise ValueError("not a QGroundControl .plan file (fileType != 'Plan')")
    raw = doc.get("mission", {}).get("items", [])
    jump_ids: dict[int, int] = {}
    for i, it in enumerate(raw):
        if it.get("type") != "SimpleItem":
            raise ValueError(f"item {i}: {it.get('type')!r} items are not supported (SimpleItem only)")
        if "doJumpId" in it:
            jump_ids[int(it["doJumpId"])] = i
    items = []
    for i, it in enumerate(raw):
        p = [_num(v) for v in it["params"]]
        if int(it["command"]) == Cmd.DO_JUMP:
            if int(p[0]) not in jump_ids:
                raise ValueError(f"item {i}: DO_JUMP to doJumpId {p[0]:g}, which no item has")
            p[0] = float(jump_ids[int(p[0])])
        items.append(_item(it.get("frame", Frame.MISSION), it["command"], int(bool(it.get("autoContinue", True))),
                           p, p[4], p[5], p[6]))
    fence = []
    geo = doc.get("geoFence", {})
    for c in geo.get("circles", []):
        lat, lon = c["circle"]["center"]
        cmd = Cmd.NAV_FENCE_CIRCLE_INCLUSION if c.get("inclusion", True) else Cmd.NAV_FENCE_CIRCLE_EXCLUSION
        fence.append(_item(Frame.GLOBAL_INT, cmd, 1, [c["circle"]["radius"], 0, 0, 0], lat, lon, 0.0))
    for poly in geo.get("polygons", []):
        n = len(poly["polygon"])
        cmd = (Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION if poly.get("inclusion", True)
               else Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION)
        fence += [_item(Frame.GLOBAL_INT, cmd, 1, [n, 0, 0, 0], lat, lon, 0.0) for lat, lon in poly["polygon"]]
    if (ret := geo.get("breachReturn")) is not None and len(ret) >= 2:  # QGC's [lat, lon, alt above home]
        fence.append(_item(Frame.GLOBAL_RELATIVE_ALT, Cmd.NAV_FENCE_RETURN_POINT, 1, [0, 0, 0, 0], ret[0], ret[1],
                           float(ret[2]) if len(ret) > 2 else 0.0))
    rally = [_item(Frame.GLOBAL_RELATIVE_ALT, Cmd.NAV_RALLY_POINT, 0, [0, 0, 0, 0], lat, lon, alt)
             for lat, lon, alt in doc.get("rallyPoints", {}).get("points", [])]
    return PlanFile(tuple(items), tuple(fence), tuple(rally))


def _deg_or_m(it: MissionItem) -> tuple[float, float]:
    return to_float_xy(it.frame, it.x, it.y)


def _json_num(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def _fence_json(fence: tuple[MissionItem, ...]) -> dict[str, Any]:
    """The FENCE plan as QGroundControl's geoFence: circles, and polygons from runs of vertices (param1 = count)."""
    circles: list[dict[str, Any]] = []
    polygons: list[dict[str, Any]] = []
    out: dict[str, Any] = {"version": 2, "circles": circles, "polygons": polygons}
    i = 0
    while i < len(fence):
        it = fence[i]
        lat, lon = _deg_or_m(it)
        if it.command in (Cmd.NAV_FENCE_CIRCLE_INCLUSION, Cmd.NAV_FENCE_CIRCLE_EXCLUSION):
            circles.append({"circle": {"center": [lat, lon], "radius": it.param1},
                            "inclusion": it.command == Cmd.NAV_FENCE_CIRCLE_INCLUSION, "version": 1})
            i += 1
        elif it.command in (Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION):
            n = max(1, int(it.param1))
            polygons.append({"polygon": [list(_deg_or_m(v)) for v in fence[i:i + n]],
                             "inclusion": it.command == Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, "version": 1})
            i += n
        elif it.command == Cmd.NAV_FENCE_RETURN_POINT:
            out["breachReturn"] = [lat, lon, it.z]
            i += 1
        else:
            raise ValueError(f"fence item {i}: command {it.command} has no place in a .plan's geoFence")
    return out


def write_qgc_plan(plan: PlanFile, home: tuple[float, float, float] | None = None) -> str:
    """`plan` as a QGroundControl .plan (JSON) that read_qgc_plan reads back equal. home: (lat, lon, alt AMSL) for
    plannedHomePosition (QGC shows it; nothing here reads it)."""
    items = []
    for i, it in enumerate(plan.mission):
        x, y = _deg_or_m(it)
        params = [_json_num(v) for v in (*it.params, x, y, it.z)]
        if it.command == Cmd.DO_JUMP:  # the target's item number as its doJumpId (items are numbered i + 1)
            params[0] = float(int(it.param1) + 1)
        items.append({"type": "SimpleItem", "autoContinue": bool(it.autocontinue), "command": it.command,
                      "doJumpId": i + 1, "frame": it.frame, "params": params})
    rally = [[*_deg_or_m(r), r.z] for r in plan.rally]
    doc = {"fileType": "Plan", "version": 1, "groundStation": "navig8-mission",
           "mission": {"version": 2, "firmwareType": 12, "vehicleType": 2, "items": items,
                       "plannedHomePosition": list(home) if home else [0.0, 0.0, 0.0]},
           "geoFence": _fence_json(plan.fence), "rallyPoints": {"version": 2, "points": rally}}
    return json.dumps(doc, indent=2) + "\n"


def read_wpl(text: str) -> PlanFile:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines or not lines[0].startswith("QGC WPL"):
        raise ValueError(f"not a waypoint file (first line must be {WPL_HEADER!r})")
    items = []
    for k, ln in enumerate(lines[1:]):
        f = ln.split()
        if len(f) != 12:
            raise ValueError(f"line {k + 2}: 12 fields expected, got {len(f)}")
        frame, command = int(f[2]), int(f[3])
        p = [float(v) for v in f[4:8]]
        items.append(_item(frame, command, int(f[11]), p, float(f[8]), float(f[9]), float(f[10])))
    return PlanFile(tuple(items))


def write_wpl(items: tuple[MissionItem, ...], current: int = 0) -> str:
    out = [WPL_HEADER]
    for i, it in enumerate(items):
        x, y = to_float_xy(it.frame, it.x, it.y)
        vals = [i, int(i == current), it.frame, it.command, *it.params, x, y, it.z, it.autocontinue]
        out.append("\t".join(f"{v:.8g}" if isinstance(v, float) else str(v) for v in vals))
    return "\n".join(out) + "\n"


def read_plan(path: str | Path) -> PlanFile:
    text = Path(path).read_text(encoding="utf-8")
    if text.lstrip().startswith("{"):
        return read_qgc_plan(json.loads(text))
    return read_wpl(text)


# --- the client side of the mission protocol ------------------------------------------------------------
def _from_vehicle(conn: Any, kinds: list[str], timeout_s: float) -> Any | None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        m = conn.recv_match(type=kinds, blocking=True, timeout=max(0.01, deadline - time.monotonic()))
        if m is not None and m.get_srcSystem() == conn.target_system and m.get_srcComponent() == 1:
            if getattr(m, "target_system", conn.source_system) in (0, conn.source_system):
                return m
    return None


def upload(conn: Any, items: tuple[MissionItem, ...], mission_type: int = MissionType.MISSION,
           timeout_s: float = _TIMEOUT_S, stop_after: int | None = None) -> int:
    """Upload `items` (item 0 marked current); the vehicle's MISSION_ACK result (MAV_MISSION_RESULT).

    stop_after: answer only that many requests, then go silent (a cut-off upload, for tests). Raises TimeoutError
    when the vehicle stops answering."""
    conn.mav.mission_count_send(conn.target_system, 1, len(items), mission_type)
    answered = 0
    while True:
        m = _from_vehicle(conn, ["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], timeout_s)
        if m is None:
            raise TimeoutError(f"mission upload: no answer from the vehicle for {timeout_s} s")
        if m.get_type() == "MISSION_ACK":
            if m.mission_type == mission_type:
                return int(m.type)
            continue
        if m.mission_type != mission_type or not 0 <= m.seq < len(items):
            continue
        if stop_after is not None and answered >= stop_after:
            return -1
        it = items[m.seq]
        if m.get_type() == "MISSION_REQUEST_INT":
            conn.mav.mission_item_int_send(conn.target_system, 1, m.seq, it.frame, it.command, int(m.seq == 0),
                                           it.autocontinue, *it.params, it.x, it.y, it.z, mission_type)
        else:
            x, y = to_float_xy(it.frame, it.x, it.y)
            conn.mav.mission_item_send(conn.target_system, 1, m.seq, it.frame, it.command, int(m.seq == 0),
                                       it.autocontinue, *it.params, x, y, it.z, mission_type)
        answered += 1


def download(conn: Any, mission_type: int = MissionType.MISSION, timeout_s: float = _TIMEOUT_S,
             retries: int = 5) -> tuple[tuple[MissionItem, ...], int]:
    """The vehicle's plan of `mission_type` and its start item; each request is repeated up to `retries` times."""
    count = None
    for _ in range(retries):
        conn.mav.mission_request_list_send(conn.target_system, 1, mission_type)
        count = _from_vehicle(conn, ["MISSION_COUNT"], timeout_s / retries)
        if count is not None and count.mission_type == mission_type:
            break
    if count is None:
        raise TimeoutError("mission download: no MISSION_COUNT")
    items: list[MissionItem] = []
    current = 0
    for seq in range(count.count):
        for _ in range(retries):
            conn.mav.mission_request_int_send(conn.target_system, 1, seq, mission_type)
            m = _from_vehicle(conn, ["MISSION_ITEM_INT"], timeout_s / retries)
            if m is not None and m.seq == seq and m.mission_type == mission_type:
                break
        else:
            raise TimeoutError(f"mission download: no item {seq}")
        items.append(MissionItem(m.frame, m.command, m.autocontinue, m.param1, m.param2, m.param3, m.param4, m.x,
                                 m.y, m.z))
        current = seq if m.current else current
    conn.mav.mission_ack_send(conn.target_system, 1, 0, mission_type)
    return tuple(items), current


# --- a scenario as a plan ---------------------------------------------------------------------------------
RAMP_STEP_S = 0.25  # the arm's initial ramp, as joint-target steps this far apart


def plan_from_scenario(name_or_path: str) -> tuple[MissionItem, ...]:
    from navig8_fc.flight.script import load_flight_script
    from sim_bridge.scenario import load_scenario

    script = load_flight_script(name_or_path)
    world = load_scenario(name_or_path)
    events: list[tuple[float, int, MissionItem]] = []  # (t, order, item)

    def waypoint(t: float) -> MissionItem:
        sp = script.setpoint_at(t)
        x, y = round(sp.pos_ned_m[0] * 1e4), round(sp.pos_ned_m[1] * 1e4)
        return MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 0.0, 1000.0, 0.0, math.degrees(sp.yaw_rad), x, y,
                           sp.pos_ned_m[2])

    def pitch(t: float) -> MissionItem:
        return MissionItem(Frame.MISSION, Cmd.NAVIG8_PITCH_HOLD, 1, math.degrees(script.setpoint_at(t).pitch_rad),
                           0.0, 0.0, 0.0, 0, 0, 0.0)

    def joints(q: tuple[float, float, float]) -> MissionItem:
        d = [round(math.degrees(v), 6) for v in q]
        return MissionItem(Frame.MISSION, Cmd.NAVIG8_ARM_JOINTS, 1, d[0], d[1], d[2], 1.0, 0, 0, 0.0)

    events.append((0.0, 0, waypoint(0.0)))
    events.append((0.0, 1, pitch(0.0)))
    for t, ch, _v in script.steps:
        events.append((t, 2, pitch(t) if ch == "pitch_deg" else waypoint(t)))
    for seg in world.arm_segments:
        if seg.t1_s > seg.t0_s:
            n = max(1, math.ceil((seg.t1_s - seg.t0_s) / RAMP_STEP_S))
            for k in range(1, n + 1):
                f = k / n
                q = tuple(a + f * (b - a) for a, b in zip(seg.q_start_rad, seg.q_end_rad, strict=True))
                events.append((seg.t0_s + f * (seg.t1_s - seg.t0_s), 3, joints(q)))  # type: ignore[arg-type]
        else:
            events.append((seg.t0_s, 3, joints(seg.q_end_rad)))
    # Commands at the very end act on nothing in the scripted run (it stops there): leave them out, and end the
    # plan with a delay up to the duration.
    events = [e for e in events if e[0] < script.duration_s - 1e-9]
    events.sort(key=lambda e: (e[0], e[1]))
    items: list[MissionItem] = []
    t_now = 0.0
    for t, _, item in events:
        if t > t_now + 1e-9:
            items.append(MissionItem(Frame.MISSION, Cmd.CONDITION_DELAY, 1, round(t - t_now, 6), 0, 0, 0, 0, 0, 0.0))
            t_now = t
        items.append(item)
    if script.duration_s > t_now + 1e-9:
        items.append(MissionItem(Frame.MISSION, Cmd.CONDITION_DELAY, 1, round(script.duration_s - t_now, 6), 0, 0, 0,
                                 0, 0, 0.0))
    return tuple(items)


def fly(conn: Any, items: tuple[MissionItem, ...], timeout_s: float, out: Any = sys.stdout) -> dict[str, Any]:
    """Upload, Mission, arm if needed, progress until the end; the summary (module docstring)."""
    result = upload(conn, items)
    if result != 0:
        raise RuntimeError(f"upload refused: MISSION_ACK {result}")
    ts = conn.target_system
    conn.mav.set_mode_send(ts, 1, 0x04040000)  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PX4 AUTO.MISSION
    t0 = time.monotonic()
    deadline = t0 + timeout_s
    armed = False
    flew = False
    reached: list[int] = []
    home = None
    path_m = 0.0
    last_pos = None
    state = None
    next_arm_try = 0.0
    last_print = -1.0
    while time.monotonic() < deadline:
        m = conn.recv_match(type=["HEARTBEAT", "MISSION_CURRENT", "MISSION_ITEM_REACHED", "LOCAL_POSITION_NED",
                                  "HOME_POSITION", "STATUSTEXT"], blocking=True, timeout=0.5)
        now = time.monotonic()
        if not armed and now >= next_arm_try:
            conn.mav.command_long_send(ts, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)  # COMPONENT_ARM_DISARM
            next_arm_try = now + 1.0
        if m is None or m.get_srcSystem() != ts or m.get_srcComponent() != 1:
            continue
        kind = m.get_type()
        if kind == "HEARTBEAT":
            was = armed
            armed = bool(m.base_mode & 128)
            flew = flew or armed
            if was and not armed and reached:
                break  # landed and disarmed at the end
        elif kind == "HOME_POSITION":
            home = (m.x, m.y, m.z)
        elif kind == "MISSION_ITEM_REACHED":
            if not reached or reached[-1] != m.seq:
                reached.append(m.seq)
        elif kind == "LOCAL_POSITION_NED":
            pos = (m.x, m.y, m.z)
            if last_pos is not None:
                path_m += math.dist(pos, last_pos)
            last_pos = pos
        elif kind == "STATUSTEXT":
            out.write(f"  [{m.text}]\n")
        elif kind == "MISSION_CURRENT":
            state = m.mission_state
            if now - last_print >= 1.0:
                last_print = now
                d = math.dist(last_pos, home) if last_pos and home else math.nan
                out.write(f"t {now - t0:6.1f} s  item {m.seq}/{m.total}  state {m.mission_state}  "
                          f"from home {d:5.2f} m\n")
            if m.mission_state == 5 and reached:  # MISSION_STATE_COMPLETE
                break
    summary = {"items": len(items), "reached": reached, "complete": state == 5 or (flew and not armed),
               "wall_time_s": round(time.monotonic() - t0, 2), "path_m": round(path_m, 3),
               "from_home_m": round(math.dist(last_pos, home), 3) if last_pos and home else None}
    out.write(f"summary: {json.dumps(summary)}\n")
    return summary


def connect(url: str, timeout_s: float = 15.0) -> Any:
    conn = mavutil.mavlink_connection(url, source_system=255, source_component=190, dialect="common")
    hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=timeout_s,
                         condition="HEARTBEAT.get_srcComponent() == 1")
    if hb is None:
        raise TimeoutError(f"no vehicle heartbeat on {url} within {timeout_s} s")
    conn.target_system, conn.target_component = hb.get_srcSystem(), 1
    return conn


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="navig8-mission", description=__doc__.split("\n\n")[0])
    ap.add_argument("action", choices=["upload", "download", "clear", "fly", "from-scenario"])
    ap.add_argument("file", nargs="?", help="plan file to upload (.plan JSON or waypoint text) / to write")
    ap.add_argument("--connect", default="udpin:127.0.0.1:14550", help="pymavlink connection string")
    ap.add_argument("--scenario", default="paper", help="from-scenario: the scenario (name or YAML path)")
    ap.add_argument("--timeout", type=float, default=300.0, help="fly: give up after this many seconds")
    a = ap.parse_args(argv)
    if a.action == "from-scenario":
        text = write_wpl(plan_from_scenario(a.scenario))
        if a.file:
            Path(a.file).write_text(text, encoding="utf-8")
        else:
            sys.stdout.write(text)
        return 0
    conn = connect(a.connect)
    if a.action == "fly":
        if not a.file:
            ap.error("fly needs a plan file")
        summary = fly(conn, read_plan(a.file).mission, a.timeout)
        return 0 if summary["complete"] else 1
    if a.action == "clear":
        conn.mav.mission_clear_all_send(conn.target_system, 1, MissionType.ALL)
        ack = _from_vehicle(conn, ["MISSION_ACK"], _TIMEOUT_S)
        print("cleared" if ack is not None and ack.type == 0 else "clear failed")
        return 0 if ack is not None and ack.type == 0 else 1
    if a.action == "download":
        items, current = download(conn)
        if a.file and a.file.endswith(".plan"):
            text = write_qgc_plan(PlanFile(items, download(conn, MissionType.FENCE)[0],
                                           download(conn, MissionType.RALLY)[0]))
        else:
            text = write_wpl(items, current)
        if a.file:
            Path(a.file).write_text(text, encoding="utf-8")
        else:
            sys.stdout.write(text)
        return 0
    if not a.file:
        ap.error("upload needs a plan file")
    plan = read_plan(a.file)
    for kind, items in ((MissionType.MISSION, plan.mission), (MissionType.FENCE, plan.fence),
                        (MissionType.RALLY, plan.rally)):
        if kind != MissionType.MISSION and not items:
            continue
        result = upload(conn, items, kind)
        print(f"{kind.name.lower()}: {len(items)} items -> MISSION_ACK {result}")
        if result != 0:
            return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
