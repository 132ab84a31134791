"""A scenario file's own world overrides (`world:` in params/scenarios/*.yaml): paper_wrong_model's controller model."""

from __future__ import annotations

import pytest
import yaml

from sim_bridge.world import load_world


def test_paper_wrong_model_changes_only_the_controllers_model() -> None:
    paper, wrong = load_world("paper"), load_world("paper_wrong_model")
    assert wrong.vehicle == paper.vehicle  # the plant flies the true vehicle
    assert wrong.fc_vehicle.uav_mass_kg == pytest.approx(0.8 * paper.vehicle.uav_mass_kg)
    for got, true in zip(wrong.fc_vehicle.uav_inertia_array.diagonal(), paper.vehicle.uav_inertia_array.diagonal(),
                         strict=True):
        assert got == pytest.approx(0.6 * true)
    assert wrong.scenario.script.steps == paper.scenario.script.steps and wrong.scenario.events == paper.scenario.events
    # the caller's overrides apply after the file's: a factor on top of the file's factor
    again = load_world("paper_wrong_model", {"fc_vehicle.uav.mass_kg*": 0.5})
    assert again.fc_vehicle.uav_mass_kg == pytest.approx(0.4 * paper.vehicle.uav_mass_kg)


def test_a_scenarios_own_overrides_cannot_change_the_scenario(tmp_path) -> None:
    from navig8_fc.flight.script import read_scenario_file

    d = read_scenario_file("ident")
    d["world"] = {"scenario.object.mass_kg": 0.0}
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(ValueError, match="cannot change the scenario"):
        load_world(p)
