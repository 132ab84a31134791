"""The mode switch (pure, on sim time): the vehicle's arming state and mode, the switch between modes, and the
step that runs the mode in force.

`ModeSwitch` owns the modes (one object each, built once with the shared `ModeContext`) and calls the new mode's
`enter` at the first step after a switch, its `update` at every step, and follows the `Transition` a mode asks
for when it ends. It checks nothing but an orbit's own parameters (`start_orbit`): the mode manager
(navig8_fc.modes.manager) decides what is allowed (pre-arm, faults, which mode may be chosen when) and calls
`switch`/`disarm`. READY (on the ground, armed or not; the
controller idle) has no object: the switch idles whenever the vehicle is disarmed or in READY.
"""

from __future__ import annotations

from collections.abc import Callable

from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Plan
from navig8_fc.mission.rally import return_destination
from navig8_fc.modes.context import ModeContext, Step, Transition, idle
from navig8_fc.modes.hold import Hold
from navig8_fc.modes.land import Land
from navig8_fc.modes.land_detector import LandDetector
from navig8_fc.modes.mission import Mission
from navig8_fc.modes.offboard import Offboard
from navig8_fc.modes.orbit import Orbit, OrbitPlan, OrbitRequest, resolve
from navig8_fc.modes.position import Position
from navig8_fc.modes.px4 import BASE_MODE_ARMED, BASE_MODE_DISARMED, FlightMode, landed_state, system_status
from navig8_fc.modes.records import MissionScript, ModeConfig, ModeInputs, ModeOutput, Vec3, Verdict, sanitised
from navig8_fc.modes.rtl import Return
from navig8_fc.modes.takeoff import Takeoff
from navig8_fc.modes.tasks import TaskTracker

_SELECTABLE_DISARMED = (FlightMode.HOLD, FlightMode.MISSION)


class ModeSwitch:
    """The vehicle's mode state and its step (module docstring)."""

    def __init__(self, config: ModeConfig, script: MissionScript | None) -> None:
        self.tasks = TaskTracker(config)  # the long-running flight command (takeoff, land, return, reposition)
        ctx = self.ctx = ModeContext(config, LandDetector(config), self.tasks)
        self.detector = ctx.detector
        self.hold, self.takeoff, self.land = Hold(ctx), Takeoff(ctx), Land(ctx)
        self.position, self.offboard, self.rtl = Position(ctx), Offboard(ctx), Return(ctx)
        self.mission = Mission(ctx, script)
        self.orbit = Orbit(ctx, lambda: self.position.sticks)
        self._by_mode = {FlightMode.HOLD: self.hold, FlightMode.TAKEOFF: self.takeoff, FlightMode.LAND: self.land,
                         FlightMode.POSCTL: self.position, FlightMode.OFFBOARD: self.offboard,
                         FlightMode.RTL: self.rtl, FlightMode.MISSION: self.mission, FlightMode.ORBIT: self.orbit}
        air_start = script is not None and script.starts_armed_in_air
        self.armed = air_start
        self.mode = FlightMode.MISSION if air_start else FlightMode.READY
        self.entry_pending = True  # the mode's entry actions run at the next step
        self._entries = 0  # mode entries (ModeOutput.entries)
        self.last: ModeInputs | None = None  # the last (sanitised) state sample
        self.home_yaw_rad = 0.0

    def switch(self, mode: FlightMode) -> None:
        """Change to `mode` (also the same mode: entered again); a running task of another mode is cancelled."""
        self.tasks.mode_changed(self.mode, mode)
        if self.mode is FlightMode.MISSION and mode is not FlightMode.MISSION:
            self.mission.pause(self.last)
        self.mode = mode
        self.entry_pending = True

    def load_plan(self, plan: Plan, origin: GeoOrigin) -> None:
        """An uploaded mission plan (ModeManager.load_plan): a mission in flight goes on with it at the next step;
        an emptied plan holds."""
        self.mission.load(plan, origin)
        if self.mode is FlightMode.MISSION and self.mission.script is None:
            if self.mission.plan is None:
                self.switch(FlightMode.HOLD)
                self.ctx.events.append("Mission cleared: holding")
            else:
                self.entry_pending = True

    def start_orbit(self, req: OrbitRequest, problem: Callable[[OrbitPlan], str] | None) -> Verdict:
        """MAV_CMD_DO_ORBIT (or Orbit chosen as a mode): resolved against the orbit being flown (navig8_fc.modes.orbit),
        checked by `problem` (the operating volume: '' when it passes), then flown from the next step."""
        last = self.last
        here, yaw = (last.pos_ned_m, last.yaw_rad) if last is not None else ((0.0, 0.0, 0.0), 0.0)
        flown = self.orbit.plan if self.mode is FlightMode.ORBIT else None
        plan, refusal, note = resolve(req, flown, here, yaw, self.orbit.limits)
        if plan is None or (problem is not None and (refusal := problem(plan))):
            return Verdict(False, f"Orbit refused: {refusal}" if plan is not None else refusal)
        self.orbit.plan = plan
        self.switch(FlightMode.ORBIT)  # (again): approach or circle from where the vehicle is
        c = plan.centre_ned_m
        self.ctx.events.append(f"Orbit: centre N {c[0]:.1f} E {c[1]:.1f} D {c[2]:.1f} m, r {plan.signed_radius_m:g} m")
        if note:
            self.ctx.events.append(note)
        return Verdict(True)

    def disarm(self) -> None:
        self.armed = False
        self.switch(FlightMode.READY)

    def here(self) -> Vec3:
        return self.last.pos_ned_m if self.last is not None else (0.0, 0.0, 0.0)

    def return_destination(self) -> Vec3:
        """Where a return started now goes: home or the closest rally point (navig8_fc.mission.rally)."""
        here = self.here()
        return return_destination(here, self.ctx.home or here, self.ctx.rally_points()).pos_ned_m

    def home_z(self) -> float:
        if self.ctx.home is not None:
            return self.ctx.home[2]
        return self.last.pos_ned_m[2] if self.last is not None else 0.0

    def step(self, inp: ModeInputs, faulted: bool) -> ModeOutput:
        """One control tick: home and the land detector, the mode's entry if pending, its update; `faulted`: a
        fault is set (MAV_STATE CRITICAL while armed)."""
        inp = sanitised(inp, self.last)
        t = inp.t_s
        prev = self.last
        if prev is None:
            dt = 0.0
        else:
            dt = t - prev.t_s
            if dt < 0.0:  # max(dt, 0.0)
                dt = 0.0
        ctx = self.ctx
        home = ctx.home
        if home is None:
            script = self.mission.script
            if script is not None and script.starts_armed_in_air:
                home = (inp.pos_ned_m[0], inp.pos_ned_m[1], ctx.config.air_start_home_z_ned_m)
            else:
                home = inp.pos_ned_m
            ctx.home = home
            self.home_yaw_rad = inp.yaw_rad
        landed = self.detector.step(inp, home[2])
        self.last = inp
        if not self.armed and self.mode is not FlightMode.READY and self.mode not in _SELECTABLE_DISARMED:
            self.switch(FlightMode.READY)
        if self.entry_pending:
            self._enter(inp)
        step = self._run(inp, dt)
        self.tasks.update(inp, self.mode, self.armed)
        armed, mode, events = self.armed, self.mode, ctx.events
        out = ModeOutput(
            t, armed, step.engaged, step.setpoint, mode, mode.custom_mode,
            BASE_MODE_ARMED if armed else BASE_MODE_DISARMED,
            landed_state(mode, armed, self.detector.landed, self.land.touchdown_t_s is not None, self.hold.on_ground),
            system_status(armed, inp.sensors_ok, faulted),
            landed, ctx.home, self.home_yaw_rad, step.mission_time_s,
            tuple(events) if events else (),
            self.mission.progress_now(mode is FlightMode.MISSION),
            self.mission.take_actions(),
            self._entries,
        )
        if events:
            events.clear()
        ctx.last_output = out
        return out

    def _enter(self, inp: ModeInputs) -> None:
        """Entry actions that need a state sample (where to hold, where a ramp starts)."""
        self.entry_pending = False
        self._entries += 1
        mode = self.mode
        if mode is FlightMode.HOLD:
            self.hold.enter(inp)
        elif mode is FlightMode.POSCTL:
            self.position.enter(inp)
        elif mode is FlightMode.OFFBOARD:
            self.offboard.enter(inp)
        elif mode is FlightMode.RTL:
            self.rtl.enter(inp, self.mission.origin)
        elif mode is FlightMode.TAKEOFF:
            self.takeoff.enter(inp, self.home_z())
        elif mode is FlightMode.LAND:
            self.land.enter(inp, self.home_z())
        elif mode is FlightMode.MISSION:
            self.mission.enter(inp, self.armed)
        elif mode is FlightMode.ORBIT:
            self.orbit.enter(inp)

    def _run(self, inp: ModeInputs, dt: float) -> Step:
        if not self.armed or self.mode is FlightMode.READY:
            return Step(idle(inp), False)
        step = self._by_mode[self.mode].update(inp, dt)
        if step.then is not None:
            self._follow(step.then)
        return step

    def _follow(self, then: Transition) -> None:
        """The mode that ran asked to go on to `then.mode` (context.Transition)."""
        if then.land_xy is not None:
            self.land.go_down_at(then.land_xy)
        if then.mode is FlightMode.READY:
            self.disarm()  # Land: disarmed after touchdown (Land announced it)
        else:
            self.switch(then.mode)
        if then.mode is FlightMode.READY or then.hold_at is not None:
            self.entry_pending = False  # READY needs no entry; HOLD is handed the setpoint
            if then.hold_at is not None:
                self.hold.hold(then.hold_at, then.on_ground)
