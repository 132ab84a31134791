"""A pymavlink ground station against the real two-process SITL over loopback UDP.

MAVLink only: runs against any FC by connection string (`make test-hil`, docs/hil.md); the parameter it sets is
restored and the flight ends landed and disarmed."""

from __future__ import annotations

import math
import time

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import PARAM_SET_WAIT_S, FcTarget, wait_for

from navig8_fc.modes import px4_custom_mode
from navig8_fc.modes.px4 import Px4AutoSubMode, Px4MainMode
from navig8_fc.params.registry import ParamRegistry

M = mavlink2
FC_LOCAL = {"speed": 2.0}  # the local pair (conftest.py `fc`)


def _command(gcs, command: int, *params: float, timeout_s: float = 5.0):
    p = list(params) + [0.0] * (7 - len(params))
    gcs.mav.command_long_send(gcs.target_system, 1, command, 0, *p)
    ack = wait_for(gcs, "COMMAND_ACK", timeout_s, lambda m: m.command == command)
    assert ack is not None, f"no COMMAND_ACK for {command}"
    return ack


def _download_params(gcs, timeout_s: float = 20.0) -> dict[str, tuple[int, float]]:
    gcs.mav.param_request_list_send(gcs.target_system, 1)
    got: dict[int, tuple[str, float]] = {}
    count = None
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and (count is None or len(got) < count):
        m = wait_for(gcs, "PARAM_VALUE", max(0.05, deadline - time.monotonic()))
        if m is None:
            break
        count = m.param_count
        got[m.param_index] = (m.param_id, m.param_value)
    assert count is not None and sorted(got) == list(range(count)), f"missing indices: {count} vs {len(got)}"
    return {name: (i, v) for i, (name, v) in got.items()}


def _wait_state(gcs, pred, timeout_s: float, what: str):
    m = wait_for(gcs, ["HEARTBEAT", "LOCAL_POSITION_NED", "EXTENDED_SYS_STATE"], timeout_s, pred)
    assert m is not None, f"timed out waiting for {what}"
    return m


def _read(gcs, name: str) -> float:
    gcs.mav.param_request_read_send(gcs.target_system, 1, name.encode(), -1)
    pv = wait_for(gcs, "PARAM_VALUE", PARAM_SET_WAIT_S, lambda m: m.param_id == name)
    assert pv is not None, f"no PARAM_VALUE {name}"
    return pv.param_value


def test_pymavlink_gcs_session(fc: FcTarget) -> None:
    reg = ParamRegistry.from_defaults(check_stability=False)
    with fc.session() as gcs:
        ol_pos_k = _read(gcs, "OL_POS_K")
        try:
            hb = wait_for(gcs, "HEARTBEAT", 15.0, lambda m: m.get_srcComponent() == 1)
            assert hb is not None
            assert hb.type == M.MAV_TYPE_TRICOPTER and hb.autopilot == M.MAV_AUTOPILOT_GENERIC
            assert not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
            # AUTOPILOT_VERSION on request
            ack = _command(gcs, M.MAV_CMD_REQUEST_MESSAGE, 148)
            assert ack.result == M.MAV_RESULT_ACCEPTED
            av = wait_for(gcs, "AUTOPILOT_VERSION", 3.0)
            assert av is not None
            for cap in (M.MAV_PROTOCOL_CAPABILITY_MISSION_INT, M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
                        M.MAV_PROTOCOL_CAPABILITY_MAVLINK2):
                assert av.capabilities & cap
            # full parameter download: every index exactly once
            params = _download_params(gcs)
            assert set(params) == {d.name for d in reg.definitions}
            # refused set (stability floor) -> old value echoed + STATUSTEXT; accepted set -> new value
            k_min = _read(gcs, "INDI_K_MIN")  # 0.5 by default
            gcs.mav.param_set_send(gcs.target_system, 1, b"INDI_K_MIN", 0.1, M.MAV_PARAM_TYPE_REAL32)
            pv = wait_for(gcs, "PARAM_VALUE", PARAM_SET_WAIT_S, lambda m: m.param_id == "INDI_K_MIN")
            assert pv is not None and abs(pv.param_value - k_min) < 1e-6
            st = wait_for(gcs, "STATUSTEXT", 5.0, lambda m: "INDI_K_MIN" in m.text)
            assert st is not None and "stability floor" in st.text
            gcs.mav.param_set_send(gcs.target_system, 1, b"OL_POS_K", 1.2, M.MAV_PARAM_TYPE_REAL32)
            pv = wait_for(gcs, "PARAM_VALUE", 5.0, lambda m: m.param_id == "OL_POS_K")
            assert pv is not None and abs(pv.param_value - 1.2) < 1e-6
            # unknown command -> UNSUPPORTED
            assert _command(gcs, 42424).result == M.MAV_RESULT_UNSUPPORTED
            # arm -> takeoff 2 m -> hold -> land -> disarm
            fc.require_flight()  # skips the rest with --bridge=none (the parameter is restored below)
            deadline = time.monotonic() + 20.0
            while True:
                ack = _command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
                if ack.result == M.MAV_RESULT_ACCEPTED or time.monotonic() > deadline:
                    break
                time.sleep(0.5)  # pre-arm checks may need the first sensor data
            assert ack.result == M.MAV_RESULT_ACCEPTED
            _wait_state(gcs, lambda m: m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 1
                        and m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 5.0, "armed heartbeat")
            assert _command(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 2.0).result == \
                M.MAV_RESULT_IN_PROGRESS  # a long-running command: its final ACK comes at the takeoff altitude
            hold = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER)
            _wait_state(gcs, lambda m: m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 1
                        and m.custom_mode == hold, 30.0, "Hold after takeoff")
            lp = _wait_state(gcs, lambda m: m.get_type() == "LOCAL_POSITION_NED", 5.0, "position")
            assert abs(-lp.z - 2.0) < 0.3, lp
            assert _command(gcs, M.MAV_CMD_NAV_LAND).result == M.MAV_RESULT_IN_PROGRESS
            _wait_state(gcs, lambda m: m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 1
                        and not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 40.0, "disarm after landing")
            es = _wait_state(gcs, lambda m: m.get_type() == "EXTENDED_SYS_STATE", 5.0, "landed state")
            assert es.landed_state == M.MAV_LANDED_STATE_ON_GROUND
        finally:
            gcs.mav.param_set_send(gcs.target_system, 1, b"OL_POS_K", ol_pos_k, M.MAV_PARAM_TYPE_REAL32)
            assert wait_for(gcs, "PARAM_VALUE", 5.0, lambda m: m.param_id == "OL_POS_K"
                            and abs(m.param_value - ol_pos_k) < 1e-6) is not None, "OL_POS_K not restored"
