"""The command the plant holds (docs/plant.md): validated once per step call, so nothing invalid ever reaches the
state. A non-finite entry holds the last valid value of its channel, an out-of-range entry is clamped to the
vehicle's limits (actuators) or the joint limit (joint targets); both are counted. No I/O."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from sim_bridge.messages import ActuatorCommand
from sim_bridge.plant_layout import N_C, C

_C_ACT, _C_JOVR, _C_JTGT = C.ACT.sl, int(C.JOVR), int(C.JTGT)


class CommandGuard:
    """The command vector (plant_layout.C) the integrator reads, and the counts of what was held or clamped."""

    def __init__(self, act_lo: Sequence[float], act_hi: Sequence[float], joint_limit_rad: float) -> None:
        self.vector = np.zeros(N_C)
        self._lo, self._hi = [float(v) for v in act_lo], [float(v) for v in act_hi]
        self._qlim = joint_limit_rad
        self._valid_cmd = [0.0] * 5  # last valid value per actuator channel
        self._valid_joint = [0.0, 0.0, 0.0]
        self.nonfinite = 0
        self.clamped = 0

    def hold(self, act: Sequence[float], q_rad: Sequence[float]) -> None:
        """The initial command (as valid): the actuators at `act`, the joints' last valid targets `q_rad`."""
        self.vector[_C_ACT] = act
        self._valid_cmd = [float(v) for v in act]
        self._valid_joint = [float(v) for v in q_rad]

    def apply(self, cmd: ActuatorCommand) -> None:
        tilt, speed = cmd.tilt_rad, cmd.speed_rad_s
        vals = [float(tilt[0]), float(tilt[1]), float(speed[0]), float(speed[1]), float(speed[2])]
        valid = self._valid_cmd
        lo, hi = self._lo, self._hi
        for i in range(5):
            v = vals[i]
            if not math.isfinite(v):
                self.nonfinite += 1
                vals[i] = v = valid[i]
            elif v < lo[i]:
                self.clamped += 1
                vals[i] = v = lo[i]
            elif v > hi[i]:
                self.clamped += 1
                vals[i] = v = hi[i]
            valid[i] = v
        c = self.vector
        c[_C_ACT] = vals
        jt = cmd.joint_targets_rad
        if jt is None:
            c[_C_JOVR] = 0.0
            return
        c[_C_JOVR] = 1.0
        for j in range(3):
            v = float(jt[j])
            if not math.isfinite(v):
                self.nonfinite += 1
                v = self._valid_joint[j]
            elif abs(v) > self._qlim:
                self.clamped += 1
                v = math.copysign(self._qlim, v)
            self._valid_joint[j] = v
            c[_C_JTGT + j] = v
