"""The legacy SET_MODE message (PX4 custom_mode encoding) switches modes; an unknown mode is refused by STATUSTEXT.

MAVLink only: runs against any FC by connection string (`make test-hil`, docs/hil.md). The local pair starts in
the air (the hover scenario, AUTO.MISSION); an FC on the ground takes off first (arm, takeoff 1.5 m) and ends
landed and disarmed where it took off."""

from __future__ import annotations

import math
import time

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import FcTarget, command, wait_for

from navig8_fc.modes import px4_custom_mode
from navig8_fc.modes.px4 import Px4AutoSubMode, Px4MainMode

M = mavlink2
FC_LOCAL = {"scenario": "hover", "speed": 2.0}  # the local pair (conftest.py `fc`): armed at 2 m


def _fc_hb(pred):  # noqa: ANN001, ANN202
    return lambda m: m.get_srcComponent() == 1 and pred(m)


def test_set_mode_message(fc: FcTarget) -> None:
    fc.require_flight()
    hold = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER)
    land = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LAND)
    position = px4_custom_mode(Px4MainMode.POSCTL, 0)
    with fc.session() as gcs:
        hb = wait_for(gcs, "HEARTBEAT", 5.0, _fc_hb(lambda m: True))
        took_off = not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
        if took_off:
            deadline = time.monotonic() + 30.0
            while command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result != M.MAV_RESULT_ACCEPTED:
                assert time.monotonic() < deadline, "arming never accepted"
                wait_for(gcs, "HEARTBEAT", 0.5)  # pre-arm checks may need the first sensor data
            assert command(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 1.5).result in (
                M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_IN_PROGRESS)
            assert wait_for(gcs, "HEARTBEAT", 40.0, _fc_hb(lambda m: m.custom_mode == hold)) is not None, \
                "no Hold after takeoff"
        # In the air: SET_MODE Position, then back to Hold (each applied, as the heartbeat says).
        gcs.mav.set_mode_send(gcs.target_system, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, position)
        assert wait_for(gcs, "HEARTBEAT", 5.0, _fc_hb(lambda m: m.custom_mode == position)) is not None, \
            "SET_MODE Position not applied"
        gcs.mav.set_mode_send(gcs.target_system, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, hold)
        hb = wait_for(gcs, "HEARTBEAT", 5.0, _fc_hb(lambda m: m.custom_mode == hold))
        assert hb is not None, "SET_MODE Hold not applied"
        gcs.mav.set_mode_send(gcs.target_system, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 5)  # ArduCopter LOITER
        st = wait_for(gcs, "STATUSTEXT", 5.0, lambda m: "not supported" in m.text or "refused" in m.text)
        assert st is not None
        # The refused mode changed nothing: the next heartbeats still say Hold.
        hb = wait_for(gcs, "HEARTBEAT", 5.0, lambda m: m.get_srcComponent() == 1)
        assert hb is not None and hb.custom_mode == hold
        gcs.mav.set_mode_send(gcs.target_system, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, land)
        hb = wait_for(gcs, "HEARTBEAT", 5.0, _fc_hb(lambda m: m.custom_mode == land))
        assert hb is not None, "SET_MODE Land not applied"
        if took_off:  # leave it as found: landed, disarmed
            assert wait_for(gcs, "HEARTBEAT", 60.0, _fc_hb(lambda m: not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)) \
                is not None, "no disarm after landing"
