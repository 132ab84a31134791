"""The standard-modes messages (AVAILABLE_MODES, CURRENT_MODE; MAVLink development.xml) built from the mode table
(navig8_fc.modes.px4: each mode's PX4 custom_mode, its MAV_STANDARD_MODE and properties). Pure: the GCS service
sends them (docs/gcs.md, "Standard modes")."""

from __future__ import annotations

import math
from typing import Any

from navig8_fc.modes.px4 import AVAILABLE_MODES, standard_mode_of


def available_modes(mav: Any, index_param: float) -> list[Any] | None:
    """REQUEST_MESSAGE(AVAILABLE_MODES) param2: 0 (or NaN) = every mode, 1..N = that one, else None (DENIED)."""
    n = len(AVAILABLE_MODES)
    index = 0 if math.isnan(index_param) else int(round(index_param))
    if not 0 <= index <= n:
        return None
    picked = range(1, n + 1) if index == 0 else (index,)
    out = []
    for i in picked:
        mode, std, props = AVAILABLE_MODES[i - 1]
        name = mode.label.encode() if std == 0 else b""  # standard modes are named by the ground station
        out.append(mav.available_modes_encode(n, i, int(std), mode.custom_mode, props, name))
    return out


def current_mode(mav: Any, custom_mode: int, intended_custom_mode: int) -> Any:
    """CURRENT_MODE: the mode flown (standard and custom) and the one a ground station last asked for (0 unknown)."""
    return mav.current_mode_encode(standard_mode_of(custom_mode), custom_mode, intended_custom_mode)
