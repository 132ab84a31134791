"""A saved worst case (params/scenarios/falsified_proposed.yaml, found by navig8-falsify) flies in process as its
regression campaign flies it, and reproduces what the search recorded for it (the header's per-seed line): the
saved files are the case that was found, rounding and world overrides included. When a change to the controller
moves this number, the case may no longer be its worst: run the search again (docs/campaigns.md, "Falsification").
The search was run for the adaptive law flying its estimate K_hat (INDI_LAM_REF 1, the defaults then): the campaign's
`proposed_khat` variant, which this test flies; `proposed` is the defaults now (the flown gain).
"""

from __future__ import annotations

import re
from importlib.resources import files

import pytest
import yaml

from navig8_tools.falsify import flight_score
from navig8_tools.sim import run
from sim_bridge.world import load_world

CASE = "falsified_proposed"
SEED = 1001  # the search's first flight seed


def test_the_proposed_worst_case_reproduces_the_search(tmp_path):
    text = (files("navig8_params.scenarios") / f"{CASE}.yaml").read_text()
    recorded = re.search(rf"flight seed {SEED}: score ([0-9.]+)", text)
    assert recorded, "the scenario's header notes the search's flights"
    campaign = yaml.safe_load((files("navig8_params") / "campaigns" / f"{CASE}.yaml").read_text())
    variant = campaign["variants"]["proposed_khat"]
    world = load_world(CASE)
    own = yaml.safe_load(text)["world"]  # the plant's side and the FC model's, from the scenario itself
    assert world.vehicle.object_offset_m == own["vehicle.object.offset_from_tip_m"]
    assert world.fc_vehicle.object_offset_m == own["fc_vehicle.object.offset_from_tip_m"]
    assert world.plant.duct_fault_t_s == own.get("plant.actuators.duct_fault_t_s", 0.0)
    res = run(CASE, variant["controller"], seed=SEED, log_path=tmp_path / "run.mcap", overrides=variant["set"])
    score = flight_score(res.summary, world.scenario.duration_s)
    assert score == pytest.approx(float(recorded.group(1)), abs=0.006)  # the header rounds to 0.01
