"""Ground contact: resting with the motors off stays still; a drop lands without bouncing or exploding."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from sim_bridge import ActuatorCommand, Plant, load_scenario
from sim_bridge.plant import quat_to_dcm


def test_ground_scenario_rests_still(cfg, params):
    """Motors off on the skids: after 0.5 s of settling nothing moves over the next 10 s (position
    1e-9 m, attitude 1e-9 rad, speeds < 1e-9), the springs carry the weight, the accelerometer reads -g."""
    plant = Plant(cfg, params, load_scenario("ground"), np.random.default_rng(0))
    plant.step(ActuatorCommand.off(), 0.5)
    ref = plant.truth()
    assert ref.contact_points_active == 4
    contact_ned = quat_to_dcm(ref.quat_wxyz) @ ref.contact_force_frd_n
    np.testing.assert_allclose(contact_ned, [0.0, 0.0, -ref.mass_kg * cfg.gravity_m_s2], atol=1e-6)
    worst_speed = 0.0
    for _ in range(100):
        plant.step(ActuatorCommand.off(), 0.1)
        tr = plant.truth()
        speed = max(float(np.abs(tr.vel_ned_m_s).max()), float(np.abs(tr.rate_frd_rad_s).max()))
        worst_speed = max(worst_speed, speed)
    np.testing.assert_allclose(tr.pos_ned_m, ref.pos_ned_m, atol=1e-9)
    np.testing.assert_allclose(tr.euler_rad, ref.euler_rad, atol=1e-9)
    assert worst_speed < 1e-9
    np.testing.assert_allclose(tr.specific_force_frd_m_s2, [0.0, 0.0, -cfg.gravity_m_s2], atol=0.02)


@pytest.mark.parametrize("euler_deg", [(0.0, 0.0, 0.0), (8.0, -5.0, 30.0)])
def test_drop_lands_without_bouncing(cfg, params, euler_deg):
    """Dropped with the skids 0.3 m above the ground (2.4 m/s impact), level or tilted: the lowest skid
    never leaves the ground again after touchdown (no bounce), the sag stays < 2 cm, the attitude
    settles level-ish and everything is at rest within 1 s."""
    scn = load_scenario("ground")
    scn = dataclasses.replace(
        scn,
        initial=dataclasses.replace(
            scn.initial,
            on_ground=False,
            pos_ned_m=(0.0, 0.0, -0.45),
            euler_rad=tuple(map(math.radians, euler_deg)),
        ),
    )
    plant = Plant(cfg, params, scn, np.random.default_rng(0))
    pts = np.array(params.ground.contact_points_frd_m)
    lowest = []
    for _ in range(1500):
        plant.step(ActuatorCommand.off(), 0.001)
        tr = plant.truth()
        lowest.append(float(np.max(tr.pos_ned_m[2] + pts @ quat_to_dcm(tr.quat_wxyz)[2])))
    lowest_arr = np.array(lowest)
    touchdown = int(np.argmax(lowest_arr > 0.0))
    assert 0 < touchdown < 400
    assert np.all(lowest_arr[touchdown:] > 0.0)  # never airborne again
    assert lowest_arr.max() < 0.02
    assert abs(tr.euler_rad[0]) < 0.01 and abs(tr.euler_rad[1]) < 0.01
    assert np.abs(tr.vel_ned_m_s).max() < 1e-6 and np.abs(tr.rate_frd_rad_s).max() < 1e-6
