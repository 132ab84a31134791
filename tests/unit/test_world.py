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
    np.testing.assert_allclose(sb.gyro_frd_rad_s, np.asarray(tr.rate_frd_rad_s) + 0.03, atol=1e-12)
    np.testing.assert_allclose(sb.accel_frd_m_s2, np.asarray(tr.specific_force_frd_m_s2) - 0.2, atol=1e-12)


@pytest.mark.parametrize("thrust_n", [60.0, 137.5, 200.0])
def test_tail_max_thrust_sets_the_tail_of_the_truth_and_the_model(thrust_n: float) -> None:
    base = load_world("paper")
    w = load_world("paper", {"tail_max_thrust_n": thrust_n})
    w_max = max(abs(base.vehicle.tail_speed_min), abs(base.vehicle.tail_speed_max))
    for cfg in (w.vehicle, w.fc_vehicle):  # a vehicle name: the truth and the controller's model alike
        assert cfg.k_thrust_tail * w_max**2 == pytest.approx(thrust_n, rel=1e-12)
        # the drag torque per newton of the file's tail (0.02 m today) is kept
        assert cfg.k_torque_tail / cfg.k_thrust_tail == pytest.approx(
            base.vehicle.k_torque_tail / base.vehicle.k_thrust_tail, rel=1e-12)
        assert dataclasses.replace(cfg, k_thrust_tail=base.vehicle.k_thrust_tail,
                                   k_torque_tail=base.vehicle.k_torque_tail) == base.vehicle
    # a model error applied after it still reaches the model alone; `*` scales the tail's current thrust
    e = load_world("paper", {"fc_vehicle.uav.mass_kg*": 1.1, "tail_max_thrust_n": thrust_n})
    assert e.vehicle.k_thrust_tail == e.fc_vehicle.k_thrust_tail == w.vehicle.k_thrust_tail
    half = load_world("paper", {"tail_max_thrust_n": thrust_n, "tail_max_thrust_n*": 0.5})
    assert half.vehicle.k_thrust_tail * w_max**2 == pytest.approx(0.5 * thrust_n, rel=1e-12)


def test_tail_max_thrust_of_200_n_is_the_tail_of_the_paper_vehicle_today() -> None:
    base = load_world("paper")
    w_max = max(abs(base.vehicle.tail_speed_min), abs(base.vehicle.tail_speed_max))
    assert w_max == 1000.0
    w = load_world("paper", {"tail_max_thrust_n": 200.0})
    assert w.vehicle.k_thrust_tail == pytest.approx(2.0e-4, rel=1e-12)
    assert w.vehicle.k_torque_tail == pytest.approx(0.02 * 2.0e-4, rel=1e-12)
    with pytest.raises(ValueError, match="tail_max_thrust_n"):
        load_world("paper", {"tail_max_thrust_n": 0.0})


@pytest.mark.parametrize("scale", [0.075, 0.5, 1.0, 1.3])
def test_arm_servo_speed_scale_slows_the_servo_in_time(scale: float) -> None:
    base = load_world("paper")
    w = load_world("paper", {"arm_servo_speed_scale": scale})
    assert w.plant.joint_v_max_rad_s == pytest.approx(scale * base.plant.joint_v_max_rad_s, rel=1e-12)
    assert w.plant.joint_a_max_rad_s2 == pytest.approx(scale**2 * base.plant.joint_a_max_rad_s2, rel=1e-12)
    assert dataclasses.replace(w.plant, joint_v_max_rad_s=base.plant.joint_v_max_rad_s,
                               joint_a_max_rad_s2=base.plant.joint_a_max_rad_s2) == base.plant
    assert w.vehicle == base.vehicle == w.fc_vehicle
    with pytest.raises(ValueError, match="arm_servo_speed_scale"):
        load_world("paper", {"arm_servo_speed_scale": -1.0})


def _servo_step_response(v_max: float, a_max: float, q_to: float, h_s: float, n: int) -> np.ndarray:
    """The plant's joint servo law (sim_bridge.joint_servo.servo_accel) after a step command, every h_s."""
    from sim_bridge.joint_servo import servo_accel

    q, qd, out = 0.0, 0.0, np.empty(n)
    for k in range(n):
        out[k] = q
        a = servo_accel(q_to - q, qd, h_s, a_max, v_max)
        q, qd = q + qd * h_s + 0.5 * a * h_s * h_s, qd + a * h_s
    return out


def test_a_slowed_servo_flies_the_same_move_stretched_in_time() -> None:
    """v by s and a by s^2: the servo's step response at scale s is the nominal one at time s t."""
    base = load_world("paper").plant
    s = 0.25
    slow = load_world("paper", {"arm_servo_speed_scale": s}).plant
    h = 1e-3
    fast = _servo_step_response(base.joint_v_max_rad_s, base.joint_a_max_rad_s2, 1.2, h, 600)
    stretched = _servo_step_response(slow.joint_v_max_rad_s, slow.joint_a_max_rad_s2, 1.2, h, 2400)
    assert fast[-1] == pytest.approx(1.2, abs=1e-9) and stretched[-1] == pytest.approx(1.2, abs=1e-9)
    k = np.arange(0, 600, 5)
    np.testing.assert_allclose(stretched[(k / s).astype(int)], fast[k], atol=5e-3)


def test_the_bridge_writes_the_vehicle_the_fc_flies_in_a_world(tmp_path) -> None:
    """navig8-sitl --world: the bridge writes the world's vehicle (truth and model alike, plus the controller's own
    errors) for navig8-fc --vehicle; the FC loads it as its constants."""
    import subprocess
    import sys

    from navig8_fc.core.vehicle import VehicleConfig

    out = tmp_path / "v.yaml"
    p = subprocess.run([sys.executable, "-m", "sim_bridge.bridge", "--scenario", "paper", "--world",
                        "tail_max_thrust_n=200", "--world", "fc_vehicle.uav.mass_kg=4.0", "--write-fc-vehicle",
                        str(out)], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    cfg = VehicleConfig.load(out)
    assert cfg.k_thrust_tail * cfg.tail_speed_max**2 == pytest.approx(200.0)
    assert cfg.uav_mass_kg == pytest.approx(4.0)
    bad = subprocess.run([sys.executable, "-m", "sim_bridge.bridge", "--world", "vehicle.nope=1",
                          "--write-fc-vehicle", str(tmp_path / "x.yaml")], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "nope" in bad.stderr and not (tmp_path / "x.yaml").exists()
