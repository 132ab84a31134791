"""OFFBOARD: fly the streamed target (`OffboardTarget`, navig8_fc.modes.records; pure).

The reference starts where the vehicle was being held (the last engaged setpoint) and integrates velocity-only
axes and yaw rate; the flown setpoint adds the velocity feed-forward v / OL_POS_K (`pos_gain_1_s`). An attitude
target (SET_ATTITUDE_TARGET, read as PX4 reads it) is a multicopter's collective thrust along its attitude: it becomes
the acceleration that thrust would give (`attitude_acceleration`), limited to the reference's acceleration, integrated
with a multicopter's drag (DRAG_TAU_S) into a velocity kept within VEL_LEAD_M_S of the vehicle's and OL_VEL_MAX, and
flown as a velocity (an acceleration target the same way, as given, without the drag); the body rolls to
make its sideways part (the outer loop's roll nulls the body-y force), pitches and yaws as commanded (docs/gcs.md,
"Offboard"). Velocity-driven references stop at the ceiling, VOL_ALT_MAX above home (as PX4's LNDMC_ALT_MAX). On the
ground it idles until the target is offboard_liftoff_m above the vehicle (PX4's takeoff state
machine keeps the motors at idle while landed and no climb is asked). A stream lost between the stack's check and
the step: Hold.
"""

from __future__ import annotations

import math

from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.core.rotation import euler_to_quat, rotate_body_to_ned
from navig8_fc.modes.context import ModeContext, Step, Transition, below_ceiling, idle, integrate_led, wrap_pi
from navig8_fc.modes.px4 import FlightMode
from navig8_fc.modes.records import ModeInputs, OffboardTarget, ReferenceLimits, Vec3

VEL_LEAD_M_S = 1.0  # an acceleration target's velocity stays this close to the vehicle's (no wind-up while it lags)
# An attitude target's velocity decays as a multicopter's does in still air (linear drag, v' = a - v / tau): a level
# attitude slows down and stops instead of drifting on for ever (docs/model.md, "Offboard attitude targets").
DRAG_TAU_S = 3.0
_NAN3: Vec3 = (math.nan, math.nan, math.nan)


def body_to_ned(roll: float, pitch: float, yaw: float, v: Vec3) -> Vec3:
    """A body (FRD) vector in NED at the ZYX Euler attitude (roll, pitch, yaw)."""
    return rotate_body_to_ned(euler_to_quat(roll, pitch, yaw), v)


def attitude_acceleration(tgt: OffboardTarget, hover_thrust: float, g: float) -> Vec3:
    """The NED acceleration a multicopter at the target's attitude has: with a normalised body thrust vector T (a
    collective thrust t is (0, 0, -t)), g R(q) T / hover_thrust + (0, 0, g), so t = hover_thrust level holds the
    altitude, more climbs, a roll phi at thrust t pushes sideways with g t sin(phi) / hover_thrust; without a thrust,
    the horizontal acceleration of level flight at that tilt (g tan(tilt) along it) and no vertical demand (NaN).
    NaN everywhere when the target has no attitude."""
    if not tgt.attitude_given:
        return _NAN3
    if all(math.isfinite(c) for c in tgt.thrust_body):
        k = g / hover_thrust
        a = body_to_ned(tgt.roll_rad, tgt.pitch_rad, tgt.yaw_rad, tgt.thrust_body)
        return k * a[0], k * a[1], k * a[2] + g
    d = body_to_ned(tgt.roll_rad, tgt.pitch_rad, tgt.yaw_rad, (0.0, 0.0, -1.0))  # the thrust's direction
    return -g * d[0] / d[2], -g * d[1] / d[2], math.nan  # d[2] < 0: tilts are refused beyond 60 deg


def _clip_norm(v: list[float], limit: float) -> None:
    n = math.sqrt(sum(c * c for c in v))
    if n > limit > 0.0:
        v[:] = [c * limit / n for c in v]


class Offboard:
    def __init__(self, ctx: ModeContext) -> None:
        self._ctx = ctx
        self.target: OffboardTarget | None = None  # the last streamed target while it is fresh (None: lost)
        self.pos_gain_1_s = 1.0  # the outer loop's OL_POS_K: velocity feed-forward as a position offset v / K_p
        self.limits = ReferenceLimits()  # what the reference flies (an attitude target's acceleration and speed)
        self._ref = Setpoint((0.0, 0.0, 0.0))  # the reference (set on entry)
        self._vel = [0.0, 0.0, 0.0]  # an attitude target's integrated velocity (NED)

    def set_target(self, sp: Setpoint | OffboardTarget | None) -> None:
        """A Setpoint is a position target (position, pitch, yaw); None: the stream is lost."""
        self.target = OffboardTarget.of(sp) if isinstance(sp, Setpoint) else sp

    def enter(self, inp: ModeInputs) -> None:
        out = self._ctx.last_output
        x, y, z = inp.pos_ned_m
        self._ref = (Setpoint(out.setpoint.pos_ned_m, out.setpoint.pitch_rad, out.setpoint.yaw_rad)
                     if out is not None and out.engaged else Setpoint((x, y, z), 0.0, inp.yaw_rad))
        self._vel = list(inp.vel_ned_m_s)

    def update(self, inp: ModeInputs, dt: float) -> Step:
        ctx = self._ctx
        if self.target is None:  # lost between the stack's check and this step
            return Step(ctx.last_output.setpoint if ctx.last_output else idle(inp), True, None,
                        Transition(FlightMode.HOLD))
        sp = self._fly(self.target, inp, dt)
        if ctx.detector.landed and sp.pos_ned_m[2] > inp.pos_ned_m[2] - ctx.config.offboard_liftoff_m:
            return Step(idle(inp), False)  # on the ground and not asked to climb: idle, as PX4's takeoff state
        return Step(sp, True)

    def _accelerated(self, tgt: OffboardTarget, pos: Vec3, vel: Vec3, inp: ModeInputs, dt: float) -> Vec3:
        """`vel` with the attitude's acceleration, or an acceleration target's, integrated on the axes that have
        neither a position nor a velocity (module docstring)."""
        lim = self.limits
        if tgt.attitude_given:  # a multicopter's acceleration, slowed by its drag
            acc = list(attitude_acceleration(tgt, self._ctx.config.hover_thrust, lim.gravity_m_s2))
            drag_tau_s = DRAG_TAU_S
        else:  # an acceleration target: integrated as given
            acc, drag_tau_s = list(tgt.acc_ned_m_s2), math.inf
        axes = [i for i in range(3) if math.isnan(pos[i]) and math.isnan(vel[i]) and math.isfinite(acc[i])]
        if not axes:
            self._vel = list(inp.vel_ned_m_s)
            return vel
        a = [acc[i] for i in axes]
        _clip_norm(a, lim.acc_max_m_s2)
        for i, ai in zip(axes, a, strict=True):
            v0 = inp.vel_ned_m_s[i]
            v = self._vel[i] + (ai - self._vel[i] / drag_tau_s) * dt
            self._vel[i] = min(v0 + VEL_LEAD_M_S, max(v0 - VEL_LEAD_M_S, v))
        if self._ctx.detector.landed:
            self._vel[2] = min(self._vel[2], 0.0)  # not into the ground
        v = [self._vel[i] for i in axes]
        _clip_norm(v, lim.speed_max_m_s)
        out = list(vel)
        for i, vi in zip(axes, v, strict=True):
            out[i] = self._vel[i] = vi
        return out[0], out[1], out[2]

    def _fly(self, tgt: OffboardTarget, inp: ModeInputs, dt: float) -> Setpoint:
        """The streamed target -> this step's setpoint (OffboardTarget's docstring). The reference (self._ref)
        integrates velocity-only axes and yaw rate; the flown setpoint adds the velocity feed-forward."""
        ref = self._ref
        pos = tgt.pos_ned_m
        vel = self._accelerated(tgt, pos, tgt.vel_ned_m_s, inp, dt)
        v_int = tuple(0.0 if math.isnan(v) or not math.isnan(p) else v for p, v in zip(pos, vel, strict=True))
        moved = integrate_led(ref.pos_ned_m, v_int, inp.pos_ned_m, dt, self._ctx.config.manual_lead_m)  # type: ignore[arg-type]
        ref_pos = tuple(m if math.isnan(p) else p for p, m in zip(pos, moved, strict=True))
        if self._ctx.detector.landed:  # the reference does not sink into the ground under an idle vehicle
            ref_pos = (ref_pos[0], ref_pos[1], min(ref_pos[2], inp.pos_ned_m[2]))
        capped = below_ceiling(ref_pos, self._ctx)  # type: ignore[arg-type]
        if capped is not ref_pos:  # at the ceiling (VOL_ALT_MAX): an attitude target's climb stops there too
            ref_pos = capped
            self._vel[2] = max(self._vel[2], 0.0)
        if not math.isnan(tgt.yaw_rad):
            yaw = tgt.yaw_rad
        elif not math.isnan(tgt.yaw_rate_rad_s):
            yaw = wrap_pi(ref.yaw_rad + tgt.yaw_rate_rad_s * dt)
        else:
            yaw = ref.yaw_rad
        pitch = ref.pitch_rad if math.isnan(tgt.pitch_rad) else tgt.pitch_rad
        self._ref = Setpoint(ref_pos, pitch, yaw)  # type: ignore[arg-type]
        k = self.pos_gain_1_s
        if k <= 0.0 or all(math.isnan(v) for v in vel):
            return self._ref
        ff = tuple(r if math.isnan(v) else r + v / k for r, v in zip(ref_pos, vel, strict=True))
        return Setpoint(below_ceiling(ff, self._ctx), pitch, yaw)  # type: ignore[arg-type]
