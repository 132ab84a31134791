"""RTL (AUTO.RTL, Return; pure): a one-item plan (NAV_RETURN_TO_LAUNCH) flown by the mission executor from the
current reference, as PX4's RTL_TYPE 0 (rtl.cpp; navig8_fc.mission.rally): the destination is home or the closest
rally point more than 10 m from home; climb to rtl_alt_m (RTL_RETURN_ALT) above it if lower, fly there, then LAND
there (the return task goes on into the landing and is DONE at touchdown)."""

from __future__ import annotations

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.mission.executor import MissionExecutor
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Cmd, MissionItem, Plan
from navig8_fc.modes.context import ModeContext, Step, Transition, exec_config
from navig8_fc.modes.px4 import FlightMode
from navig8_fc.modes.records import ModeInputs

_RTL_PLAN = Plan(0, (MissionItem(2, int(Cmd.NAV_RETURN_TO_LAUNCH), 1, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0),))


class Return:
    def __init__(self, ctx: ModeContext) -> None:
        self._ctx = ctx
        self._exec: MissionExecutor | None = None

    def enter(self, inp: ModeInputs, origin: GeoOrigin) -> None:
        """`origin`: the uploaded plan's geodetic origin."""
        ctx = self._ctx
        start = ctx.start_setpoint(inp)
        self._exec = MissionExecutor(_RTL_PLAN, origin, ctx.home or inp.pos_ned_m,
                                     Setpoint(start.pos_ned_m, 0.0, start.yaw_rad), exec_config(ctx.config),
                                     rally=ctx.rally_points)

    def update(self, inp: ModeInputs, dt: float) -> Step:
        ex = self._exec
        assert ex is not None
        st = ex.step(inp.t_s, inp.pos_ned_m, inp.yaw_rad, dt)
        if st.land:
            dest = ex.destination
            self._ctx.events.append("Return: landing at home" if dest.is_home else
                                    f"Return: landing at rally point {dest.seq}")
            return Step(st.setpoint, True, None,
                        Transition(FlightMode.LAND, land_xy=(st.setpoint.pos_ned_m[0], st.setpoint.pos_ned_m[1])))
        return Step(st.setpoint, True)
