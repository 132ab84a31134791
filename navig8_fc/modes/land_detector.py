"""The land detector (pure, on sim time): needed for pre-arm "on ground", disarm checks, touchdown and
EXTENDED_SYS_STATE.

The vehicle is a landed candidate while it is slow (|v_down| < landed_max_vz_m_s and horizontal speed below
landed_max_vxy_m_s) and carries little thrust (thrust/weight < landed_max_thrust_ratio); when the caller does
not know the thrust (NaN), "near home altitude" (height above home < landed_max_height_m) replaces the
thrust cue. The candidate must hold for landed_hold_s (except at the very first sample, so a vehicle that
boots on the ground is landed at once). Thrust is the strongest cue because on touchdown the landing
setpoint keeps descending below the ground (bounded by land_setpoint_floor_m), so INDI drives the thrust
down within a few steps while the ground holds the vehicle still, the same signature PX4's multicopter land
detector looks for (low thrust + no vertical motion).
"""

from __future__ import annotations

import math

from navig8_fc.modes.records import ModeConfig, ModeInputs

_isfinite = math.isfinite


class LandDetector:
    """Landed / not landed from speed, thrust (or height above home) held for a while (module docstring)."""

    def __init__(self, config: ModeConfig) -> None:
        self._cfg = config
        # The (frozen) config's thresholds, read once per step.
        self._max_vz = config.landed_max_vz_m_s
        self._max_vxy = config.landed_max_vxy_m_s
        self._max_thrust_ratio = config.landed_max_thrust_ratio
        self._max_height = config.landed_max_height_m
        self._hold_s = config.landed_hold_s
        self._candidate_since_s: float | None = None
        self._seen_sample = False
        self.landed = False

    def slow(self, inp: ModeInputs) -> bool:
        """Below the landed speeds (vertical and horizontal)."""
        vx, vy, vz = inp.vel_ned_m_s
        return abs(vz) < self._max_vz and math.hypot(vx, vy) < self._max_vxy

    def candidate(self, inp: ModeInputs, home_z_ned_m: float | None) -> bool:
        if not self.slow(inp):
            return False
        thrust_ratio = inp.thrust_ratio
        if _isfinite(thrust_ratio):
            return thrust_ratio < self._max_thrust_ratio
        return home_z_ned_m is not None and (home_z_ned_m - inp.pos_ned_m[2]) < self._max_height

    def step(self, inp: ModeInputs, home_z_ned_m: float | None) -> bool:
        if self.candidate(inp, home_z_ned_m):
            t = inp.t_s
            since = self._candidate_since_s
            if since is None:
                # At the very first sample there is no history: a vehicle that boots resting is landed at once.
                since = self._candidate_since_s = t if self._seen_sample else t - self._hold_s
            self.landed = t - since >= self._hold_s
        else:
            self._candidate_since_s = None
            self.landed = False
        self._seen_sample = True
        return self.landed

