"""MISSION (AUTO.MISSION; pure): a scripted setpoint function (a scenario such as the paper's, `MissionScript`)
or, without one, the uploaded plan (navig8_fc.mission.executor; docs/gcs.md "Mission execution").

A script that starts armed in the air starts the manager in MISSION, armed, with the mission clock equal to sim
time minus `MissionScript.start_t_s`, so the SITL run commands exactly what the in-process run commands. The
mission clock pauses when the mode is left (resumed at the next entry; a finished mission starts again); at
its end the script's last setpoint is held (HOLD). A plan starts at its start item (resumes where it was when
re-entered unfinished) from the current reference, hands its landing to LAND and its end to HOLD.
"""

from __future__ import annotations

from navig8_fc.mission.executor import MissionExecutor
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Plan, Progress
from navig8_fc.modes.context import ModeContext, Step, Transition, exec_config
from navig8_fc.modes.px4 import FlightMode
from navig8_fc.modes.records import MissionScript, ModeInputs


class Mission:
    def __init__(self, ctx: ModeContext, script: MissionScript | None) -> None:
        self._ctx = ctx
        self.script = script
        air_start = script is not None and script.starts_armed_in_air
        # Mission clock: mission time = t_s - _t0_s while in MISSION; _elapsed_s when paused.
        self._t0_s: float | None = script.start_t_s if air_start and script else None
        self._elapsed_s = 0.0
        # An uploaded plan (flown when there is no script) and its executor.
        self.plan: Plan | None = None
        self.origin = GeoOrigin()
        self._exec: MissionExecutor | None = None
        self.progress = Progress()
        self._reached_count = 0
        self._actions: list[tuple[str, object]] = []

    def load(self, plan: Plan, origin: GeoOrigin) -> None:
        """An uploaded plan (or a new start item); an air start's hold that yields to a plan gives way to it."""
        self.plan = plan if plan.items else None
        self.origin = origin
        if self.plan is not None and self.script is not None and self.script.yields_to_plan:
            self.script = None  # the air start's hold gives way to the plan (flown from where the vehicle is)
            self._t0_s = None
        self._exec = None
        self.progress = Progress(plan.current, reached_log=self.progress.reached_log)

    def pause(self, last: ModeInputs | None) -> None:
        """MISSION is left: the script's clock stops (at the last sample's time)."""
        if self._t0_s is not None:
            if last is not None:
                self._elapsed_s = max(last.t_s - self._t0_s, 0.0)
            self._t0_s = None

    def progress_now(self, in_mission: bool) -> Progress:
        """The plan's progress, active while it is being flown."""
        p = self.progress
        active = in_mission and self.script is None
        return p if p.active == active else Progress(p.current, p.reached, active, p.finished, p.reached_log)

    def take_actions(self) -> tuple[tuple[str, object], ...]:
        """The plan items' arm/gripper actions since the last call."""
        actions = tuple(self._actions) if self._actions else ()
        if self._actions:
            self._actions.clear()
        return actions

    def enter(self, inp: ModeInputs, armed: bool) -> None:
        if self.script is None:
            self._enter_plan(inp, armed)
        else:
            self._enter_script(inp, self.script)

    def _enter_plan(self, inp: ModeInputs, armed: bool) -> None:
        if not armed:
            return  # selected on the ground: starts when armed
        ctx = self._ctx
        start = ctx.start_setpoint(inp)
        assert self.plan is not None
        if self._exec is None or self._exec.finished:
            self._exec = MissionExecutor(self.plan, self.origin, ctx.home or inp.pos_ned_m, start,
                                         exec_config(ctx.config), self._reached_count, ctx.rally_points)
            ctx.events.append(f"Mission started at item {self._exec.progress.current}")
        else:
            ctx.events.append(f"Mission resumed at item {self._exec.progress.current}")

    def _enter_script(self, inp: ModeInputs, script: MissionScript) -> None:
        duration = script.duration_s
        if self._t0_s is None:
            if duration is not None and self._elapsed_s >= duration:
                self._elapsed_s = 0.0  # a finished mission starts again
            self._t0_s = inp.t_s - self._elapsed_s
            verb = "resumed" if self._elapsed_s > 0.0 else "started"
            self._ctx.events.append(f"Mission {script.name} {verb}")
        else:
            self._ctx.events.append(f"Mission {script.name} started (armed in the air)")

    def update(self, inp: ModeInputs, dt: float) -> Step:
        if self.script is None:
            return self._update_plan(inp, dt)
        return self._update_script(inp.t_s, self.script)

    def _update_script(self, t_s: float, script: MissionScript) -> Step:
        assert self._t0_s is not None
        mission_t = t_s - self._t0_s
        duration = script.duration_s
        if duration is not None and mission_t >= duration:
            final = script.setpoint_at(duration)
            self._elapsed_s = duration
            self._t0_s = None
            self._ctx.events.append(f"Mission {script.name} complete: holding")
            return Step(final, True, None, Transition(FlightMode.HOLD, hold_at=final))
        return Step(script.setpoint_at(mission_t), True, mission_t)

    def _update_plan(self, inp: ModeInputs, dt: float) -> Step:
        ex = self._exec
        assert ex is not None
        ctx = self._ctx
        st = ex.step(inp.t_s, inp.pos_ned_m, inp.yaw_rad, dt)
        self._reached_count = ex.reached_count
        self.progress = ex.progress
        self._actions += st.actions
        ctx.events += st.events
        if st.land:
            ctx.events.append("Mission: landing")
            return Step(st.setpoint, True, None,
                        Transition(FlightMode.LAND, land_xy=(st.setpoint.pos_ned_m[0], st.setpoint.pos_ned_m[1])))
        if ex.finished:
            return Step(st.setpoint, True, None,
                        Transition(FlightMode.HOLD, hold_at=st.setpoint, on_ground=ctx.detector.landed))
        return Step(st.setpoint, True)
