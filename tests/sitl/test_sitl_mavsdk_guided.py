"""MAVSDK (the pinned mavsdk-grpc, its bundled mavsdk_server) flies a mission, offboard position NED, goto_location
and return_to_launch over real UDP; each ends where it should within TOL_M (LOCAL_POSITION_NED from telemetry).

MAVLink only: runs against any FC by connection string (`make test-hil`, docs/hil.md; MAVSDK takes the API
string); it returns home, lands, and clears the plan it uploaded."""

from __future__ import annotations

import asyncio
import math
import time

import mavsdk_grpc as mavsdk
from mavsdk_grpc.mission_raw import MissionItem
from mavsdk_grpc.offboard import PositionNedYaw
from sitl_helpers import FcTarget, free_udp_ports

from navig8_fc.mission.geo import GeoOrigin

TOL_M = 0.5
FC_LOCAL = {"speed": 2.0}  # the local pair (conftest.py `fc`)
ORIGIN = GeoOrigin()  # the FC's default global origin


async def _ned(drone) -> tuple[float, float, float]:
    async for pv in drone.telemetry.position_velocity_ned():
        return pv.position.north_m, pv.position.east_m, pv.position.down_m


async def _wait_at(drone, target: tuple[float, float, float], timeout_s: float, tol: float = TOL_M) -> float:
    """Wait until the vehicle is within tol of target and slow; the final distance (raises on timeout)."""
    deadline = time.monotonic() + timeout_s
    async for pv in drone.telemetry.position_velocity_ned():
        p, v = pv.position, pv.velocity
        d = math.dist((p.north_m, p.east_m, p.down_m), target)
        if d < tol and math.hypot(v.north_m_s, v.east_m_s, v.down_m_s) < 0.2:
            return d
        if time.monotonic() > deadline:
            raise TimeoutError(f"not at {target} within {timeout_s} s: at {p}")
    raise AssertionError("telemetry ended")


def _item(seq: int, command: int, n: float, e: float, rel_alt: float, p1: float = 0.0, p2: float = 0.0) -> MissionItem:
    lat, lon, _ = ORIGIN.to_global((n, e, 0.0))
    return MissionItem(seq, 6, command, int(seq == 0), 1, p1, p2, 0.0, float("nan"), round(lat * 1e7),
                       round(lon * 1e7), rel_alt, 0)


async def _session(address: str, grpc_port: int) -> dict:
    out: dict = {}
    drone = mavsdk.System(port=grpc_port)
    try:
        await drone.connect(system_address=address)
        async for state in drone.core.connection_state():
            if state.is_connected:
                break
        async for h in drone.telemetry.health():
            if h.is_global_position_ok and h.is_home_position_ok and h.is_armable:
                break
        home = await _ned(drone)
        # Mission (mission_raw): takeoff 2 m, two waypoints, the last one held.
        n0, e0 = home[0], home[1]
        items = [_item(0, 22, n0, e0, 2.0), _item(1, 16, n0 + 1.5, e0, 2.0, 0.5, 0.2),
                 _item(2, 16, n0 + 1.5, e0 + 1.5, 2.5, 0.5, 0.2)]
        await drone.mission_raw.upload_mission(items)
        await drone.action.arm()
        await drone.mission_raw.start_mission()
        deadline = time.monotonic() + 40.0
        async for prog in drone.mission_raw.mission_progress():
            out.setdefault("progress", []).append((prog.current, prog.total))
            if prog.current == prog.total or time.monotonic() > deadline:
                break
        out["mission_d"] = await _wait_at(drone, (home[0] + 1.5, home[1] + 1.5, home[2] - 2.5), 20.0)
        out["mission_finished"] = await drone.mission_raw.is_mission_finished()
        # Offboard position NED.
        target = (home[0] + 0.5, home[1] - 1.0, home[2] - 2.0)
        await drone.offboard.set_position_ned(PositionNedYaw(*target, 90.0))
        await drone.offboard.start()
        async for fm in drone.telemetry.flight_mode():
            out["offboard_mode"] = str(fm)
            break
        out["offboard_d"] = await _wait_at(drone, target, 20.0)
        await drone.offboard.stop()
        # goto_location (DO_REPOSITION), altitude AMSL.
        # 4.5 m from home: Return's flight home then lasts a few heartbeats (from 1.1 m away it had switched to its
        # landing, Land, before the first HEARTBEAT MAVSDK read on a loaded machine).
        goto = (home[0] - 4.0, home[1] + 2.0, home[2] - 3.0)
        lat, lon, alt = ORIGIN.to_global(goto)
        await drone.action.goto_location(lat, lon, alt, 0.0)
        out["goto_d"] = await _wait_at(drone, goto, 25.0)
        # Return to launch: climb (already above 2.5 m), home, land, disarm.
        await drone.action.return_to_launch()
        async for fm in drone.telemetry.flight_mode():
            out["rtl_mode"] = str(fm)
            break
        deadline = time.monotonic() + 40.0
        async for armed in drone.telemetry.armed():
            if not armed or time.monotonic() > deadline:
                out["disarmed"] = not armed
                break
        end = await _ned(drone)
        out["home_d"] = math.dist(end, home)
        await drone.mission_raw.clear_mission()  # leave the FC as found: no plan
    finally:
        drone._stop_mavsdk_server()
    return out


def test_mavsdk_mission_offboard_goto_and_return(fc: FcTarget) -> None:
    fc.require_flight()
    (grpc_port,) = free_udp_ports(1)
    out = asyncio.run(asyncio.wait_for(_session(fc.mavsdk_address("api"), grpc_port), 180.0))
    assert out["progress"][-1][0] == out["progress"][-1][1] == 3 and out["mission_finished"], out
    assert out["mission_d"] < TOL_M and out["offboard_d"] < TOL_M and out["goto_d"] < TOL_M, out
    assert out["offboard_mode"] == "OFFBOARD" and out["rtl_mode"] == "RETURN_TO_LAUNCH", out
    assert out["disarmed"] and out["home_d"] < TOL_M, out
