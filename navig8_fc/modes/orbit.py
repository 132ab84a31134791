"""ORBIT (PX4's POSCTL.ORBIT, MAV_CMD_DO_ORBIT; pure): circle a centre at a radius, a tangential speed and an
altitude, as PX4's orbit flight task flies it (PX4 src/modules/flight_mode_manager/tasks/Orbit/FlightTaskOrbit.cpp,
`applyCommandParameters`, `_sanitizeParams`, `_generate_circle_approach_setpoints`, `_generate_circle_setpoints`,
`_generate_circle_yaw_setpoints`; docs/gcs.md "Orbit"):

- `resolve`: what a request leaves out (NaN) is the orbit being flown, or PX4's defaults when none is (radius 1 m,
  1 m/s, clockwise, facing the centre, the centre where the vehicle is, its altitude); a radius outside
  [1 m, ORB_RAD_MAX] is refused (PX4: "Orbit radius limit exceeded");
- `limited_speed`: the speed gives way, never the radius (PX4 keeps v^2 < 2 m/s^2 r): the centripetal acceleration
  stays within CENTRIPETAL_SHARE of the position reference's acceleration limit (OL_ACC_REF with command shaping,
  else OL_ACC_MAX; the rest pulls the vehicle back onto the circle), and the velocity the loop commands on the circle
  (the speed and the centripetal part a / OL_VEL_K the velocity stage adds) stays within OL_VEL_MAX;
- away from the circle the vehicle first flies to its closest point at the orbit's altitude, facing the centre, and
  circles once within ON_CIRCLE_M of it (and ON_CIRCLE_ALT_M of the altitude), as PX4's circle approach;
- on the circle, an angle advances at omega = v / r (the speed ramps up at SPEED_RAMP_SHARE of the acceleration
  limit, as PX4 slews it) and the setpoint is the point at that angle divided by the position reference's frequency
  response H(i omega) (`reference_response`): the setpoint interface carries a position only, and the reference (the
  command shaper, or the loop itself without shaping) is linear on the circle, so the reference flies exactly the
  circle at radius r and speed v instead of a smaller circle lagging behind;
- the heading per ORBIT_YAW_BEHAVIOUR (`orbit_yaw`).
The angle to fly (param4, radians, 0 = forever) ends the orbit in Hold; PX4 ignores it.
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Callable
from dataclasses import dataclass

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.modes.context import ModeContext, Step, Transition, approach, wrap_pi
from navig8_fc.modes.px4 import FlightMode
from navig8_fc.modes.records import ModeInputs, ReferenceLimits, Vec3

RADIUS_MIN_M = 1.0  # PX4's _radius_min
DEFAULT_RADIUS_M, DEFAULT_SPEED_M_S = 1.0, 1.0  # PX4's activate(): what a first orbit flies when not told
CENTRIPETAL_SHARE = 0.8  # of the reference's acceleration limit; the rest corrects the radius
ON_CIRCLE_M = 2.0  # PX4's _horizontal_acceptance_radius: closer than this to the circle, the approach is over
ON_CIRCLE_ALT_M = 0.8  # PX4's NAV_MC_ALT_RAD default: ... and this close to the orbit's altitude
SPEED_RAMP_SHARE = 0.5  # the tangential speed ramps up at this share of the acceleration limit
# ORBIT_YAW_BEHAVIOUR (common.xml)
YAW_TO_CENTRE, YAW_INITIAL, YAW_UNCONTROLLED, YAW_TANGENT, YAW_RC, YAW_UNCHANGED = range(6)
_NAN = math.nan


@dataclass(frozen=True)
class OrbitRequest:
    """MAV_CMD_DO_ORBIT in local NED (NaN: not given)."""

    radius_m: float = _NAN  # signed: positive clockwise seen from above, negative counter-clockwise
    speed_m_s: float = _NAN  # tangential, >= 0
    yaw_behaviour: int = YAW_UNCHANGED  # ORBIT_YAW_BEHAVIOUR 0..4; 5: unchanged
    sweep_rad: float = _NAN  # the angle to fly, then Hold; 0: forever
    centre_ne_m: tuple[float, float] = (_NAN, _NAN)  # both given, or the centre is kept / the vehicle's position
    alt_down_m: float = _NAN  # the orbit's altitude as NED down


@dataclass(frozen=True)
class OrbitPlan:
    """The orbit flown (ORBIT_EXECUTION_STATUS reports it): its centre (NED, z = the orbit's altitude), radius,
    speed (limited), direction, heading behaviour, the angle to fly (0: forever) and the heading when commanded."""

    centre_ned_m: Vec3
    radius_m: float
    speed_m_s: float
    clockwise: bool
    yaw_behaviour: int
    sweep_rad: float
    initial_yaw_rad: float

    @property
    def signed_radius_m(self) -> float:  # MAVLink's convention: the sign is the direction
        return self.radius_m if self.clockwise else -self.radius_m

    @property
    def signed_speed_m_s(self) -> float:  # positive: the angle from north towards east grows (clockwise)
        return self.speed_m_s if self.clockwise else -self.speed_m_s


def limited_speed(radius_m: float, speed_m_s: float, limits: ReferenceLimits) -> float:
    """The tangential speed flown (module docstring): min(|v|, sqrt(CENTRIPETAL_SHARE a r), v_c), where v_c solves
    v_c^2 + (v_c^2 / (r K_v))^2 = OL_VEL_MAX^2 (the velocity command on the circle at OL_VEL_MAX)."""
    k = radius_m * limits.vel_k_1_s
    x = 0.5 * k * k * (math.sqrt(1.0 + 4.0 * (limits.speed_max_m_s / k) ** 2) - 1.0)  # v_c^2
    return min(abs(speed_m_s), math.sqrt(CENTRIPETAL_SHARE * limits.acc_max_m_s2 * radius_m), math.sqrt(x))


def resolve(req: OrbitRequest, flown: OrbitPlan | None, here: Vec3, yaw_rad: float,
            limits: ReferenceLimits) -> tuple[OrbitPlan | None, str, str]:
    """(the orbit to fly, '', a note when the speed was limited) or (None, the reason it is refused, '')."""
    if math.isfinite(req.radius_m):
        radius, clockwise = abs(req.radius_m), req.radius_m > 0.0
    else:
        radius = flown.radius_m if flown else DEFAULT_RADIUS_M
        clockwise = flown.clockwise if flown else True
    if not RADIUS_MIN_M <= radius <= limits.orbit_radius_max_m:
        return None, (f"Orbit radius {radius:g} m outside [{RADIUS_MIN_M:g}, {limits.orbit_radius_max_m:g}] m "
                      "(ORB_RAD_MAX)"), ""
    if math.isfinite(req.speed_m_s) and req.speed_m_s < 0.0:
        return None, "Orbit speed must be >= 0 (the radius's sign sets the direction)", ""
    if math.isfinite(req.sweep_rad) and req.sweep_rad < 0.0:
        return None, "Orbit angle (param4) must be >= 0 rad (0: forever)", ""
    if not 0 <= req.yaw_behaviour <= YAW_UNCHANGED:
        return None, f"Orbit yaw behaviour {req.yaw_behaviour} unknown (0..5)", ""
    asked = req.speed_m_s if math.isfinite(req.speed_m_s) else (flown.speed_m_s if flown else DEFAULT_SPEED_M_S)
    speed = limited_speed(radius, asked, limits)
    yaw = req.yaw_behaviour if req.yaw_behaviour != YAW_UNCHANGED else (flown.yaw_behaviour if flown
                                                                        else YAW_TO_CENTRE)
    sweep = req.sweep_rad if math.isfinite(req.sweep_rad) else (flown.sweep_rad if flown else 0.0)
    old = flown.centre_ned_m if flown else here
    n, e = req.centre_ne_m if all(map(math.isfinite, req.centre_ne_m)) else old[:2]
    d = req.alt_down_m if math.isfinite(req.alt_down_m) else old[2]
    note = (f"Orbit: {asked:.2f} m/s limited to {speed:.2f} m/s at radius {radius:g} m (OL_VEL_MAX, OL_ACC_REF)"
            if asked - speed > 0.01 else "")
    return OrbitPlan((n, e, d), radius, speed, clockwise, yaw, sweep, yaw_rad), "", note


def reference_response(omega_rad_s: float, limits: ReferenceLimits) -> complex:
    """H(i omega) of the position reference from setpoint to reference, per horizontal axis (a circle in N + iE is
    multiplied by it): the shaper's cascade p''' = K_j (K_v (K_p (sp - p) - p') - p''), or without shaping the
    loop's p'' = K_v (K_p (sp - p) - p')."""
    s = 1j * omega_rad_s
    kp, kv, kj = limits.pos_k_1_s, limits.vel_k_1_s, limits.jerk_k_1_s
    if kj > 0.0:
        return kj * kv * kp / (s ** 3 + kj * s * s + kj * kv * s + kj * kv * kp)
    return kv * kp / (s * s + kv * s + kv * kp)


def orbit_yaw(behaviour: int, centre_ned_m: Vec3, pos_ned_m: Vec3, clockwise: bool, initial_rad: float,
              current_rad: float) -> float:
    """The heading per ORBIT_YAW_BEHAVIOUR from the vehicle's position (PX4's _generate_circle_yaw_setpoints): the
    front to the centre, along the circle in the direction flown, the heading when commanded, or (uncontrolled, RC:
    the caller's) the current one."""
    dn, de = pos_ned_m[0] - centre_ned_m[0], pos_ned_m[1] - centre_ned_m[1]
    if behaviour == YAW_INITIAL:
        return initial_rad
    if math.hypot(dn, de) < 1e-6 or behaviour not in (YAW_TO_CENTRE, YAW_TANGENT):
        return current_rad
    if behaviour == YAW_TO_CENTRE:
        return math.atan2(-de, -dn)
    s = 1.0 if clockwise else -1.0
    return math.atan2(s * dn, -s * de)


def on_circle(plan: OrbitPlan, pos_ned_m: Vec3) -> bool:
    c = plan.centre_ned_m
    return (abs(math.hypot(pos_ned_m[0] - c[0], pos_ned_m[1] - c[1]) - plan.radius_m) < ON_CIRCLE_M
            and abs(pos_ned_m[2] - c[2]) < ON_CIRCLE_ALT_M)


class Orbit:
    """The mode (module docstring). `sticks` gives the MANUAL_CONTROL sticks (YAW_RC turns with the yaw stick)."""

    def __init__(self, ctx: ModeContext, sticks: Callable[[], tuple[float, float, float, float]]) -> None:
        self._ctx, self._sticks = ctx, sticks
        self.limits = ReferenceLimits()
        self.plan: OrbitPlan | None = None  # the orbit commanded (flown while in ORBIT)
        self.circling = False  # False: approaching the circle
        self._theta = self._speed = self._swept = 0.0  # angle from north towards east, signed speed, angle flown
        self._approach_to: Vec3 = (0.0, 0.0, 0.0)
        self._pitch = self._yaw = 0.0

    def enter(self, inp: ModeInputs) -> None:
        plan = self.plan
        assert plan is not None
        start = self._ctx.start_setpoint(inp)
        self._pitch, self._yaw = start.pitch_rad, start.yaw_rad
        self.circling = False
        c, p = plan.centre_ned_m, inp.pos_ned_m
        dn, de = p[0] - c[0], p[1] - c[1]
        d = math.hypot(dn, de)
        un, ue = (dn / d, de / d) if d > 1e-6 else (1.0, 0.0)
        self._approach_to = (c[0] + plan.radius_m * un, c[1] + plan.radius_m * ue, c[2])
        if on_circle(plan, p):
            self._start_circle(inp)

    def _start_circle(self, inp: ModeInputs) -> None:
        plan = self.plan
        assert plan is not None
        c, p, v = plan.centre_ned_m, inp.pos_ned_m, inp.vel_ned_m_s
        self._theta = math.atan2(p[1] - c[1], p[0] - c[0])
        tangential = -math.sin(self._theta) * v[0] + math.cos(self._theta) * v[1]  # along the clockwise tangent
        self._speed = max(-plan.speed_m_s, min(plan.speed_m_s, tangential))
        self._swept = 0.0
        self.circling = True
        self._ctx.events.append(f"Orbit: circling r {plan.radius_m:g} m at {plan.speed_m_s:.2f} m/s "
                                + ("clockwise" if plan.clockwise else "counter-clockwise"))

    def update(self, inp: ModeInputs, dt: float) -> Step:
        plan = self.plan
        assert plan is not None
        if not self.circling:
            if not on_circle(plan, inp.pos_ned_m):
                self._yaw = orbit_yaw(YAW_TO_CENTRE, plan.centre_ned_m, inp.pos_ned_m, plan.clockwise, 0.0, self._yaw)
                return Step(Setpoint(self._approach_to, self._pitch, self._yaw), True)
            self._start_circle(inp)
        r, c = plan.radius_m, plan.centre_ned_m
        self._speed = approach(self._speed, plan.signed_speed_m_s, SPEED_RAMP_SHARE * self.limits.acc_max_m_s2 * dt)
        omega = self._speed / r
        self._theta = wrap_pi(self._theta + omega * dt)
        self._swept += abs(omega) * dt
        z = r * cmath.exp(1j * self._theta) / reference_response(omega, self.limits)
        if plan.yaw_behaviour == YAW_RC:
            stick = self._sticks()[3]
            cfg = self._ctx.config
            self._yaw = wrap_pi(self._yaw + (0.0 if abs(stick) < cfg.manual_deadband else stick)
                                * cfg.manual_yaw_rate_rad_s * dt)
        else:
            self._yaw = orbit_yaw(plan.yaw_behaviour, c, inp.pos_ned_m, plan.clockwise, plan.initial_yaw_rad, self._yaw)
        sp = Setpoint((c[0] + z.real, c[1] + z.imag, c[2]), self._pitch, self._yaw)
        if plan.sweep_rad > 0.0 and self._swept >= plan.sweep_rad:
            self._ctx.events.append(f"Orbit: {plan.sweep_rad:.2f} rad flown: holding")
            return Step(sp, True, None, Transition(FlightMode.HOLD))
        return Step(sp, True)
