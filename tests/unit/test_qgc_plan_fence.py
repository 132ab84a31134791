"""A QGroundControl .plan's geofence (inclusion and exclusion circles and polygons) read into FENCE items that the
vehicle's checks accept, and enforced as QGC drew them (the fence's breach rule against hand-placed points)."""

from __future__ import annotations

from navig8_fc.mission.fence import Fence
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Cmd, MissionType, Plan, check_item, check_plan
from navig8_tools.mission import read_qgc_plan

LAT0, LON0 = 47.397742, 8.545594  # PX4 SITL's home
DLAT_PER_M = 1.0 / 111_195.0  # deg of latitude per metre (spherical earth, 6371 km)


def _plan() -> dict:
    square = [[LAT0 - 50 * DLAT_PER_M, LON0 - 0.0008], [LAT0 + 50 * DLAT_PER_M, LON0 - 0.0008],
              [LAT0 + 50 * DLAT_PER_M, LON0 + 0.0008], [LAT0 - 50 * DLAT_PER_M, LON0 + 0.0008]]
    return {"fileType": "Plan", "version": 1, "mission": {"items": []},
            "geoFence": {"version": 2,
                         "polygons": [{"inclusion": True, "polygon": square, "version": 1}],
                         "circles": [{"inclusion": False, "version": 1,
                                      "circle": {"center": [LAT0 + 30 * DLAT_PER_M, LON0], "radius": 8.0}}]}}


def test_qgc_fence_becomes_items_the_vehicle_accepts_and_enforces() -> None:
    pf = read_qgc_plan(_plan())
    cmds = [it.command for it in pf.fence]
    assert cmds == [Cmd.NAV_FENCE_CIRCLE_EXCLUSION] + [Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION] * 4
    assert all(check_item(it, MissionType.FENCE, len(pf.fence)) is None for it in pf.fence)
    assert check_plan(pf.fence, MissionType.FENCE) is None
    origin = GeoOrigin(LAT0, LON0, 488.0)
    fence = Fence.from_plan(Plan(MissionType.FENCE, pf.fence), origin)
    home = (0.0, 0.0, 0.0)
    assert fence.zones_not_enforced(home) == 0
    assert fence.breach((10.0, 0.0, -2.0), home, 0.0, 0.0) is None
    assert "exclusion circle" in (fence.breach((28.0, 0.0, -2.0), home, 0.0, 0.0) or "")  # 2 m from its centre
    assert fence.breach((39.0, 0.0, -2.0), home, 0.0, 0.0) is None  # past the circle, inside the square
    assert "inclusion polygon" in (fence.breach((55.0, 0.0, -2.0), home, 0.0, 0.0) or "")  # north of the square


def _key(items: tuple) -> list[tuple]:
    return [tuple("nan" if isinstance(v, float) and v != v else v
                  for v in (it.frame, it.command, it.autocontinue, *it.params, it.x, it.y, it.z)) for it in items]


def test_a_plan_written_as_qgc_json_reads_back_equal() -> None:
    """write_qgc_plan (what `navig8-mission download OUT.plan` writes) against read_qgc_plan: every item of the three
    plans back, a DO_JUMP's target through its doJumpId, NaN parameters through null, polygons regrouped."""
    import json
    import math

    from navig8_tools.mission import PlanFile, write_qgc_plan

    doc = _plan()
    doc["geoFence"]["polygons"].append({"inclusion": False, "version": 1, "polygon": [
        [LAT0 + 5 * DLAT_PER_M, LON0], [LAT0 + 8 * DLAT_PER_M, LON0], [LAT0 + 8 * DLAT_PER_M, LON0 + 0.0001]]})
    item = {"type": "SimpleItem", "autoContinue": True, "frame": 3}
    doc["mission"]["items"] = [
        {**item, "command": 22, "doJumpId": 1, "params": [0, 0, 0, None, LAT0, LON0, 2.5]},
        {**item, "command": 16, "doJumpId": 2, "params": [0, 0.5, 0, None, LAT0 + 0.0001, LON0, 3.0]},
        {**item, "command": 178, "doJumpId": 3, "frame": 2, "params": [1, 2.0, -1, 0, 0, 0, None]},
        {**item, "command": 16, "doJumpId": 4, "frame": 1, "params": [0, 0, 0, None, 4.0, -2.5, -3.0]},
        {**item, "command": 177, "doJumpId": 5, "frame": 2, "params": [2, 3, 0, 0, 0, 0, 0]},
        {**item, "command": 20, "doJumpId": 6, "frame": 2, "params": [None, None, None, None, 0, 0, 0]}]
    doc["geoFence"]["breachReturn"] = [LAT0 - 0.0001, LON0, 4.0]
    doc["rallyPoints"] = {"version": 2, "points": [[LAT0 + 0.0002, LON0, 0.0], [LAT0, LON0 - 0.0003, 5.0]]}
    plan = read_qgc_plan(doc)
    assert (len(plan.mission), len(plan.fence), len(plan.rally)) == (6, 9, 2)
    assert plan.mission[4].param1 == 1.0  # doJumpId 2 is item 1
    text = write_qgc_plan(PlanFile(plan.mission, plan.fence, plan.rally), home=(LAT0, LON0, 488.0))
    written = json.loads(text)
    assert written["mission"]["items"][4]["params"][0] == 2  # item 1 again as its doJumpId
    assert written["mission"]["items"][5]["params"][0] is None and math.isnan(plan.mission[5].param1)
    back = read_qgc_plan(written)
    for a, b in ((back.mission, plan.mission), (back.fence, plan.fence), (back.rally, plan.rally)):
        assert _key(a) == _key(b)
