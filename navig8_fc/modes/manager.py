"""Flight-mode and arming state machine of the flight controller (pure, on sim time): arming and its checks, the
commands that choose modes, and the fault registry.

One `step(ModeInputs) -> ModeOutput` per control tick, on the sensor bundle's time (lockstep: the bridge is
the time master, DESIGN §4). Commands (`arm`, `disarm`, `takeoff`, `land`, `set_mode`) arrive between steps
from the GCS side; they answer at once with a `Verdict` (accepted, or the reason for STATUSTEXT) and change
`armed`/the mode at once, while everything that needs a fresh state sample (where a ramp starts, where to
hold) happens at the next step: the new mode's `enter`. The manager never touches sockets, clocks or pymavlink.

The manager decides (`ModeReadout` holds its state and what it reports, `ModeManager` adds the commands and the step);
the mode switch (`switch.ModeSwitch`) holds the mode state and runs the step. Modes (PX4
encoding, navig8_fc.modes.px4; docs/gcs.md), each a small class in its own module of this package
(navig8_fc.modes.context describes what they share and hand back):
- READY (AUTO.READY): on the ground, armed or not; controller idle (motors off in the model). No class.
- TAKEOFF `takeoff.Takeoff`, HOLD `hold.Hold`, LAND `land.Land`, POSCTL `position.Position`, OFFBOARD
  `offboard.Offboard`, RTL `rtl.Return`, MISSION `mission.Mission` (a scenario script or an uploaded plan), ORBIT
  `orbit.Orbit` (MAV_CMD_DO_ORBIT).
The land detector is `land_detector.LandDetector`, Hold's stopping point `braking`, the long-running commands'
tracking `tasks.TaskTracker`, the records (config, inputs, outputs) `records`, the MAVLink encodings `px4`.

Home is the position at arming (PX4); before the first arming it is where the vehicle stood at the first
step, so a GCS has a home to show (MAVSDK examples wait for home before arming). For an air start, home is
the start position projected onto `ModeConfig.air_start_home_z_ned_m` (the plant's ground is NED z = 0).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Plan, Progress
from navig8_fc.modes.braking import braking_distance_m
from navig8_fc.modes.land_detector import LandDetector
from navig8_fc.modes.orbit import OrbitPlan, OrbitRequest
from navig8_fc.modes.px4 import (
    BASE_MODE_ARMED,
    BASE_MODE_DISARMED,
    STATE_STANDBY,
    FlightMode,
    Px4AutoSubMode,
    Px4MainMode,
    px4_mode_name,
    system_status,
)
from navig8_fc.modes.records import (
    MissionScript,
    ModeConfig,
    ModeInputs,
    ModeOutput,
    OffboardTarget,
    ReferenceLimits,
    Vec3,
    Verdict,
)
from navig8_fc.modes.switch import ModeSwitch
from navig8_fc.modes.tasks import TASK_CANCELLED, TASK_DONE, TASK_FAILED, TASK_RUNNING, TaskStatus

__all__ = [  # the manager's API, and the names callers import from here
    "TASK_CANCELLED", "TASK_DONE", "TASK_FAILED", "TASK_RUNNING", "LandDetector", "MissionScript", "ModeConfig",
    "ModeInputs", "ModeManager", "ModeOutput", "ModeReadout", "OffboardTarget", "TaskStatus", "Verdict",
    "braking_distance_m",
]


class ModeReadout:
    """The mode manager's state and what it reports: the mode switch, the faults set from outside the step, the
    pre-arm check and the read-only views (ModeManager adds the commands and the step)."""

    def __init__(self, config: ModeConfig | None = None, script: MissionScript | None = None) -> None:
        self._cfg = config or ModeConfig()
        sw = self._sw = ModeSwitch(self._cfg, script)  # the mode state and its step
        self._ctx, self._tasks, self._detector = sw.ctx, sw.tasks, sw.detector
        # Faults reported from outside the step (the FlightStack's link checks, rate check): name -> reason.
        self._faults: dict[str, str] = {}

    # --- read access ---------------------------------------------------------------------------------
    @property
    def config(self) -> ModeConfig:
        return self._cfg

    @property
    def script(self) -> MissionScript | None:
        return self._sw.mission.script

    @property
    def armed(self) -> bool:
        return self._sw.armed

    @property
    def flight_mode(self) -> FlightMode:
        return self._sw.mode

    @property
    def entry_pending(self) -> bool:  # a mode's entry runs at the next step: it alone reads ModeInputs.accel_ned_m_s2
        return self._sw.entry_pending

    @property
    def custom_mode(self) -> int:
        return self._sw.mode.custom_mode

    @property
    def base_mode(self) -> int:
        return BASE_MODE_ARMED if self._sw.armed else BASE_MODE_DISARMED

    @property
    def landed(self) -> bool:
        return self._detector.landed

    @property
    def home_ned_m(self) -> Vec3 | None:
        return self._ctx.home

    @property
    def home_yaw_rad(self) -> float:
        return self._sw.home_yaw_rad

    @property
    def last_output(self) -> ModeOutput | None:
        return self._ctx.last_output

    @property
    def sticks(self) -> tuple[float, float, float, float]:
        """The last MANUAL_CONTROL sticks as Position mode flies them (x, y, r in [-1, 1], z in [0, 1])."""
        return self._sw.position.sticks

    @property
    def offboard_target(self) -> OffboardTarget | None:
        """The streamed offboard target in force (None: no stream, or lost)."""
        return self._sw.offboard.target

    @property
    def task(self) -> TaskStatus | None:
        """The last long-running flight command (running or how it ended); None before the first."""
        return self._tasks.task

    @property
    def mission_progress(self) -> Progress:
        return self._sw.mission.progress

    @property
    def faults(self) -> dict[str, str]:
        """The faults now set (name -> reason); a copy."""
        return dict(self._faults)

    def set_fault(self, name: str, reason: str) -> None:
        """A fault found outside the step (e.g. no sensor bundles for FS_SENS_TOUT, a control-rate mismatch): pre-arm
        fails with `reason`, takeoff is refused and an armed vehicle reports MAV_STATE_CRITICAL until `clear_fault`;
        the flight itself is not changed (the FlightStack decides on failsafe actions)."""
        self._faults[name] = reason

    def clear_fault(self, name: str) -> bool:
        """Clear a fault; True when it was set."""
        return self._faults.pop(name, None) is not None

    @property
    def system_status(self) -> int:
        """MAV_STATE now, including faults set since the last step (HEARTBEAT reads this, not the last step's)."""
        if self._sw.last is None:
            return STATE_STANDBY
        return system_status(self._sw.armed, self._sw.last.sensors_ok, bool(self._faults))

    def prearm_check(self) -> Verdict:
        """Would `arm()` pass its checks now? (Also drives SYS_STATUS's PREARM_CHECK health bit.)"""
        inp = self._sw.last
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

    @property
    def orbit_plan(self) -> OrbitPlan | None:
        """The orbit being flown (None outside ORBIT)."""
        return self._sw.orbit.plan if self._sw.mode is FlightMode.ORBIT else None


class ModeManager(ModeReadout):
    """Arming, modes and setpoints (module docstring). Not thread-safe: one owner calls everything."""

    # --- commands ------------------------------------------------------------------------------------
    def arm(self, force: bool = False) -> Verdict:
        if self._sw.armed:
            return Verdict(True, "already armed")
        if self._sw.last is None:
            return Verdict(False, "Arming denied: no sensor data yet")
        if not force:
            check = self.prearm_check()
            if not check.ok:
                return Verdict(False, f"Arming denied: {check.reason}")
        inp = self._sw.last
        self._sw.armed = True
        self._ctx.home = inp.pos_ned_m
        self._sw.home_yaw_rad = inp.yaw_rad
        # Armed in Mission: the mission starts. A forced arm in the air must not leave the controller idle: hold
        # where the vehicle is.
        if self._sw.mode is FlightMode.MISSION:
            self._sw.switch(FlightMode.MISSION)
        else:
            self._sw.switch(FlightMode.READY if self._detector.landed else FlightMode.HOLD)
        self._ctx.events.append("Armed" + (" (forced)" if force else ""))
        return Verdict(True)

    def disarm(self, force: bool = False) -> Verdict:
        if not self._sw.armed:
            return Verdict(True, "already disarmed")
        if not force and not self._detector.landed:
            return Verdict(False, "Disarming denied: not landed")
        self._disarm("Disarmed" + (" (forced)" if force else ""))
        return Verdict(True)

    def takeoff(self, alt_above_home_m: float = math.nan) -> Verdict:
        if not self._sw.armed:
            return Verdict(False, "Takeoff denied: not armed")
        alt = self._cfg.takeoff_default_alt_m if math.isnan(alt_above_home_m) else float(alt_above_home_m)
        if not (0.0 < alt <= self._cfg.takeoff_max_alt_m):
            return Verdict(False, f"Takeoff denied: altitude {alt:g} m outside (0, {self._cfg.takeoff_max_alt_m:g}]")
        if self._sw.last is not None and not self._sw.last.sensors_ok:
            return Verdict(False, "Takeoff denied: sensors not ready")
        if self._faults:
            return Verdict(False, f"Takeoff denied: {next(iter(self._faults.values()))}")
        self._sw.takeoff.alt_m = alt
        if self._sw.mode is FlightMode.TAKEOFF and not self._sw.entry_pending:
            self._sw.takeoff.retarget(self._sw.home_z())  # the ramp carries on from where it is
        else:
            self._sw.switch(FlightMode.TAKEOFF)
        here = self._sw.here()
        self._tasks.start("takeoff", here, (here[0], here[1], self._sw.home_z() - alt))
        self._ctx.events.append(f"Takeoff to {alt:.1f} m above home")
        return Verdict(True)

    def land(self) -> Verdict:
        if not self._sw.armed:
            return Verdict(False, "Land denied: not armed")
        if self._sw.mode is FlightMode.RTL and self._tasks.running:
            self._tasks.end(TASK_CANCELLED, "replaced by land")  # land here, not at home
        if self._sw.mode is not FlightMode.LAND:
            self._sw.switch(FlightMode.LAND)
            self._ctx.events.append("Landing")
        if not self._detector.landed and not self._tasks.running_kind("land", "return"):
            here = self._sw.here()
            self._tasks.start("land", here, (here[0], here[1], self._sw.home_z()))
        return Verdict(True)

    def set_mode(self, custom_main: int, custom_sub: int) -> Verdict:
        """PX4 main/sub mode (DO_SET_MODE p2/p3)."""
        mode = FlightMode.from_px4(int(custom_main), int(custom_sub))
        if mode is None:
            return Verdict(
                False, f"Mode {px4_mode_name(custom_main, custom_sub)} not supported "
                "(Ready, Takeoff, Hold, Land, Mission, Return, Offboard, Position, Orbit)"
            )
        if mode is FlightMode.TAKEOFF:
            return self.takeoff()
        if mode is FlightMode.LAND:
            return self.land()
        if mode is FlightMode.READY:
            if self._sw.armed and not self._detector.landed:
                return Verdict(False, "Mode Ready denied: only on the ground")
            return self._enter_mode(mode)
        flying = self._sw.armed and not self._detector.landed
        if mode is FlightMode.RTL:
            return self._enter_mode(mode, "Returning to launch") if flying else Verdict(
                False, "Return denied: not flying")
        if mode is FlightMode.POSCTL:
            return self._enter_mode(mode, "Position") if flying else Verdict(
                False, "Position denied: not flying (take off first)")
        if mode is FlightMode.ORBIT:  # chosen as a mode: PX4's defaults around where the vehicle is
            return self.orbit(OrbitRequest()) if self._sw.mode is not mode else Verdict(True)
        if mode is FlightMode.OFFBOARD:
            if self._sw.offboard.target is None:
                return Verdict(False, "Offboard denied: no setpoint stream (send SET_POSITION_TARGET_* first)")
            return self._enter_mode(mode, "Offboard") if self._sw.armed else Verdict(
                False, "Offboard denied: not armed")
        # Hold and Mission can be selected while disarmed, as on PX4 (arming then starts the mission).
        if mode is FlightMode.HOLD:
            return self._enter_mode(mode, "Hold")
        if self._sw.mission.script is None and self._sw.mission.plan is None:
            return Verdict(False, "Mode Mission denied: no mission loaded")
        return self._enter_mode(mode)

    def _enter_mode(self, mode: FlightMode, event: str = "") -> Verdict:
        """Switch to `mode` (announcing `event`, if any) unless already in it."""
        if self._sw.mode is not mode:
            self._sw.switch(mode)
            if event:
                self._ctx.events.append(event)
        return Verdict(True)

    def set_custom_mode(self, custom_mode: int) -> Verdict:  # set_mode from a PX4-encoded custom_mode
        return self.set_mode((custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF)

    def load_plan(self, plan: Plan, origin: GeoOrigin) -> None:
        """An uploaded mission plan (or a new start item): flown in MISSION when there is no script. A mission
        in flight continues on the new plan from its start item at the next step."""
        self._sw.load_plan(plan, origin)

    def load_rally(self, plan: Plan, origin: GeoOrigin) -> None:
        """An uploaded rally plan (empty: cleared): every return chooses among its points (mission.rally)."""
        self._ctx.rally, self._ctx.rally_origin = (plan if plan.items else None), origin

    def set_mode_params(self, takeoff_alt_m: float, rtl_alt_m: float, hover_thrust: float = 0.5,
                        max_height_m: float = math.inf) -> None:
        """MIS_TAKEOFF_ALT, RTL_RETURN_ALT, MPC_THR_HOVER and VOL_ALT_MAX, live: the next takeoff / return /
        attitude target, the ceiling of velocity-driven references from the next step."""
        cfg = self._cfg
        new = (takeoff_alt_m, rtl_alt_m, hover_thrust, max_height_m)
        if (cfg.takeoff_default_alt_m, cfg.rtl_alt_m, cfg.hover_thrust, cfg.max_height_m) != new:
            self._cfg = self._ctx.config = replace(cfg, takeoff_default_alt_m=takeoff_alt_m, rtl_alt_m=rtl_alt_m,
                                                   hover_thrust=hover_thrust, max_height_m=max_height_m)

    def offboard_setpoint(self, sp: Setpoint | OffboardTarget | None) -> None:
        """The latest streamed offboard target (a Setpoint: position, pitch, yaw; None: the stream is lost, the
        FlightStack decides on timeouts). Offboard flies it; losing it in Offboard holds where the vehicle is."""
        self._sw.offboard.set_target(sp)
        if sp is None and self._sw.mode is FlightMode.OFFBOARD:
            self._sw.switch(FlightMode.HOLD)

    def manual_input(self, x: float, y: float, z: float, r: float) -> None:
        """MANUAL_CONTROL sticks, normalised: x forward, y right, r yaw right in [-1, 1], z throttle in [0, 1]
        (0.5 = hold altitude). Position mode flies them; centred sticks hold."""
        self._sw.position.set_sticks(x, y, z, r)

    def reposition(self, pos_ned_m: Vec3, yaw_rad: float = math.nan) -> Verdict:
        """DO_REPOSITION (MAVSDK goto_location, QGC Go to / Pause): Hold at pos_ned_m (NaN: here), yaw_rad (NaN:
        keep)."""
        if not self._sw.armed or self._detector.landed:
            return Verdict(False, "Reposition denied: not flying")
        self._sw.hold.reposition_to(pos_ned_m, yaw_rad)
        if self._sw.mode is FlightMode.HOLD and not self._sw.entry_pending:
            self._sw.hold.apply_reposition()
        else:
            self._sw.switch(FlightMode.HOLD)
        here = self._sw.here()
        self._tasks.start("reposition", here, tuple(h if math.isnan(p) else p  # type: ignore[arg-type]
                                                    for p, h in zip(pos_ned_m, here, strict=True)))
        return Verdict(True)

    def orbit(self, req: OrbitRequest, problem: Callable[[OrbitPlan], str] | None = None) -> Verdict:
        """MAV_CMD_DO_ORBIT, only in flight (navig8_fc.modes.orbit); `problem`: why a resolved orbit may not fly."""
        if not self._sw.armed or self._detector.landed:
            return Verdict(False, "Orbit denied: not flying (take off first)")
        return self._sw.start_orbit(req, problem)

    def return_to_launch(self) -> Verdict:
        """MAV_CMD_NAV_RETURN_TO_LAUNCH: Return mode, reported as a long command (done at touchdown at home)."""
        verdict = self.set_mode(int(Px4MainMode.AUTO), int(Px4AutoSubMode.RTL))
        if verdict.ok and not self._tasks.running_kind("return"):
            self._tasks.start("return", self._sw.here(), self._sw.return_destination())
        return verdict

    def cancel_task(self) -> bool:
        """COMMAND_CANCEL: stop the running flight command and hold where the vehicle is; False when none runs."""
        tk = self._tasks.task
        if tk is None or not tk.running:
            return False
        self._tasks.end(TASK_CANCELLED, "cancelled")
        self._sw.hold.drop_reposition()
        self._sw.switch(FlightMode.HOLD)  # entry: hold here (on the ground: stays idle)
        self._ctx.events.append(f"{tk.kind.capitalize()} cancelled: holding")
        return True

    def fail_task(self, reason: str) -> None:
        """A failsafe takes over: the running flight command ends FAILED (before the failsafe changes the mode)."""
        if self._tasks.running:
            self._tasks.end(TASK_FAILED, reason)

    def set_position_gain(self, pos_k_1_s: float) -> None:
        """The outer loop's position gain OL_POS_K (1/s): offboard velocity feed-forward is the offset v / K_p."""
        self._sw.offboard.pos_gain_1_s = float(pos_k_1_s)

    def set_braking(self, acc_m_s2: float, jerk_m_s3: float, lag_s: float = 0.0) -> None:
        """The limits the position reference brakes with (OL_ACC_REF, OL_JERK_MAX and its jerk stage's lag when
        shaping; else OL_ACC_MAX, no jerk limit (inf), no lag): Hold's entry point is where they stop the vehicle."""
        self._sw.hold.set_braking(float(acc_m_s2), float(jerk_m_s3), float(lag_s))  # ValueError: not positive

    def set_reference_limits(self, limits: ReferenceLimits) -> None:
        """What the position reference flies: the next orbit's speed, Offboard's acceleration targets."""
        self._sw.orbit.limits = self._sw.offboard.limits = limits

    # --- the step ------------------------------------------------------------------------------------
    def step(self, inp: ModeInputs) -> ModeOutput:
        return self._sw.step(inp, bool(self._faults))

    def _disarm(self, event: str) -> None:
        self._sw.disarm()
        self._ctx.events.append(event)
