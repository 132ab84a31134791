"""What a ground station (or a failsafe in the shell) asks of the vehicle, as typed records. The GCS microservices
turn MAVLink into these (navig8_fc/gcs/commands.py, offboard.py, the MANUAL_CONTROL and mission paths of
GcsService); `FlightStack.command(record)` applies one between two control steps and answers with a `Verdict`
(accepted, or the reason a GCS is shown). Plain data: no MAVLink, no I/O."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Plan
from navig8_fc.modes.orbit import OrbitRequest
from navig8_fc.modes.records import OffboardTarget

Vec3 = tuple[float, float, float]
GripperAction = Literal["grab", "release"]


@dataclass(frozen=True)
class Arm:
    force: bool = False  # skip the pre-arm checks (MAV_CMD_COMPONENT_ARM_DISARM p2 = 21196)


@dataclass(frozen=True)
class Disarm:
    force: bool = False  # also in the air


@dataclass(frozen=True)
class Takeoff:
    alt_m: float = math.nan  # above home; NaN: the default takeoff altitude


@dataclass(frozen=True)
class Land:
    pass


@dataclass(frozen=True)
class ReturnToLaunch:
    pass


@dataclass(frozen=True)
class SetMode:
    base_mode: int
    custom_mode: int  # PX4 encoding (main << 16 | sub << 24)


@dataclass(frozen=True)
class Reposition:
    pos_ned_m: Vec3  # hold here (a NaN component: where the vehicle is)
    yaw_rad: float = math.nan  # NaN: keep


@dataclass(frozen=True)
class Orbit:
    request: OrbitRequest  # MAV_CMD_DO_ORBIT in local NED (NaN parts: not given; navig8_fc.modes.orbit)


@dataclass(frozen=True)
class Gripper:
    action: GripperAction


@dataclass(frozen=True)
class ArmJoints:
    q_rad: Vec3  # joint targets, held until the next


@dataclass(frozen=True)
class CancelTask:
    channel: str  # TASK_FLIGHT or TASK_ARM (navig8_fc.flight.stack)


@dataclass(frozen=True)
class OffboardSetpoint:
    target: Setpoint | OffboardTarget  # NED, rad; OffboardTarget: NaN parts not given


@dataclass(frozen=True)
class ManualInput:
    x: float  # forward, [-1, 1]
    y: float  # right, [-1, 1]
    z: float  # throttle, [0, 1], 0.5 = hold altitude
    r: float  # yaw right, [-1, 1]


@dataclass(frozen=True)
class LoadMission:
    plan: Plan  # the uploaded mission in force (or its new start item), flown in Mission mode
    origin: GeoOrigin


@dataclass(frozen=True)
class LoadFence:
    plan: Plan  # the uploaded FENCE plan, checked in flight
    origin: GeoOrigin


@dataclass(frozen=True)
class LoadRally:
    plan: Plan  # the uploaded RALLY plan: Return goes to the closest of home and its points (mission.rally)
    origin: GeoOrigin


VehicleCommand = (Arm | Disarm | Takeoff | Land | ReturnToLaunch | SetMode | Reposition | Orbit | Gripper | ArmJoints
                  | CancelTask | OffboardSetpoint | ManualInput | LoadMission | LoadFence | LoadRally)
