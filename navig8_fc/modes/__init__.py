"""Flight modes and arming: a pure state machine on sim time (navig8_fc.modes.manager: arming, the mode switch,
faults), one module per mode (takeoff, hold, land, position, offboard, rtl, mission, orbit), the land detector, the
long-running command tracking (tasks), Hold's braking distance (braking), PX4 mode encoding (px4)."""

from navig8_fc.modes.land_detector import LandDetector
from navig8_fc.modes.manager import ModeManager
from navig8_fc.modes.px4 import (
    FlightMode,
    MavLandedState,
    MavModeFlag,
    MavState,
    Px4AutoSubMode,
    Px4MainMode,
    decode_px4_custom_mode,
    px4_custom_mode,
)
from navig8_fc.modes.records import MissionScript, ModeConfig, ModeInputs, ModeOutput, OffboardTarget, Verdict

__all__ = [
    "FlightMode",
    "LandDetector",
    "MavLandedState",
    "MavModeFlag",
    "MavState",
    "MissionScript",
    "ModeConfig",
    "ModeInputs",
    "ModeManager",
    "ModeOutput",
    "OffboardTarget",
    "Px4AutoSubMode",
    "Px4MainMode",
    "Verdict",
    "decode_px4_custom_mode",
    "px4_custom_mode",
]
