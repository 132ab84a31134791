"""MAVSDK (gRPC wrapper with its bundled mavsdk_server) flies the SITL: the API-client path on 14540+N.

MAVLink only: runs against any FC by connection string (`make test-hil`, docs/hil.md; MAVSDK takes the API
string); it lands where it took off."""

from __future__ import annotations

import asyncio
import time

import mavsdk_grpc as mavsdk  # the test extras install it (`make test`)
import pytest
from sitl_helpers import FcTarget, free_udp_ports

FC_LOCAL = {"speed": 2.0}  # the local pair (conftest.py `fc`)


async def _session(address: str, grpc_port: int) -> dict:
    out: dict = {}
    drone = mavsdk.System(port=grpc_port)
    try:
        await drone.connect(system_address=address)
        await _fly(drone, out)
    finally:
        drone._stop_mavsdk_server()  # the library starts mavsdk_server; stop it with the test, not at exit
    return out


async def _fly(drone, out: dict) -> None:
    async for state in drone.core.connection_state():
        if state.is_connected:
            break
    async for h in drone.telemetry.health():
        if h.is_global_position_ok and h.is_home_position_ok and h.is_armable:
            out["health"] = h
            break
    async for fm in drone.telemetry.flight_mode():
        out["mode_on_ground"] = str(fm)
        break
    out["k_min"] = await drone.param.get_param_float("INDI_K_MIN")
    await drone.action.arm()
    await drone.action.set_takeoff_altitude(2.0)
    await drone.action.takeoff()
    deadline = time.monotonic() + 20.0
    async for pv in drone.telemetry.position_velocity_ned():
        if -pv.position.down_m > 1.8 or time.monotonic() > deadline:
            out["alt_m"] = -pv.position.down_m
            break
    await drone.action.hold()
    async for fm in drone.telemetry.flight_mode():
        out["mode_hold"] = str(fm)
        break
    await drone.action.land()
    async for armed in drone.telemetry.armed():
        if not armed:
            out["disarmed"] = True
            break


def test_mavsdk_connects_checks_health_and_flies(fc: FcTarget) -> None:
    fc.require_flight()
    (grpc_port,) = free_udp_ports(1)  # any free port number; mavsdk_server binds TCP on it
    out = asyncio.run(asyncio.wait_for(_session(fc.mavsdk_address("api"), grpc_port), 90.0))
    assert out["health"].is_armable and out["mode_on_ground"] == "READY"
    assert out["k_min"] == pytest.approx(0.5)
    assert out["alt_m"] > 1.8 and out["mode_hold"] == "HOLD" and out["disarmed"]
