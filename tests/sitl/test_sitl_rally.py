"""Rally points over real UDP, pymavlink as the ground station (navig8-mission's client): a QGroundControl .plan with
a mission, an inclusion polygon, an exclusion circle and two rally points is uploaded (what `navig8-mission upload`
sends) and downloaded equal, plan by plan and as the .plan `navig8-mission download OUT.plan` writes; then the
vehicle is pushed out of the polygon in Position mode (MANUAL_CONTROL, stick right), the fence failsafe runs
FS_FENCE_ACT = 3 (Return), and Return goes to the nearest rally point (PX4's RTL_TYPE 0: not home, which is farther)
and lands there.

Geometry (NED m about home): the polygon spans north -6..20, east -6..6; the exclusion circle (r 1.5 m) is at
(-3, -3); rally point 0 at (14, 0) (14 m from home: usable), rally point 1 at (0, -15), outside the fence. The
vehicle repositions to (12, 4.5) at 2.5 m, then Position mode's stick takes it east across 6 m: at (12, 6) home is
13.4 m away, rally point 0 6.3 m, rally point 1 24.2 m."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import PARAM_SET_WAIT_S, FcTarget, command, wait_for

from navig8_fc.gcs.params import decode_param_value, encode_param_value
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import MissionType
from navig8_fc.modes import px4_custom_mode
from navig8_fc.modes.px4 import Px4AutoSubMode, Px4MainMode
from navig8_tools.mission import PlanFile, download, read_plan, read_qgc_plan, upload, write_qgc_plan

M = mavlink2
FC_LOCAL = {"speed": 3.0}  # the local pair (conftest.py `fc`)
ORIGIN = GeoOrigin()  # the FC's default global origin (ORIGIN_* parameters)
RALLY_0 = (14.0, 0.0)
LAND_TOL_M = 0.5


def _ll(home: tuple[float, float], n: float, e: float) -> list[float]:
    lat, lon, _ = ORIGIN.to_global((home[0] + n, home[1] + e, 0.0))
    return [lat, lon]


def _qgc_plan(home: tuple[float, float]) -> dict:
    square = [_ll(home, n, e) for n, e in ((-6, -6), (20, -6), (20, 6), (-6, 6))]
    item = {"type": "SimpleItem", "autoContinue": True, "frame": 3, "doJumpId": 1}
    return {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
            "mission": {"version": 2, "firmwareType": 12, "vehicleType": 2, "items": [
                {**item, "command": 22, "params": [0, 0, 0, None, *_ll(home, 0, 0), 2.5]},
                {**item, "command": 16, "doJumpId": 2, "params": [0, 0, 0, None, *_ll(home, 5, 0), 2.5]},
                {**item, "command": 20, "doJumpId": 3, "frame": 2, "params": [0, 0, 0, 0, 0, 0, 0]}]},
            "geoFence": {"version": 2, "polygons": [{"inclusion": True, "version": 1, "polygon": square}],
                         "circles": [{"inclusion": False, "version": 1,
                                      "circle": {"center": _ll(home, -3, -3), "radius": 1.5}}]},
            "rallyPoints": {"version": 2, "points": [[*_ll(home, *RALLY_0), 0], [*_ll(home, 0, -15), 0]]}}


def _fence_act(gcs, value: int | None = None) -> int:
    """FS_FENCE_ACT (INT32, bytewise on the wire): set it when value is given; the value in force."""
    if value is None:
        gcs.mav.param_request_read_send(gcs.target_system, 1, b"FS_FENCE_ACT", -1)
    else:
        wire = encode_param_value(value, M.MAV_PARAM_TYPE_INT32)
        gcs.mav.param_set_send(gcs.target_system, 1, b"FS_FENCE_ACT", wire, M.MAV_PARAM_TYPE_INT32)
    pv = wait_for(gcs, "PARAM_VALUE", PARAM_SET_WAIT_S, lambda m: m.param_id == "FS_FENCE_ACT")
    assert pv is not None, "no PARAM_VALUE FS_FENCE_ACT"
    return int(decode_param_value(pv.param_value, pv.param_type))


def _key(items: tuple) -> list[tuple]:
    return [tuple("nan" if isinstance(v, float) and math.isnan(v) else round(v, 4) if isinstance(v, float) else v
                  for v in (it.frame, it.command, it.autocontinue, *it.params, it.x, it.y, it.z)) for it in items]


def _fc_hb(gcs, pred, timeout_s: float):
    return wait_for(gcs, "HEARTBEAT", timeout_s, lambda m: m.get_srcComponent() == 1 and pred(m))


def _fly_to(gcs, home, n: float, e: float, alt: float, timeout_s: float) -> None:
    lat, lon = _ll(home, n, e)
    gcs.mav.command_int_send(gcs.target_system, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_DO_REPOSITION,
                             0, 0, -1, 1, 0, math.nan, round(lat * 1e7), round(lon * 1e7), alt)
    lp = wait_for(gcs, "LOCAL_POSITION_NED", timeout_s,
                  lambda m: math.hypot(m.x - home[0] - n, m.y - home[1] - e) < 0.4 and abs(m.z + alt) < 0.4)
    assert lp is not None, f"never reached ({n}, {e})"


def test_qgc_plan_with_rally_points_round_trips_and_a_fence_breach_returns_to_the_nearest(fc: FcTarget,
                                                                                         tmp_path: Path) -> None:
    fc.require_flight()
    rtl = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.RTL)
    with fc.session() as gcs:
        before = _fence_act(gcs)
        try:
            hp = wait_for(gcs, "HOME_POSITION", 15.0)
            assert hp is not None
            home = (hp.x, hp.y)
            path = tmp_path / "rally.plan"
            path.write_text(json.dumps(_qgc_plan(home)))
            plan = read_plan(path)
            assert (len(plan.mission), len(plan.fence), len(plan.rally)) == (3, 5, 2)
            for kind, items in ((MissionType.MISSION, plan.mission), (MissionType.FENCE, plan.fence),
                                (MissionType.RALLY, plan.rally)):
                assert upload(gcs, items, kind) == M.MAV_MISSION_ACCEPTED, kind
                assert _key(download(gcs, kind)[0]) == _key(items), kind
            # what `navig8-mission download OUT.plan` writes: the three plans as a .plan that reads back equal
            held = PlanFile(*(download(gcs, kind)[0] for kind in (MissionType.MISSION, MissionType.FENCE,
                                                                  MissionType.RALLY)))
            back = read_qgc_plan(json.loads(write_qgc_plan(held)))
            for a, b in ((back.mission, plan.mission), (back.fence, plan.fence), (back.rally, plan.rally)):
                assert _key(a) == _key(b)
            assert _fence_act(gcs, 3) == 3
            deadline = time.monotonic() + 15.0
            while command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result != M.MAV_RESULT_ACCEPTED:
                assert time.monotonic() < deadline, "arming never accepted"
                time.sleep(0.3)
            assert command(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 2.5).result in (
                M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_IN_PROGRESS)
            assert _fc_hb(gcs, lambda m: m.custom_mode == px4_custom_mode(4, 3), 20.0), "no Hold after takeoff"
            _fly_to(gcs, home, 12.0, 4.5, 2.5, 20.0)
            posctl = px4_custom_mode(Px4MainMode.POSCTL)
            gcs.mav.set_mode_send(gcs.target_system, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, posctl)
            assert _fc_hb(gcs, lambda m: m.custom_mode == posctl, 5.0), "no Position mode"
            texts: list[str] = []
            deadline = time.monotonic() + 15.0
            while not any(t.startswith("Fence breach") for t in texts):  # stick right (east) until the breach
                assert time.monotonic() < deadline, f"no fence breach: {texts}"
                gcs.mav.manual_control_send(gcs.target_system, 0, 1000, 500, 0, 0)
                st = wait_for(gcs, "STATUSTEXT", 0.05)
                texts += [st.text] if st is not None else []
            assert "outside the inclusion polygon: retur" in texts[-1], texts  # "...: returning", chunked at 50
            assert _fc_hb(gcs, lambda m: m.custom_mode == rtl, 5.0), "no Return after the breach"
            st = wait_for(gcs, "STATUSTEXT", 20.0, lambda m: m.text.startswith("Return: landing"))
            assert st is not None and st.text == "Return: landing at rally point 0", st
            assert _fc_hb(gcs, lambda m: not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 20.0), "not disarmed"
            lp = wait_for(gcs, "LOCAL_POSITION_NED", 5.0)
            assert lp is not None
            off = math.hypot(lp.x - home[0] - RALLY_0[0], lp.y - home[1] - RALLY_0[1])
            assert off < LAND_TOL_M and abs(lp.z - hp.z) < LAND_TOL_M, (lp.x, lp.y, lp.z)
        finally:
            _fence_act(gcs, before)
            gcs.mav.mission_clear_all_send(gcs.target_system, 1, M.MAV_MISSION_TYPE_ALL)
            wait_for(gcs, "MISSION_ACK", 5.0)
