"""World overrides (sim_bridge/world.py): each name changes exactly its entry, `*` scales, bad names refuse."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from navig8_fc.core.vehicle import VehicleConfig
from sim_bridge import ActuatorCommand, Plant, PlantParams, load_scenario
from sim_bridge.world import load_world, parse_world_items, world_args


def test_no_overrides_is_the_packaged_world() -> None:
    w = load_world("paper")
    assert w.plant == PlantParams.load()
    assert w.vehicle == VehicleConfig.load() == w.fc_vehicle
    assert w.scenario == load_scenario("paper")


def test_set_scale_and_derived_names_change_only_their_entries() -> None:
    base = load_world("paper")
    w = load_world("paper", {"plant.joint_servo.v_max_rad_s": 2.5, "scenario.events.0.mass_kg": 3.0,
                             "scenario.arm.amplitude_deg": 30.0, "fc_vehicle.uav.mass_kg*": 1.1,
                             "sensor_noise_scale": 2.0, "actuator_bandwidth_scale": 0.5,
                             "plant.sensors.gyro_bias_rad_s": 0.02})
    assert w.plant.joint_v_max_rad_s == 2.5 and w.plant.joint_a_max_rad_s2 == base.plant.joint_a_max_rad_s2
    assert w.scenario.events[0].mass_kg == 3.0 and w.scenario.events[0].t_s == base.scenario.events[0].t_s
    assert max(w.scenario.arm_segments[0].q_end_rad) == pytest.approx(np.radians(30.0), abs=1e-12)
    assert w.fc_vehicle.uav_mass_kg == pytest.approx(1.1 * base.vehicle.uav_mass_kg, rel=1e-12)
    assert w.vehicle == base.vehicle  # a model error is the controller's alone
    for f in dataclasses.fields(w.plant.sensors):
        new, old = getattr(w.plant.sensors, f.name), getattr(base.plant.sensors, f.name)
        if "_sigma_" in f.name:
            assert new == pytest.approx(2.0 * old, rel=1e-12)
        elif f.name != "gyro_bias_rad_s":
            assert new == old
    assert w.plant.tilt_dynamics.omega_n_rad_s == pytest.approx(0.5 * base.plant.tilt_dynamics.omega_n_rad_s)
    assert w.plant.speed_dynamics.omega_n_rad_s == pytest.approx(0.5 * base.plant.speed_dynamics.omega_n_rad_s)
    # `vehicle.` is the truth and the model alike
    both = load_world("paper", {"vehicle.uav.mass_kg": 6.0})
    assert both.vehicle.uav_mass_kg == both.fc_vehicle.uav_mass_kg == 6.0


@pytest.mark.parametrize("name", ["plant.joint_servo.nope", "scenario.events.7.mass_kg", "nothing.x", "plant",
                                  "plant.sensors"])
def test_unknown_or_non_leaf_names_refuse(name: str) -> None:
    with pytest.raises(ValueError, match="world override"):
        load_world("paper", {name: 1.0})


def test_invalid_values_refuse_through_the_documents_own_checks() -> None:
    with pytest.raises(ValueError, match="joint servo limits"):
        load_world("paper", {"plant.joint_servo.v_max_rad_s": -1.0})


def test_parse_and_format_round_trip() -> None:
    items = {"plant.joint_servo.v_max_rad_s": 0.1 + 0.2, "fc_vehicle.uav.mass_kg*": 1.1}
    args = world_args(items)
    assert parse_world_items(args[1::2]) == items  # repr keeps every bit of the float
    with pytest.raises(ValueError):
        parse_world_items(["plant.joint_servo.v_max_rad_s"])
    with pytest.raises(ValueError):
        parse_world_items(["a=b"])


def test_sensor_bias_is_a_constant_offset_on_every_axis() -> None:
    """With no noise the gyro reads the true rate plus the bias, the accelerometer the specific force plus its."""
    w = load_world("hover", {"plant.sensors.gyro_bias_rad_s": 0.03, "plant.sensors.accel_bias_m_s2": -0.2})
    params = w.plant.without_noise()
    plant = Plant(w.vehicle, params, w.scenario, np.random.default_rng(0))
    cmd = plant.trim_command()
    plant.step(ActuatorCommand(cmd.tilt_rad, cmd.speed_rad_s), 0.01)
    sb, tr = plant.sense(), plant.truth()
    np.testing.assert_allclose(sb.gyro_frd, np.asarray(tr.rate_frd_rad_s) + 0.03, atol=1e-12)
    np.testing.assert_allclose(sb.accel_frd, np.asarray(tr.specific_force_frd_m_s2) - 0.2, atol=1e-12)
