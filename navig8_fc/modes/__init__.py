"""Flight modes and arming: a pure state machine on sim time (navig8_fc.modes.manager), PX4 mode encoding."""

from navig8_fc.modes.manager import (
    LandDetector,
    MissionScript,
    ModeConfig,
    ModeInputs,
    ModeManager,
    ModeOutput,
    OffboardTarget,
    Verdict,
)
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
