"""OFFBOARD: fly the streamed target (`OffboardTarget`, navig8_fc.modes.records; pure).

The reference starts where the vehicle was being held (the last engaged setpoint) and integrates velocity-only
axes and yaw rate; the flown setpoint adds the velocity feed-forward v / OL_POS_K (`pos_gain_1_s`). On the
ground it idles until the target is offboard_liftoff_m above the vehicle (PX4's takeoff state machine keeps the
motors at idle while landed and no climb is asked). A stream lost between the stack's check and the step: Hold.
"""

from __future__ import annotations

import math

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.modes.context import ModeContext, Step, Transition, climb_rate_down, idle, integrate_led, wrap_pi
from navig8_fc.modes.px4 import FlightMode
from navig8_fc.modes.records import ModeInputs, OffboardTarget


class Offboard:
    def __init__(self, ctx: ModeContext) -> None:
        self._ctx = ctx
        self.target: OffboardTarget | None = None  # the last streamed target while it is fresh (None: lost)
        self.pos_gain_1_s = 1.0  # the outer loop's OL_POS_K: velocity feed-forward as a position offset v / K_p
        self._ref = Setpoint((0.0, 0.0, 0.0))  # the reference (set on entry)

    def set_target(self, sp: Setpoint | OffboardTarget | None) -> None:
        """A Setpoint is a position target (position, pitch, yaw); None: the stream is lost."""
        self.target = OffboardTarget.of(sp) if isinstance(sp, Setpoint) else sp

    def enter(self, inp: ModeInputs) -> None:
        out = self._ctx.last_output
        x, y, z = inp.pos_ned
        self._ref = (Setpoint(out.setpoint.pos_ned, out.setpoint.pitch_rad, out.setpoint.yaw_rad)
                     if out is not None and out.engaged else Setpoint((x, y, z), 0.0, inp.yaw_rad))

    def update(self, inp: ModeInputs, dt: float) -> Step:
        ctx = self._ctx
        if self.target is None:  # lost between the stack's check and this step
            return Step(ctx.last_output.setpoint if ctx.last_output else idle(inp), True, None,
                        Transition(FlightMode.HOLD))
        sp = self._fly(self.target, inp, dt)
        if ctx.detector.landed and sp.pos_ned[2] > inp.pos_ned[2] - ctx.config.offboard_liftoff_m:
            return Step(idle(inp), False)  # on the ground and not asked to climb: idle, as PX4's takeoff state
        return Step(sp, True)

    def _fly(self, tgt: OffboardTarget, inp: ModeInputs, dt: float) -> Setpoint:
        """The streamed target -> this step's setpoint (OffboardTarget's docstring). The reference (self._ref)
        integrates velocity-only axes and yaw rate; the flown setpoint adds the velocity feed-forward."""
        ref = self._ref
        pos, vel = tgt.pos_ned, tgt.vel_ned
        if not math.isnan(tgt.throttle) and math.isnan(pos[2]) and math.isnan(vel[2]):
            vel = (vel[0], vel[1], climb_rate_down(tgt.throttle, self._ctx.config))
        v_int = tuple(0.0 if math.isnan(v) or not math.isnan(p) else v for p, v in zip(pos, vel, strict=True))
        moved = integrate_led(ref.pos_ned, v_int, inp.pos_ned, dt, self._ctx.config.manual_lead_m)  # type: ignore[arg-type]
        ref_pos = tuple(m if math.isnan(p) else p for p, m in zip(pos, moved, strict=True))
        if not math.isnan(tgt.yaw_rad):
            yaw = tgt.yaw_rad
        elif not math.isnan(tgt.yaw_rate_rad_s):
            yaw = wrap_pi(ref.yaw_rad + tgt.yaw_rate_rad_s * dt)
        else:
            yaw = ref.yaw_rad
        pitch = ref.pitch_rad if math.isnan(tgt.pitch_rad) else tgt.pitch_rad
        self._ref = Setpoint(ref_pos, pitch, yaw)  # type: ignore[arg-type]
        k = self.pos_gain_1_s
        if k <= 0.0 or all(math.isnan(v) for v in vel):
            return self._ref
        ff = tuple(r if math.isnan(v) else r + v / k for r, v in zip(ref_pos, vel, strict=True))
        return Setpoint(ff, pitch, yaw)  # type: ignore[arg-type]
