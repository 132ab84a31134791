"""GCS arm-joint targets (MAV_CMD_USER_1) and DO_GRIPPER reach the simulated arm through the bridge."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import gcs_client, sitl, wait_for, wait_heartbeat

from navig8_tools.logdata import load_run

M = mavlink2
MAV_CMD_NAVIG8_ARM_JOINTS = 31010
JOINT_TOL_RAD = 0.3  # telemetry carries the encoders (sigma 0.08 rad, params/plant.yaml): ~4 sigma


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


def test_arm_joint_targets_and_gripper_release(tmp_path: Path) -> None:
    with sitl(tmp_path, scenario="hover", speed=2.0) as run:
        gcs = gcs_client(run.gcs_port)
        try:
            wait_heartbeat(gcs, 15.0)
            # The bridge is stepping: the arm channels of ACTUATOR_OUTPUT_STATUS report the held pose (q = 0).
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
            gcs.close()
    tr = load_run(run.log)["/truth"]
    q = tr.field("joint_pos_rad", 3)
    np.testing.assert_allclose(q[-1], np.radians([30, 10, -10]), atol=math.radians(0.5))
    mass = tr.field("object_mass_kg")
    assert mass[0] == 1.0 and mass[-1] == 0.0
    assert np.max(np.abs(q)) < math.radians(31)  # the refused 170 deg target never reached the arm
