"""Offboard targets (SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT, SET_ATTITUDE_TARGET) -> an `OffboardTarget`.

Pure: the caller gives the decoded fields (a global position already projected to NED) and sends the STATUSTEXTs.
Read as PX4's mavlink_receiver does (handle_message_set_position_target_local_ned / _global_int,
handle_message_set_attitude_target and fill_thrust; docs/gcs.md "Offboard"): every ignore bit of type_mask makes that
component NaN (not given); a target with no position, velocity or attitude is refused ("invalid"), as is an
acceleration flagged as a force (FORCE_SET). What this vehicle's FlightStack cannot fly is named, not flown:
- acceleration (afx..afz): flown on the axes with neither a position nor a velocity (integrated into the reference,
  as PX4 flies an acceleration setpoint); beside a position or velocity on its axis it is named and ignored (PX4
  feeds it forward; the setpoint interface carries position, velocity feed-forward, pitch and yaw);
- SET_ATTITUDE_TARGET: the quaternion is the attitude and `thrust` the normalised collective thrust [0, 1] along its
  body -z, as PX4 reads them for a multicopter (MAV_TYPE_TRICOPTER: thrust_body = (0, 0, -thrust)); with
  THRUST_BODY_SET (bit 5) `thrust_body` is the thrust vector in body axes, as given. The mode flies the acceleration
  that thrust at that attitude gives a multicopter (navig8_fc.modes.offboard.attitude_acceleration, MPC_THR_HOVER =
  level hover), within the reference's limits; the body pitches and yaws as commanded and rolls to make the
  sideways part. Roll and pitch beyond +-60 deg are refused; body rates alone (attitude ignored) are refused: the
  INDI stack takes attitude targets, its rate loop is internal; body rates beside an attitude are named, not flown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from navig8_fc.core.rotation import quat_to_euler
from navig8_fc.mission.plan import PITCH_HOLD_MAX_DEG
from navig8_fc.modes.manager import OffboardTarget

Vec3 = tuple[float, float, float]
NAN3: Vec3 = (math.nan, math.nan, math.nan)

# POSITION_TARGET_TYPEMASK (common.xml)
PT_X, PT_Y, PT_Z, PT_VX, PT_VY, PT_VZ, PT_AX, PT_AY, PT_AZ = (1 << i for i in range(9))
PT_FORCE_SET, PT_YAW, PT_YAW_RATE = 512, 1024, 2048
PT_ACCEL = PT_AX | PT_AY | PT_AZ
# ATTITUDE_TARGET_TYPEMASK (common.xml)
AT_ROLL_RATE, AT_PITCH_RATE, AT_YAW_RATE, AT_THRUST_BODY_SET, AT_THRUST, AT_ATTITUDE = 1, 2, 4, 32, 64, 128
AT_RATES = AT_ROLL_RATE | AT_PITCH_RATE | AT_YAW_RATE
MAV_FRAME_LOCAL_NED, MAV_FRAME_BODY_NED = 1, 8
PITCH_MAX_RAD = math.radians(PITCH_HOLD_MAX_DEG)  # the same bound as the pitch-hold mission item (roll too)


@dataclass(frozen=True)
class Decoded:
    """A target to fly (with `ignored` naming any part not flown, for one STATUSTEXT), or a refusal."""

    target: OffboardTarget | None
    refusal: str = ""
    ignored: str = ""


def _given(mask: int, bits: tuple[int, int, int], values: Vec3) -> Vec3:
    return tuple(math.nan if mask & b else float(v) for b, v in zip(bits, values, strict=True))  # type: ignore


def position_target(kind: str, mask: int, frame: int, pos_ned_m: Vec3, vel: Vec3, acc: Vec3, yaw_rad: float,
                    yaw_rate_rad_s: float, yaw_now_rad: float) -> Decoded:
    """SET_POSITION_TARGET_*: pos_ned_m already in NED (a global position projected by the caller), `frame` only
    for BODY_NED (velocities in the heading frame, position ignored, as PX4), vel/acc/yaw as sent."""
    pos = _given(mask, (PT_X, PT_Y, PT_Z), pos_ned_m)
    v = _given(mask, (PT_VX, PT_VY, PT_VZ), vel)
    a = _given(mask, (PT_AX, PT_AY, PT_AZ), acc)
    has_acc = (mask & PT_ACCEL) != PT_ACCEL
    if frame == MAV_FRAME_BODY_NED:
        pos = NAN3
        v, a = _heading_to_ned(v, yaw_now_rad), _heading_to_ned(a, yaw_now_rad)
    if has_acc and mask & PT_FORCE_SET:
        return Decoded(None, f"{kind}: force targets are not supported (type_mask {mask})")
    # an acceleration is flown where neither a position nor a velocity is given on its axis (integrated, as PX4's
    # acceleration setpoint); beside them it would be a feed-forward, which the setpoint cannot carry: named
    a_flown = tuple(c if math.isnan(p) and math.isnan(w) else math.nan for p, w, c in zip(pos, v, a, strict=True))
    target = OffboardTarget(pos, v, math.nan if mask & PT_YAW else float(yaw_rad),
                            math.nan if mask & PT_YAW_RATE else float(yaw_rate_rad_s),
                            acc_ned_m_s2=a_flown)  # type: ignore[arg-type]
    if all(math.isnan(c) for c in (*pos, *v, *a_flown)):
        return Decoded(None, f"{kind} invalid: no position, velocity or acceleration (type_mask {mask})")
    problem = target.problem()
    if problem:
        return Decoded(None, f"{kind}: {problem}")
    fed_forward = any(not math.isnan(c) and math.isnan(f) for c, f in zip(a, a_flown, strict=True))
    ignored = "Offboard: acceleration ignored beside pos/vel" if fed_forward else ""  # one STATUSTEXT chunk
    return Decoded(target, ignored=ignored)


def _heading_to_ned(v: Vec3, yaw_rad: float) -> Vec3:
    """BODY_NED: forward/right in the heading frame to north/east (PX4), down as given; nothing given: nothing."""
    if all(math.isnan(c) for c in v):
        return v
    fwd, right = (0.0 if math.isnan(c) else c for c in v[:2])
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return c * fwd - s * right, s * fwd + c * right, 0.0 if math.isnan(v[2]) else v[2]


def attitude_target(mask: int, q_wxyz: tuple[float, float, float, float], thrust: float, body_rates: Vec3,
                    thrust_body: Vec3 = NAN3) -> Decoded:
    """SET_ATTITUDE_TARGET -> the attitude and a normalised body thrust vector (module docstring)."""
    kind = "SET_ATTITUDE_TARGET"
    if mask & AT_ATTITUDE:
        if (mask & AT_RATES) != AT_RATES:
            return Decoded(None, f"{kind}: body-rate targets are not supported (the INDI stack takes an attitude; "
                                 "send the quaternion)")
        return Decoded(None, f"{kind} invalid: no attitude (type_mask {mask})")
    if not all(math.isfinite(c) for c in q_wxyz):
        return Decoded(None, f"{kind}: quaternion must be finite")
    norm = math.sqrt(sum(c * c for c in q_wxyz))
    if not 0.9 < norm < 1.1:
        return Decoded(None, f"{kind}: quaternion is not a unit quaternion (|q| = {norm:.3f})")
    roll, pitch, yaw = quat_to_euler(tuple(c / norm for c in q_wxyz))
    for name, angle in (("pitch", pitch), ("roll", roll)):
        if abs(angle) > PITCH_MAX_RAD:
            return Decoded(None, f"{kind}: {name} {math.degrees(angle):.0f} deg beyond +-{PITCH_HOLD_MAX_DEG:.0f} deg")
    body = NAN3
    if mask & AT_THRUST_BODY_SET:  # PX4: the vector as given (the ignore bit is not looked at)
        if all(math.isnan(c) for c in thrust_body):  # the dialect's message has no such field (pymavlink's common)
            return Decoded(None, f"{kind}: THRUST_BODY_SET but no thrust_body received; send thrust")
        if not all(math.isfinite(c) and abs(c) <= 1.0 for c in thrust_body):
            return Decoded(None, f"{kind}: thrust_body must lie in [-1, 1] on each axis")
        body = (float(thrust_body[0]), float(thrust_body[1]), float(thrust_body[2]))
    elif not mask & AT_THRUST:
        if not (math.isfinite(thrust) and 0.0 <= thrust <= 1.0):
            return Decoded(None, f"{kind}: thrust {thrust:g} outside [0, 1]")
        body = (0.0, 0.0, -float(thrust))  # a multicopter's collective (PX4's fill_thrust)
    rates = _given(mask, (AT_ROLL_RATE, AT_PITCH_RATE, AT_YAW_RATE), body_rates)
    ignored = ("Offboard: body rates ignored (the attitude is flown)"
               if any(math.isfinite(r) and r != 0.0 for r in rates) else "")
    return Decoded(OffboardTarget(NAN3, NAN3, yaw, math.nan, pitch, roll, body), ignored=ignored)
