"""navig8-campaign's SITL kind: each row is navig8-sitl (two processes over MAVLink/UDP) on its own --instance,
side by side on the pool; the world override reaches the plant through navig8-bridge --world."""

from __future__ import annotations

from pathlib import Path

import pytest

from navig8_tools.campaign import Campaign, run_campaign

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
