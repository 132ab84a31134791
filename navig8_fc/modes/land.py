"""LAND (AUTO.LAND; pure): descend at land_descent_rate_m_s where the mode was entered (or where a mission or
Return said); on touchdown (the land detector, or ground contact) the controller goes idle, the land or return
task is DONE, and the vehicle disarms land_disarm_delay_s later (-> READY)."""

from __future__ import annotations

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.modes.context import ModeContext, Step, Transition, approach, idle
from navig8_fc.modes.px4 import FlightMode
from navig8_fc.modes.records import ModeInputs

LAND_CONTACT_LAG_M = 0.2  # LAND: the setpoint this far below a slow vehicle near home height = ground contact


class Land:
    def __init__(self, ctx: ModeContext) -> None:
        self._ctx = ctx
        self._land_xy: tuple[float, float] | None = None  # where a mission's landing goes down (else: here)
        self._sp: Setpoint | None = None  # x, y, pitch, yaw of the descent
        self._ramp_z = 0.0
        self._target_z = 0.0
        self.touchdown_t_s: float | None = None

    def go_down_at(self, xy: tuple[float, float]) -> None:
        """The next entry descends at xy (a mission's landing item, Return at home), not where the vehicle is."""
        self._land_xy = xy

    def enter(self, inp: ModeInputs, home_z: float) -> None:
        x, y, z = inp.pos_ned_m
        if self._land_xy is not None:
            x, y = self._land_xy
            self._land_xy = None
        self._sp = Setpoint((x, y, z), 0.0, inp.yaw_rad)
        self._ramp_z = z
        self._target_z = max(home_z, z) + self._ctx.config.land_setpoint_floor_m
        self.touchdown_t_s = None

    def update(self, inp: ModeInputs, dt: float) -> Step:
        assert self._sp is not None
        ctx = self._ctx
        if self.touchdown_t_s is None:
            if ctx.detector.landed or self._ground_contact(inp):
                self.touchdown_t_s = inp.t_s
                ctx.events.append("Landed")
                ctx.tasks.complete("land", "return")
                return Step(idle(inp), False)
            self._ramp_z = approach(self._ramp_z, self._target_z, ctx.config.land_descent_rate_m_s * dt)
            n, e, _ = self._sp.pos_ned_m
            return Step(Setpoint((n, e, self._ramp_z), 0.0, self._sp.yaw_rad), True)
        if inp.t_s - self.touchdown_t_s >= ctx.config.land_disarm_delay_s:
            ctx.events.append("Disarmed after landing")
            return Step(idle(inp), False, None, Transition(FlightMode.READY))
        return Step(idle(inp), False)

    def _ground_contact(self, inp: ModeInputs) -> bool:
        """Touchdown without the detector's hold: within land_contact_height_m of home height, slow, and held up by
        something: the descending setpoint is LAND_CONTACT_LAG_M below the vehicle. Without that last condition a
        slow hover anywhere below home height (home on a roof) was taken for touchdown."""
        home = self._ctx.home
        z = inp.pos_ned_m[2]
        return (home is not None and abs(home[2] - z) < self._ctx.config.land_contact_height_m
                and self._ramp_z > z + LAND_CONTACT_LAG_M and self._ctx.detector.slow(inp))
