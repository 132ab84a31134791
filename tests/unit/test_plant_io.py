"""The plant's seams: commands (bad input), sensors (noise, rates, seeds), scenarios, determinism."""

from __future__ import annotations

import dataclasses
import math
from importlib.resources import files

import numpy as np
import pytest
import yaml

from navig8_fc.core.vehicle import VehicleConfig
from sim_bridge import (
    ActuatorCommand,
    Plant,
    PlantParams,
    Scenario,
    SensorBundle,
    SensorField,
    Truth,
    load_scenario,
)
from sim_bridge.plant import trim_actuators
from sim_bridge.plant_layout import X


@pytest.fixture(scope="module")
def params() -> PlantParams:
    return PlantParams.load()


def _run(cfg, params, seed: int, n: int = 200):
    plant = Plant(cfg, params, load_scenario("paper"), np.random.default_rng(seed))
    cmd = plant.trim_command()
    sensors, truths = [], []
    for _ in range(n):
        plant.step(cmd, 0.01)
        b = plant.sense()
        t = plant.truth()
        sensors.append(np.concatenate([
            b.gyro_frd_rad_s, b.accel_frd_m_s2, b.pos_ned_m, b.vel_ned_m_s, b.quat_wxyz,
            b.duct_tilt_rad, b.prop_speed_rad_s, b.joint_pos_rad, b.joint_rate_rad_s,
        ]))
        truths.append(np.concatenate([
            t.pos_ned_m, t.vel_ned_m_s, t.quat_wxyz, t.rate_frd_rad_s, t.actuator_pos,
            t.joint_pos_rad, t.reaction_force_frd_n, t.reaction_moment_o_frd_nm,
        ]))
    return np.array(sensors), np.array(truths)


def test_same_seed_same_trajectory_bit_for_bit(cfg, params):
    s1, t1 = _run(cfg, params, seed=42)
    s2, t2 = _run(cfg, params, seed=42)
    assert np.array_equal(s1, s2) and np.array_equal(t1, t2)
    s3, t3 = _run(cfg, params, seed=43)
    assert np.array_equal(t1, t3)  # the truth does not depend on the sensor noise
    assert not np.array_equal(s1, s3)


def test_nonfinite_and_out_of_range_commands_are_clamped_and_counted(cfg, params):
    plant = Plant(cfg, params, load_scenario("hover"), np.random.default_rng(0))
    trim = plant.trim_command()
    plant.step(trim, 0.01)
    bad = ActuatorCommand((math.nan, 99.0), (math.inf, -1e9, -5.0), joint_targets_rad=(math.nan, 3.0, 0.1))
    plant.step(bad, 0.05)
    tr = plant.truth()
    # alpha1 NaN -> held; alpha3 99 -> clamped; w1 inf -> held; w2 -1e9 -> clamped; w3 -5 -> clamped;
    # joint 1 NaN -> held (last valid = the initial pose), joint 2 -> clamped to the limit
    assert tr.cmd_nonfinite_count == 3
    assert tr.cmd_clamped_count == 4
    assert tr.actuator_cmd[0] == trim.tilt_rad[0]
    assert tr.actuator_cmd[1] == cfg.tilt_max_rad
    assert tr.actuator_cmd[2] == trim.speed_rad_s[0]
    assert tr.actuator_cmd[3] == cfg.tail_speed_min
    assert tr.actuator_cmd[4] == cfg.duct_speed_min
    assert tr.joint_target_rad[0] == 0.0 and tr.joint_target_rad[1] == cfg.joint_limit_rad
    plant.step(ActuatorCommand((math.nan,) * 2, (math.nan,) * 3), 0.5)
    tr = plant.truth()
    assert tr.cmd_nonfinite_count == 8
    state = (tr.pos_ned_m, tr.vel_ned_m_s, tr.quat_wxyz, tr.rate_frd_rad_s, tr.actuator_pos, tr.joint_pos_rad)
    for v in state:
        assert np.all(np.isfinite(v))
    lo = [cfg.tilt_min_rad] * 2 + [cfg.duct_speed_min, cfg.tail_speed_min, cfg.duct_speed_min]
    hi = [cfg.tilt_max_rad] * 2 + [cfg.duct_speed_max, cfg.tail_speed_max, cfg.duct_speed_max]
    assert np.all(tr.actuator_pos >= lo) and np.all(tr.actuator_pos <= hi)
    assert np.all(np.abs(tr.joint_pos_rad) <= cfg.joint_limit_rad)


def test_step_rejects_partial_physics_steps(cfg, params):
    plant = Plant(cfg, params, load_scenario("hover"), np.random.default_rng(0))
    with pytest.raises(ValueError):
        plant.step(plant.trim_command(), 0.0015)


def test_sensor_noise_matches_paper_sigmas(cfg, params):
    """Hover, trim: the sample standard deviations of (measurement - truth) over 2000 samples are the
    paper's sigmas within 6 % (4 sigma of the estimator at n = 2000 is ~6 %)."""
    plant = Plant(cfg, params, load_scenario("hover"), np.random.default_rng(7))
    cmd = plant.trim_command()
    keys = ("gyro", "accel", "duct", "prop", "jq", "jqd", "pos", "vel")
    err: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    for _ in range(2000):
        plant.step(cmd, 0.01)
        b, t = plant.sense(), plant.truth()
        assert b.updated == SensorField.ALL and b.time_us == t.time_us
        err["gyro"].append(b.gyro_frd_rad_s - t.rate_frd_rad_s)
        err["accel"].append(b.accel_frd_m_s2 - t.specific_force_frd_m_s2)
        err["duct"].append(b.duct_tilt_rad - t.actuator_pos[:2])
        err["prop"].append(b.prop_speed_rad_s - t.actuator_pos[2:])
        err["jq"].append(b.joint_pos_rad - t.joint_pos_rad)
        err["jqd"].append(b.joint_rate_rad_s - t.joint_rate_rad_s)
        err["pos"].append(b.pos_ned_m - t.pos_ned_m)
        err["vel"].append(b.vel_ned_m_s - t.vel_ned_m_s)
    s = params.sensors
    expected = {
        "gyro": s.gyro_sigma_rad_s, "accel": s.accel_sigma_m_s2, "duct": s.duct_tilt_sigma_rad,
        "prop": s.prop_speed_sigma_rad_s, "jq": s.joint_pos_sigma_rad, "jqd": s.joint_rate_sigma_rad_s,
        "pos": s.mocap_pos_sigma_m, "vel": s.mocap_vel_sigma_m_s,
    }
    for key, sigma in expected.items():
        e = np.array(err[key])
        np.testing.assert_allclose(e.std(axis=0), sigma, rtol=0.06, err_msg=key)
        np.testing.assert_allclose(e.mean(axis=0), 0.0, atol=4 * sigma / math.sqrt(len(e)), err_msg=key)


def test_sensor_rates_and_sample_and_hold(cfg, params):
    """IMU at 200 Hz, mocap at 50 Hz, sensed every 5 ms: the IMU is fresh every call, the mocap every
    4th; a stale group repeats its previous sample exactly."""
    pp = dataclasses.replace(params, sensors=dataclasses.replace(params.sensors, imu_rate_hz=200.0,
                                                                 mocap_rate_hz=50.0))
    plant = Plant(cfg, pp, load_scenario("hover"), np.random.default_rng(0))
    cmd = plant.trim_command()
    prev = plant.sense()
    assert prev.updated == SensorField.ALL
    for k in range(1, 13):
        plant.step(cmd, 0.005)
        b = plant.sense()
        assert b.is_updated(SensorField.IMU)
        assert b.is_updated(SensorField.MOCAP) == (k % 4 == 0)
        if not b.is_updated(SensorField.MOCAP):
            assert np.array_equal(b.pos_ned_m, prev.pos_ned_m) and np.array_equal(b.quat_wxyz, prev.quat_wxyz)
        assert not b.gyro_frd_rad_s.flags.writeable
        prev = b


def test_scenarios_load_and_paper_events(cfg, params):
    for name in ("paper", "hover", "ground"):
        assert load_scenario(name).name == name
    scn = load_scenario("paper")
    assert scn.duration_s == 30.0
    assert scn.object_mass(5.999) == 1.0 and scn.object_mass(6.0) == 2.0
    a = math.radians(20.0)
    np.testing.assert_allclose(scn.arm_targets(0.0), 0.0)
    np.testing.assert_allclose(scn.arm_targets(1.0), a / 2)  # the "gradual" ramp to Pose 1
    np.testing.assert_allclose(scn.arm_targets(2.4), a)
    for t, sign in ((2.5, -1), (4.99, -1), (5.0, 1), (7.5, -1), (29.9, -1), (30.0, 1)):
        np.testing.assert_allclose(scn.arm_targets(t), sign * a, err_msg=str(t))
    # the plant applies the mass change at t = 6 s and follows the same schedule
    plant = Plant(cfg, params, scn, np.random.default_rng(0), base_mode="fixed")
    cmd = plant.trim_command()
    plant.step(cmd, 6.0)
    assert plant.truth().object_mass_kg == 2.0 and plant.truth().gripper_closed
    plant.step(cmd, 0.0)
    np.testing.assert_allclose(plant.truth().joint_target_rad, scn.arm_targets(6.0 - 1e-3))


def test_paper_setpoints_match_the_enu_text():
    """The NED setpoints of paper.yaml are Eq. 25 mapped E -> y, N -> x, U -> -z, yaw_NED = 90 - yaw_ENU."""
    raw = yaml.safe_load((files("navig8_params.scenarios") / "paper.yaml").read_text())
    enu = raw["enu_commands"]
    scn = load_scenario("paper")
    e, n, u = enu["initial"]["pos_enu_m"]
    pitch, yaw = enu["initial"]["pitch_deg"], enu["initial"]["yaw_deg"]
    for t in (0.0, 4.9, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0):
        for st in enu["steps"]:
            if st["t_s"] <= t:
                e, n, u = st.get("e_m", e), st.get("n_m", n), st.get("u_m", u)
                pitch, yaw = st.get("pitch_deg", pitch), st.get("yaw_deg", yaw)
        sp = scn.script.setpoint_at(t)
        np.testing.assert_allclose(sp.pos_ned_m, (n, e, -u), err_msg=str(t))
        assert sp.pitch_rad == pytest.approx(math.radians(pitch))
        assert sp.yaw_rad == pytest.approx(math.radians(90.0 - yaw))
    tr = Plant(VehicleConfig.load(), PlantParams.load(), scn, np.random.default_rng(0)).truth()
    np.testing.assert_allclose(tr.euler_rad, [0.0, 0.0, math.radians(90.0)], atol=1e-12)  # facing east


def test_hover_scenarios_start_at_trim(cfg, params):
    for name in ("paper", "hover"):
        plant = Plant(cfg, params, load_scenario(name), np.random.default_rng(0))
        tr = plant.truth()
        np.testing.assert_allclose(tr.actuator_pos, trim_actuators(cfg, tr.joint_pos_rad, tr.object_mass_kg))
        # F_y of the dihedral is not nulled by vehicle.hover_trim (G_C has no F_y row): ~5e-5 m/s^2
        assert np.all(np.abs(tr.accel_frd_m_s2) < [1e-9, 1e-4, 1e-9])
        np.testing.assert_allclose(tr.ang_accel_frd_rad_s2, 0.0, atol=1e-9)


def test_messages_are_complete_and_frozen(cfg, params):
    """sense() and truth() build immutable messages: every field set, none writable, no field missing or extra."""
    plant = Plant(cfg, params, load_scenario("paper"), np.random.default_rng(0))
    for msg, cls in ((plant.sense(), SensorBundle), (plant.truth(), Truth)):
        assert type(msg) is cls and set(msg._asdict()) == set(cls._fields) and all(v is not None for v in msg)
        with pytest.raises(AttributeError):
            msg.time_us = 5  # type: ignore[misc]
        with pytest.raises(TypeError):
            cls(**{**msg._asdict(), "extra": 1})
        with pytest.raises(TypeError):
            cls(**{k: v for k, v in msg._asdict().items() if k != "time_us"})
        for v in msg._asdict().values():
            if isinstance(v, np.ndarray):
                assert not v.flags.writeable


def test_state_vector_and_truth_at_a_state(cfg, params):
    """state_vector is a read-only copy of the state; truth_at(state) is truth() at that state and moves nothing."""
    plant = Plant(cfg, params, load_scenario("paper"), np.random.default_rng(0))
    plant.step(plant.trim_command(), 0.05)
    x = plant.state_vector
    assert not x.flags.writeable and x.shape == (int(X.SIZE),)
    np.testing.assert_array_equal(x[X.Q.sl], plant.truth().joint_pos_rad)
    now, at = plant.truth(), plant.truth_at(x)
    for name, v in now._asdict().items():
        np.testing.assert_array_equal(getattr(at, name), v, err_msg=name)
    moved = x.copy()
    moved[X.MOBJ] = 2.0
    assert plant.truth_at(moved).mass_kg == pytest.approx(now.mass_kg - now.object_mass_kg + 2.0, rel=1e-12)
    np.testing.assert_array_equal(plant.state_vector, x)  # the plant did not change
    with pytest.raises(ValueError):
        plant.truth_at(x[:-1])


def test_grasp_and_release_events(cfg, params):
    """release at 0.5 s, grasp of 1.5 kg at 1.0 s (off the physics grid: applied at the next step)."""
    scn = Scenario.from_dict({
        "name": "events",
        "duration_s": 2.0,
        "initial": {"pos_ned_m": [0.0, 0.0, -5.0]},
        "object": {"gripper_closed": True, "mass_kg": 1.0},
        "events": [{"t_s": 0.5, "kind": "release"}, {"t_s": 1.0004, "kind": "grasp", "mass_kg": 1.5}],
    })
    plant = Plant(cfg, params, scn, np.random.default_rng(0), base_mode="fixed")
    cmd = plant.trim_command()
    seen = []
    for _ in range(1200):
        plant.step(cmd, 0.001)
        tr, b = plant.truth(), plant.sense()
        assert b.gripper_closed == tr.gripper_closed
        seen.append((tr.time_us, tr.object_mass_kg, tr.gripper_closed, tr.mass_kg))
    by_t = {t: (m, g, mt) for t, m, g, mt in seen}
    assert by_t[499_000][:2] == (1.0, True) and by_t[500_000][:2] == (0.0, False)
    assert by_t[1_000_000][:2] == (0.0, False) and by_t[1_001_000][:2] == (1.5, True)
    assert by_t[1_001_000][2] == pytest.approx(cfg.uam_mass_kg + 1.5)
    assert scn.object_mass(0.7) == 0.0 and scn.object_mass(1.1) == 1.5 and not scn.gripper_closed_at(0.7)
