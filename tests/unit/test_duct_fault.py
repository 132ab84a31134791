"""The duct fault (params/plant.yaml `actuators.duct_efficiency`, `duct_fault_t_s`) against closed forms.

A duct at efficiency e gives e K_T w^2 of thrust and e K_Q w^2 of drag torque. Hover trim: the fault scales the
duct's columns of G_C, so the trim's U components of that duct are the nominal ones over e and everything else is
unchanged: the faulty duct's speed is the nominal speed / sqrt(e) (x sqrt(2) at e = 0.5), at the same tilt. The
lost wrench at a given command is (1 - e) times the duct's own thrust and drag, written here from the vehicle's
constants and geometry (not from vehicle.propulsion_per_input, which the plant uses).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from navig8_fc.core.vehicle import VehicleConfig
from sim_bridge import Plant, load_scenario
from sim_bridge.params import PlantParams
from sim_bridge.world import load_world


def _faulty(params: PlantParams, efficiency: tuple[float, float], t_s: float = 0.0) -> PlantParams:
    return dataclasses.replace(params, duct_efficiency=efficiency, duct_fault_t_s=t_s)


def _duct_wrench(cfg: VehicleConfig, duct: int, alpha_rad: float, w_rad_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Force (FRD) and moment about O of one duct at full efficiency: thrust K_T w^2 along
    d = [sin a, -/+ sin g cos a, -cos g cos a] (duct 1 right: -, duct 3 left: +) at r (duct 3: y mirrored), drag
    torque -/+ s1 K_Q w^2 d (duct 1 against its spin, duct 3 the opposite)."""
    sg, cg = math.sin(cfg.dihedral_rad), math.cos(cfg.dihedral_rad)
    side = -1.0 if duct == 1 else 1.0
    d = np.array([math.sin(alpha_rad), side * sg * math.cos(alpha_rad), -cg * math.cos(alpha_rad)])
    r = np.array(cfg.duct_right_frd_m) * np.array([1.0, -side, 1.0])
    w2 = w_rad_s * abs(w_rad_s)
    force = cfg.k_thrust_duct * w2 * d
    drag = side * cfg.spin_duct1 * cfg.k_torque_duct * w2 * d
    return force, np.cross(r, force) + drag


@pytest.mark.parametrize("efficiency", [(0.5, 1.0), (1.0, 0.5), (0.7, 1.0)])
def test_trim_with_a_weak_duct_is_its_nominal_speed_over_sqrt_e_and_holds(cfg, params, efficiency):
    """Hover trim with one duct at e: that duct's speed x 1/sqrt(e) (sqrt(2) at 0.5), its tilt and the other
    actuators the nominal trim's (to 1e-9); flown open loop for 3 s, the faulty trim holds the hover (position
    < 1 mm, attitude < 1e-9 rad, as the nominal trim does in test_plant_physics.test_hover_trim_holds)."""
    scn = load_scenario("hover")
    nominal = Plant(cfg, params, scn, np.random.default_rng(0)).truth().actuator_pos
    plant = Plant(cfg, _faulty(params, efficiency), scn, np.random.default_rng(0))
    tr0 = plant.truth()
    i = 2 if efficiency[0] != 1.0 else 4  # (alpha1, alpha3, w1, w2, w3): the faulty duct's speed
    e = min(efficiency)
    expected = np.array(nominal, dtype=float)
    expected[i] = nominal[i] / math.sqrt(e)
    np.testing.assert_allclose(tr0.actuator_pos, expected, rtol=0.0, atol=1e-9)
    if e == 0.5:
        assert tr0.actuator_pos[i] == pytest.approx(math.sqrt(2.0) * nominal[i], abs=1e-9)
    cmd = plant.trim_command()
    np.testing.assert_allclose([*cmd.tilt_rad, *cmd.speed_rad_s], expected, atol=1e-9)
    for _ in range(300):
        plant.step(cmd, 0.01)
    tr = plant.truth()
    assert np.linalg.norm(tr.pos_ned_m - tr0.pos_ned_m) < 1e-3
    np.testing.assert_allclose(tr.euler_rad, tr0.euler_rad, atol=1e-9)


@pytest.mark.parametrize("duct, efficiency", [(1, (0.6, 1.0)), (3, (1.0, 0.5))])
def test_fault_onset_takes_away_1_minus_e_of_the_ducts_thrust_and_drag(cfg, params, duct, efficiency):
    """Onset at 1.0 s with the nominal trim held: until then the propulsive wrench is the nominal one; from the
    first physics step at 1.0 s it lacks exactly (1 - e) of the duct's thrust and drag torque (closed form above),
    to 1e-9 N / N m; the initial trim is the nominal one (the fault is not there yet)."""
    scn = load_scenario("hover")
    plant = Plant(cfg, _faulty(params, efficiency, t_s=1.0), scn, np.random.default_rng(0))
    nominal = Plant(cfg, params, scn, np.random.default_rng(0))
    np.testing.assert_allclose(plant.truth().actuator_pos, nominal.truth().actuator_pos, atol=1e-12)
    cmd = plant.trim_command()
    for _ in range(99):
        plant.step(cmd, 0.01)
    before = plant.truth()
    np.testing.assert_allclose(before.prop_force_frd_n, nominal.truth().prop_force_frd_n, atol=1e-9)
    plant.step(cmd, 0.01)
    after = plant.truth()
    a1, a3, w1, _, w3 = after.actuator_pos
    alpha, w = (a1, w1) if duct == 1 else (a3, w3)
    f_duct, m_duct = _duct_wrench(cfg, duct, alpha, w)
    e = min(efficiency)
    full_f, full_m = np.zeros(3), np.zeros(3)
    for k, (al, ww) in ((1, (a1, w1)), (3, (a3, w3))):
        f, m = _duct_wrench(cfg, k, al, ww)
        full_f, full_m = full_f + f, full_m + m
    w2 = after.actuator_pos[3]
    tail_f = np.array([0.0, 0.0, -cfg.k_thrust_tail * w2 * abs(w2)])
    tail_m = np.cross(np.array(cfg.tail_frd_m), tail_f) + np.array(
        [0.0, 0.0, cfg.spin_tail * cfg.k_torque_tail * w2 * abs(w2)])
    np.testing.assert_allclose(after.prop_force_frd_n, full_f + tail_f - (1.0 - e) * f_duct, atol=1e-9)
    np.testing.assert_allclose(after.prop_moment_frd_nm, full_m + tail_m - (1.0 - e) * m_duct, atol=1e-9)
    # and the loss is what it should be: a roll moment towards the weak side (duct 1 is on the right, +y)
    assert np.linalg.norm(after.prop_force_frd_n - before.prop_force_frd_n) > 1.0
    roll = after.prop_moment_frd_nm[0] - before.prop_moment_frd_nm[0]
    assert roll > 0.0 if duct == 1 else roll < 0.0


def test_the_fault_is_a_world_override_and_validated():
    """`plant.actuators.duct_efficiency.1=0.5` reaches the plant's parameters; an efficiency outside (0, 1] or a
    negative onset is refused."""
    w = load_world("hover", {"plant.actuators.duct_efficiency.1": 0.5, "plant.actuators.duct_fault_t_s": 2.5})
    assert w.plant.duct_efficiency == (1.0, 0.5) and w.plant.duct_fault_t_s == 2.5 and w.plant.duct_faulted
    assert not PlantParams.load().duct_faulted
    for bad in ({"plant.actuators.duct_efficiency.0": 0.0}, {"plant.actuators.duct_efficiency.0": 1.2},
                {"plant.actuators.duct_fault_t_s": -1.0}):
        with pytest.raises(ValueError, match="duct fault"):
            load_world("hover", bad)
