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
