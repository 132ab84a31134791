"""GCS arm-joint targets (MAV_CMD_USER_1) and DO_GRIPPER reach the simulated arm through the bridge.

The commands and the joints (ACTUATOR_OUTPUT_STATUS) cross the GCS link: that part runs against any FC by
connection string (`make test-hil`, docs/hil.md); an FC on the ground takes off to 2 m first and lands after.
The local pair starts in the hover scenario (in the air, the paper's 1 kg object held): its log then shows the
joints at the target, the object released and the refused target never reaching the arm (local only)."""

from __future__ import annotations

import math
import time

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import FcTarget, wait_for

from navig8_fc.modes import px4_custom_mode
from navig8_fc.modes.px4 import Px4AutoSubMode, Px4MainMode
from navig8_tools.logdata import load_run

M = mavlink2
MAV_CMD_NAVIG8_ARM_JOINTS = 31010
JOINT_TOL_RAD = 0.3  # telemetry carries the encoders (sigma 0.08 rad, params/plant.yaml): ~4 sigma
FC_LOCAL = {"scenario": "hover", "speed": 2.0}  # the local pair (conftest.py `fc`): armed at 2 m, q = 0


def _command(gcs, command: int, *params: float):
    p = list(params) + [0.0] * (7 - len(params))
    gcs.mav.command_long_send(gcs.target_system, 1, command, 0, *p)
    ack = wait_for(gcs, "COMMAND_ACK", 5.0, lambda m: m.command == command)
    assert ack is not None
    return ack


def _joints(gcs, cond, timeout_s: float):
    """The arm joints (rad) from ACTUATOR_OUTPUT_STATUS channels 5-7, once they satisfy cond (else None)."""
    m = wait_for(gcs, "ACTUATOR_OUTPUT_STATUS", timeout_s, lambda m: cond(np.array(m.actuator[5:8])))
    return None if m is None else np.array(m.actuator[5:8])


def _fc_hb(pred):  # noqa: ANN001, ANN202
    return lambda m: m.get_srcComponent() == 1 and pred(m)


def _take_off(gcs) -> None:
    """Arm and take off to 2 m (an FC that starts on the ground); returns once it holds there."""
    deadline = time.monotonic() + 30.0
    while _command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result != M.MAV_RESULT_ACCEPTED:
        assert time.monotonic() < deadline, "arming never accepted"
        wait_for(gcs, "HEARTBEAT", 0.5)
    assert _command(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 2.0).result in (
        M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_IN_PROGRESS)
    hold = px4_custom_mode(Px4MainMode.AUTO, Px4AutoSubMode.LOITER)
    assert wait_for(gcs, "HEARTBEAT", 40.0, _fc_hb(lambda m: m.custom_mode == hold)) is not None


def test_arm_joint_targets_and_gripper_release(fc: FcTarget) -> None:
    fc.require_flight()
    with fc.session() as gcs:
        hb = wait_for(gcs, "HEARTBEAT", 5.0, _fc_hb(lambda m: True))
        took_off = not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
        if took_off:
            _take_off(gcs)
        # The bridge is stepping: ACTUATOR_OUTPUT_STATUS reports the arm joints (the local hover scenario: q = 0).
        found = [_joints(gcs, lambda q: True, 15.0) for _ in range(5)]
        assert all(q is not None for q in found), "no ACTUATOR_OUTPUT_STATUS"
        q0 = np.mean(found, axis=0)  # the pose as found, restored before landing
        try:
            if fc.local is not None:
                assert _joints(gcs, lambda q: np.allclose(q, 0.0, atol=JOINT_TOL_RAD), 15.0) is not None
            # out of the joint range: refused with a reason, nothing changes
            ack = _command(gcs, MAV_CMD_NAVIG8_ARM_JOINTS, 170, 0, 0, 1)
            assert ack.result == M.MAV_RESULT_DENIED
            # a long-running command: IN_PROGRESS now, its final ACK when the joints are there
            assert _command(gcs, MAV_CMD_NAVIG8_ARM_JOINTS, 30, 10, -10, 1).result == M.MAV_RESULT_IN_PROGRESS
            target = np.radians([30, 10, -10])
            assert _joints(gcs, lambda q: np.allclose(q, target, atol=JOINT_TOL_RAD), 10.0) is not None, \
                "the arm never reached the accepted joint targets"
            assert _command(gcs, M.MAV_CMD_DO_GRIPPER, 1, 0).result == M.MAV_RESULT_ACCEPTED  # p2 0 = release
            # The release reaches the bridge with the next step: let a few telemetry periods of flight follow it.
            for _ in range(3):
                assert wait_for(gcs, "ACTUATOR_OUTPUT_STATUS", 5.0) is not None
        finally:
            if took_off:  # leave it as found: the arm back where it was, landed, disarmed
                _command(gcs, MAV_CMD_NAVIG8_ARM_JOINTS, *np.round(np.degrees(q0)), 1)
                _joints(gcs, lambda q: np.allclose(q, q0, atol=JOINT_TOL_RAD), 10.0)
                _command(gcs, M.MAV_CMD_NAV_LAND)
                assert wait_for(gcs, "HEARTBEAT", 60.0, _fc_hb(lambda m: not m.base_mode
                                                               & M.MAV_MODE_FLAG_SAFETY_ARMED)) is not None


def test_local_log_shows_the_arm_and_the_release(fc: FcTarget) -> None:
    run = fc.require_local("the arm's truth is in the local log")
    run.stop()
    tr = load_run(run.log)["/truth"]
    q = tr.field("joint_pos_rad", 3)
    np.testing.assert_allclose(q[-1], np.radians([30, 10, -10]), atol=math.radians(0.5))
    mass = tr.field("object_mass_kg")
    assert mass[0] == 1.0 and mass[-1] == 0.0
    assert np.max(np.abs(q)) < math.radians(31)  # the refused 170 deg target never reached the arm


