"""FlightStack: the flight controller as one pure object (mode manager + failsafe decisions + controller core).

`step(sensors, imu_fresh, time_us) -> StepResult` runs one control tick on the sensor bundle's time;
`command(record)` answers a ground station between steps (navig8_fc/flight/commands.py); `check_links`,
`sensor_data` and `tick_failed` take what the shell measures (link ages on its own clock, invalid sensor data, a
tick that raised) for the failsafes; `state()` publishes a frozen `VehicleState`. navig8-fc (lockstep SITL), navig8-sim
(in-process) and the tests drive this same object, so they fly the same code path. No sockets, clocks, prints
or pymavlink here: the caller sends, logs and keeps time.

The failsafe decisions live in navig8_fc/flight/failsafe.py (`Failsafes`), fed by the step and by the shell's
`check_links`, `sensor_data` and `tick_failed`.
Parameter changes in the registry apply at the next step: gains and bounds swap in place; a change of rate,
filter or estimator settings rebuilds the core (its filters depend on them).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

from navig8_fc.core import stability
from navig8_fc.core.arm_preview import hold_plan, plan_rows
from navig8_fc.core.controller import (
    MOTORS_OFF,
    ActuatorCommand,
    ControllerConfig,
    ControllerStatus,
    FcSensors,
    FlightControllerCore,
)
from navig8_fc.core.outer_loop import JERK_K_PER_VEL_K, OuterLoopConfig, Setpoint
from navig8_fc.core.rotation import quat_to_euler
from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.flight.arm_task import ArmJointTask
from navig8_fc.flight.battery import SimulatedPack
from navig8_fc.flight.commands import (
    Arm,
    ArmJoints,
    CancelTask,
    Disarm,
    Gripper,
    Land,
    LoadFence,
    LoadMission,
    LoadRally,
    ManualInput,
    OffboardSetpoint,
    Orbit,
    Reposition,
    ReturnToLaunch,
    SetMode,
    Takeoff,
    VehicleCommand,
)
from navig8_fc.flight.failsafe import Failsafes, FailsafeSettings
from navig8_fc.flight.ff_notices import FeedforwardNotices
from navig8_fc.flight.script import FlightScript
from navig8_fc.flight.sensor_cal import SensorCalibration
from navig8_fc.flight.state import (
    SEVERITY_INFO,
    SEVERITY_WARNING,
    ArmRequest,
    Notice,
    StepResult,
    VehicleState,
)
from navig8_fc.mission.fence import Fence
from navig8_fc.mission.volume import OperatingVolume
from navig8_fc.modes.manager import (
    ModeConfig,
    ModeInputs,
    ModeManager,
    ModeOutput,
    TaskStatus,
    Verdict,
)
from navig8_fc.modes.records import ReferenceLimits
from navig8_fc.params.registry import ParamRegistry

SYSTEM_STATUS_CRITICAL = 5  # MAV_STATE_CRITICAL: a failsafe is in force (PX4 reports the same)
ESTIMATOR_WARMUP_S = 0.5  # 5 time constants of the INDI feedback filter before arming is allowed
_NO_ACCEL = (0.0, 0.0, 0.0)
FAULT_LINK = "link"  # ModeManager fault name: the sim link leaves no stable loop (link_fault)
TASK_FLIGHT, TASK_ARM = "flight", "arm"  # the two kinds of long-running command that can run side by side


def rotor_thrusts_n(vehicle: VehicleConfig, speed_rad_s: tuple[float, float, float]) -> tuple[float, float, float]:
    """Thrust of duct 1, the tail rotor and duct 3 (N) from the propeller speeds: T = k w^2, the tail's sign
    following its direction of spin (U5 = sign(w2) w2^2, Sec. 3)."""
    w1, w2, w3 = speed_rad_s
    kd = vehicle.k_thrust_duct
    return kd * w1 * w1, vehicle.k_thrust_tail * w2 * abs(w2), kd * w3 * w3


def throttle_pct(vehicle: VehicleConfig, speed_rad_s: tuple[float, float, float]) -> float:
    """Collective thrust (duct 1 + tail + duct 3, N) as a percentage of the most the actuators can give at their
    speed limits (VFR_HUD throttle); a reversed tail counts against it, as it does against the lift."""
    t_max = sum(rotor_thrusts_n(vehicle, (vehicle.duct_speed_max, vehicle.tail_speed_max, vehicle.duct_speed_max)))
    return 100.0 * sum(rotor_thrusts_n(vehicle, speed_rad_s)) / t_max


def configure_modes(modes: ModeManager, outer: OuterLoopConfig, values: Mapping[str, float]) -> None:
    """What the modes need of the outer loop and the parameters: the position gain (offboard velocity feed-forward),
    the braking limits (where Hold stops), what the reference can fly (Orbit, attitude targets), the take-off and
    return heights, the hover thrust and the ceiling of velocity-driven references."""
    modes.set_position_gain(outer.pos_k)
    if outer.jerk_max_m_s3 > 0.0:  # the shaped reference brakes at OL_ACC_REF with its jerk limit, its jerk
        # stage answering 1 / K_j late
        modes.set_braking(outer.ref_acc_max_m_s2, outer.jerk_max_m_s3, 1.0 / (JERK_K_PER_VEL_K * outer.vel_k))
    else:  # the setpoint goes to the loop as it is: the loop's own acceleration limit
        modes.set_braking(outer.acc_max_m_s2, math.inf)
    modes.set_reference_limits(ReferenceLimits.of_outer_loop(outer, float(values["ORB_RAD_MAX"])))
    modes.set_mode_params(float(values["MIS_TAKEOFF_ALT"]), float(values["RTL_RETURN_ALT"]),
                          float(values["MPC_THR_HOVER"]), float(values["VOL_ALT_MAX"]))


class FlightStack:
    """Mode manager + failsafes + controller core (module docstring). One owner calls everything."""

    def __init__(self, vehicle: VehicleConfig, registry: ParamRegistry, script: FlightScript | None = None,
                 mode_config: ModeConfig | None = None, sensor_source: str = "navig8-bridge") -> None:
        self.vehicle = vehicle
        self.registry = registry
        self.script = script
        self._sensor_source = sensor_source  # named in the sensor-stale notices
        self._core: FlightControllerCore | None = None
        self._cfg_generation = -1
        self._link_k_floor = 0.0  # the registry's link floor the core flies (reconfigure)
        self.lambda_crit = self.lambda_min = math.nan  # lambda_min: INDI_LAMBDA_MIN, the target beside lambda_crit
        # the arm's commanded trajectory the core's arm preview reads (INDI_ARM_FF = 2): the script's, then held
        # targets of arm-joint commands
        self._arm_plan = (plan_rows(tuple((g.t0_s, g.t1_s, g.q_start_rad, g.q_end_rad) for g in script.arm_plan))
                          if script is not None and script.arm_plan else None)
        self._modes = ModeManager(mode_config or ModeConfig(), script.mission() if script is not None else None)
        self._handlers = self._command_handlers()  # command record type -> what applies it
        self._sensor_cal: SensorCalibration | None = None  # the gyro offsets and level horizon (None: nothing)
        self._fs = Failsafes(self._modes, FailsafeSettings.from_params(registry.as_dict()), sensor_source)
        self._ff_notices: FeedforwardNotices  # built with the first core (reconfigure)
        self.reconfigure()
        self._weight_n = vehicle.uam_mass_kg * vehicle.gravity_m_s2
        self._n_steps = 0
        self._last_time_us: int | None = None
        self._sensors: FcSensors | None = None
        self._status: ControllerStatus | None = None
        self._command: ActuatorCommand = MOTORS_OFF
        self._mode_out: ModeOutput | None = None
        self._pack = SimulatedPack()  # the battery, loaded with the rotors' induced power
        self._arm_request: ArmRequest | None = None
        self._notices: list[Notice] = []  # decided in the step before the mode manager runs (the rate check)
        # The long-running arm-joint move (COMMAND_ACK IN_PROGRESS): its status, start and target (rad), start time.
        self._arm_task = ArmJointTask()

    # --- configuration ---------------------------------------------------------------------------------
    @property
    def core(self) -> FlightControllerCore:
        assert self._core is not None
        return self._core

    @property
    def mode_config(self) -> ModeConfig:
        """The mode manager's configuration in force (MIS_TAKEOFF_ALT and RTL_RETURN_ALT applied)."""
        return self._modes.config

    def reconfigure(self) -> bool:
        """Apply the registry's parameters if they changed since the last call (each step calls it); True when
        something was applied."""
        reg = self.registry
        if reg.generation == self._cfg_generation:
            return False
        values = reg.flown_values()  # one snapshot types every component's settings (the automatic link floor in)
        cfg = ControllerConfig.from_params(values, self.vehicle)
        core = self._core
        # the automatic link floor moved the flown K's floor alone: applied in place (it may rise in flight), never a
        # new core (a new core's filters and estimator start afresh)
        link_floor_only = (core is not None and reg.link_k_floor != self._link_k_floor
                           and replace(cfg.indi, k_flown_min=core.config.indi.k_flown_min) == core.config.indi)
        self._link_k_floor = reg.link_k_floor
        if (core is None or (cfg.indi != core.config.indi and not link_floor_only) or cfg.ckf != core.config.ckf
                or cfg.acc_ref != core.config.acc_ref or cfg.arm_wrench != core.config.arm_wrench):
            if core is None:  # what the feed-forward checks start from: the models' parameters
                self._ff_notices = FeedforwardNotices.of(cfg)
            else:
                self._ff_notices.new_core()
            self._core = FlightControllerCore(self.vehicle, cfg)
            self._core.set_arm_plan(self._arm_plan)
        else:
            core.update_gains(cfg.outer, cfg.k_min, cfg.k_max)
            if link_floor_only and cfg.indi != core.config.indi:
                core.set_flown_floor(cfg.indi.k_flown_min)
        configure_modes(self._modes, cfg.outer, values)
        self._cfg_generation = reg.generation
        self._fs.configure(FailsafeSettings.from_params(values))  # typed once per change, not per step
        indi = cfg.indi
        self.lambda_crit = stability.lambda_crit(indi.act_wn_rad_s, indi.act_zeta, cfg.dt_s, indi.lpf_tau_s)
        self.lambda_min = float(values["INDI_LAMBDA_MIN"])
        self._sensor_cal = SensorCalibration.from_params(values)
        return True

    # --- the control step ------------------------------------------------------------------------------
    def step(self, sensors: FcSensors, imu_fresh: bool = True, time_us: int | None = None) -> StepResult:
        """One control tick on `sensors` (sim time). imu_fresh: this step's IMU sample is new (the pre-arm
        sensor check); time_us: the bundle's integer time stamp, for the spacing check (default: from t_s)."""
        self.reconfigure()
        if self._sensor_cal is not None:  # the calibration in force (the published sensors are the corrected ones)
            sensors = self._sensor_cal.apply(sensors)
        t_us = round(sensors.t_s * 1e6) if time_us is None else int(time_us)
        prev_us = self._last_time_us
        self._last_time_us = t_us
        if (rate_notice := self._fs.spacing(prev_us, t_us)) is not None:  # the bridge's --dt against INDI_RATE_HZ
            self._notices.append(rate_notice)
        core = self._core
        assert core is not None
        modes = self._modes
        t1, t2, t3 = rotor_thrusts_n(self.vehicle, sensors.prop_speed_rad_s)
        was_armed = modes.armed
        accel = core.reference_accel_ned if modes.entry_pending else _NO_ACCEL  # its one reader: a mode's entry
        out = modes.step(ModeInputs(sensors.t_s, sensors.pos_ned_m, sensors.vel_ned_m_s,
                                    quat_to_euler(sensors.quat_wxyz)[2],
                                    (t1 + t2 + t3) / self._weight_n, imu_fresh,
                                    self._n_steps * core.config.dt_s >= ESTIMATOR_WARMUP_S, accel))
        if out.armed and not was_armed:
            core.reset()  # the estimator's start delay counts from arming
        elif self._mode_out is not None and out.entries != self._mode_out.entries:
            # A mode (re-)entered (also Hold after a cancelled reposition): the command shaper continues from where
            # the vehicle is, never from a reference that was heading for the old target.
            core.resync_reference()
        cmd, st = core.step(sensors, out.setpoint, engaged=out.engaged)
        if st.ff is not None or st.indi is not None:
            self._notices += self._ff_notices.notices(st)
        self._pack.discharge(sensors.t_s, t1, t2, t3)
        if fs_notices := self._fs.after_step(out.armed, self._pack.state, sensors.pos_ned_m):  # battery, fence
            self._notices += fs_notices
        self._sensors, self._status, self._command, self._mode_out = sensors, st, cmd, out
        if self._arm_task.running:
            self._arm_task.update(sensors.joint_pos_rad, sensors.t_s)
        self._n_steps += 1
        notices = self._notices
        if out.events:
            notices += [Notice(SEVERITY_INFO, ev) for ev in out.events]
        for kind, value in out.actions:  # plan items acting on the arm: checked and applied as the commands are
            ok, reason = self.command(Gripper(value) if kind == "gripper" else ArmJoints(value))  # type: ignore[arg-type]
            if not ok:
                notices.append(Notice(SEVERITY_WARNING, f"Mission item refused: {reason}"))
        if notices:
            self._notices = []
        req, self._arm_request = self._arm_request, None
        return StepResult(cmd, st, out.setpoint, out.armed, out.engaged, tuple(notices), req)

    # --- failsafe inputs from the shell (navig8_fc/flight/failsafe.py decides) -----------------------------
    def check_links(self, sensor_age_s: float | None, gcs_heartbeat_age_s: float | None,
                    offboard_age_s: float | None = None) -> tuple[Notice, ...]:
        """The link ages the shell measures on its own clock: since the last sensor bundle (None before the first),
        the last GCS heartbeat (None: no GCS ever sent one), the last offboard setpoint (None: none yet). Returns
        the notices to announce now; call it often (every loop of the shell)."""
        self.reconfigure()  # a timeout changed between steps (or with no steps at all) applies now
        t_s = self._sensors.t_s if self._sensors is not None else 0.0
        return tuple(self._fs.links(sensor_age_s, gcs_heartbeat_age_s, offboard_age_s, t_s))

    def sensor_data(self, bad_groups: tuple[str, ...], bad_for_s: float) -> tuple[Notice, ...]:
        """The sensor groups the sim guard replaced by their last good values in this bundle, and for how long some
        group has failed (sim s)."""
        notice = self._fs.sensor_data(bad_groups, bad_for_s)
        return () if notice is None else (notice,)

    def link_fault(self, reason: str | None) -> None:
        """The sim link's stability check (the shell's, navig8_fc/shell/fc_process.py): `reason` refuses arming (a
        pre-arm failure; armed: MAV_STATE_CRITICAL, nothing else changes) until it is called with None."""
        if reason is None:
            self._modes.clear_fault(FAULT_LINK)
        else:
            self._modes.set_fault(FAULT_LINK, reason)

    def tick_failed(self, error: str, n_errors: int) -> tuple[Notice, ...]:
        """The control tick raised `error` (its n_errors-th time); the shell holds the last good command."""
        notice = self._fs.tick_failed(error, n_errors)
        return () if notice is None else (notice,)

    @property
    def failsafes(self) -> tuple[str, ...]:
        """The failsafes in force (names), for HEARTBEAT/SYS_STATUS."""
        return self._fs.in_force

    # --- commands -------------------------------------------------------------------------------------
    def command(self, cmd: VehicleCommand) -> Verdict:
        """Apply one command record (navig8_fc/flight/commands.py) between two steps: accepted, or the reason."""
        handler = self._handlers.get(type(cmd))
        if handler is None:
            return Verdict(False, f"{type(cmd).__name__}: not a vehicle command")
        return handler(cmd)

    def _command_handlers(self) -> dict[type, Callable[[Any], Verdict]]:
        m = self._modes
        return {
            Arm: lambda c: m.arm(c.force),
            Disarm: lambda c: m.disarm(c.force),
            Takeoff: lambda c: m.takeoff(c.alt_m),
            Land: lambda c: m.land(),
            ReturnToLaunch: lambda c: m.return_to_launch(),
            SetMode: lambda c: m.set_custom_mode(int(c.custom_mode)),
            Reposition: lambda c: m.reposition(c.pos_ned_m, c.yaw_rad),
            Orbit: self._orbit,
            Gripper: self._gripper,
            ArmJoints: self._arm_joints,
            CancelTask: self._cancel_task,
            OffboardSetpoint: self._offboard_setpoint,
            ManualInput: self._manual_input,
            LoadMission: self._load_mission,
            LoadFence: self._load_fence,
            LoadRally: self._load_rally,
        }

    def _orbit(self, cmd: Orbit) -> Verdict:  # DO_ORBIT: the resolved circle must lie in the volume (VOL_*), about home
        vol, home = OperatingVolume.from_params(self.registry.as_dict()), self._modes.home_ned_m or (0.0, 0.0, 0.0)
        return self._modes.orbit(cmd.request, lambda plan: vol.orbit_problem(plan.centre_ned_m, plan.radius_m, home))

    def _gripper(self, cmd: Gripper) -> Verdict:
        self._queue(ArmRequest(gripper=cmd.action))
        return Verdict(True)

    def _arm_joints(self, cmd: ArmJoints) -> Verdict:
        q_rad = cmd.q_rad
        if not all(math.isfinite(q) for q in q_rad):
            return Verdict(False, "arm joints: targets must be finite")
        lim = self.vehicle.joint_limit_rad
        if any(abs(q) > lim for q in q_rad):
            return Verdict(False, f"arm joints: targets beyond +-{math.degrees(lim):.0f} deg")
        target = (float(q_rad[0]), float(q_rad[1]), float(q_rad[2]))
        self._queue(ArmRequest(joint_target_rad=target))
        self._arm_plan = hold_plan(target)
        self.core.set_arm_plan(self._arm_plan)
        s = self._sensors
        if s is not None:  # tracked once the joints are measured (a long-running command)
            self._arm_task.start(s.joint_pos_rad, target, s.t_s)
        return Verdict(True)

    def task_status(self, channel: str) -> TaskStatus | None:
        """The last long-running command of `channel` (TASK_FLIGHT: takeoff, land, return, reposition; TASK_ARM:
        arm-joint moves), running or how it ended; None before the first."""
        return self._modes.task if channel == TASK_FLIGHT else self._arm_task.status

    def _cancel_task(self, cmd: CancelTask) -> Verdict:
        """COMMAND_CANCEL: stop the running command of the channel and hold (the vehicle where it comes to rest, the
        joints where they are); refused when nothing runs there."""
        if cmd.channel == TASK_FLIGHT:
            return Verdict(True) if self._modes.cancel_task() else Verdict(False, "no flight command running")
        s = self._sensors
        if s is None or not self._arm_task.cancel():
            return Verdict(False, "no arm move running")
        self._queue(ArmRequest(joint_target_rad=tuple(s.joint_pos_rad)))  # type: ignore[arg-type]
        return Verdict(True)

    def _offboard_setpoint(self, cmd: OffboardSetpoint) -> Verdict:
        sp = cmd.target
        if isinstance(sp, Setpoint):
            if not all(math.isfinite(v) for v in (*sp.pos_ned_m, sp.pitch_rad, sp.yaw_rad)):
                return Verdict(False, "Offboard setpoint must be finite")
        elif sp.problem():
            return Verdict(False, sp.problem())
        self._modes.offboard_setpoint(sp)
        self._fs.offboard_alive()
        return Verdict(True)

    def _manual_input(self, cmd: ManualInput) -> Verdict:
        self._modes.manual_input(cmd.x, cmd.y, cmd.z, cmd.r)
        return Verdict(True)

    def _load_mission(self, cmd: LoadMission) -> Verdict:
        self._modes.load_plan(cmd.plan, cmd.origin)
        return Verdict(True)

    def _load_fence(self, cmd: LoadFence) -> Verdict:
        """The uploaded FENCE plan (inclusion circles and polygons), checked in flight with FS_FENCE_ACT."""
        self._fs.load_fence(Fence.from_plan(cmd.plan, cmd.origin))
        return Verdict(True)

    def _load_rally(self, cmd: LoadRally) -> Verdict:
        """The uploaded RALLY plan: Return (the mode, a plan's return item, the return failsafes) goes to the closest
        of home and its points (navig8_fc.mission.rally)."""
        self._modes.load_rally(cmd.plan, cmd.origin)
        return Verdict(True)

    def _queue(self, req: ArmRequest) -> None:
        p = self._arm_request
        if p is not None:  # merge: keep both a joint target and a gripper action queued before the next step
            req = ArmRequest(req.joint_target_rad or p.joint_target_rad, req.gripper or p.gripper)
        self._arm_request = req

    # --- published state -------------------------------------------------------------------------------
    def state(self) -> VehicleState:
        battery = self._pack.flush()  # the pack up to the last step
        m = self._modes
        mo = self._mode_out
        faults = m.faults
        return VehicleState(
            armed=m.armed,
            base_mode=mo.base_mode if mo is not None else m.base_mode,
            custom_mode=mo.custom_mode if mo is not None else m.custom_mode,
            flight_mode=mo.flight_mode if mo is not None else m.flight_mode,
            system_status=SYSTEM_STATUS_CRITICAL if m.armed and self._fs.in_force else m.system_status,
            landed_state=mo.landed_state if mo is not None else 0,
            landed=m.landed,
            home_ned_m=mo.home_ned_m if mo is not None else None,
            home_yaw_rad=mo.home_yaw_rad if mo is not None else 0.0,
            mission_time_s=mo.mission_time_s if mo is not None else None,
            sensors=self._sensors,
            sensors_ok=self._sensors is not None and not self._fs.sensors_stale,
            status=self._status,
            command=self._command,
            setpoint=mo.setpoint if mo is not None else None,
            engaged=mo.engaged if mo is not None else False,
            faults=tuple(faults.items()),
            prearm=m.prearm_check(),
            battery=battery,
            gcs_lost=self._fs.gcs_lost,
            pending_arm_request=self._arm_request,
            lambda_crit=self.lambda_crit,
            n_steps=self._n_steps,
            mission=mo.mission if mo is not None else m.mission_progress,
            failsafes=self.failsafes,
            sticks=m.sticks,
            offboard_target=m.offboard_target,
            orbit=m.orbit_plan,
        )
