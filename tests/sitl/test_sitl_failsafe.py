"""Failsafes over SITL: GCS loss (the default action, Land), battery critical (Return) and a fence breach (Land).

All three are commanded and seen over MAVLink (parameters set, HEARTBEAT modes, STATUSTEXT): they run against any
FC by connection string (`make test-hil`, docs/hil.md), and every parameter set is restored. The local log's
STATUSTEXT record is checked on the local pair only."""

from __future__ import annotations

import math
import time

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import PARAM_SET_WAIT_S, FcTarget, wait_for

from navig8_fc.gcs.params import decode_param_value, encode_param_value
from navig8_fc.modes import px4_custom_mode
from navig8_fc.modes.px4 import Px4AutoSubMode, Px4MainMode
from navig8_fc.shell.mcap_log import read_mcap

M = mavlink2
FC_LOCAL = {"speed": 2.0}  # the local pair (conftest.py `fc`)


def _beat(gcs) -> None:
    gcs.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)


def _until(gcs, pred, timeout_s: float, beat: bool, texts: list[str] | None = None) -> bool:
    """Until an FC HEARTBEAT satisfies pred (beating meanwhile if told); the STATUSTEXTs seen go to texts."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if beat:
            _beat(gcs)
        m = wait_for(gcs, ["HEARTBEAT", "STATUSTEXT"], 0.3, lambda m: m.get_srcComponent() == 1)
        if m is not None and m.get_type() == "STATUSTEXT":
            if texts is not None:
                texts.append(m.text)
        elif m is not None and pred(m):
            return True
    return False


def _read(gcs, name: str) -> float:
    gcs.mav.param_request_read_send(gcs.target_system, 1, name.encode(), -1)
    pv = wait_for(gcs, "PARAM_VALUE", PARAM_SET_WAIT_S, lambda m: m.param_id == name)
    assert pv is not None, f"no PARAM_VALUE {name}"
    return decode_param_value(pv.param_value, pv.param_type)  # INT32 values travel bytewise


def _cmd(gcs, command: int, *params: float) -> int:
    p = list(params) + [0.0] * (7 - len(params))
    gcs.mav.command_long_send(gcs.target_system, 1, command, 0, *p)
    ack = wait_for(gcs, "COMMAND_ACK", 5.0, lambda m: m.command == command)
    assert ack is not None
    return ack.result


def test_gcs_heartbeat_loss_lands_the_vehicle(fc: FcTarget) -> None:
    fc.require_flight()
    land = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LAND)
    hold = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER)
    texts: list[str] = []
    with fc.session() as gcs:
        tout = _read(gcs, "FS_GCS_TOUT")
        try:
            _beat(gcs)
            _set_param(gcs, "FS_GCS_TOUT", 1.0)
            _arm_and_take_off(gcs, 1.5, beat=True)
            assert _until(gcs, lambda m: m.custom_mode == hold, 30.0, beat=True), "no Hold after takeoff"
            # the GCS goes silent: the FC lands and disarms by itself, and says why on the link
            assert _until(gcs, lambda m: m.custom_mode == land, 10.0, beat=False, texts=texts), \
                "no Land after GCS loss"
            assert _until(gcs, lambda m: not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 40.0, beat=False,
                          texts=texts)
        finally:
            _set_param(gcs, "FS_GCS_TOUT", tout)
    assert "GCS link lost: landing" in texts, texts


def _set_param(gcs, name: str, value: float, int32: bool = False) -> None:
    if int32:
        wire = encode_param_value(int(value), M.MAV_PARAM_TYPE_INT32)
        gcs.mav.param_set_send(gcs.target_system, 1, name.encode(), wire, M.MAV_PARAM_TYPE_INT32)
    else:
        gcs.mav.param_set_send(gcs.target_system, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32)
    assert wait_for(gcs, "PARAM_VALUE", PARAM_SET_WAIT_S, lambda m: m.param_id == name) is not None


def _arm_and_take_off(gcs, alt_m: float, beat: bool = False) -> None:
    deadline = time.monotonic() + 15.0
    while _cmd(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) != M.MAV_RESULT_ACCEPTED:
        assert time.monotonic() < deadline, "arming never accepted"
        if beat:
            _beat(gcs)
        time.sleep(0.3)
    assert _cmd(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, alt_m) == M.MAV_RESULT_IN_PROGRESS


def test_battery_critical_returns_and_fence_breach_lands(fc: FcTarget) -> None:
    """Battery critical -> FS_BAT_CRIT_ACT = 3 (Return: home, land, disarm); then a fence breach (FENCE_ALT_MAX)
    -> FS_FENCE_ACT = 2 (Land). Both announced by STATUSTEXT; HEARTBEAT CRITICAL while in force."""
    fc.require_flight()
    rtl = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.RTL)
    land = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LAND)
    changed = {"FS_BAT_CRIT_ACT": True, "FS_BAT_CRIT_PCT": False, "FENCE_ALT_MAX": False, "FS_FENCE_ACT": True}
    with fc.session() as gcs:
        before = {name: _read(gcs, name) for name in changed}
        try:
            _set_param(gcs, "FS_BAT_CRIT_ACT", 3, int32=True)
            _set_param(gcs, "FS_BAT_CRIT_PCT", 100.0)  # the full pack is at the threshold: critical at takeoff
            _arm_and_take_off(gcs, 1.5)
            st = wait_for(gcs, "STATUSTEXT", 20.0, lambda m: m.text.startswith("Battery critical"))
            assert st is not None and st.text.endswith("returning"), st
            hb = wait_for(gcs, "HEARTBEAT", 5.0, lambda m: m.get_srcComponent() == 1 and m.custom_mode == rtl)
            assert hb is not None and hb.system_status == M.MAV_STATE_CRITICAL
            assert _until(gcs, lambda m: not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 40.0, beat=False)
            # Fence: 1 m above home at most, landing as the action.
            _set_param(gcs, "FS_BAT_CRIT_PCT", 0.0)
            _set_param(gcs, "FENCE_ALT_MAX", 1.0)
            _set_param(gcs, "FS_FENCE_ACT", 2, int32=True)
            _arm_and_take_off(gcs, 2.0)
            st = wait_for(gcs, "STATUSTEXT", 20.0, lambda m: m.text.startswith("Fence breach"))
            assert st is not None and "above home" in st.text and st.text.endswith("landing"), st
            assert _until(gcs, lambda m: m.custom_mode == land, 5.0, beat=False)
            assert _until(gcs, lambda m: not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 40.0, beat=False)
        finally:
            for name, int32 in changed.items():
                _set_param(gcs, name, before[name], int32=int32)


def test_local_log_records_the_gcs_loss(fc: FcTarget) -> None:
    run = fc.require_local("the STATUSTEXT record is in the local log")
    run.stop()
    texts = [d["text"] for _, _, d in read_mcap(run.log, ["/fc/statustext"])]
    assert "GCS link lost: landing" in texts, texts
