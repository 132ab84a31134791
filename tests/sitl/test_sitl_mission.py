"""Missions over real UDP with pymavlink as the ground station (navig8-mission's client): an
8-item plan uploaded and downloaded item for item, an upload cut off halfway leaves the old plan in force, a plan
with one bad item is refused whole with the result code that names it, and the plan survives a restart (state
dir).

The protocol and the flight are MAVLink only: they run against any FC by connection string (`make test-hil`,
docs/hil.md), and the plan is cleared at the end there. The restart (a second FC process on the state dir) and
the Foxglove record of the plan (the log) need the local pair and skip when pointed elsewhere."""

from __future__ import annotations

import math
import shutil
import time
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import FcTarget, gcs_client, sitl, wait_for, wait_heartbeat

from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Cmd, Frame, MissionItem
from navig8_fc.modes import px4_custom_mode
from navig8_fc.modes.px4 import Px4AutoSubMode, Px4MainMode
from navig8_fc.shell.mcap_log import read_mcap
from navig8_tools.mission import download, upload

M = mavlink2
_LAT, _LON, _ = GeoOrigin().to_global((0.0, 1.0, 0.0))  # 1 m east of the origin (the default GeoOrigin)
EIGHT = (
    MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_TAKEOFF, 1, 0, 0, 0, math.nan, 0, 0, 2.0),
    MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 1.0, 0.25, 0, 90.0, 10000, 0, -2.0),
    MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_WAYPOINT, 1, 0, 0.25, 0, math.nan, round(_LAT * 1e7),
                round(_LON * 1e7), 2.5),
    MissionItem(Frame.MISSION, Cmd.DO_GRIPPER, 1, 1, 0, 0, 0, 0, 0, 0),
    MissionItem(Frame.MISSION, Cmd.NAVIG8_ARM_JOINTS, 1, 20, 20, 20, 1, 0, 0, 0),
    MissionItem(Frame.MISSION, Cmd.NAVIG8_PITCH_HOLD, 1, 20, 2, 0, 0, 0, 0, 0),
    MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_LOITER_TIME, 1, 2, 0, 0, math.nan, 0, 0, 2.0),
    MissionItem(Frame.MISSION, Cmd.NAV_RETURN_TO_LAUNCH, 1, 0, 0, 0, 0, 0, 0, 0),
)
HOME_TOL_M = 0.5
FC_LOCAL = {"speed": 2.0}  # the local pair (conftest.py `fc`)


def _same(a: tuple[MissionItem, ...], b: tuple[MissionItem, ...]) -> bool:
    def key(it: MissionItem) -> tuple:
        return tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in
                     (it.frame, it.command, it.autocontinue, *it.params, it.x, it.y, it.z))
    return [key(i) for i in a] == [key(i) for i in b]


def test_mission_upload_download_interrupted_refused(fc: FcTarget) -> None:
    with fc.session() as gcs:
        assert upload(gcs, EIGHT) == M.MAV_MISSION_ACCEPTED
        items, current = download(gcs)
        assert _same(items, EIGHT) and current == 0
        # Cut off after 4 of 8 items: the vehicle repeats its request, gives up after 5 s, keeps the old plan.
        other = EIGHT[:3] + (EIGHT[6], EIGHT[7]) * 2 + (EIGHT[7],)
        assert upload(gcs, other, stop_after=4) == -1
        st = wait_for(gcs, "STATUSTEXT", 8.0, lambda m: "timed out" in m.text)
        assert st is not None, "no upload timeout reported"
        assert _same(download(gcs)[0], EIGHT)
        # One bad item (DO_GRIPPER action 3) refuses the whole plan with INVALID_PARAM2 and says why.
        bad = EIGHT[:3] + (MissionItem(Frame.MISSION, Cmd.DO_GRIPPER, 1, 1, 3, 0, 0, 0, 0, 0),) + EIGHT[4:]
        assert upload(gcs, bad) == M.MAV_MISSION_INVALID_PARAM2
        st = wait_for(gcs, "STATUSTEXT", 3.0, lambda m: "Item 3" in m.text)
        assert st is not None and "action" in st.text
        assert _same(download(gcs)[0], EIGHT)
        cur = wait_for(gcs, "MISSION_CURRENT", 3.0)
        assert cur is not None and cur.total == 8 and cur.mission_state == M.MISSION_STATE_NOT_STARTED


def test_plan_survives_a_restart(fc: FcTarget, tmp_path: Path) -> None:
    """A new FC process on (a copy of) the state dir the plan was stored in has the plan."""
    run = fc.require_local("starts a second FC process on the local state dir")
    state = tmp_path / "state"
    shutil.copytree(run.state_dir, state)
    with sitl(tmp_path, scenario="ground", speed=1.0, state_dir=state, log_name="again.mcap",
              start_bridge=False) as run2:
        gcs = gcs_client(run2.gcs_port)
        try:
            wait_heartbeat(gcs, 15.0)
            assert _same(download(gcs)[0], EIGHT)
        finally:
            gcs.close()


def test_eight_item_plan_flown_reached_in_order_lands_at_home_and_disarms(fc: FcTarget) -> None:
    """Upload -> download equal -> Mission (selected while disarmed) -> arm -> MISSION_ITEM_REACHED 0..7 in order ->
    lands within HOME_TOL_M of home -> disarms. On the local pair (the module's last test: it stops the pair),
    the log's Foxglove record draws the plan."""
    fc.require_flight()
    with fc.session() as gcs:
        try:
            home = wait_for(gcs, "HOME_POSITION", 15.0)
            assert home is not None
            assert upload(gcs, EIGHT) == M.MAV_MISSION_ACCEPTED
            assert _same(download(gcs)[0], EIGHT)
            gcs.mav.set_mode_send(gcs.target_system, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0x04040000)
            assert wait_for(gcs, "HEARTBEAT", 5.0, lambda m: m.get_srcComponent() == 1
                            and m.custom_mode == 0x04040000) is not None, "Mission not selectable while disarmed"
            deadline = time.monotonic() + 20.0
            while True:  # arm once the estimator has warmed up (pre-arm checks)
                gcs.mav.command_long_send(gcs.target_system, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
                ack = wait_for(gcs, "COMMAND_ACK", 2.0, lambda m: m.command == M.MAV_CMD_COMPONENT_ARM_DISARM)
                if ack is not None and ack.result == M.MAV_RESULT_ACCEPTED:
                    break
                assert time.monotonic() < deadline, "arming refused"
                time.sleep(0.5)
            reached: list[int] = []
            deadline = time.monotonic() + 90.0
            disarmed_after_flight = None
            while time.monotonic() < deadline:
                m = gcs.recv_match(type=["MISSION_ITEM_REACHED", "HEARTBEAT"], blocking=True, timeout=1.0)
                if m is None:
                    continue
                if m.get_type() == "MISSION_ITEM_REACHED":
                    if not reached or reached[-1] != m.seq:
                        reached.append(m.seq)
                elif m.get_srcComponent() == 1 and reached and not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED:
                    disarmed_after_flight = m
                    break
            assert reached == list(range(8)), reached
            assert disarmed_after_flight is not None, "not disarmed after the mission"
            pos = wait_for(gcs, "LOCAL_POSITION_NED", 5.0)
            assert pos is not None
            hx, hy = home.x, home.y
            assert math.hypot(pos.x - hx, pos.y - hy) < HOME_TOL_M and abs(pos.z - home.z) < HOME_TOL_M
        finally:
            if fc.local is None:  # an FC elsewhere is left without the plan; the local one keeps it for the log check
                gcs.mav.mission_clear_all_send(gcs.target_system, 1, 0)
                ack = wait_for(gcs, "MISSION_ACK", 5.0)
                assert ack is not None and ack.type == M.MAV_MISSION_ACCEPTED
            gcs.mav.set_mode_send(gcs.target_system, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                  px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER))  # Hold
    if fc.local is None:
        return  # the rest reads the local log
    fc.local.stop()
    # Foxglove's 3D view draws the uploaded plan (/foxglove/mission, ENU world): home, the five position items
    # in order (takeoff over home, the local waypoint 1 m north at 2 m, ...), back home.
    records = [rec for _, _, rec in read_mcap(fc.local.log, ["/foxglove/mission"])]
    assert records, "no /foxglove/mission record"
    poses = [p["position"] for p in records[-1]["poses"]]
    assert len(poses) == 6, poses
    enu = [(p["x"], p["y"], p["z"]) for p in poses]
    home_enu = (home.y, home.x, -home.z)
    for got, want in ((enu[0], home_enu), (enu[2], (0.0, 1.0, 2.0)), (enu[-1], home_enu)):
        assert all(abs(a - b) < 1e-6 for a, b in zip(got, want, strict=True)), (got, want)
