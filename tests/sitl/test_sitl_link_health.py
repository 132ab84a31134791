"""Link health as a ground station sees it: a stalled bridge (STATUSTEXT, SYS_STATUS health and pre-arm bits,
arming denied, recovery), a control-rate mismatch between INDI_RATE_HZ and the bridge's --dt, replies routed
to the link that asked, and the /fc/statustext log's publish time. Real processes on free loopback ports,
bounded waits; every process is stopped.

The routing of replies is MAVLink only (two clients, GCS and API links): it runs against any FC by connection
string (`make test-hil`, docs/hil.md) and restores what it changes. The rest stalls or reconfigures the local
bridge or reads the local log, and skips when pointed elsewhere."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import PARAM_SET_WAIT_S, FcTarget, free_udp_ports, gcs_client, sitl, wait_for, wait_heartbeat

from navig8_fc.shell import fc_options as fo
from navig8_fc.shell import fc_process as fp
from navig8_fc.shell.mcap_log import read_mcap, read_mcap_records

M = mavlink2
SENSOR_BITS = M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL | M.MAV_SYS_STATUS_SENSOR_GPS
PREARM = M.MAV_SYS_STATUS_PREARM_CHECK


def _fc_in_process(tmp_path: Path, log: Path | None = None) -> fp.FlightControllerProcess:
    bridge, gcs, api = free_udp_ports(3)  # where the FC sends; it binds port 0
    argv = ["--sim-port", "0", "--bridge-port", str(bridge), "--gcs-bind-port", "0",
            "--api-bind-port", "0", "--gcs-port", str(gcs), "--api-port", str(api),
            "--state-dir", str(tmp_path), "--defaults"]
    if log is not None:
        argv += ["--log", str(log)]
    return fp.FlightControllerProcess(fo.options_from_args(fo.build_arg_parser().parse_args(argv)))


def _command(conn: Any, command: int, *params: float, timeout_s: float = 5.0) -> int:
    p = list(params) + [0.0] * (7 - len(params))
    conn.mav.command_long_send(conn.target_system, 1, command, 0, *p)
    ack = wait_for(conn, "COMMAND_ACK", timeout_s, lambda m: m.command == command)
    assert ack is not None, f"no COMMAND_ACK for {command}"
    return int(ack.result)


def _set_param(conn: Any, name: str, value: float, param_type: int = M.MAV_PARAM_TYPE_REAL32) -> None:
    conn.mav.param_set_send(conn.target_system, 1, name.encode(), value, param_type)
    pv = wait_for(conn, "PARAM_VALUE", PARAM_SET_WAIT_S, lambda m: m.param_id == name)
    assert pv is not None, f"no PARAM_VALUE for {name}"


def _texts_until(conn: Any, pred, timeout_s: float) -> Any:
    return wait_for(conn, "STATUSTEXT", timeout_s, lambda m: pred(m.text))


def _sys_status(conn: Any, cond, timeout_s: float) -> Any:
    return wait_for(conn, "SYS_STATUS", timeout_s, cond)


def _full_text(conn: Any, first: Any) -> str:
    """The whole text of a STATUSTEXT that may be chunked (id != 0: chunks until one shorter than 50)."""
    assert first is not None, "no STATUSTEXT"
    text, m = first.text, first
    while first.id and len(m.text) == 50:
        m = wait_for(conn, "STATUSTEXT", 2.0, lambda x: x.id == first.id)
        assert m is not None, f"missing chunk of {text!r}"
        text += m.text
    return text


@pytest.mark.local_only("reads the local log")
def test_statustext_log_publish_time_is_wall_clock(tmp_path: Path) -> None:
    log = tmp_path / "fc.mcap"
    fc = _fc_in_process(tmp_path, log)
    try:
        t0 = time.time_ns()
        fc.statustext("hello from the test", severity=6)
        t1 = time.time_ns()
    finally:
        fc.close()
    recs = [(t, pub, d) for topic, t, pub, d in read_mcap_records(log, ["/fc/statustext"])]
    assert len(recs) == 1 and recs[0][2]["text"] == "hello from the test"
    assert t0 <= recs[0][1] <= t1, "publish_time must be the writer's wall clock (docs/logs.md)"


@pytest.mark.local_only("stalls the local bridge process")
def test_stalled_bridge_is_reported_and_blocks_arming(tmp_path: Path) -> None:
    with sitl(tmp_path, scenario="ground", speed=1.0) as run:
        gcs = gcs_client(run.gcs_port)
        try:
            wait_heartbeat(gcs, 15.0)
            _set_param(gcs, "FS_SENS_TOUT", 0.3)
            ok = _sys_status(gcs, lambda m: m.onboard_control_sensors_health & PREARM, 15.0)
            assert ok is not None and ok.onboard_control_sensors_health & SENSOR_BITS == SENSOR_BITS
            # The bridge dies: the FC must say so, drop the health and pre-arm bits and refuse to arm.
            assert run.bridge is not None
            run.bridge.kill()
            run.bridge.wait(timeout=10.0)
            st = _texts_until(gcs, lambda t: "navig8-bridge" in t and "no sensor data" in t.lower(), 5.0)
            assert st is not None, "no STATUSTEXT about the silent bridge"
            assert st.severity <= M.MAV_SEVERITY_ERROR
            bad = _sys_status(gcs, lambda m: not m.onboard_control_sensors_health & PREARM, 5.0)
            assert bad is not None, "PREARM_CHECK stays healthy without sensor data"
            assert bad.onboard_control_sensors_health & SENSOR_BITS == 0
            assert bad.onboard_control_sensors_present & (SENSOR_BITS | PREARM) == SENSOR_BITS | PREARM
            assert _command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_DENIED
            why = _full_text(gcs, _texts_until(gcs, lambda t: t.startswith("Arming denied"), 3.0))
            assert "navig8-bridge" in why, why
            hb = wait_for(gcs, "HEARTBEAT", 3.0, lambda m: m.get_srcComponent() == 1)
            assert hb is not None and not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
            assert hb.system_status == M.MAV_STATE_STANDBY
            # Exactly one report per outage.
            again = _texts_until(gcs, lambda t: "no sensor data" in t.lower(), 1.5)
            assert again is None, "the outage was reported more than once"
        finally:
            gcs.close()
        run.stop()
    events = [d["text"] for _, _, d in read_mcap(run.log, ["/fc/event"])]
    assert any("navig8-bridge" in e for e in events), events


@pytest.mark.local_only("stalls and resumes the local bridge process")
def test_bridge_back_after_a_stall_restores_health(tmp_path: Path) -> None:
    # A stopped (SIGSTOP) bridge stalls the lockstep; SIGCONT resumes it: health must come back.
    import signal

    with sitl(tmp_path, scenario="ground", speed=1.0) as run:
        gcs = gcs_client(run.gcs_port)
        try:
            wait_heartbeat(gcs, 15.0)
            _set_param(gcs, "FS_SENS_TOUT", 0.3)
            assert _sys_status(gcs, lambda m: m.onboard_control_sensors_health & PREARM, 15.0) is not None
            assert _command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
            assert run.bridge is not None
            run.bridge.send_signal(signal.SIGSTOP)
            try:
                assert _texts_until(gcs, lambda t: "no sensor data" in t.lower(), 5.0) is not None
                assert _sys_status(gcs, lambda m: not m.onboard_control_sensors_health & PREARM, 5.0) is not None
                hb = wait_for(gcs, "HEARTBEAT", 3.0, lambda m: m.get_srcComponent() == 1)
                assert hb is not None and hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
                assert hb.system_status == M.MAV_STATE_CRITICAL, "armed without sensor data must be CRITICAL"
            finally:
                run.bridge.send_signal(signal.SIGCONT)
            back = _texts_until(gcs, lambda t: "navig8-bridge" in t and "back" in t, 10.0)
            assert back is not None, "no STATUSTEXT when sensor data resumed"
            good = _sys_status(gcs, lambda m: m.onboard_control_sensors_health & (SENSOR_BITS | PREARM)
                               == SENSOR_BITS | PREARM, 10.0)
            assert good is not None, "health did not come back with the bundles"
            hb = wait_for(gcs, "HEARTBEAT", 3.0, lambda m: m.get_srcComponent() == 1)
            assert hb is not None and hb.system_status == M.MAV_STATE_ACTIVE
            assert _command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == M.MAV_RESULT_ACCEPTED
            assert _command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
        finally:
            gcs.close()


@pytest.mark.local_only("starts the local bridge with another --dt")
def test_indi_rate_that_disagrees_with_the_bridge_is_reported(tmp_path: Path) -> None:
    with sitl(tmp_path, scenario="ground", speed=1.0) as run:
        gcs = gcs_client(run.gcs_port)
        try:
            wait_heartbeat(gcs, 15.0)
            assert _sys_status(gcs, lambda m: m.onboard_control_sensors_health & PREARM, 15.0) is not None
            # The bridge steps 10 ms (--dt 0.01); 200 Hz needs 5 ms.
            _set_param(gcs, "INDI_RATE_HZ", 200.0)
            st = _texts_until(gcs, lambda t: "rate mismatch" in t, 5.0)
            assert st is not None, "no STATUSTEXT about the rate mismatch"
            assert st.severity <= M.MAV_SEVERITY_ERROR
            full = _full_text(gcs, st)
            assert "10 ms" in full and "INDI_RATE_HZ 200" in full and "5 ms" in full, full
            assert "navig8-bridge --dt 0.005" in full and "INDI_RATE_HZ 100" in full, full
            bad = _sys_status(gcs, lambda m: not m.onboard_control_sensors_health & PREARM, 5.0)
            assert bad is not None, "pre-arm must fail on a rate mismatch"
            assert _command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_DENIED
            why = _full_text(gcs, _texts_until(gcs, lambda t: t.startswith("Arming denied"), 3.0))
            assert "rate mismatch" in why and "INDI_RATE_HZ 200" in why, why
            again = _texts_until(gcs, lambda t: "rate mismatch" in t, 1.0)
            assert again is None, "the mismatch was reported more than once"
            # Restoring the rate clears it.
            _set_param(gcs, "INDI_RATE_HZ", 100.0)
            good = _sys_status(gcs, lambda m: m.onboard_control_sensors_health & PREARM, 5.0)
            assert good is not None, "pre-arm stays failed after INDI_RATE_HZ was restored"
        finally:
            gcs.close()
        run.stop()
    events = [d["text"] for _, _, d in read_mcap(run.log, ["/fc/event"])]
    assert any("INDI_RATE_HZ" in e for e in events), events


def test_replies_go_to_the_link_that_asked(fc: FcTarget) -> None:
    with fc.session("gcs", source_system=255) as gcs, fc.session("api", source_system=245) as api:
        old = None
        try:
            # Both clients talk first so the FC knows both peers.
            for c in (gcs, api):
                c.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            time.sleep(0.3)
            # A command from the API client: ACKed to it only.
            assert _command(api, M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE) == M.MAV_RESULT_ACCEPTED
            assert wait_for(gcs, ["COMMAND_ACK", "MESSAGE_INTERVAL"], 1.0) is None, "the GCS got the API's reply"
            # ...and the other way round.
            assert _command(gcs, M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == \
                M.MAV_RESULT_ACCEPTED
            assert wait_for(gcs, "AUTOPILOT_VERSION", 3.0) is not None
            assert wait_for(api, ["COMMAND_ACK", "AUTOPILOT_VERSION"], 1.0) is None, "the API got the GCS's reply"
            # A parameter read is a reply; a parameter set is announced on both links.
            api.mav.param_request_read_send(api.target_system, 1, b"OL_POS_K", -1)
            old = wait_for(api, "PARAM_VALUE", 3.0, lambda m: m.param_id == "OL_POS_K")
            assert old is not None
            assert wait_for(gcs, "PARAM_VALUE", 1.0) is None, "the GCS got the API's PARAM_VALUE read"
            api.mav.param_set_send(api.target_system, 1, b"OL_POS_K", 1.1, M.MAV_PARAM_TYPE_REAL32)
            for c in (api, gcs):
                pv = wait_for(c, "PARAM_VALUE", 3.0, lambda m: m.param_id == "OL_POS_K")
                assert pv is not None and abs(pv.param_value - 1.1) < 1e-6
            # The paced list goes to the link that asked.
            api.mav.param_request_list_send(api.target_system, 1)
            assert wait_for(api, "PARAM_VALUE", 3.0) is not None
            assert wait_for(gcs, "PARAM_VALUE", 1.0) is None, "the GCS got the API's parameter list"
            # Telemetry, heartbeats and events stay on both links.
            for c in (gcs, api):
                assert wait_for(c, "HEARTBEAT", 3.0, lambda m: m.get_srcComponent() == 1) is not None
                assert wait_for(c, "ATTITUDE", 3.0) is not None
            assert _command(api, M.MAV_CMD_DO_GRIPPER, 1, M.GRIPPER_ACTION_GRAB) == M.MAV_RESULT_ACCEPTED
            for c in (gcs, api):
                assert wait_for(c, "STATUSTEXT", 3.0, lambda m: m.text == "Gripper: grab") is not None
        finally:  # leave the FC as found: the gain back, the gripper open
            if old is not None:
                api.mav.param_set_send(api.target_system, 1, b"OL_POS_K", old.param_value, M.MAV_PARAM_TYPE_REAL32)
                assert wait_for(api, "PARAM_VALUE", 3.0, lambda m: m.param_id == "OL_POS_K"
                                and abs(m.param_value - old.param_value) < 1e-6) is not None
            _command(api, M.MAV_CMD_DO_GRIPPER, 1, M.GRIPPER_ACTION_RELEASE)
