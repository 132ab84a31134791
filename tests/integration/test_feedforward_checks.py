"""The model-based feed-forwards cannot hurt: each is checked against what is measured and fades to the
measurement-based path when they disagree (docs/model.md, "Feed-forward that cannot hurt").

In-process, seed 1, `stretched_grasp_release` (a 1.5 kg object grasped at the end of the stretched arm, pitch 30 deg,
yaw 60 deg, released while pitched), the default (±60 N tail) vehicle, with servos and actuators that do not match
the FC's models (the FC's ARM_SERVO_* and ACT_WN stay at their defaults):
- an arm servo 7x slower than its data sheet (0.6 rad/s, 6 rad/s^2 against 4 and 42): the defaults and the supervised
  arm preview hold 20 deg; the same preview trusted blindly (no check, no identification) exceeds the bound by more
  than 10 deg (42 deg with the defaults' flown gain, which keeps the vehicle; flying K_hat, INDI_LAM_REF 1, it lost it);
- joint 1 stalls in the middle of the 13 s move: the same three, the blind preview lost;
- the duct and propeller actuators 4x slower than ACT_WN: the defaults (identification + check of the U0 model) keep
  the vehicle; the model U0 without them loses it.
Each comparison shows the test can fail: the check is what separates the two."""

from __future__ import annotations

import pytest

from navig8_tools.sim import run

SCENARIO = "stretched_grasp_release"
ATT_BOUND_DEG = 20.0
SLOW_ARM = {"plant.joint_servo.v_max_rad_s": 0.6, "plant.joint_servo.a_max_rad_s2": 6.0}
STALL = {"plant.joint_servo.stall_joint": 0, "plant.joint_servo.stall_t_s": 13.1}
SLOW_ACTUATORS = {"actuator_bandwidth_scale": 0.25}
PREVIEW = {"INDI_ARM_FF": 2}
BLIND_PREVIEW = {"INDI_ARM_FF": 2, "ARM_CHK_TOL": 10.0, "ARM_SERVO_ID": 0}
CASES = {
    "slow_arm_defaults": ({}, SLOW_ARM), "slow_arm_preview": (PREVIEW, SLOW_ARM),
    "slow_arm_blind": (BLIND_PREVIEW, SLOW_ARM),
    "stall_defaults": ({}, STALL), "stall_preview": (PREVIEW, STALL), "stall_blind": (BLIND_PREVIEW, STALL),
    "slow_actuators_defaults": ({}, SLOW_ACTUATORS), "slow_actuators_unchecked": ({"ACT_ID": 0}, SLOW_ACTUATORS),
}


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, dict]:
    d = tmp_path_factory.mktemp("ffchk")
    return {name: run(SCENARIO, "proposed", seed=1, log_path=d / f"{name}.mcap", overrides=p, world=w).summary
            for name, (p, w) in CASES.items()}


def _ok(s: dict, bound: float) -> None:
    assert s["lost_control"] is False
    assert s["max_att_error_deg"] <= bound, s["max_att_error_deg"]


def test_a_slow_arm_servo_costs_no_control(runs) -> None:
    _ok(runs["slow_arm_defaults"], ATT_BOUND_DEG)
    _ok(runs["slow_arm_preview"], ATT_BOUND_DEG)
    # the preview trusted against the measured joints: 42.4 deg (lost with INDI_LAM_REF 1, the previous defaults)
    blind = runs["slow_arm_blind"]["max_att_error_deg"]
    assert blind > ATT_BOUND_DEG + 10.0, blind


def test_a_stalled_joint_costs_no_control(runs) -> None:
    _ok(runs["stall_defaults"], ATT_BOUND_DEG)
    _ok(runs["stall_preview"], ATT_BOUND_DEG + 5.0)  # the stall's own impulse lands before any check can see it
    assert runs["stall_blind"]["lost_control"] is True


def test_slow_actuators_cost_no_control(runs) -> None:
    _ok(runs["slow_actuators_defaults"], 30.0)
    assert runs["slow_actuators_unchecked"]["lost_control"] is True  # the U0 model trusted against the measurement
