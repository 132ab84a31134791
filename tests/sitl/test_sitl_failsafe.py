"""GCS-loss failsafe: a ground station that stops sending heartbeats makes a hovering vehicle land."""

from __future__ import annotations

import math
import time
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import gcs_client, sitl, wait_for, wait_heartbeat

from navig8_fc.modes import px4_custom_mode
from navig8_fc.modes.px4 import Px4AutoSubMode, Px4MainMode
from navig8_fc.shell.mcap_log import read_mcap

M = mavlink2


def _beat(gcs) -> None:
    gcs.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)


def _until(gcs, pred, timeout_s: float, beat: bool) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if beat:
            _beat(gcs)
        m = wait_for(gcs, "HEARTBEAT", 0.3, lambda m: m.get_srcComponent() == 1)
        if m is not None and pred(m):
            return True
    return False


def _cmd(gcs, command: int, *params: float) -> int:
    p = list(params) + [0.0] * (7 - len(params))
    gcs.mav.command_long_send(gcs.target_system, 1, command, 0, *p)
    ack = wait_for(gcs, "COMMAND_ACK", 5.0, lambda m: m.command == command)
    assert ack is not None
    return ack.result


def test_gcs_heartbeat_loss_lands_the_vehicle(tmp_path: Path) -> None:
    land = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LAND)
    hold = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER)
    with sitl(tmp_path, scenario="ground", speed=2.0) as run:
        gcs = gcs_client(run.gcs_port)
        try:
            wait_heartbeat(gcs, 15.0)
            _beat(gcs)
            gcs.mav.param_set_send(gcs.target_system, 1, b"FS_GCS_TOUT", 1.0, M.MAV_PARAM_TYPE_REAL32)
            assert wait_for(gcs, "PARAM_VALUE", 5.0, lambda m: m.param_id == "FS_GCS_TOUT") is not None
            deadline = time.monotonic() + 15.0
            while _cmd(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) != M.MAV_RESULT_ACCEPTED:
                assert time.monotonic() < deadline, "arming never accepted"
                _beat(gcs)
                time.sleep(0.3)
            assert _cmd(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 1.5) == \
                M.MAV_RESULT_ACCEPTED
            assert _until(gcs, lambda m: m.custom_mode == hold, 30.0, beat=True), "no Hold after takeoff"
            # the GCS goes silent: the FC lands and disarms by itself
            assert _until(gcs, lambda m: m.custom_mode == land, 10.0, beat=False), "no Land after GCS loss"
            assert _until(gcs, lambda m: not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 40.0, beat=False)
        finally:
            gcs.close()
    texts = [d["text"] for _, _, d in read_mcap(run.log, ["/fc/statustext"])]
    assert "GCS link lost: landing" in texts, texts
