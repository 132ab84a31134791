"""Grasp and release where the envelope campaign puts them: a grasp with the arm stretched out (80/10/10 deg,
reached by a ramped arm step) and a release with the body pitched. The plant's mass properties and reaction follow
the vehicle model at that pose, and the state stays continuous through the event."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.core.vehicle import VehicleConfig, mass_properties
from sim_bridge import Plant, PlantParams
from sim_bridge.scenario import Scenario

STRETCHED_DEG = (80.0, 10.0, 10.0)


def _scenario(**kw) -> Scenario:
    d = {"name": "grasp_pose", "duration_s": 5.0, "initial": {"pos_ned_m": [0.0, 0.0, -5.0]}} | kw
    return Scenario.from_dict(d)


def test_a_grasp_with_the_arm_stretched_adds_the_object_at_the_tip_of_that_pose() -> None:
    cfg, params = VehicleConfig.load(), PlantParams.load()
    scn = _scenario(object={"gripper_closed": False, "mass_kg": 0.0},
                    arm={"kind": "steps", "steps": [{"t_s": 0.2, "q_deg": list(STRETCHED_DEG), "ramp_s": 1.0}]},
                    events=[{"t_s": 2.0, "kind": "grasp", "mass_kg": 2.5}])
    plant = Plant(cfg, params, scn, np.random.default_rng(0), base_mode="fixed")  # a test stand: a_O = w' = 0
    cmd = plant.trim_command()
    for _ in range(1999):
        plant.step(cmd, 0.001)
    before = plant.truth()
    plant.step(cmd, 0.001)
    after = plant.truth()
    q = np.radians(STRETCHED_DEG)
    np.testing.assert_allclose(before.joint_pos_rad, q, atol=1e-9)  # arrived and at rest before the grasp
    np.testing.assert_allclose(before.joint_rate_rad_s, 0.0, atol=1e-9)
    assert not before.gripper_closed and after.gripper_closed and after.object_mass_kg == 2.5
    for tr, m in ((before, 0.0), (after, 2.5)):
        mp = mass_properties(cfg, tr.joint_pos_rad, m)
        assert tr.mass_kg == pytest.approx(mp.mass_kg, rel=1e-12)
        np.testing.assert_allclose(tr.com_frd_m, mp.com_frd_m, atol=1e-12)
        np.testing.assert_allclose(tr.inertia_com_kgm2, mp.inertia_com, atol=1e-12)
    # at rest on the stand the arm's reaction is its weight: the object adds m g down at the tip, whose lever
    # about the mount is where the object's mass moved the composite CoM
    r_obj = (after.mass_kg * after.com_frd_m - before.mass_kg * before.com_frd_m) / 2.5
    mount = np.asarray(cfg.mount_frd_m)
    lever = r_obj - mount
    g = cfg.gravity_m_s2
    d_force = after.reaction_force_frd_n - before.reaction_force_frd_n
    np.testing.assert_allclose(d_force, [0.0, 0.0, 2.5 * g], atol=1e-6)
    d_moment = after.reaction_moment_mount_frd_nm - before.reaction_moment_mount_frd_nm
    np.testing.assert_allclose(d_moment, np.cross(lever, [0.0, 0.0, 2.5 * g]), atol=1e-6)
    assert abs(d_moment[1]) > 2.5 * g * 0.5  # the stretched arm's tip is more than 0.5 m out: a large moment


def test_a_release_while_pitched_drops_the_mass_and_keeps_the_state_continuous() -> None:
    cfg, params = VehicleConfig.load(), PlantParams.load()
    pitch = math.radians(35.0)
    scn = _scenario(initial={"pos_ned_m": [0.0, 0.0, -5.0], "euler_deg": [0.0, 35.0, 0.0],
                             "joint_pos_deg": list(STRETCHED_DEG), "actuators": "trim"},
                    object={"gripper_closed": True, "mass_kg": 2.0}, arm={"kind": "hold"},
                    events=[{"t_s": 0.3, "kind": "release"}])
    plant = Plant(cfg, params.without_noise(), scn, np.random.default_rng(0))  # a free base
    cmd = plant.trim_command()
    trs = []
    for _ in range(500):
        plant.step(cmd, 0.001)
        trs.append(plant.truth())
    i = next(k for k, tr in enumerate(trs) if not tr.gripper_closed)
    before, after = trs[i - 1], trs[i]
    assert after.time_us == 300_000 and after.object_mass_kg == 0.0 and before.object_mass_kg == 2.0
    assert before.euler_rad[1] == pytest.approx(pitch, abs=0.05)  # still pitched when it lets go
    assert after.mass_kg == pytest.approx(mass_properties(cfg, after.joint_pos_rad, 0.0).mass_kg, rel=1e-12)
    # one physics step apart: position, velocity, attitude and rates move by what one step can move them
    assert np.linalg.norm(after.vel_ned_m_s - before.vel_ned_m_s) < 0.05
    assert np.linalg.norm(after.rate_frd_rad_s - before.rate_frd_rad_s) < 0.05
    assert abs(after.euler_rad[1] - before.euler_rad[1]) < 1e-3
    for tr in trs:
        assert all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in tr if not isinstance(v, bool))
