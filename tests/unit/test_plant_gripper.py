"""Plant.command_gripper: the GCS's grab/release (NAVIG8_ARM_CMD through the bridge) acts like a scenario event."""

from __future__ import annotations

import numpy as np
import pytest

from navig8_fc.core.vehicle import VehicleConfig
from sim_bridge import Plant, PlantParams, load_scenario


def _plant(scenario: str) -> Plant:
    return Plant(VehicleConfig.load(), PlantParams.load(), load_scenario(scenario), np.random.default_rng(0))


def test_release_and_grab_change_mass_now() -> None:
    p = _plant("hover")
    cmd = p.trim_command()
    p.step(cmd, 0.02)
    m0 = p.truth().mass_kg
    assert p.command_gripper(False) is True
    tr = p.truth()  # mass properties are re-evaluated at once, before the next step
    assert not tr.gripper_closed and tr.object_mass_kg == 0.0 and tr.mass_kg == pytest.approx(m0 - 1.0)
    assert not p.sense().gripper_closed
    assert p.command_gripper(False) is False  # already open: nothing changes
    p.step(cmd, 0.02)
    assert p.command_gripper(True, 0.5) is True
    tr = p.truth()
    assert tr.gripper_closed and tr.object_mass_kg == 0.5 and tr.mass_kg == pytest.approx(m0 - 0.5)
    assert p.command_gripper(True, 3.0) is False  # closed already: the held mass stays
    assert p.truth().object_mass_kg == 0.5


def test_grab_rejects_bad_mass() -> None:
    p = _plant("ground")
    with pytest.raises(ValueError):
        p.command_gripper(True, float("nan"))
    with pytest.raises(ValueError):
        p.command_gripper(True, -1.0)
    assert not p.truth().gripper_closed
