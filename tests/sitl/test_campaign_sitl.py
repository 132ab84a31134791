"""navig8-campaign's SITL kind: each row is navig8-sitl (two processes over MAVLink/UDP) on its own --instance,
side by side on the pool; the world override reaches the plant through navig8-bridge --world; with a plan, the
worker is each run's ground station and flies the plan over MAVLink (upload, Mission, arm) before the summary."""

from __future__ import annotations

from pathlib import Path

import pytest

from navig8_fc.mission.plan import Cmd, Frame, MissionItem
from navig8_tools.campaign import run_campaign
from navig8_tools.campaign_spec import Campaign
from navig8_tools.mission import write_wpl

G_M_S2 = 9.80665


def test_sitl_rows_run_side_by_side_and_the_object_mass_reaches_the_plant(tmp_path: Path) -> None:
    c = Campaign.from_dict({
        "name": "sitl_small", "kind": "sitl", "scenario": "hover", "duration_s": 1.5, "timeout_s": 180,
        "seeds": [1], "variants": {"proposed": {"controller": "proposed"}},
        "factors": {"object_mass_kg": {"world": "scenario.object.mass_kg", "grid": [0.0, 3.0]}},
    })
    res = run_campaign(c, tmp_path, workers=2, progress=False)
    t = res.table.set_index("object_mass_kg")
    assert t["status"].tolist() == ["ok", "ok"], t["error"].tolist()
    assert not t["lost_control"].any()
    assert t["replay"].str.contains("--instance").all() and t["replay"].nunique() == 2
    # hovering with the arm still, the mount carries the object's weight: 3 kg more is ~3 g N more (independent:
    # m g), within the hover's small accelerations
    dforce = t.loc[3.0, "peak_reaction_force_n"] - t.loc[0.0, "peak_reaction_force_n"]
    assert dforce == pytest.approx(3.0 * G_M_S2, abs=3.0)


STEP_M = 1.0  # the plan: 1 m north of the hover point and back
RADIUS_M = 0.15  # each waypoint's acceptance radius


def test_sitl_rows_fly_an_uploaded_plan_each_on_its_own_instance(tmp_path: Path) -> None:
    plan = (MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 0.0, RADIUS_M, 0.0, 0.0, round(STEP_M * 1e4), 0, -2.0),
            MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 0.0, RADIUS_M, 0.0, 0.0, 0, 0, -2.0))
    (tmp_path / "out_and_back.waypoints").write_text(write_wpl(plan))
    c = Campaign.from_dict({
        "name": "sitl_plan", "kind": "sitl", "scenario": "hover", "duration_s": 8.0, "speed": 2.0,
        "timeout_s": 180, "plan": "out_and_back.waypoints", "seeds": [1, 2],
        "variants": {"proposed": {"controller": "proposed"}},
    }, tmp_path)
    res = run_campaign(c, tmp_path / "out", workers=2, progress=False)
    t = res.table
    assert t["status"].tolist() == ["ok", "ok"], t["error"].tolist()
    assert t["mission_complete"].all() and t["success"].all()
    assert (t["mission_items"] == 2).all() and (t["mission_reached"] == 2).all()
    # flown, not only accepted: the setpoint stepped 1 m away (the position error right after the step is the step)
    # and the vehicle went there and came back: fly() sums the LOCAL_POSITION_NED path until the plan completes,
    # at least (STEP - r) out and (STEP - 2 r) back with r the acceptance radius, less the chords between telemetry
    # samples (10 Hz on the wall clock at --speed 2: 0.2 s of flight apart; the defaults' flown gain turns at the
    # far waypoint within one or two samples, so up to ~0.3 m of the turn falls between them: 1.24 m against 1.55 m
    # was measured). More than one step means it came back part of the way, not only out.
    assert t["max_pos_error_m"].between(0.9 * STEP_M, 1.3 * STEP_M).all(), t["max_pos_error_m"].tolist()
    low = STEP_M + 0.1
    assert t["mission_path_m"].between(low, 3.0 * STEP_M).all(), t["mission_path_m"].tolist()
    assert not t["lost_control"].any()
    # each run on its own instance, and each replays with navig8-sitl + navig8-mission fly
    instances = t["replay"].str.extract(r"--instance (\d+)")[0]
    assert instances.nunique() == 2
    assert t["replay"].str.contains("navig8-mission fly").all()
