"""Interop tests for any Navig8 FC, through connection strings only (docs/hil.md, "A test suite for any FC").

    pytest tests/sitl/test_hil_interop.py                                   # starts the local pair (default)
    pytest tests/sitl/test_hil_interop.py --fc-gcs=udpin:0.0.0.0:14550 --fc-api=udpin:0.0.0.0:14540 \\
        --bridge=tcpin:SIM:4560                                             # an FC running elsewhere
    make test-hil FC_GCS=udpin:0.0.0.0:14550 FC_API=udpin:0.0.0.0:14540 BRIDGE=...

Every assertion is on what crosses the link (HEARTBEAT, AUTOPILOT_VERSION, COMMAND_ACK, PARAM_VALUE, STATUSTEXT,
the mission protocol, LOCAL_POSITION_NED, EXTENDED_SYS_STATE). What needs the local log skips when pointed
elsewhere; the flight skips with --bridge=none (no simulator behind the FC). One FC for the whole module: the
parameters changed are restored, the mission uploaded is cleared, the flight ends landed and disarmed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as m2
from sitl_helpers import (
    HOVER_TOL_XY_M,
    HOVER_TOL_Z_M,
    FcTarget,
    command,
    mcap_metadata,
    takeoff_hover_land,
    wait_fc_heartbeat,
    wait_for,
)

from navig8_fc.mission.plan import Cmd, Frame, MissionItem
from navig8_tools.mission import download, upload

PLAN = (
    MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_TAKEOFF, 1, 0, 0, 0, math.nan, 0, 0, 2.0),
    MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 1.0, 0.25, 0, 90.0, 10000, 0, -2.0),
    MissionItem(Frame.MISSION, Cmd.NAV_RETURN_TO_LAUNCH, 1, 0, 0, 0, 0, 0, 0, 0),
)


@pytest.fixture(scope="module")
def gcs(fc: FcTarget) -> Iterator[Any]:
    conn = fc.connect("gcs")
    try:
        wait_fc_heartbeat(conn, fc.sysid)
        yield conn
    finally:
        conn.close()


def test_identity_and_capabilities(gcs: Any) -> None:
    hb = wait_fc_heartbeat(gcs, gcs.target_system, 5.0)
    assert hb.type == m2.MAV_TYPE_TRICOPTER and hb.autopilot in (m2.MAV_AUTOPILOT_GENERIC, m2.MAV_AUTOPILOT_PX4)
    assert command(gcs, m2.MAV_CMD_REQUEST_MESSAGE, m2.MAVLINK_MSG_ID_AUTOPILOT_VERSION).result == \
        m2.MAV_RESULT_ACCEPTED
    av = wait_for(gcs, "AUTOPILOT_VERSION", 5.0)
    assert av is not None
    for cap in (m2.MAV_PROTOCOL_CAPABILITY_MISSION_INT, m2.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
                m2.MAV_PROTOCOL_CAPABILITY_MAVLINK2):
        assert av.capabilities & cap


def test_api_link_answers_too(fc: FcTarget) -> None:
    api = fc.connect("api", source_system=245)
    try:
        wait_fc_heartbeat(api, fc.sysid)
        assert command(api, 42424).result == m2.MAV_RESULT_UNSUPPORTED
    finally:
        api.close()


def _param(gcs: Any, name: str, timeout_s: float = 5.0) -> Any:
    pv = wait_for(gcs, "PARAM_VALUE", timeout_s, lambda m: m.param_id == name)
    assert pv is not None, f"no PARAM_VALUE {name}"
    return pv


def test_parameters_download_set_refuse_restore(gcs: Any) -> None:
    gcs.mav.param_request_list_send(gcs.target_system, 1)
    got: dict[int, str] = {}
    count = None
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline and (count is None or len(got) < count):
        m = wait_for(gcs, "PARAM_VALUE", max(0.05, deadline - time.monotonic()))
        if m is None:
            break
        count = m.param_count
        got[m.param_index] = m.param_id
    assert count is not None and sorted(got) == list(range(count)), f"indices missing: {count} vs {len(got)}"
    assert {"INDI_RATE_HZ", "OL_POS_K", "FC_TIMING"} <= set(got.values())
    gcs.mav.param_request_read_send(gcs.target_system, 1, b"OL_POS_K", -1)
    old = _param(gcs, "OL_POS_K").param_value
    try:
        gcs.mav.param_set_send(gcs.target_system, 1, b"OL_POS_K", old + 0.1, m2.MAV_PARAM_TYPE_REAL32)
        assert abs(_param(gcs, "OL_POS_K").param_value - (old + 0.1)) < 1e-5
    finally:
        gcs.mav.param_set_send(gcs.target_system, 1, b"OL_POS_K", old, m2.MAV_PARAM_TYPE_REAL32)
        assert abs(_param(gcs, "OL_POS_K").param_value - old) < 1e-6
    # out of range: refused, the old value echoed, a STATUSTEXT says why
    gcs.mav.param_request_read_send(gcs.target_system, 1, b"INDI_RATE_HZ", -1)
    rate = _param(gcs, "INDI_RATE_HZ").param_value
    gcs.mav.param_set_send(gcs.target_system, 1, b"INDI_RATE_HZ", 5.0, m2.MAV_PARAM_TYPE_INT32)
    assert _param(gcs, "INDI_RATE_HZ").param_value == rate
    assert wait_for(gcs, "STATUSTEXT", 5.0, lambda m: "INDI_RATE_HZ" in m.text) is not None


def test_unknown_command_is_unsupported(gcs: Any) -> None:
    assert command(gcs, 42424).result == m2.MAV_RESULT_UNSUPPORTED


def test_mission_upload_download_clear(gcs: Any) -> None:
    assert upload(gcs, PLAN) == m2.MAV_MISSION_ACCEPTED
    items, _ = download(gcs)
    assert [(i.command, i.frame) for i in items] == [(i.command, i.frame) for i in PLAN]
    assert items[1].x == PLAN[1].x and items[1].z == pytest.approx(PLAN[1].z)
    gcs.mav.mission_clear_all_send(gcs.target_system, 1, 0)
    ack = wait_for(gcs, "MISSION_ACK", 5.0)
    assert ack is not None and ack.type == m2.MAV_MISSION_ACCEPTED
    assert download(gcs)[0] == ()


def test_takeoff_hover_land(fc: FcTarget, gcs: Any) -> None:
    fc.require_flight()
    err = takeoff_hover_land(gcs)
    assert err["err_z_m"] < HOVER_TOL_Z_M and err["err_xy_m"] < HOVER_TOL_XY_M, err


def test_local_log_records_the_session(fc: FcTarget) -> None:
    run = fc.require_local("its log is not here")
    run.stop()
    stats = mcap_metadata(run.log, "fc_stats")
    assert int(stats["ticks"]) > 1000
    assert "gcs" in mcap_metadata(run.log, "link_counters")
