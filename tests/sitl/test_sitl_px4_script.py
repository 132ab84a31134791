"""A plain pymavlink script written for PX4 runs unmodified against `navig8-fc --autopilot px4`: take-off to an
altitude above mean sea level, a waypoint by DO_REPOSITION, Return and Land, each acknowledged ACCEPTED at once as
PX4's Commander does (a PX4 script reads the first COMMAND_ACK and checks `result == ACCEPTED`), the outcome
watched in telemetry (docs/gcs.md, "Long-running commands", the table by identity)."""

from __future__ import annotations

import math
import time
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import FcTarget, wait_for

M = mavlink2
FC_LOCAL = {"speed": 2.0, "fc_args": ["--autopilot", "px4"]}  # the local pair (conftest.py `fc`)


def _px4_command(gcs: Any, command: int, *p: float) -> None:
    """What a PX4 script does: send, read the first COMMAND_ACK for it, require ACCEPTED."""
    params = list(p) + [0.0] * (7 - len(p))
    gcs.mav.command_long_send(gcs.target_system, 1, command, 0, *params)
    ack = wait_for(gcs, "COMMAND_ACK", 5.0, lambda m: m.command == command)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED, (command, ack)


def _until(gcs: Any, kind: str, pred: Any, timeout_s: float, what: str) -> Any:
    m = wait_for(gcs, kind, timeout_s, pred)
    assert m is not None, f"timed out waiting for {what}"
    return m


def test_a_px4_pymavlink_script_takes_off_repositions_returns_and_lands(fc: FcTarget) -> None:
    fc.require_flight()
    with fc.session() as gcs:
        hb = _until(gcs, "HEARTBEAT", lambda m: m.get_srcComponent() == 1, 10.0, "a heartbeat")
        if fc.local is not None:
            assert hb.autopilot == M.MAV_AUTOPILOT_PX4
        elif hb.autopilot != M.MAV_AUTOPILOT_PX4:
            pytest.skip("the FC elsewhere does not announce the PX4 identity")
        gcs.mav.command_long_send(gcs.target_system, 1, M.MAV_CMD_REQUEST_MESSAGE, 0,
                                  M.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0)
        home = _until(gcs, "HOME_POSITION", None, 20.0, "HOME_POSITION")
        home_amsl_m = home.altitude * 1e-3
        deadline = time.monotonic() + 20.0  # pre-arm checks pass once the estimator has settled
        while True:
            gcs.mav.command_long_send(gcs.target_system, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            ack = _until(gcs, "COMMAND_ACK", lambda m: m.command == M.MAV_CMD_COMPONENT_ARM_DISARM, 5.0, "arm ACK")
            if ack.result == M.MAV_RESULT_ACCEPTED or time.monotonic() > deadline:
                break
            time.sleep(0.5)
        assert ack.result == M.MAV_RESULT_ACCEPTED
        # Take-off: p7 is AMSL on PX4 (QGC's PX4 plugin sends home + the height).
        _px4_command(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, home_amsl_m + 2.0)
        _until(gcs, "GLOBAL_POSITION_INT", lambda m: m.relative_alt > 1800, 40.0, "2 m above home")
        # A waypoint 3 m north by DO_REPOSITION (p2 bit 0: switch to Hold/Loiter, as PX4 requires), alt AMSL.
        lat, lon = home.latitude * 1e-7 + 3.0 / 111_195.0, home.longitude * 1e-7
        _px4_command(gcs, M.MAV_CMD_DO_REPOSITION, -1, M.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, 0, math.nan,
                     lat, lon, home_amsl_m + 2.0)
        _until(gcs, "LOCAL_POSITION_NED", lambda m: abs(m.x - 3.0) < 0.4 and abs(m.vx) < 0.3, 40.0, "the waypoint")
        _px4_command(gcs, M.MAV_CMD_NAV_RETURN_TO_LAUNCH)
        _until(gcs, "LOCAL_POSITION_NED", lambda m: abs(m.x) < 0.5, 40.0, "the way home")
        _px4_command(gcs, M.MAV_CMD_NAV_LAND)
        _until(gcs, "EXTENDED_SYS_STATE", lambda m: m.landed_state == M.MAV_LANDED_STATE_ON_GROUND, 60.0, "touchdown")
