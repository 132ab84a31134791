"""The FlightStack's seams: what it answers to (`VehicleCommands`), what one step gives (`StepResult`), what it
publishes (`VehicleState`), and what the shell announces for it (`Notice`). Plain data, no I/O."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Protocol

from navig8_fc.core.controller import ActuatorCommand, ControllerStatus, FcSensors
from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.flight.battery import BatteryState
from navig8_fc.flight.commands import GripperAction, VehicleCommand
from navig8_fc.mission.plan import Progress
from navig8_fc.modes.manager import OffboardTarget, TaskStatus, Verdict
from navig8_fc.modes.orbit import OrbitPlan
from navig8_fc.modes.px4 import FlightMode

Vec3 = tuple[float, float, float]

# MAV_SEVERITY values (common.xml), so the stack needs no MAVLink import.
SEVERITY_CRITICAL, SEVERITY_ERROR, SEVERITY_WARNING, SEVERITY_INFO = 2, 3, 4, 6


class VehicleCommands(Protocol):
    """What a ground station can ask of the vehicle; `FlightStack` implements it."""

    def command(self, cmd: VehicleCommand) -> Verdict:
        """Apply one command record (navig8_fc/flight/commands.py); a refusal's reason is shown as STATUSTEXT."""
        ...

    def task_status(self, channel: str) -> TaskStatus | None:
        """The last long-running command of a channel ("flight": takeoff, land, return, reposition; "arm": arm-joint
        moves), running or ended; None before the first."""
        ...


@dataclass(frozen=True)
class ArmRequest:
    """An arm-joint target and/or a gripper action for the simulated hardware (the bridge applies it)."""

    joint_target_rad: Vec3 | None = None
    gripper: GripperAction | None = None


@dataclass(frozen=True)
class Notice:
    """Something the shell announces: `statustext` to every GCS (and the log) at `severity`, `event` to the
    run's event log. Either may be None."""

    severity: int
    statustext: str | None = None
    event: str | None = None


class StepResult(NamedTuple):
    """One control step: the actuator command and the controller's status, the setpoint flown, whether the
    vehicle is armed and the controller engaged, the notices to announce and an arm request for the bridge
    (sent before the step's answer so it applies on this step). A NamedTuple: built once per control step,
    where a frozen dataclass's __init__ costs ~1 us (~2 % of the stack's step)."""

    command: ActuatorCommand
    status: ControllerStatus
    setpoint: Setpoint
    armed: bool
    engaged: bool
    notices: tuple[Notice, ...]
    arm_request: ArmRequest | None


@dataclass(frozen=True)
class VehicleState:
    """What the vehicle is, as of now: the last step's outputs with commands and faults since applied.

    `armed` and `system_status` are current (a command or a fault changes them at once); the mode fields,
    landed state and home are the last step's (None/defaults before the first step)."""

    armed: bool
    base_mode: int  # MAV_MODE_FLAG
    custom_mode: int  # PX4 encoding
    flight_mode: FlightMode
    system_status: int  # MAV_STATE
    landed_state: int  # MAV_LANDED_STATE (0 undefined before the first step)
    landed: bool
    home_ned_m: Vec3 | None
    home_yaw_rad: float
    mission_time_s: float | None
    sensors: FcSensors | None  # the last step's input
    sensors_ok: bool  # a step has run and no sensor-stale fault is set
    status: ControllerStatus | None  # the last step's controller status
    command: ActuatorCommand  # the last step's output
    setpoint: Setpoint | None
    engaged: bool
    faults: tuple[tuple[str, str], ...]  # (name, reason)
    prearm: Verdict
    battery: BatteryState
    gcs_lost: bool
    pending_arm_request: ArmRequest | None
    lambda_crit: float  # critical eigenvalue of H(s) for the parameters in force (Eq. 9-13)
    n_steps: int
    mission: Progress = Progress()  # the uploaded plan's progress (MISSION_CURRENT, MISSION_ITEM_REACHED)
    failsafes: tuple[str, ...] = ()  # failsafes in force (HEARTBEAT system_status CRITICAL while armed)
    # the MANUAL_CONTROL sticks as Position mode flies them (x, y, r in [-1, 1], z in [0, 1]; centred: 0.5 z)
    sticks: tuple[float, float, float, float] = (0.0, 0.0, 0.5, 0.0)
    offboard_target: OffboardTarget | None = None  # the streamed offboard target in force (None: none, or lost)
    orbit: OrbitPlan | None = None  # the orbit being flown (ORBIT_EXECUTION_STATUS; None outside ORBIT)
