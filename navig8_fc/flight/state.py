"""The FlightStack's seams: what it answers to (`VehicleCommands`), what one step gives (`StepResult`), what it
publishes (`VehicleState`), and what the shell announces for it (`Notice`). Plain data, no I/O."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, NamedTuple, Protocol

from navig8_fc.core.controller import ActuatorCommand, ControllerStatus, FcSensors
from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.flight.battery import BatteryState
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Plan, Progress
from navig8_fc.modes.manager import OffboardTarget, TaskStatus, Verdict
from navig8_fc.modes.px4 import FlightMode

Vec3 = tuple[float, float, float]
GripperAction = Literal["grab", "release"]

# MAV_SEVERITY values (common.xml), so the stack needs no MAVLink import.
SEVERITY_CRITICAL, SEVERITY_ERROR, SEVERITY_WARNING, SEVERITY_INFO = 2, 3, 4, 6


class VehicleCommands(Protocol):
    """What a ground station can ask of the vehicle; `FlightStack` implements it.

    Each returns (ok, reason): reason is shown as STATUSTEXT when ok is False."""

    def arm(self, force: bool) -> tuple[bool, str]: ...

    def disarm(self, force: bool) -> tuple[bool, str]: ...

    def takeoff(self, alt_m: float) -> tuple[bool, str]:
        """Climb to alt_m above home (NaN: the default takeoff altitude)."""
        ...

    def land(self) -> tuple[bool, str]: ...

    def set_mode(self, base_mode: int, custom_mode: int) -> tuple[bool, str]:
        """custom_mode in PX4 encoding (main << 16 | sub << 24)."""
        ...

    def gripper(self, action: GripperAction) -> tuple[bool, str]: ...

    def arm_joints(self, q_rad: tuple[float, float, float]) -> tuple[bool, str]: ...

    def offboard_setpoint(self, sp: Setpoint | OffboardTarget) -> tuple[bool, str]:
        """A streamed offboard setpoint or target (NED, rad; OffboardTarget: NaN parts not given); Offboard mode
        flies the latest."""
        ...

    def manual_input(self, x: float, y: float, z: float, r: float) -> None:
        """MANUAL_CONTROL sticks, normalised (x, y, r in [-1, 1], z in [0, 1], 0.5 = hold altitude)."""
        ...

    def reposition(self, pos_ned: Vec3, yaw_rad: float) -> tuple[bool, str]:
        """DO_REPOSITION: hold at pos_ned (NaN components: keep), yaw_rad (NaN: keep)."""
        ...

    def return_to_launch(self) -> tuple[bool, str]:
        """MAV_CMD_NAV_RETURN_TO_LAUNCH: Return mode, tracked as a long-running command."""
        ...

    def task_status(self, channel: str) -> TaskStatus | None:
        """The last long-running command of a channel ("flight": takeoff, land, return, reposition; "arm": arm-joint
        moves), running or ended; None before the first."""
        ...

    def cancel_task(self, channel: str) -> bool:
        """COMMAND_CANCEL: stop the running command of the channel and hold; False when none runs."""
        ...

    def load_fence(self, plan: Plan, origin: GeoOrigin) -> None:
        """The uploaded FENCE plan, checked in flight."""
        ...

    def load_mission(self, plan: Plan, origin: GeoOrigin) -> None:
        """The uploaded mission plan in force (or its new start item), flown in Mission mode."""
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
    home_ned: Vec3 | None
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
