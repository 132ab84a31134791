"""The arm-joint move as a long-running command (MAV_CMD_NAVIG8_ARM_JOINTS: COMMAND_ACK IN_PROGRESS with progress,
then one final ACK): started when the joints are measured, its progress the share of the largest joint error
removed, DONE within ARM_JOINT_REACHED_RAD of the target, FAILED after ARM_JOINT_TIMEOUT_S of sim time, CANCELLED
by COMMAND_CANCEL or a newer target. Pure: the step hands in the measured joints and sim time."""

from __future__ import annotations

import math
from collections.abc import Sequence

from navig8_fc.modes.tasks import TASK_CANCELLED, TASK_DONE, TASK_FAILED, TaskStatus

ARM_JOINT_REACHED_RAD = math.radians(2.0)  # an arm-joint move is complete when every joint is this close ...
ARM_JOINT_TIMEOUT_S = 10.0  # ... and FAILED when it is not within this (sim time; a 120 deg move takes ~3 s)


class ArmJointTask:
    """The last arm-joint move (running or how it ended)."""

    def __init__(self) -> None:
        self.status: TaskStatus | None = None  # None before the first move
        self._move: tuple[tuple[float, ...], tuple[float, ...], float] = ((), (), 0.0)  # start, target, t0

    @property
    def running(self) -> bool:
        return self.status is not None and self.status.running

    def start(self, q_now_rad: Sequence[float], target_rad: tuple[float, ...], t_s: float) -> None:
        """A new target: the running move (if any) ends CANCELLED, replaced."""
        tk = self.status
        n = tk.task_id + 1 if tk is not None else 1
        if tk is not None and tk.running:
            self.status = TaskStatus(n - 1, "arm_joints", TASK_CANCELLED, tk.progress_pct, "replaced by a new target")
        self.status = TaskStatus(n, "arm_joints")
        self._move = (tuple(q_now_rad), target_rad, t_s)

    def cancel(self) -> bool:
        """COMMAND_CANCEL: the running move ends CANCELLED; False when none runs."""
        tk = self.status
        if tk is None or not tk.running:
            return False
        self.status = TaskStatus(tk.task_id, tk.kind, TASK_CANCELLED, tk.progress_pct, "cancelled")
        return True

    def update(self, q_rad: Sequence[float], t_s: float) -> None:
        """Progress of the running move from the measured joints: the share of the largest joint error removed
        (never decreasing); DONE within ARM_JOINT_REACHED_RAD of the target, FAILED after ARM_JOINT_TIMEOUT_S."""
        tk = self.status
        if tk is None or not tk.running:
            return
        q0, target, t0 = self._move
        err = max(abs(q - t) for q, t in zip(q_rad, target, strict=True))
        if err < ARM_JOINT_REACHED_RAD:
            self.status = TaskStatus(tk.task_id, tk.kind, TASK_DONE, 100.0)
        elif t_s - t0 > ARM_JOINT_TIMEOUT_S:
            self.status = TaskStatus(tk.task_id, tk.kind, TASK_FAILED, tk.progress_pct,
                                     f"joints {math.degrees(err):.1f} deg off after {ARM_JOINT_TIMEOUT_S:g} s")
        else:
            err0 = max(abs(q - t) for q, t in zip(q0, target, strict=True))
            pct = 100.0 * max(0.0, 1.0 - err / err0) if err0 > 0.0 else 0.0
            if pct > tk.progress_pct:
                self.status = TaskStatus(tk.task_id, tk.kind, progress_pct=pct)
