"""Flight-mode and arming state machine of the flight controller (pure, on sim time).

One `step(ModeInputs) -> ModeOutput` per control tick, on the sensor bundle's time (lockstep: the bridge is
the time master, DESIGN §4). Commands (`arm`, `disarm`, `takeoff`, `land`, `set_mode`) arrive between steps
from the GCS side; they answer at once with a `Verdict` (accepted, or the reason for STATUSTEXT) and change
`armed`/the mode at once, while everything that needs a fresh state sample (where a ramp starts, where to
hold) happens at the next step. The manager never touches sockets, clocks or pymavlink.

Modes (PX4 encoding, navig8_fc.modes.px4; docs/gcs.md):
- READY (AUTO.READY): on the ground, armed or not; controller idle (motors off in the model).
- TAKEOFF (AUTO.TAKEOFF): the altitude setpoint ramps from where the vehicle is at `takeoff_climb_rate_m_s`
  to home + alt; done when the ramp has arrived and the vehicle is within `takeoff_reached_tol_m` -> HOLD.
- HOLD (AUTO.LOITER, MAVSDK "Hold"): position hold where the vehicle comes to rest when the mode is entered (its
  horizontal stopping point at the position reference's braking limits, as PX4's Loiter `calculate_breaking_stop`
  and ArduPilot's `get_stopping_point_xy`), or at the takeoff target. Holding the entry point itself would fly
  past it and back (docs/gcs.md "Hold").
  Entered on the ground it stays idle (PX4 behaves the same: Hold does not take off).
- LAND (AUTO.LAND): descend at `land_descent_rate_m_s` where the mode was entered; on touchdown (land
  detector) the controller goes idle and the vehicle disarms `land_disarm_delay_s` later -> READY.
- MISSION (AUTO.MISSION): follow a scripted setpoint function (a scenario such as the paper's). A script that
  starts armed in the air starts the manager in MISSION, armed, with the mission clock equal to sim time
  minus `MissionScript.start_t_s`, so the SITL run commands exactly what the in-process run commands.

Home is the position at arming (PX4); before the first arming it is where the vehicle stood at the first
step, so a GCS has a home to show (MAVSDK examples wait for home before arming). For an air start, home is
the start position projected onto `ModeConfig.air_start_home_z_ned_m` (the plant's ground is NED z = 0).

The land detector is navig8_fc.modes.land_detector, Hold's braking distance navig8_fc.modes.braking, the
records (config, inputs, outputs, verdict, script, offboard target) navig8_fc.modes.records.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.mission.executor import ExecConfig, MissionExecutor
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Cmd, MissionItem, Plan, Progress
from navig8_fc.modes.braking import braking_distance_m
from navig8_fc.modes.land_detector import LandDetector
from navig8_fc.modes.px4 import FlightMode, MavLandedState, MavModeFlag, MavState, Px4AutoSubMode, Px4MainMode
from navig8_fc.modes.records import (
    MissionScript,
    ModeConfig,
    ModeInputs,
    ModeOutput,
    OffboardTarget,
    Vec3,
    Verdict,
)

LAND_CONTACT_LAG_M = 0.2  # LAND: the setpoint this far below a slow vehicle near home height = ground contact


TASK_RUNNING, TASK_DONE, TASK_FAILED, TASK_CANCELLED = 0, 1, 2, 3  # TaskStatus.state


@dataclass(frozen=True)
class TaskStatus:
    """A long-running command's progress (COMMAND_ACK IN_PROGRESS, then its final result; docs/gcs.md).

    task_id grows with every task started; kind names the command ("takeoff", "land", "return", "reposition",
    "arm_joints"); progress_pct 0..100, never decreasing. A task ends DONE (it got there), CANCELLED (COMMAND_CANCEL,
    or another command took over) or FAILED (a failsafe took over, or it could not complete)."""

    task_id: int
    kind: str
    state: int = TASK_RUNNING
    progress_pct: float = 0.0
    reason: str = ""

    @property
    def running(self) -> bool:
        return self.state == TASK_RUNNING



class ModeManager:
    """Arming, modes and setpoints (module docstring). Not thread-safe: one owner calls everything."""

    def __init__(self, config: ModeConfig | None = None, script: MissionScript | None = None) -> None:
        self._cfg = config or ModeConfig()
        self._script = script
        self._detector = LandDetector(self._cfg)
        air_start = script is not None and script.starts_armed_in_air
        self._armed = air_start
        self._mode = FlightMode.MISSION if air_start else FlightMode.READY
        self._entry_pending = True
        self._entries = 0  # mode entries (ModeOutput.entries)
        self._last: ModeInputs | None = None
        self._last_output: ModeOutput | None = None
        self._home: Vec3 | None = None
        self._home_yaw_rad = 0.0
        self._events: list[str] = []
        # Mode state, set on entry.
        self._sp: Setpoint | None = None  # HOLD target; ramp modes keep x, y, pitch, yaw here
        self._ob_ref = Setpoint((0.0, 0.0, 0.0))  # Offboard's reference (set on entry)
        self._ramp_z: float = 0.0
        self._target_z: float = 0.0
        self._takeoff_alt_m: float = self._cfg.takeoff_default_alt_m
        self._touchdown_t_s: float | None = None
        self._hold_on_ground = False
        # Mission clock: mission time = t_s - _mission_t0_s while in MISSION; _mission_elapsed_s when paused.
        self._mission_t0_s: float | None = script.start_t_s if air_start and script else None
        self._mission_elapsed_s = 0.0
        # Faults reported from outside the step (the FlightStack's link checks, rate check): name -> reason.
        self._faults: dict[str, str] = {}
        # An uploaded plan (flown in MISSION when there is no script) and its executor.
        self._plan: Plan | None = None
        self._origin = GeoOrigin()
        self._exec: MissionExecutor | None = None
        self._progress = Progress()
        self._reached_count = 0
        self._land_xy: tuple[float, float] | None = None  # where a mission's landing goes down (else: here)
        self._actions: list[tuple[str, object]] = []
        self._rtl: MissionExecutor | None = None  # Return mode flies a one-item plan (NAV_RETURN_TO_LAUNCH)
        self._offboard: OffboardTarget | None = None  # the last streamed target while it is fresh (None: lost)
        self._pos_gain_1_s = 1.0  # the outer loop's OL_POS_K: velocity feed-forward as a position offset v / K_p
        self._brake_acc_m_s2 = math.inf  # the position reference's braking limits (set_braking; inf: stops at once)
        self._brake_jerk_m_s3 = math.inf
        self._brake_lag_s = 0.0
        self._reposition: tuple[Vec3, float] | None = None  # DO_REPOSITION target for Hold's entry
        self._sticks: tuple[float, float, float, float] = (0.0, 0.0, 0.5, 0.0)  # x fwd, y right, z 0..1, r
        # The long-running flight command in progress (takeoff, land, return, reposition) and its geometry.
        self._task: TaskStatus | None = None
        self._task_n = 0
        self._task_from: Vec3 = (0.0, 0.0, 0.0)
        self._task_to: Vec3 = (0.0, 0.0, 0.0)

    # --- read access ---------------------------------------------------------------------------------
    @property
    def config(self) -> ModeConfig:
        return self._cfg

    @property
    def script(self) -> MissionScript | None:
        return self._script

    @property
    def armed(self) -> bool:
        return self._armed

    @property
    def flight_mode(self) -> FlightMode:
        return self._mode

    @property
    def custom_mode(self) -> int:
        return self._mode.custom_mode

    @property
    def base_mode(self) -> int:
        return _BASE_MODE_ARMED if self._armed else _BASE_MODE_DISARMED

    @property
    def landed(self) -> bool:
        return self._detector.landed

    @property
    def home_ned(self) -> Vec3 | None:
        return self._home

    @property
    def home_yaw_rad(self) -> float:
        return self._home_yaw_rad

    @property
    def last_output(self) -> ModeOutput | None:
        return self._last_output

    @property
    def faults(self) -> dict[str, str]:
        """The faults now set (name -> reason); a copy."""
        return dict(self._faults)

    def set_fault(self, name: str, reason: str) -> None:
        """A fault found outside the step (e.g. no sensor bundles for FS_SENS_TOUT, a control-rate mismatch):
        pre-arm fails with `reason`, takeoff is refused and an armed vehicle reports MAV_STATE_CRITICAL until
        `clear_fault(name)`. The flight itself is not changed (the FlightStack decides on failsafe actions)."""
        self._faults[name] = reason

    def clear_fault(self, name: str) -> bool:
        """Clear a fault; True when it was set."""
        return self._faults.pop(name, None) is not None

    @property
    def system_status(self) -> int:
        """MAV_STATE now, including faults set since the last step (HEARTBEAT reads this, not the last step's)."""
        if self._last is None:
            return _STANDBY
        return self._system_status(self._last)

    def prearm_check(self) -> Verdict:
        """Would `arm()` pass its checks now? (Also drives SYS_STATUS's PREARM_CHECK health bit.)"""
        inp = self._last
        if inp is None:
            return Verdict(False, "no sensor data yet")
        if self._faults:
            return Verdict(False, next(iter(self._faults.values())))
        if not inp.sensors_ok:
            return Verdict(False, "sensors not ready (missing or stale data)")
        if not inp.estimator_ready:
            return Verdict(False, "estimator not ready")
        if not self._detector.landed:
            return Verdict(False, "vehicle not detected on the ground")
        return Verdict(True)

    # --- commands ------------------------------------------------------------------------------------
    def arm(self, force: bool = False) -> Verdict:
        if self._armed:
            return Verdict(True, "already armed")
        if self._last is None:
            return Verdict(False, "Arming denied: no sensor data yet")
        if not force:
            check = self.prearm_check()
            if not check.ok:
                return Verdict(False, f"Arming denied: {check.reason}")
        inp = self._last
        self._armed = True
        self._home = inp.pos_ned
        self._home_yaw_rad = inp.yaw_rad
        # Armed in Mission: the mission starts. A forced arm in the air must not leave the controller idle: hold
        # where the vehicle is.
        if self._mode is FlightMode.MISSION:
            self._switch(FlightMode.MISSION)
        else:
            self._switch(FlightMode.READY if self._detector.landed else FlightMode.HOLD)
        self._events.append("Armed" + (" (forced)" if force else ""))
        return Verdict(True)

    def disarm(self, force: bool = False) -> Verdict:
        if not self._armed:
            return Verdict(True, "already disarmed")
        if not force and not self._detector.landed:
            return Verdict(False, "Disarming denied: not landed")
        self._disarm("Disarmed" + (" (forced)" if force else ""))
        return Verdict(True)

    def takeoff(self, alt_above_home_m: float = math.nan) -> Verdict:
        if not self._armed:
            return Verdict(False, "Takeoff denied: not armed")
        alt = self._cfg.takeoff_default_alt_m if math.isnan(alt_above_home_m) else float(alt_above_home_m)
        if not (0.0 < alt <= self._cfg.takeoff_max_alt_m):
            return Verdict(False, f"Takeoff denied: altitude {alt:g} m outside (0, {self._cfg.takeoff_max_alt_m:g}]")
        if self._last is not None and not self._last.sensors_ok:
            return Verdict(False, "Takeoff denied: sensors not ready")
        if self._faults:
            return Verdict(False, f"Takeoff denied: {next(iter(self._faults.values()))}")
        self._takeoff_alt_m = alt
        if self._mode is FlightMode.TAKEOFF and not self._entry_pending:
            self._target_z = self._home_z() - alt  # retarget; the ramp carries on from where it is
        else:
            self._switch(FlightMode.TAKEOFF)
        here = self._here()
        self._start_task("takeoff", (here[0], here[1], self._home_z() - alt))
        self._events.append(f"Takeoff to {alt:.1f} m above home")
        return Verdict(True)

    def land(self) -> Verdict:
        if not self._armed:
            return Verdict(False, "Land denied: not armed")
        if self._mode is FlightMode.RTL and self._task is not None and self._task.running:
            self._end_task(TASK_CANCELLED, "replaced by land")  # land here, not at home
        if self._mode is not FlightMode.LAND:
            self._switch(FlightMode.LAND)
            self._events.append("Landing")
        if not self._detector.landed and not (self._task is not None and self._task.running
                                                and self._task.kind in ("land", "return")):
            here = self._here()
            self._start_task("land", (here[0], here[1], self._home_z()))
        return Verdict(True)

    def set_mode(self, custom_main: int, custom_sub: int) -> Verdict:
        """PX4 main/sub mode (DO_SET_MODE p2/p3)."""
        mode = FlightMode.from_px4(int(custom_main), int(custom_sub))
        if mode is None:
            return Verdict(
                False, f"Mode {_px4_name(custom_main, custom_sub)} not supported "
                "(Ready, Takeoff, Hold, Land, Mission, Return, Offboard, Position)"
            )
        if mode is FlightMode.TAKEOFF:
            return self.takeoff()
        if mode is FlightMode.LAND:
            return self.land()
        if mode is FlightMode.READY:
            if self._armed and not self._detector.landed:
                return Verdict(False, "Mode Ready denied: only on the ground")
            if self._mode is not FlightMode.READY:
                self._switch(FlightMode.READY)
            return Verdict(True)
        flying = self._armed and not self._detector.landed
        if mode is FlightMode.RTL:
            return self._enter_mode(mode, "Returning to launch") if flying else Verdict(
                False, "Return denied: not flying")
        if mode is FlightMode.POSCTL:
            return self._enter_mode(mode, "Position") if flying else Verdict(
                False, "Position denied: not flying (take off first)")
        if mode is FlightMode.OFFBOARD:
            if self._offboard is None:
                return Verdict(False, "Offboard denied: no setpoint stream (send SET_POSITION_TARGET_* first)")
            return self._enter_mode(mode, "Offboard") if self._armed else Verdict(False, "Offboard denied: not armed")
        # Hold and Mission can be selected while disarmed, as on PX4 (arming then starts the mission).
        if mode is FlightMode.HOLD:
            if self._mode is not FlightMode.HOLD:
                self._switch(FlightMode.HOLD)
                self._events.append("Hold")
            return Verdict(True)
        # MISSION
        if self._script is None and self._plan is None:
            return Verdict(False, "Mode Mission denied: no mission loaded")
        if self._mode is not FlightMode.MISSION:
            self._switch(FlightMode.MISSION)
        return Verdict(True)

    def _enter_mode(self, mode: FlightMode, event: str) -> Verdict:
        """Switch to `mode` (announcing `event`) unless already in it."""
        if self._mode is not mode:
            self._switch(mode)
            self._events.append(event)
        return Verdict(True)

    def set_custom_mode(self, custom_mode: int) -> Verdict:
        """Same as set_mode, from a PX4-encoded custom_mode."""
        return self.set_mode((custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF)

    def load_plan(self, plan: Plan, origin: GeoOrigin) -> None:
        """An uploaded mission plan (or a new start item): flown in MISSION when there is no script. A mission
        in flight continues on the new plan from its start item at the next step."""
        self._plan = plan if plan.items else None
        self._origin = origin
        if self._plan is not None and self._script is not None and self._script.yields_to_plan:
            self._script = None  # the air start's hold gives way to the plan (flown from where the vehicle is)
            self._mission_t0_s = None
        self._exec = None
        self._progress = Progress(plan.current, reached_log=self._progress.reached_log)
        if self._mode is FlightMode.MISSION and self._script is None:
            if self._plan is None:
                self._switch(FlightMode.HOLD)
                self._events.append("Mission cleared: holding")
            else:
                self._entry_pending = True

    def offboard_setpoint(self, sp: Setpoint | OffboardTarget | None) -> None:
        """The latest streamed offboard target (a Setpoint: position, pitch, yaw; None: the stream is lost, the
        FlightStack decides on timeouts). Offboard mode flies it; losing it in Offboard switches to Hold where the
        vehicle is."""
        self._offboard = OffboardTarget.of(sp) if isinstance(sp, Setpoint) else sp
        if sp is None and self._mode is FlightMode.OFFBOARD:
            self._switch(FlightMode.HOLD)

    def manual_input(self, x: float, y: float, z: float, r: float) -> None:
        """MANUAL_CONTROL sticks, normalised: x forward, y right, r yaw right in [-1, 1], z throttle in [0, 1]
        (0.5 = hold altitude). Position mode flies them; centred sticks hold."""
        def clip(v: float, lo: float) -> float:
            return 0.0 if not math.isfinite(v) else min(1.0, max(lo, v))

        self._sticks = (clip(x, -1.0), clip(y, -1.0), clip(z, 0.0) if math.isfinite(z) else 0.5, clip(r, -1.0))

    def reposition(self, pos_ned: Vec3, yaw_rad: float = math.nan) -> Verdict:
        """DO_REPOSITION (MAVSDK goto_location, QGC Go to / Pause): Hold at pos_ned (a NaN component: where the
        vehicle is), yaw_rad (NaN: keep)."""
        if not self._armed or self._detector.landed:
            return Verdict(False, "Reposition denied: not flying")
        self._reposition = (pos_ned, yaw_rad)
        if self._mode is FlightMode.HOLD and not self._entry_pending:
            self._apply_reposition()
        else:
            self._switch(FlightMode.HOLD)
        here = self._here()
        self._start_task("reposition", tuple(h if math.isnan(p) else p  # type: ignore[arg-type]
                                             for p, h in zip(pos_ned, here, strict=True)))
        return Verdict(True)

    def return_to_launch(self) -> Verdict:
        """MAV_CMD_NAV_RETURN_TO_LAUNCH: Return mode, reported as a long command (done at touchdown at home)."""
        verdict = self.set_mode(int(Px4MainMode.AUTO), int(Px4AutoSubMode.RTL))
        if verdict.ok and not (self._task is not None and self._task.running and self._task.kind == "return"):
            self._start_task("return", self._home or self._here())
        return verdict

    # --- long-running commands -----------------------------------------------------------------------------
    @property
    def task(self) -> TaskStatus | None:
        """The last long-running flight command (running or how it ended); None before the first."""
        return self._task

    def cancel_task(self) -> bool:
        """COMMAND_CANCEL: stop the running flight command and hold where the vehicle is; False when none runs."""
        tk = self._task
        if tk is None or not tk.running:
            return False
        self._end_task(TASK_CANCELLED, "cancelled")
        self._reposition = None
        self._switch(FlightMode.HOLD)  # entry: hold here (on the ground: stays idle)
        self._events.append(f"{tk.kind.capitalize()} cancelled: holding")
        return True

    def fail_task(self, reason: str) -> None:
        """A failsafe takes over: the running flight command ends FAILED (before the failsafe changes the mode)."""
        if self._task is not None and self._task.running:
            self._end_task(TASK_FAILED, reason)

    def _here(self) -> Vec3:
        return self._last.pos_ned if self._last is not None else (0.0, 0.0, 0.0)

    def _start_task(self, kind: str, to: Vec3) -> None:
        if self._task is not None and self._task.running:
            self._end_task(TASK_CANCELLED, f"replaced by {kind}")
        self._task_n += 1
        self._task = TaskStatus(self._task_n, kind)
        self._task_from, self._task_to = self._here(), to

    def _end_task(self, state: int, reason: str = "") -> None:
        tk = self._task
        assert tk is not None
        self._task = TaskStatus(tk.task_id, tk.kind, state, 100.0 if state == TASK_DONE else tk.progress_pct, reason)

    def _update_task(self, inp: ModeInputs) -> None:
        """Progress (the share of the start-to-target distance covered, never decreasing) and the end of the running
        task when its mode was left (a command's own ending is set where it happens: touchdown, takeoff done)."""
        tk = self._task
        if tk is None or not tk.running:
            return
        mode = self._mode
        own = {"takeoff": (FlightMode.TAKEOFF,), "land": (FlightMode.LAND,), "reposition": (FlightMode.HOLD,),
               "return": (FlightMode.RTL, FlightMode.LAND)}[tk.kind]
        if mode not in own or not self._armed:
            self._end_task(TASK_FAILED, f"mode changed to {mode.label}")
            return
        d = math.dist(inp.pos_ned, self._task_to)
        if tk.kind == "reposition" and d < self._cfg.reposition_reached_tol_m and math.hypot(
                *inp.vel_ned) < self._cfg.reposition_reached_speed_m_s:
            self._end_task(TASK_DONE)
            return
        d0 = math.dist(self._task_from, self._task_to)
        pct = 100.0 * min(1.0, max(0.0, 1.0 - d / d0)) if d0 > 1e-6 else 0.0
        if pct > tk.progress_pct:
            self._task = TaskStatus(tk.task_id, tk.kind, TASK_RUNNING, pct)

    def _apply_reposition(self) -> None:
        assert self._sp is not None and self._reposition is not None
        (n, e, d), yaw = self._reposition
        self._reposition = None
        x, y, z = self._sp.pos_ned
        pos = (x if math.isnan(n) else n, y if math.isnan(e) else e, z if math.isnan(d) else d)
        self._sp = Setpoint(pos, self._sp.pitch_rad, self._sp.yaw_rad if math.isnan(yaw) else yaw)
        self._hold_on_ground = False
        self._events.append(f"Reposition to N {pos[0]:.2f} E {pos[1]:.2f} D {pos[2]:.2f} m")

    @property
    def mission_progress(self) -> Progress:
        return self._progress

    # --- the step ------------------------------------------------------------------------------------
    def step(self, inp: ModeInputs) -> ModeOutput:
        inp = self._sanitise(inp)
        t = inp.t_s
        prev = self._last
        if prev is None:
            dt = 0.0
        else:
            dt = t - prev.t_s
            if dt < 0.0:  # max(dt, 0.0)
                dt = 0.0
        home = self._home
        if home is None:
            if self._script is not None and self._script.starts_armed_in_air:
                home = (inp.pos_ned[0], inp.pos_ned[1], self._cfg.air_start_home_z_ned_m)
            else:
                home = inp.pos_ned
            self._home = home
            self._home_yaw_rad = inp.yaw_rad
        landed = self._detector.step(inp, home[2])
        self._last = inp
        if not self._armed and self._mode is not FlightMode.READY and self._mode not in _SELECTABLE_DISARMED:
            self._switch(FlightMode.READY)
        if self._entry_pending:
            self._enter(inp)
        setpoint, engaged, mission_time = self._run(inp, dt)
        self._update_task(inp)
        armed = self._armed
        mode = self._mode
        events = self._events
        out = ModeOutput(
            t,
            armed,
            engaged,
            setpoint,
            mode,
            mode.custom_mode,
            _BASE_MODE_ARMED if armed else _BASE_MODE_DISARMED,
            self._landed_state(),
            self._system_status(inp),
            landed,
            self._home,
            self._home_yaw_rad,
            mission_time,
            tuple(events) if events else (),
            self._mission_progress_now(),
            tuple(self._actions) if self._actions else (),
            self._entries,
        )
        if events:
            events.clear()
        if self._actions:
            self._actions.clear()
        self._last_output = out
        return out

    # --- internals -----------------------------------------------------------------------------------
    def _sanitise(self, inp: ModeInputs) -> ModeInputs:
        """A sample with NaN/Inf state must not become a setpoint: reuse the last good state, flag sensors."""
        pos, vel = inp.pos_ned, inp.vel_ned
        # One NaN or Inf term makes the sum NaN or Inf, so a finite sum means every term is finite (the common
        # case, one check); a non-finite sum is either a bad sample or finite terms that overflowed: look closer.
        total = pos[0] + pos[1] + pos[2] + vel[0] + vel[1] + vel[2] + inp.yaw_rad + inp.t_s
        if total - total == 0.0 or all(map(_isfinite, (*pos, *vel, inp.yaw_rad, inp.t_s))):
            return inp
        last = self._last
        pos = last.pos_ned if last is not None else (0.0, 0.0, 0.0)
        yaw = last.yaw_rad if last is not None else 0.0
        t = inp.t_s if math.isfinite(inp.t_s) else (last.t_s if last is not None else 0.0)
        return ModeInputs(t, pos, (0.0, 0.0, 0.0), yaw, inp.thrust_ratio, False, inp.estimator_ready)

    def _home_z(self) -> float:
        if self._home is not None:
            return self._home[2]
        return self._last.pos_ned[2] if self._last is not None else 0.0

    def _switch(self, mode: FlightMode) -> None:
        tk = self._task
        if tk is not None and tk.running and mode is not self._mode and not (
                tk.kind == "return" and mode is FlightMode.LAND):
            self._end_task(TASK_CANCELLED, f"mode changed to {mode.label}")
        if self._mode is FlightMode.MISSION and mode is not FlightMode.MISSION and self._mission_t0_s is not None:
            if self._last is not None:
                self._mission_elapsed_s = max(self._last.t_s - self._mission_t0_s, 0.0)
            self._mission_t0_s = None
        self._mode = mode
        self._entry_pending = True

    def _disarm(self, event: str) -> None:
        self._armed = False
        self._switch(FlightMode.READY)
        self._events.append(event)

    def _current_pitch(self) -> float:
        out = self._last_output
        return out.setpoint.pitch_rad if out is not None and out.engaged else 0.0

    def _enter(self, inp: ModeInputs) -> None:
        """Entry actions that need a state sample (where to hold, where a ramp starts)."""
        self._entry_pending = False
        self._entries += 1
        x, y, z = inp.pos_ned
        mode = self._mode
        if mode is FlightMode.HOLD:
            self._hold_on_ground = self._detector.landed
            if not self._hold_on_ground:
                x, y = self._stopping_point(x, y, inp.vel_ned, inp.accel_ned)
            self._sp = Setpoint((x, y, z), self._current_pitch(), inp.yaw_rad)
            if self._reposition is not None:
                self._apply_reposition()
        elif mode is FlightMode.POSCTL:
            self._sp = Setpoint((x, y, z), self._current_pitch(), inp.yaw_rad)
        elif mode is FlightMode.OFFBOARD:  # the reference starts where the vehicle was being held
            out = self._last_output
            self._sp = (Setpoint(out.setpoint.pos_ned, out.setpoint.pitch_rad, out.setpoint.yaw_rad)
                        if out is not None and out.engaged else Setpoint((x, y, z), 0.0, inp.yaw_rad))
            self._ob_ref = self._sp
        elif mode is FlightMode.RTL:
            out = self._last_output
            start = out.setpoint if out is not None and out.engaged else Setpoint((x, y, z), 0.0, inp.yaw_rad)
            self._rtl = MissionExecutor(_RTL_PLAN, self._origin, self._home or inp.pos_ned,
                                        Setpoint(start.pos_ned, 0.0, start.yaw_rad), self._exec_config())
        elif mode is FlightMode.TAKEOFF:
            self._sp = Setpoint((x, y, z), 0.0, inp.yaw_rad)
            self._ramp_z = z
            self._target_z = self._home_z() - self._takeoff_alt_m
        elif mode is FlightMode.LAND:
            if self._land_xy is not None:
                x, y = self._land_xy
                self._land_xy = None
            self._sp = Setpoint((x, y, z), 0.0, inp.yaw_rad)
            self._ramp_z = z
            self._target_z = max(self._home_z(), z) + self._cfg.land_setpoint_floor_m
            self._touchdown_t_s = None
        elif mode is FlightMode.MISSION and self._script is None:
            if not self._armed:
                return  # selected on the ground: starts when armed
            out = self._last_output
            start = out.setpoint if out is not None and out.engaged else Setpoint((x, y, z), 0.0, inp.yaw_rad)
            assert self._plan is not None
            if self._exec is None or self._exec.finished:
                self._exec = MissionExecutor(self._plan, self._origin, self._home or inp.pos_ned, start,
                                             self._exec_config(), self._reached_count)
                self._events.append(f"Mission started at item {self._exec.progress.current}")
            else:
                self._events.append(f"Mission resumed at item {self._exec.progress.current}")
        elif mode is FlightMode.MISSION:
            assert self._script is not None
            duration = self._script.duration_s
            if self._mission_t0_s is None:
                if duration is not None and self._mission_elapsed_s >= duration:
                    self._mission_elapsed_s = 0.0  # a finished mission starts again
                self._mission_t0_s = inp.t_s - self._mission_elapsed_s
                verb = "resumed" if self._mission_elapsed_s > 0.0 else "started"
                self._events.append(f"Mission {self._script.name} {verb}")
            else:
                self._events.append(f"Mission {self._script.name} started (armed in the air)")
        else:
            self._sp = None

    def _run(self, inp: ModeInputs, dt: float) -> tuple[Setpoint, bool, float | None]:
        mode = self._mode
        if mode is FlightMode.MISSION and self._armed:
            if self._script is None:
                return self._run_plan(inp, dt)
            return self._run_mission(inp.t_s)
        if not self._armed or mode is FlightMode.READY:
            return _idle(inp), False, None
        if mode is FlightMode.HOLD:
            assert self._sp is not None
            if self._hold_on_ground:
                return _idle(inp), False, None
            return self._sp, True, None
        if mode is FlightMode.RTL:
            return self._run_rtl(inp, dt)
        if mode is FlightMode.POSCTL:
            return self._run_position(inp, dt), True, None
        if mode is FlightMode.OFFBOARD:
            if self._offboard is None:  # lost between the stack's check and this step
                self._switch(FlightMode.HOLD)
                return self._last_output.setpoint if self._last_output else _idle(inp), True, None
            sp = self._run_offboard(inp, dt)
            if self._detector.landed and sp.pos_ned[2] > inp.pos_ned[2] - self._cfg.offboard_liftoff_m:
                return _idle(inp), False, None  # on the ground and not asked to climb: idle, as PX4's takeoff state
            return sp, True, None
        if mode is FlightMode.TAKEOFF:
            assert self._sp is not None
            self._ramp_z = _approach(self._ramp_z, self._target_z, self._cfg.takeoff_climb_rate_m_s * dt)
            sp = Setpoint((self._sp.pos_ned[0], self._sp.pos_ned[1], self._ramp_z), 0.0, self._sp.yaw_rad)
            if (
                self._ramp_z == self._target_z
                and abs(inp.pos_ned[2] - self._target_z) < self._cfg.takeoff_reached_tol_m
            ):
                if self._task is not None and self._task.running and self._task.kind == "takeoff":
                    self._end_task(TASK_DONE)
                self._switch(FlightMode.HOLD)
                self._entry_pending = False
                self._hold_on_ground = False
                self._sp = sp
                self._events.append(f"Takeoff complete: holding at {self._takeoff_alt_m:.1f} m")
            return sp, True, None
        if mode is FlightMode.LAND:
            assert self._sp is not None
            if self._touchdown_t_s is None:
                if self._detector.landed or self._ground_contact(inp):
                    self._touchdown_t_s = inp.t_s
                    self._events.append("Landed")
                    if self._task is not None and self._task.running and self._task.kind in ("land", "return"):
                        self._end_task(TASK_DONE)
                    return _idle(inp), False, None
                self._ramp_z = _approach(self._ramp_z, self._target_z, self._cfg.land_descent_rate_m_s * dt)
                return (
                    Setpoint((self._sp.pos_ned[0], self._sp.pos_ned[1], self._ramp_z), 0.0, self._sp.yaw_rad),
                    True,
                    None,
                )
            if inp.t_s - self._touchdown_t_s >= self._cfg.land_disarm_delay_s:
                self._disarm("Disarmed after landing")
                self._entry_pending = False
            return _idle(inp), False, None
        raise AssertionError(f"unhandled mode {mode}")  # MISSION is handled first

    def _ground_contact(self, inp: ModeInputs) -> bool:
        """LAND's touchdown without the detector's hold: within land_contact_height_m of home height, slow, and held
        up by something: the descending setpoint is LAND_CONTACT_LAG_M below the vehicle. Without that last
        condition a slow hover anywhere below home height (home on a roof) was taken for touchdown."""
        home = self._home
        z = inp.pos_ned[2]
        return (home is not None and abs(home[2] - z) < self._cfg.land_contact_height_m
                and self._ramp_z > z + LAND_CONTACT_LAG_M and self._detector.slow(inp))

    def _run_mission(self, t_s: float) -> tuple[Setpoint, bool, float | None]:
        script = self._script
        assert script is not None and self._mission_t0_s is not None
        mission_t = t_s - self._mission_t0_s
        duration = script.duration_s
        if duration is not None and mission_t >= duration:
            final = script.setpoint_at(duration)
            self._mission_elapsed_s = duration
            self._mission_t0_s = None
            self._mode = FlightMode.HOLD
            self._hold_on_ground = False
            self._sp = final
            self._events.append(f"Mission {script.name} complete: holding")
            return final, True, None
        return script.setpoint_at(mission_t), True, mission_t

    def _run_position(self, inp: ModeInputs, dt: float) -> Setpoint:
        """Sticks -> velocities in the heading frame, integrated into the position setpoint (PX4's Position mode:
        centred sticks hold), the setpoint kept within manual_lead_m of the vehicle."""
        assert self._sp is not None
        cfg = self._cfg
        db = cfg.manual_deadband
        x, y, r = (0.0 if abs(v) < db else v for v in (self._sticks[0], self._sticks[1], self._sticks[3]))
        sp = self._sp
        yaw = _wrap_pi(sp.yaw_rad + r * cfg.manual_yaw_rate_rad_s * dt)
        c, s_ = math.cos(yaw), math.sin(yaw)
        v = cfg.manual_speed_m_s
        vn, ve, vd = (c * x - s_ * y) * v, (s_ * x + c * y) * v, self._climb_rate_down(self._sticks[2])
        self._sp = Setpoint(_integrate_led(sp.pos_ned, (vn, ve, vd), inp.pos_ned, dt, cfg.manual_lead_m),
                            sp.pitch_rad, yaw)
        return self._sp

    def _climb_rate_down(self, throttle: float) -> float:
        """A throttle in [0, 1] (0.5 = hold altitude, deadband around it) -> NED down speed, m/s."""
        z = throttle - 0.5
        return 0.0 if abs(z) < self._cfg.manual_deadband else -2.0 * z * self._cfg.manual_climb_m_s

    def set_position_gain(self, pos_k_1_s: float) -> None:
        """The outer loop's position gain OL_POS_K (1/s): offboard velocity feed-forward is the offset v / K_p."""
        self._pos_gain_1_s = float(pos_k_1_s)

    def set_braking(self, acc_m_s2: float, jerk_m_s3: float, lag_s: float = 0.0) -> None:
        """The limits the position reference brakes with (OL_ACC_REF and OL_JERK_MAX when shaping, with its jerk
        stage's lag; else OL_ACC_MAX, no jerk limit (inf), no lag): Hold's entry point is where they bring the
        vehicle to rest."""
        if not (acc_m_s2 > 0.0 and jerk_m_s3 > 0.0 and lag_s >= 0.0):
            raise ValueError(f"braking limits must be positive (inf = none), got {acc_m_s2}, {jerk_m_s3}, {lag_s}")
        self._brake_acc_m_s2, self._brake_jerk_m_s3, self._brake_lag_s = float(acc_m_s2), float(jerk_m_s3), float(lag_s)

    def _stopping_point(self, x: float, y: float, vel_ned: Vec3, accel_ned: Vec3) -> tuple[float, float]:
        """Where the horizontal motion comes to rest under the position reference's braking limits
        (braking_distance_m); holding any nearer point flies past it and back."""
        vx, vy = vel_ned[0], vel_ned[1]
        v = math.hypot(vx, vy)
        if not v > 0.0:  # also NaN
            return x, y
        ux, uy = vx / v, vy / v
        a_along = accel_ned[0] * ux + accel_ned[1] * uy
        d = braking_distance_m(v, a_along if math.isfinite(a_along) else 0.0, self._brake_acc_m_s2,
                               self._brake_jerk_m_s3, self._brake_lag_s)
        return x + ux * d, y + uy * d

    def _run_offboard(self, inp: ModeInputs, dt: float) -> Setpoint:
        """The streamed target -> this step's setpoint (OffboardTarget's docstring). The reference (self._ob_ref)
        integrates velocity-only axes and yaw rate; the flown setpoint adds the velocity feed-forward."""
        tgt = self._offboard
        assert tgt is not None
        ref = self._ob_ref
        pos, vel = tgt.pos_ned, tgt.vel_ned
        if not math.isnan(tgt.throttle) and math.isnan(pos[2]) and math.isnan(vel[2]):
            vel = (vel[0], vel[1], self._climb_rate_down(tgt.throttle))
        v_int = tuple(0.0 if math.isnan(v) or not math.isnan(p) else v for p, v in zip(pos, vel, strict=True))
        moved = _integrate_led(ref.pos_ned, v_int, inp.pos_ned, dt, self._cfg.manual_lead_m)  # type: ignore[arg-type]
        ref_pos = tuple(m if math.isnan(p) else p for p, m in zip(pos, moved, strict=True))
        if not math.isnan(tgt.yaw_rad):
            yaw = tgt.yaw_rad
        elif not math.isnan(tgt.yaw_rate_rad_s):
            yaw = _wrap_pi(ref.yaw_rad + tgt.yaw_rate_rad_s * dt)
        else:
            yaw = ref.yaw_rad
        pitch = ref.pitch_rad if math.isnan(tgt.pitch_rad) else tgt.pitch_rad
        self._ob_ref = Setpoint(ref_pos, pitch, yaw)  # type: ignore[arg-type]
        k = self._pos_gain_1_s
        if k <= 0.0 or all(math.isnan(v) for v in vel):
            return self._ob_ref
        ff = tuple(r if math.isnan(v) else r + v / k for r, v in zip(ref_pos, vel, strict=True))
        return Setpoint(ff, pitch, yaw)  # type: ignore[arg-type]

    def _exec_config(self) -> ExecConfig:
        cfg = self._cfg
        return ExecConfig(cfg.takeoff_climb_rate_m_s, cfg.takeoff_reached_tol_m, rtl_alt_m=cfg.rtl_alt_m)

    def _run_rtl(self, inp: ModeInputs, dt: float) -> tuple[Setpoint, bool, float | None]:
        ex = self._rtl
        assert ex is not None
        st = ex.step(inp.t_s, inp.pos_ned, inp.yaw_rad, dt)
        if st.land:
            self._land_xy = (st.setpoint.pos_ned[0], st.setpoint.pos_ned[1])
            self._switch(FlightMode.LAND)
            self._events.append("Return: landing at home")
        return st.setpoint, True, None

    def _run_plan(self, inp: ModeInputs, dt: float) -> tuple[Setpoint, bool, float | None]:
        ex = self._exec
        assert ex is not None
        st = ex.step(inp.t_s, inp.pos_ned, inp.yaw_rad, dt)
        self._reached_count = ex.reached_count
        self._progress = ex.progress
        self._actions += st.actions
        self._events += st.events
        if st.land:
            self._land_xy = (st.setpoint.pos_ned[0], st.setpoint.pos_ned[1])
            self._switch(FlightMode.LAND)
            self._events.append("Mission: landing")
        elif ex.finished:
            self._switch(FlightMode.HOLD)
            self._entry_pending = False
            self._hold_on_ground = self._detector.landed
            self._sp = st.setpoint
        return st.setpoint, True, None

    def _mission_progress_now(self) -> Progress:
        p = self._progress
        active = self._mode is FlightMode.MISSION and self._script is None
        return p if p.active == active else Progress(p.current, p.reached, active, p.finished, p.reached_log)

    def _landed_state(self) -> int:
        """MAV_LANDED_STATE (as a plain int, the way ModeOutput carries it)."""
        mode = self._mode
        if not self._armed or mode is FlightMode.READY:
            return _ON_GROUND if self._detector.landed else _IN_AIR
        if mode is FlightMode.MISSION:
            return _ON_GROUND if self._detector.landed else _IN_AIR
        if mode is FlightMode.TAKEOFF:
            return _TAKEOFF
        if mode is FlightMode.LAND:
            return _LANDING if self._touchdown_t_s is None else _ON_GROUND
        if mode is FlightMode.HOLD and self._hold_on_ground:
            return _ON_GROUND
        return _IN_AIR

    def _system_status(self, inp: ModeInputs) -> int:
        """MAV_STATE (as a plain int, the way ModeOutput carries it)."""
        if not self._armed:
            return _STANDBY
        return _ACTIVE if inp.sensors_ok and not self._faults else _CRITICAL


_isfinite = math.isfinite


def _wrap_pi(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi

_SELECTABLE_DISARMED = (FlightMode.HOLD, FlightMode.MISSION)
_RTL_PLAN = Plan(0, (MissionItem(2, int(Cmd.NAV_RETURN_TO_LAUNCH), 1, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0),))
_BASE_MODE_DISARMED = int(MavModeFlag.CUSTOM_MODE_ENABLED)
_BASE_MODE_ARMED = int(MavModeFlag.CUSTOM_MODE_ENABLED) | int(MavModeFlag.SAFETY_ARMED)
_ON_GROUND = int(MavLandedState.ON_GROUND)
_IN_AIR = int(MavLandedState.IN_AIR)
_TAKEOFF = int(MavLandedState.TAKEOFF)
_LANDING = int(MavLandedState.LANDING)
_STANDBY = int(MavState.STANDBY)
_ACTIVE = int(MavState.ACTIVE)
_CRITICAL = int(MavState.CRITICAL)
def _idle(inp: ModeInputs) -> Setpoint:
    """The setpoint reported while the controller is idle: where the vehicle is."""
    return Setpoint(inp.pos_ned, 0.0, inp.yaw_rad)


def _integrate_led(sp: Vec3, vel: Vec3, pos: Vec3, dt: float, lead_m: float) -> Vec3:
    """A velocity-driven setpoint one step on (sp + vel dt per axis), kept within lead_m of the vehicle on each
    axis so it cannot wind up while the vehicle lags (Position mode's sticks, offboard velocity targets)."""
    return tuple(min(p + lead_m, max(p - lead_m, s + v * dt))  # type: ignore[return-value]
                 for s, v, p in zip(sp, vel, pos, strict=True))


def _approach(value: float, target: float, max_step: float) -> float:
    """Move `value` toward `target` by at most `max_step`; lands exactly on the target."""
    if abs(target - value) <= max_step:
        return target
    return value + math.copysign(max_step, target - value)


def _px4_name(main: int, sub: int) -> str:
    try:
        main_name = Px4MainMode(int(main)).name
    except ValueError:
        main_name = str(int(main))
    return f"{main_name}.{int(sub)}" if int(sub) else main_name
