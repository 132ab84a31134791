"""HOLD (AUTO.LOITER, MAVSDK "Hold"): position hold (pure).

Entered in the air, it holds where the vehicle comes to rest (its horizontal stopping point at the position
reference's braking limits, `braking.stopping_point`, as PX4's Loiter `calculate_breaking_stop` and ArduPilot's
`get_stopping_point_xy`); holding the entry point itself would fly past it and back (docs/gcs.md "Hold").
Takeoff, a mission or a plan that ends hands its last setpoint over instead (`hold`). Entered on the ground it
stays idle (PX4 behaves the same: Hold does not take off). DO_REPOSITION moves the held point (`reposition_to`).
"""

from __future__ import annotations

import math

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.modes.braking import stopping_point
from navig8_fc.modes.context import ModeContext, Step, idle
from navig8_fc.modes.records import ModeInputs, Vec3


class Hold:
    def __init__(self, ctx: ModeContext) -> None:
        self._ctx = ctx
        self.setpoint: Setpoint | None = None  # the held point (set on entry)
        self.on_ground = False  # entered on the ground: idle
        self._reposition: tuple[Vec3, float] | None = None  # DO_REPOSITION target for the next entry
        # The position reference's braking limits (set_braking; inf: stops at once).
        self._brake_acc_m_s2 = math.inf
        self._brake_jerk_m_s3 = math.inf
        self._brake_lag_s = 0.0

    def set_braking(self, acc_m_s2: float, jerk_m_s3: float, lag_s: float) -> None:
        if not (acc_m_s2 > 0.0 and jerk_m_s3 > 0.0 and lag_s >= 0.0):
            raise ValueError(f"braking limits must be positive (inf = none), got {acc_m_s2}, {jerk_m_s3}, {lag_s}")
        self._brake_acc_m_s2, self._brake_jerk_m_s3, self._brake_lag_s = acc_m_s2, jerk_m_s3, lag_s

    def enter(self, inp: ModeInputs) -> None:
        x, y, z = inp.pos_ned_m
        self.on_ground = self._ctx.detector.landed
        if not self.on_ground:
            x, y = stopping_point(x, y, inp.vel_ned_m_s, inp.accel_ned_m_s2, self._brake_acc_m_s2,
                                  self._brake_jerk_m_s3, self._brake_lag_s)
        self.setpoint = Setpoint((x, y, z), self._ctx.current_pitch(), inp.yaw_rad)
        if self._reposition is not None:
            self.apply_reposition()

    def hold(self, sp: Setpoint, on_ground: bool) -> None:
        """Hold `sp` without the entry actions (the mode before hands its last setpoint over)."""
        self.on_ground = on_ground
        self.setpoint = sp

    def reposition_to(self, pos_ned_m: Vec3, yaw_rad: float) -> None:
        """DO_REPOSITION: hold at pos_ned_m (NaN components: the held point's), yaw_rad (NaN: keep), applied at the
        next entry or by apply_reposition."""
        self._reposition = (pos_ned_m, yaw_rad)

    def drop_reposition(self) -> None:
        self._reposition = None

    def apply_reposition(self) -> None:
        assert self.setpoint is not None and self._reposition is not None
        (n, e, d), yaw = self._reposition
        self._reposition = None
        x, y, z = self.setpoint.pos_ned_m
        pos = (x if math.isnan(n) else n, y if math.isnan(e) else e, z if math.isnan(d) else d)
        self.setpoint = Setpoint(pos, self.setpoint.pitch_rad, self.setpoint.yaw_rad if math.isnan(yaw) else yaw)
        self.on_ground = False
        self._ctx.events.append(f"Reposition to N {pos[0]:.2f} E {pos[1]:.2f} D {pos[2]:.2f} m")

    def update(self, inp: ModeInputs, dt: float) -> Step:
        assert self.setpoint is not None
        if self.on_ground:
            return Step(idle(inp), False)
        return Step(self.setpoint, True)
