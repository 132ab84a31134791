"""What the modes share with the mode manager, and what they hand back to it (pure).

Each mode (`takeoff`, `hold`, `land`, `position`, `offboard`, `rtl`, `mission` in this package) is a small
class with `enter(inputs, ...)` (the entry actions that need a state sample, run at the first step in the mode)
and `update(inputs, dt) -> Step`. What they share with the manager comes in one `ModeContext`, owned by the
manager and given to every mode when it is built: the configuration, the land detector, the task tracker,
the home, the rally points, the last output and the event list (STATUSTEXT). A mode that ends (takeoff done,
mission done, Return landing, touchdown and disarm, offboard stream lost) says where to go next in `Step.then`; the
manager switches.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.mission.executor import ExecConfig
from navig8_fc.mission.geo import GeoOrigin
from navig8_fc.mission.plan import Plan
from navig8_fc.mission.rally import RallyPoint, rally_positions
from navig8_fc.modes.land_detector import LandDetector
from navig8_fc.modes.px4 import FlightMode
from navig8_fc.modes.records import ModeConfig, ModeInputs, ModeOutput, Vec3
from navig8_fc.modes.tasks import TaskTracker


@dataclass
class ModeContext:
    """The state the manager shares with the modes (it sets `home` and `last_output`; the modes read them)."""

    config: ModeConfig
    detector: LandDetector
    tasks: TaskTracker
    events: list[str] = field(default_factory=list)  # this step's STATUSTEXT (INFO) lines
    home: Vec3 | None = None
    last_output: ModeOutput | None = None
    rally: Plan | None = None  # the uploaded rally plan (None: none), about rally_origin
    rally_origin: GeoOrigin = field(default_factory=GeoOrigin)

    def rally_points(self) -> tuple[RallyPoint, ...]:
        """The rally points in force in local NED (their altitudes above the current home, or AMSL)."""
        if self.rally is None or self.home is None:
            return ()
        return rally_positions(self.rally, self.rally_origin, self.home)

    def current_pitch(self) -> float:
        """The pitch being flown (the last output's when the controller was engaged, else level)."""
        out = self.last_output
        return out.setpoint.pitch_rad if out is not None and out.engaged else 0.0

    def start_setpoint(self, inp: ModeInputs) -> Setpoint:
        """Where a mode that flies on from the current reference starts: the last engaged setpoint, else here."""
        out = self.last_output
        if out is not None and out.engaged:
            return out.setpoint
        x, y, z = inp.pos_ned_m
        return Setpoint((x, y, z), 0.0, inp.yaw_rad)


class Transition(NamedTuple):
    """The mode to switch to after this step. READY: disarm (Land after touchdown). `hold_at`: HOLD without its
    entry actions, holding that setpoint (on the ground: idle). `land_xy`: LAND goes down there."""

    mode: FlightMode
    hold_at: Setpoint | None = None
    on_ground: bool = False
    land_xy: tuple[float, float] | None = None


class Step(NamedTuple):
    """One step of a mode: the setpoint, whether the controller runs, the mission clock (None outside a scripted
    mission) and where to go next (None: stay)."""

    setpoint: Setpoint
    engaged: bool
    mission_time_s: float | None = None
    then: Transition | None = None


def idle(inp: ModeInputs) -> Setpoint:
    """The setpoint reported while the controller is idle: where the vehicle is."""
    return Setpoint(inp.pos_ned_m, 0.0, inp.yaw_rad)


def exec_config(cfg: ModeConfig) -> ExecConfig:
    """The mission executor's configuration (plans and Return)."""
    return ExecConfig(cfg.takeoff_climb_rate_m_s, cfg.takeoff_reached_tol_m, rtl_alt_m=cfg.rtl_alt_m)


def climb_rate_down(throttle: float, cfg: ModeConfig) -> float:
    """A throttle in [0, 1] (0.5 = hold altitude, deadband around it) -> NED down speed, m/s."""
    z = throttle - 0.5
    return 0.0 if abs(z) < cfg.manual_deadband else -2.0 * z * cfg.manual_climb_m_s


def integrate_led(sp: Vec3, vel: Vec3, pos: Vec3, dt: float, lead_m: float) -> Vec3:
    """A velocity-driven setpoint one step on (sp + vel dt per axis), kept within lead_m of the vehicle on each
    axis so it cannot wind up while the vehicle lags (Position mode's sticks, offboard velocity targets)."""
    return tuple(min(p + lead_m, max(p - lead_m, s + v * dt))  # type: ignore[return-value]
                 for s, v, p in zip(sp, vel, pos, strict=True))


def below_ceiling(pos_ned_m: Vec3, ctx: ModeContext) -> Vec3:
    """pos_ned_m no higher than the ceiling (ModeConfig.max_height_m above home; no home yet: the NED origin's
    height, where the vehicle starts), for references a velocity drives."""
    home_z = ctx.home[2] if ctx.home is not None else 0.0
    top_z = home_z - ctx.config.max_height_m
    return pos_ned_m if pos_ned_m[2] >= top_z else (pos_ned_m[0], pos_ned_m[1], top_z)


def approach(value: float, target: float, max_step: float) -> float:
    """Move `value` toward `target` by at most `max_step`; lands exactly on the target."""
    if abs(target - value) <= max_step:
        return target
    return value + math.copysign(max_step, target - value)


def wrap_pi(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi
