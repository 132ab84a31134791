"""Offboard and long commands over SITL (real processes, real UDP, pymavlink): takeoff reported IN_PROGRESS then
ACCEPTED; an Offboard velocity target tracked; an attitude target (level, yaw 0.3 rad, thrust 0.5 = MPC_THR_HOVER)
slows the vehicle to a hover as a multicopter's drag does; a
DO_REPOSITION cancelled by COMMAND_CANCEL (final ACK CANCELLED, the vehicle brakes to a stop and holds there).

MAVLink only: runs against any FC by connection string (`make test-hil`, docs/hil.md); there it ends with a
Return (home, landed, disarmed) for the next module."""

from __future__ import annotations

import math
import time
from io import BytesIO
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import FcTarget, wait_for

from navig8_fc.gcs import offboard as ob
from navig8_fc.mavlink import dialect
from navig8_fc.mission.geo import GeoOrigin

M = mavlink2
MAV_RESULT_CANCELLED = 6  # common.xml upstream (pymavlink's copy lacks it; navig8.xml has it)
FC_LOCAL = {"speed": 2.0}  # the local pair (conftest.py `fc`)
VEL_ONLY = (ob.PT_X | ob.PT_Y | ob.PT_Z | ob.PT_ACCEL | ob.PT_YAW | ob.PT_YAW_RATE)


def _cmd(gcs: Any, command: int, *p: float) -> Any:
    params = list(p) + [0.0] * (7 - len(p))
    gcs.mav.command_long_send(gcs.target_system, 1, command, 0, *params)
    ack = wait_for(gcs, "COMMAND_ACK", 5.0, lambda m: m.command == command)
    assert ack is not None, f"no COMMAND_ACK for {command}"
    return ack


def _stream(gcs: Any, send: Any, flight_s: float) -> list[Any]:
    """Send a setpoint every 50 ms (wall) until the vehicle's clock (the messages' time_boot_ms) has run `flight_s`, and
    collect LOCAL_POSITION_NED and ATTITUDE meanwhile. The vehicle's time, not the wall's: on a loaded host a lockstep
    pair flies slower than its speed, and a wall-clock window then judges a shorter flight."""
    got: list[Any] = []
    t0_ms: int | None = None
    wall_limit = time.monotonic() + max(30.0, 4.0 * flight_s)
    while t0_ms is None or got[-1].time_boot_ms - t0_ms < flight_s * 1000.0:
        assert time.monotonic() < wall_limit, f"the vehicle's clock did not run {flight_s} s"
        send()
        t_next = time.monotonic() + 0.05
        while (left := t_next - time.monotonic()) > 0:
            m = gcs.recv_match(type=["LOCAL_POSITION_NED", "ATTITUDE"], blocking=True, timeout=left)
            if m is not None:
                got.append(m)
                t0_ms = m.time_boot_ms if t0_ms is None else t0_ms
    return got


def _last(msgs: list[Any], kind: str, n: int) -> list[Any]:
    return [m for m in msgs if m.get_type() == kind][-n:]


def test_offboard_velocity_attitude_and_cancel(fc: FcTarget) -> None:
    fc.require_flight()
    cancel_mav = dialect.load().MAVLink(BytesIO(), srcSystem=255, srcComponent=190)  # COMMAND_CANCEL is ours
    with fc.session() as gcs:
        try:
            deadline = time.monotonic() + 15.0
            while _cmd(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result != M.MAV_RESULT_ACCEPTED:
                assert time.monotonic() < deadline, "arming never accepted"
                time.sleep(0.3)
            # Takeoff: a long-running command, IN_PROGRESS now, ACCEPTED (progress 100) at the altitude.
            ack = _cmd(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 1.5)
            assert ack.result == M.MAV_RESULT_IN_PROGRESS
            final = wait_for(gcs, "COMMAND_ACK", 30.0, lambda m: m.command == M.MAV_CMD_NAV_TAKEOFF
                             and m.result != M.MAV_RESULT_IN_PROGRESS)
            assert final is not None and (final.result, final.progress) == (M.MAV_RESULT_ACCEPTED, 100)

            # Offboard velocity: 0.5 m/s north, position ignored.
            def vel() -> None:
                gcs.mav.set_position_target_local_ned_send(0, gcs.target_system, 1, M.MAV_FRAME_LOCAL_NED, VEL_ONLY,
                                                           0, 0, 0, 0.5, 0, 0, 0, 0, 0, 0, 0)
            _stream(gcs, vel, 0.6)
            assert _cmd(gcs, M.MAV_CMD_DO_SET_MODE, 1, 6, 0).result == M.MAV_RESULT_ACCEPTED  # OFFBOARD
            seen = _stream(gcs, vel, 10.0)
            tail = _last(seen, "LOCAL_POSITION_NED", 20)  # the last 2 s (10 Hz)
            # The mean velocity is the commanded one; the lateral mode rings (+-0.5 m/s, ~1.2 s period) after the
            # step in speed, so single samples are not judged (docs/gcs.md "Offboard").
            vx, vy = (sum(getattr(m, k) for m in tail) / len(tail) for k in ("vx", "vy"))
            assert len(tail) == 20 and abs(vx - 0.5) < 0.05 and abs(vy) < 0.1, [(m.x, m.vx, m.vy) for m in tail]
            assert tail[-1].x - tail[0].x > 0.8  # ~0.5 m/s * 2 s northwards
            # Attitude target: level, yaw 0.3 rad, thrust 0.5 = MPC_THR_HOVER: a multicopter's hover; the 0.5 m/s it had
            # decays with the drag's 3 s (about 1.5 m on), the altitude held.
            here = tail[-1]
            q = _quat_pitch_yaw(0.0, 0.3)

            def att() -> None:
                gcs.mav.set_attitude_target_send(0, gcs.target_system, 1, ob.AT_RATES, q, 0, 0, 0, 0.5)
            seen = _stream(gcs, att, 10.0)
            a = _last(seen, "ATTITUDE", 5)
            assert all(abs(m.pitch) < math.radians(3) and abs(m.yaw - 0.3) < 0.05 for m in a), a
            held = _last(seen, "LOCAL_POSITION_NED", 20)
            p = held[-1]
            vx, vy = (sum(getattr(m, k) for m in held) / len(held) for k in ("vx", "vy"))
            assert abs(p.z - here.z) < 0.3 and math.hypot(vx, vy) < 0.15, (vx, vy, p.z, here.z)
            assert all(math.hypot(m.x - here.x, m.y - here.y) < 2.0 for m in held), [(m.x, m.y) for m in held]
            # DO_REPOSITION 8 m east (long-running), cancelled after ~1 s: CANCELLED, brakes and holds.
            lat, lon, _ = GeoOrigin().to_global((p.x, p.y + 8.0, 0.0))
            gcs.mav.command_int_send(gcs.target_system, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                     M.MAV_CMD_DO_REPOSITION, 0, 0, -1, 0, 0, math.nan, round(lat * 1e7),
                                     round(lon * 1e7), -p.z)
            ack = wait_for(gcs, "COMMAND_ACK", 5.0, lambda m: m.command == M.MAV_CMD_DO_REPOSITION)
            assert ack is not None and ack.result == M.MAV_RESULT_IN_PROGRESS
            assert wait_for(gcs, "COMMAND_ACK", 5.0, lambda m: m.command == M.MAV_CMD_DO_REPOSITION
                            and m.result == M.MAV_RESULT_IN_PROGRESS and m.progress > 0) is not None
            gcs.write(cancel_mav.command_cancel_encode(gcs.target_system, 1, M.MAV_CMD_DO_REPOSITION).pack(cancel_mav))
            final = wait_for(gcs, "COMMAND_ACK", 5.0, lambda m: m.command == M.MAV_CMD_DO_REPOSITION
                             and m.result != M.MAV_RESULT_IN_PROGRESS)
            assert final is not None and final.result == MAV_RESULT_CANCELLED
            # Hold brakes to its stopping point (docs/gcs.md "Hold"): it comes to rest without turning back, well
            # short of the target (the braking distance from 2 m/s is about 2.5 m), and stays there.
            track: list[Any] = []
            held = wait_for(gcs, "LOCAL_POSITION_NED", 10.0,
                            lambda m: track.append(m) is None and math.hypot(m.vx, m.vy, m.vz) < 0.05)
            assert held is not None, "never came to rest after the cancel"
            farthest = max(m.y for m in track)
            assert farthest - held.y < 0.25 and held.y < p.y + 5.0, [(m.y, m.vy) for m in track]
            later = wait_for(gcs, "LOCAL_POSITION_NED", 5.0, lambda m: m.time_boot_ms > held.time_boot_ms + 1500)
            assert later is not None and math.hypot(later.x - held.x, later.y - held.y) < 0.2, (held, later)
        finally:  # an FC elsewhere serves the next module: leave it as found (home, landed, disarmed)
            if fc.local is None:
                _cmd(gcs, M.MAV_CMD_NAV_RETURN_TO_LAUNCH)
                assert wait_for(gcs, "HEARTBEAT", 90.0, lambda m: m.get_srcComponent() == 1
                                and not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED) is not None, "no disarm (Return)"


def _quat_pitch_yaw(pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """q = q_z(yaw) q_y(pitch), zero roll (the product of the two half-angle quaternions)."""
    cy, sy, cp, sp = math.cos(yaw / 2), math.sin(yaw / 2), math.cos(pitch / 2), math.sin(pitch / 2)
    return (cy * cp, -sy * sp, cy * sp, sy * cp)
