"""The legacy SET_MODE message (PX4 custom_mode encoding) switches modes; an unknown mode is refused by STATUSTEXT."""

from __future__ import annotations

from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import gcs_client, sitl, wait_for, wait_heartbeat

from navig8_fc.modes import px4_custom_mode
from navig8_fc.modes.px4 import Px4AutoSubMode, Px4MainMode

M = mavlink2


def test_set_mode_message(tmp_path: Path) -> None:
    hold = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER)
    land = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LAND)
    with sitl(tmp_path, scenario="hover", speed=2.0) as run:  # armed in the air, AUTO.MISSION
        gcs = gcs_client(run.gcs_port)
        try:
            wait_heartbeat(gcs, 15.0)
            gcs.mav.set_mode_send(gcs.target_system, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, hold)
            hb = wait_for(gcs, "HEARTBEAT", 5.0, lambda m: m.get_srcComponent() == 1 and m.custom_mode == hold)
            assert hb is not None, "SET_MODE Hold not applied"
            gcs.mav.set_mode_send(gcs.target_system, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 5)  # ArduCopter LOITER
            st = wait_for(gcs, "STATUSTEXT", 5.0, lambda m: "not supported" in m.text or "refused" in m.text)
            assert st is not None
            # The refused mode changed nothing: the next heartbeats still say Hold.
            hb = wait_for(gcs, "HEARTBEAT", 5.0, lambda m: m.get_srcComponent() == 1)
            assert hb is not None and hb.custom_mode == hold
            gcs.mav.set_mode_send(gcs.target_system, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, land)
            hb = wait_for(gcs, "HEARTBEAT", 5.0, lambda m: m.get_srcComponent() == 1 and m.custom_mode == land)
            assert hb is not None, "SET_MODE Land not applied"
        finally:
            gcs.close()
