"""POSCTL (Position mode): MANUAL_CONTROL sticks fly the position setpoint (pure).

Sticks -> velocities in the heading frame, integrated into the position setpoint (PX4's Position mode: centred
sticks hold), the setpoint kept within manual_lead_m of the vehicle. Full stick is manual_speed_m_s
horizontally, manual_climb_m_s vertically, manual_yaw_rate_rad_s in yaw, with a deadband of manual_deadband.
"""

from __future__ import annotations

import math

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.modes.context import ModeContext, Step, below_ceiling, climb_rate_down, integrate_led, wrap_pi
from navig8_fc.modes.records import ModeInputs

CENTRED = (0.0, 0.0, 0.5, 0.0)  # x forward, y right, z throttle 0..1, r yaw


class Position:
    def __init__(self, ctx: ModeContext) -> None:
        self._ctx = ctx
        self.setpoint: Setpoint | None = None
        self.sticks: tuple[float, float, float, float] = CENTRED

    def set_sticks(self, x: float, y: float, z: float, r: float) -> None:
        """Normalised sticks: x forward, y right, r yaw right in [-1, 1], z throttle in [0, 1] (0.5 = hold
        altitude); a non-finite value counts as centred."""
        def clip(v: float, lo: float) -> float:
            return 0.0 if not math.isfinite(v) else min(1.0, max(lo, v))

        self.sticks = (clip(x, -1.0), clip(y, -1.0), clip(z, 0.0) if math.isfinite(z) else 0.5, clip(r, -1.0))

    def enter(self, inp: ModeInputs) -> None:
        x, y, z = inp.pos_ned_m
        self.setpoint = Setpoint((x, y, z), self._ctx.current_pitch(), inp.yaw_rad)

    def update(self, inp: ModeInputs, dt: float) -> Step:
        assert self.setpoint is not None
        cfg = self._ctx.config
        db = cfg.manual_deadband
        x, y, r = (0.0 if abs(v) < db else v for v in (self.sticks[0], self.sticks[1], self.sticks[3]))
        sp = self.setpoint
        yaw = wrap_pi(sp.yaw_rad + r * cfg.manual_yaw_rate_rad_s * dt)
        c, s_ = math.cos(yaw), math.sin(yaw)
        v = cfg.manual_speed_m_s
        vn, ve, vd = (c * x - s_ * y) * v, (s_ * x + c * y) * v, climb_rate_down(self.sticks[2], cfg)
        moved = integrate_led(sp.pos_ned_m, (vn, ve, vd), inp.pos_ned_m, dt, cfg.manual_lead_m)
        self.setpoint = Setpoint(below_ceiling(moved, self._ctx), sp.pitch_rad, yaw)
        return Step(self.setpoint, True)
