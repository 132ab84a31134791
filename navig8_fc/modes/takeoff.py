"""TAKEOFF (AUTO.TAKEOFF; pure): the altitude setpoint ramps from where the vehicle is at takeoff_climb_rate_m_s
to home + alt; done when the ramp has arrived and the vehicle is within takeoff_reached_tol_m: the takeoff task
is DONE and Hold holds the ramp's end."""

from __future__ import annotations

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.modes.context import ModeContext, Step, Transition, approach
from navig8_fc.modes.px4 import FlightMode
from navig8_fc.modes.records import ModeInputs


class Takeoff:
    def __init__(self, ctx: ModeContext) -> None:
        self._ctx = ctx
        self.alt_m: float = ctx.config.takeoff_default_alt_m  # above home: the last accepted NAV_TAKEOFF
        self._sp: Setpoint | None = None  # x, y, pitch, yaw of the climb
        self._ramp_z = 0.0
        self._target_z = 0.0

    def retarget(self, home_z: float) -> None:
        """A new altitude while climbing: the ramp carries on from where it is."""
        self._target_z = home_z - self.alt_m

    def enter(self, inp: ModeInputs, home_z: float) -> None:
        x, y, z = inp.pos_ned_m
        self._sp = Setpoint((x, y, z), 0.0, inp.yaw_rad)
        self._ramp_z = z
        self._target_z = home_z - self.alt_m

    def update(self, inp: ModeInputs, dt: float) -> Step:
        assert self._sp is not None
        cfg = self._ctx.config
        self._ramp_z = approach(self._ramp_z, self._target_z, cfg.takeoff_climb_rate_m_s * dt)
        sp = Setpoint((self._sp.pos_ned_m[0], self._sp.pos_ned_m[1], self._ramp_z), 0.0, self._sp.yaw_rad)
        if self._ramp_z == self._target_z and abs(inp.pos_ned_m[2] - self._target_z) < cfg.takeoff_reached_tol_m:
            self._ctx.tasks.complete("takeoff")
            self._ctx.events.append(f"Takeoff complete: holding at {self.alt_m:.1f} m")
            return Step(sp, True, None, Transition(FlightMode.HOLD, hold_at=sp))
        return Step(sp, True)
