"""Flight modes in PX4's custom_mode encoding, and the MAVLink enum values the mode manager reports.

Why PX4's encoding: MAVSDK decodes and sets flight modes with PX4 semantics for every autopilot that is not
ArduPilot, MAV_AUTOPILOT_GENERIC included (mavlink_notes §2.6), so a generic vehicle that wants MAVSDK's
`flight_mode`, `hold()`, `land()` and `start_mission()` to work must speak it:

    custom_mode = main_mode << 16 | sub_mode << 24        (uint32; the low 16 bits are unused)

e.g. Hold = AUTO.LOITER = (4 << 16) | (3 << 24) = 0x03040000, Mission = AUTO.MISSION = 0x04040000.

The MAVLink values are written out here (rather than imported from pymavlink) so the mode manager stays pure
(no pymavlink import); tests/unit/test_modes.py checks them against pymavlink's common dialect.
"""

from __future__ import annotations

from enum import Enum, IntEnum


class Px4MainMode(IntEnum):
    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7
    RATTITUDE = 8


class Px4AutoSubMode(IntEnum):
    READY = 1
    TAKEOFF = 2
    LOITER = 3  # MAVSDK "Hold"
    MISSION = 4
    RTL = 5
    LAND = 6
    RTGS = 7
    FOLLOW_TARGET = 8
    PRECLAND = 9


class Px4PosctlSubMode(IntEnum):
    POSCTL = 0
    ORBIT = 1  # MAV_CMD_DO_ORBIT flies it (PX4's NAVIGATION_STATE_ORBIT)


def px4_custom_mode(main: int, sub: int = 0) -> int:
    """PX4 custom_mode: main << 16 | sub << 24 (both bytes, so the result fits a uint32)."""
    if not (0 <= main <= 255 and 0 <= sub <= 255):
        raise ValueError(f"PX4 main/sub modes are bytes, got main={main}, sub={sub}")
    return (main << 16) | (sub << 24)


def decode_px4_custom_mode(custom_mode: int) -> tuple[int, int]:
    """(main, sub) from a PX4 custom_mode."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


class FlightMode(Enum):
    """The modes this flight controller implements, each with its PX4 (main, sub) pair."""

    READY = (Px4MainMode.AUTO, Px4AutoSubMode.READY)  # armed or disarmed on the ground, controller idle
    TAKEOFF = (Px4MainMode.AUTO, Px4AutoSubMode.TAKEOFF)
    HOLD = (Px4MainMode.AUTO, Px4AutoSubMode.LOITER)  # position hold
    LAND = (Px4MainMode.AUTO, Px4AutoSubMode.LAND)
    MISSION = (Px4MainMode.AUTO, Px4AutoSubMode.MISSION)  # an uploaded plan or a scripted scenario
    RTL = (Px4MainMode.AUTO, Px4AutoSubMode.RTL)  # Return: climb, fly home, land, disarm
    OFFBOARD = (Px4MainMode.OFFBOARD, 0)  # follows the setpoints a client streams
    POSCTL = (Px4MainMode.POSCTL, 0)  # Position: MANUAL_CONTROL sticks move the position setpoint
    ORBIT = (Px4MainMode.POSCTL, Px4PosctlSubMode.ORBIT)  # circles a centre (MAV_CMD_DO_ORBIT)

    def __init__(self, main: Px4MainMode, sub: int) -> None:
        # Encoded once: the mode manager reports custom_mode on every control step.
        self._custom_mode = px4_custom_mode(int(main), int(sub))

    @property
    def main(self) -> int:
        return int(self.value[0])

    @property
    def sub(self) -> int:
        return int(self.value[1])

    @property
    def custom_mode(self) -> int:
        return self._custom_mode

    @property
    def label(self) -> str:
        return _LABELS[self.name]

    @classmethod
    def from_px4(cls, main: int, sub: int) -> FlightMode | None:
        for mode in cls:
            if mode.main == main and mode.sub == sub:
                return mode
        return None


_LABELS = {"READY": "Ready", "TAKEOFF": "Takeoff", "HOLD": "Hold", "LAND": "Land", "MISSION": "Mission",
           "RTL": "Return", "OFFBOARD": "Offboard", "POSCTL": "Position", "ORBIT": "Orbit"}


# --- MAVLink enum values (common.xml / minimal.xml) the mode manager reports ---------------------------
class MavModeFlag(IntEnum):
    CUSTOM_MODE_ENABLED = 1
    SAFETY_ARMED = 128


class MavState(IntEnum):
    UNINIT = 0
    BOOT = 1
    CALIBRATING = 2
    STANDBY = 3
    ACTIVE = 4
    CRITICAL = 5
    EMERGENCY = 6


class MavLandedState(IntEnum):
    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


# --- MAVLink standard modes (AVAILABLE_MODES / CURRENT_MODE / MAV_CMD_DO_SET_STANDARD_MODE) --------------
class StandardMode(IntEnum):
    """MAV_STANDARD_MODE (common.xml numbering, the one QGroundControl compiles against)."""

    NON_STANDARD = 0
    POSITION_HOLD = 1
    ORBIT = 2
    SAFE_RECOVERY = 5  # PX4 maps AUTO_RTL here
    MISSION = 6
    LAND = 7
    TAKEOFF = 8


MODE_PROPERTY_ADVANCED = 1  # MAV_MODE_PROPERTY
MODE_PROPERTY_NOT_USER_SELECTABLE = 2

# Every mode this vehicle flies, announced in this order (AVAILABLE_MODES mode_index 1..N): the standard mode where
# it is exact (PX4's table: POSCTL -> POSITION_HOLD, AUTO_RTL -> SAFE_RECOVERY, AUTO_MISSION -> MISSION,
# AUTO_LAND -> LAND, AUTO_TAKEOFF -> TAKEOFF; ORBIT -> ORBIT, which QGroundControl offers as its own guided action
# rather than in the mode menu), the properties QGroundControl reads (Offboard needs a setpoint
# stream: advanced; Ready is where the vehicle rests, not something to select).
AVAILABLE_MODES: tuple[tuple[FlightMode, StandardMode, int], ...] = (
    (FlightMode.POSCTL, StandardMode.POSITION_HOLD, 0),
    (FlightMode.HOLD, StandardMode.NON_STANDARD, 0),
    (FlightMode.MISSION, StandardMode.MISSION, 0),
    (FlightMode.RTL, StandardMode.SAFE_RECOVERY, 0),
    (FlightMode.LAND, StandardMode.LAND, 0),
    (FlightMode.TAKEOFF, StandardMode.TAKEOFF, 0),
    (FlightMode.OFFBOARD, StandardMode.NON_STANDARD, MODE_PROPERTY_ADVANCED),
    (FlightMode.ORBIT, StandardMode.ORBIT, 0),
    (FlightMode.READY, StandardMode.NON_STANDARD, MODE_PROPERTY_NOT_USER_SELECTABLE),
)


def standard_mode_of(custom_mode: int) -> int:
    """The MAV_STANDARD_MODE of a PX4 custom_mode (NON_STANDARD when none is exact)."""
    for mode, std, _ in AVAILABLE_MODES:
        if mode.custom_mode == custom_mode:
            return int(std)
    return int(StandardMode.NON_STANDARD)


def mode_for_standard(standard_mode: int) -> FlightMode | None:
    """The mode that implements a MAV_STANDARD_MODE (None: not supported here; NON_STANDARD is not selectable)."""
    for mode, std, _ in AVAILABLE_MODES:
        if std == standard_mode and std != StandardMode.NON_STANDARD:
            return mode
    return None


# --- what the mode manager reports (plain ints, the way ModeOutput carries them) ------------------------------
BASE_MODE_DISARMED = int(MavModeFlag.CUSTOM_MODE_ENABLED)
BASE_MODE_ARMED = int(MavModeFlag.CUSTOM_MODE_ENABLED) | int(MavModeFlag.SAFETY_ARMED)
_ON_GROUND = int(MavLandedState.ON_GROUND)
_IN_AIR = int(MavLandedState.IN_AIR)
_TAKEOFF = int(MavLandedState.TAKEOFF)
_LANDING = int(MavLandedState.LANDING)
STATE_STANDBY = int(MavState.STANDBY)
_ACTIVE = int(MavState.ACTIVE)
_CRITICAL = int(MavState.CRITICAL)


def landed_state(mode: FlightMode, armed: bool, landed: bool, touched_down: bool, hold_on_ground: bool) -> int:
    """MAV_LANDED_STATE: from the land detector, except in the modes that know better (Takeoff, Land, Hold idle
    on the ground)."""
    if not armed or mode is FlightMode.READY:
        return _ON_GROUND if landed else _IN_AIR
    if mode is FlightMode.MISSION:
        return _ON_GROUND if landed else _IN_AIR
    if mode is FlightMode.TAKEOFF:
        return _TAKEOFF
    if mode is FlightMode.LAND:
        return _ON_GROUND if touched_down else _LANDING
    if mode is FlightMode.HOLD and hold_on_ground:
        return _ON_GROUND
    return _IN_AIR


def system_status(armed: bool, sensors_ok: bool, faulted: bool) -> int:
    """MAV_STATE: STANDBY disarmed; armed ACTIVE, CRITICAL with a sensor problem or a fault set."""
    if not armed:
        return STATE_STANDBY
    return _ACTIVE if sensors_ok and not faulted else _CRITICAL


def px4_mode_name(main: int, sub: int) -> str:
    """A PX4 main/sub mode's name for messages ("AUTO.3"; unknown main modes by number)."""
    try:
        main_name = Px4MainMode(int(main)).name
    except ValueError:
        main_name = str(int(main))
    return f"{main_name}.{int(sub)}" if int(sub) else main_name
