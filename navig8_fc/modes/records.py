"""The mode manager's records: its configuration, its inputs and outputs, the command verdict, the scenario script
and the offboard target (pure data; navig8_fc.modes.manager uses them, the modes read them)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

from navig8_fc.core.outer_loop import JERK_K_PER_VEL_K, OuterLoopConfig, Setpoint
from navig8_fc.mission.plan import Progress
from navig8_fc.modes.px4 import FlightMode

Vec3 = tuple[float, float, float]


class Verdict(NamedTuple):
    """Answer to a command: accepted, or refused with a reason for STATUSTEXT. Unpacks as (ok, reason)."""

    ok: bool
    reason: str = ""


@dataclass(frozen=True)
class ModeConfig:
    takeoff_climb_rate_m_s: float = 1.0
    takeoff_default_alt_m: float = 2.5  # used when NAV_TAKEOFF carries no altitude (NaN); set from MIS_TAKEOFF_ALT
    takeoff_max_alt_m: float = 20.0  # the vehicle flies in confined spaces
    takeoff_reached_tol_m: float = 0.2
    land_descent_rate_m_s: float = 0.5
    land_setpoint_floor_m: float = 0.5  # the landing setpoint stops this far below home (keeps errors bounded)
    land_disarm_delay_s: float = 1.0  # disarm this long after touchdown
    landed_max_vz_m_s: float = 0.25
    landed_max_vxy_m_s: float = 0.5
    landed_max_thrust_ratio: float = 0.5  # thrust / weight below this: the ground carries the vehicle
    landed_max_height_m: float = 0.3  # fallback cue when the thrust is unknown
    landed_hold_s: float = 0.5
    # LAND touches down at once when the vehicle is this close to home height and no longer descending: the
    # ground stopped it. The thrust cue needs landed_hold_s, and within that time an INDI with a prioritised
    # allocation answers the impact by tilting the ducts past 90 deg to push down (the vertical force ranks
    # above the forward one), which drives the vehicle along the ground.
    land_contact_height_m: float = 0.1
    air_start_home_z_ned_m: float = 0.0  # ground under an air-started vehicle (the plant's ground plane)
    rtl_alt_m: float = 2.5  # Return (mode and plan item): climb to this height above its destination first if lower
    # (home or a rally point); set from RTL_RETURN_ALT
    manual_speed_m_s: float = 1.0  # Position mode: full stick = this horizontal speed
    manual_climb_m_s: float = 0.5  # full throttle travel = this vertical speed
    manual_yaw_rate_rad_s: float = 0.8  # full yaw stick
    manual_deadband: float = 0.05  # of full stick travel
    manual_lead_m: float = 1.0  # velocity-driven setpoints (sticks, offboard velocity) stay this close to the vehicle
    # Offboard on the ground: idle until the target is this far above the vehicle (PX4's takeoff state machine keeps
    # the motors at idle while landed and no climb is asked; pushing a target into the ground must not fly)
    offboard_liftoff_m: float = 0.2
    reposition_reached_tol_m: float = 0.3  # DO_REPOSITION is complete within this distance ...
    reposition_reached_speed_m_s: float = 0.3  # ... and below this speed
    # an attitude target's normalised thrust that holds the altitude level (MPC_THR_HOVER; PX4 SITL 0.5): thrust t
    # pushes g t / hover_thrust along the commanded attitude's body -z (navig8_fc.modes.offboard)
    hover_thrust: float = 0.5
    # Velocity-driven references (Position mode's sticks, offboard velocity and attitude targets) stop this high above
    # home: VOL_ALT_MAX, as PX4 holds LNDMC_ALT_MAX as a hard ceiling (targets above it are refused on arrival)
    max_height_m: float = math.inf

    def __post_init__(self) -> None:
        positive = (
            "takeoff_climb_rate_m_s",
            "takeoff_default_alt_m",
            "takeoff_max_alt_m",
            "takeoff_reached_tol_m",
            "land_descent_rate_m_s",
            "landed_max_vz_m_s",
            "landed_max_vxy_m_s",
        )
        for name in positive:
            if not getattr(self, name) > 0.0:
                raise ValueError(f"ModeConfig.{name} must be > 0, got {getattr(self, name)}")
        if not self.takeoff_default_alt_m <= self.takeoff_max_alt_m:
            raise ValueError("ModeConfig.takeoff_default_alt_m must not exceed takeoff_max_alt_m")


@dataclass(frozen=True)
class ReferenceLimits:
    """What the position reference can fly, for the modes that make their own trajectories (Orbit; Offboard's
    acceleration targets): the FlightStack sets it from OL_* (and ORB_RAD_MAX)."""

    orbit_radius_max_m: float = 1000.0  # ORB_RAD_MAX (PX4's MC_ORBIT_RAD_MAX)
    speed_max_m_s: float = 2.0  # OL_VEL_MAX
    acc_max_m_s2: float = 2.0  # OL_ACC_REF with command shaping, else OL_ACC_MAX
    pos_k_1_s: float = 1.0  # OL_POS_K
    vel_k_1_s: float = 3.0  # OL_VEL_K
    jerk_k_1_s: float = 0.0  # the shaper's jerk stage gain (0: no shaping, the setpoint goes to the loop)
    gravity_m_s2: float = 9.80665

    @staticmethod
    def of_outer_loop(outer: OuterLoopConfig, orbit_radius_max_m: float) -> ReferenceLimits:
        """With command shaping (OL_JERK_MAX > 0) the shaped reference flies (OL_ACC_REF, its jerk stage); without it
        the loop itself (OL_ACC_MAX)."""
        shaped = outer.jerk_max_m_s3 > 0.0
        return ReferenceLimits(orbit_radius_max_m, outer.vel_max_m_s,
                               outer.ref_acc_max_m_s2 if shaped else outer.acc_max_m_s2, outer.pos_k, outer.vel_k,
                               JERK_K_PER_VEL_K * outer.vel_k if shaped else 0.0, outer.gravity_m_s2)


@dataclass(frozen=True)
class MissionScript:
    """A scripted flight: `setpoint_at(mission_time_s)` gives the setpoint (NED, rad)."""

    name: str
    setpoint_at: Callable[[float], Setpoint]
    starts_armed_in_air: bool = False
    duration_s: float | None = None  # after this the manager holds at setpoint_at(duration_s)
    start_t_s: float = 0.0  # sim time at which an air-started mission's clock reads 0
    yields_to_plan: bool = False  # only an air start holding its initial setpoint: an uploaded plan replaces it


@dataclass(frozen=True)
class OffboardTarget:
    """One streamed offboard target (NED, rad), each part optional (NaN: not given), as PX4's trajectory setpoint:
    - position given on an axis: the reference there (a client streaming a moving position gets it);
    - velocity only on an axis: the reference is integrated from it, kept within manual_lead_m of the vehicle;
    - velocity with position: velocity feed-forward (the reference is offset by v / OL_POS_K, so the outer loop's
      velocity command K_p (p_ref - p) + v equals v on the trajectory: no steady lag);
    - neither: that axis holds where its reference is;
    - yaw given: that heading; else yaw_rate given: integrated; else kept. pitch given: held (the tilt ducts hold the
      body's pitch apart from its position); else kept. Roll is the outer loop's: it rolls to make a sideways force;
    - an attitude (roll, pitch, yaw all given: SET_ATTITUDE_TARGET) with a normalised thrust vector in body axes
      (`thrust_body`; a multicopter's collective thrust t is (0, 0, -t)): the acceleration a multicopter at that
      attitude and thrust has, g R(q) thrust_body / hover_thrust + g down, flown on every axis without a position or
      velocity, within the reference's limits (navig8_fc.modes.offboard.attitude_acceleration); without a thrust the
      altitude holds and the tilt gives the level flight's horizontal acceleration;
    - an acceleration (NED) on an axis with neither position nor velocity: integrated into the reference's velocity
      (no drag: a zero acceleration keeps the speed), within the same limits."""

    pos_ned_m: Vec3 = (math.nan, math.nan, math.nan)
    vel_ned_m_s: Vec3 = (math.nan, math.nan, math.nan)
    yaw_rad: float = math.nan
    yaw_rate_rad_s: float = math.nan
    pitch_rad: float = math.nan
    roll_rad: float = math.nan
    thrust_body: Vec3 = (math.nan, math.nan, math.nan)  # normalised (hover: hover_thrust along -z), body FRD
    acc_ned_m_s2: Vec3 = (math.nan, math.nan, math.nan)  # flown on axes with neither position nor velocity

    @staticmethod
    def of(sp: Setpoint) -> OffboardTarget:
        """A plain position setpoint as a target (position, pitch and yaw given)."""
        return OffboardTarget(sp.pos_ned_m, yaw_rad=sp.yaw_rad, pitch_rad=sp.pitch_rad)

    @property
    def attitude_given(self) -> bool:
        return not any(math.isnan(v) for v in (self.roll_rad, self.pitch_rad, self.yaw_rad))

    def problem(self) -> str:
        """Why this target cannot be flown ('' when it can): no part given, or an infinite value."""
        values = (*self.pos_ned_m, *self.vel_ned_m_s, self.yaw_rad, self.yaw_rate_rad_s, self.pitch_rad, self.roll_rad,
                  *self.thrust_body, *self.acc_ned_m_s2)
        if any(math.isinf(v) for v in values):
            return "Offboard target must be finite (NaN = not given)"
        if (all(math.isnan(v) for v in (*self.pos_ned_m, *self.vel_ned_m_s, *self.acc_ned_m_s2, self.pitch_rad))
                and not self.attitude_given):
            return "Offboard target has no position, velocity, acceleration or attitude"
        return ""


class ModeInputs(NamedTuple):
    """One state sample (sim time, NED, rad) for the mode manager. A NamedTuple, as StepResult: built once per
    control step, where a frozen dataclass's __init__ costs ~1 us."""

    t_s: float
    pos_ned_m: Vec3
    vel_ned_m_s: Vec3
    yaw_rad: float
    thrust_ratio: float = math.nan  # total thrust / weight (commanded or measured); NaN = unknown
    sensors_ok: bool = True  # every sensor the controller needs is alive and fresh
    estimator_ready: bool = True  # the adaptive law / estimator has a usable estimate
    # the acceleration the vehicle is being driven with (the command shaper's reference, NED, m/s^2): where Hold
    # stops depends on it (a vehicle still speeding up stops further on)
    accel_ned_m_s2: Vec3 = (0.0, 0.0, 0.0)


class ModeOutput(NamedTuple):
    """What the mode manager decided in one step. A NamedTuple (built once per control step: a frozen dataclass's
    __init__ of 17 fields costs ~2 us)."""

    t_s: float
    armed: bool
    engaged: bool  # run the controller (False: motors off / idle)
    setpoint: Setpoint
    flight_mode: FlightMode
    custom_mode: int  # PX4 encoding
    base_mode: int  # MAV_MODE_FLAG: CUSTOM_MODE_ENABLED | SAFETY_ARMED when armed
    landed_state: int  # MAV_LANDED_STATE
    system_status: int  # MAV_STATE
    landed: bool  # land detector
    home_ned_m: Vec3 | None
    home_yaw_rad: float
    mission_time_s: float | None  # None outside MISSION
    events: tuple[str, ...] = ()  # for STATUSTEXT (INFO)
    mission: Progress = Progress()  # the uploaded plan's progress (navig8_fc.mission.executor)
    actions: tuple[tuple[str, object], ...] = ()  # arm/gripper actions of plan items (MissionExecutor.step)
    entries: int = 0  # mode entries so far: a change means a fresh reference (also on re-entering the same mode)


def sanitised(inp: ModeInputs, last: ModeInputs | None) -> ModeInputs:
    """A sample with NaN/Inf state must not become a setpoint: reuse the last good state, flag sensors."""
    pos, vel = inp.pos_ned_m, inp.vel_ned_m_s
    # One NaN or Inf term makes the sum NaN or Inf, so a finite sum means every term is finite (the common
    # case, one check); a non-finite sum is either a bad sample or finite terms that overflowed: look closer.
    total = pos[0] + pos[1] + pos[2] + vel[0] + vel[1] + vel[2] + inp.yaw_rad + inp.t_s
    if total - total == 0.0 or all(map(math.isfinite, (*pos, *vel, inp.yaw_rad, inp.t_s))):
        return inp
    pos = last.pos_ned_m if last is not None else (0.0, 0.0, 0.0)
    yaw = last.yaw_rad if last is not None else 0.0
    t = inp.t_s if math.isfinite(inp.t_s) else (last.t_s if last is not None else 0.0)
    return ModeInputs(t, pos, (0.0, 0.0, 0.0), yaw, inp.thrust_ratio, False, inp.estimator_ready)
