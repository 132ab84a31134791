"""Where a motion braked at the position reference's limits comes to rest (pure): Hold's stopping point."""

from __future__ import annotations

import math

from navig8_fc.modes.records import Vec3


def braking_distance_m(v_m_s: float, a_m_s2: float, acc_max_m_s2: float, jerk_max_m_s3: float,
                       lag_s: float = 0.0) -> float:
    """The distance a 1-D motion at speed v > 0 and acceleration a (along v) flies before it rests, braking at most at
    acc_max with the acceleration changing at most at jerk_max (inf: at once), after reacting lag_s late (the
    command shaper's jerk stage). The braking is time-optimal: the acceleration ramps from a to -a_p, holds -a_p
    while the speed needs it, and ramps back to zero as the speed reaches zero, with a_p = min(acc_max,
    sqrt(j v + a^2 / 2)) (the peak at which the two ramps alone take the speed to zero). With a = 0 and no lag it
    is v^2 / (2 A) + v A / (2 j) once the speed reaches the plateau (PX4's computeBrakingDistanceFromVelocity has
    the same two terms)."""
    big_a, j = acc_max_m_s2, jerk_max_m_s3
    if not math.isfinite(big_a):
        return 0.0
    s = v_m_s * lag_s + 0.5 * a_m_s2 * lag_s * lag_s  # the reaction
    v = v_m_s + a_m_s2 * lag_s
    if v <= 0.0:
        return max(0.0, s)
    if not math.isfinite(j):
        return max(0.0, s + v * v / (2.0 * big_a))
    a0 = max(a_m_s2, -big_a)
    a_p = min(big_a, math.sqrt(j * v + 0.5 * a0 * a0))
    a = a0
    if a_p < -a0:  # already braking harder than needed: only the ramp out
        t = -a0 / j
        return max(0.0, s + v * t + 0.5 * a * t * t + j * t ** 3 / 6.0)
    for jerk, t in ((-j, (a0 + a_p) / j), (0.0, math.nan), (j, a_p / j)):
        if jerk == 0.0:  # the plateau: until the speed the ramp out removes is what is left
            t = max(0.0, (v - a_p * a_p / (2.0 * j)) / a_p) if a_p > 0.0 else 0.0
        s += v * t + 0.5 * a * t * t + jerk * t ** 3 / 6.0
        v += a * t + 0.5 * jerk * t * t
        a += jerk * t
    return max(0.0, s)



def stopping_point(x: float, y: float, vel_ned_m_s: Vec3, accel_ned_m_s2: Vec3, acc_max_m_s2: float,
                   jerk_max_m_s3: float, lag_s: float) -> tuple[float, float]:
    """Where the horizontal motion from (x, y) comes to rest under the position reference's braking limits
    (braking_distance_m); holding any nearer point flies past it and back."""
    vx, vy = vel_ned_m_s[0], vel_ned_m_s[1]
    v = math.hypot(vx, vy)
    if not v > 0.0:  # also NaN
        return x, y
    ux, uy = vx / v, vy / v
    a_along = accel_ned_m_s2[0] * ux + accel_ned_m_s2[1] * uy
    d = braking_distance_m(v, a_along if math.isfinite(a_along) else 0.0, acc_max_m_s2, jerk_max_m_s3, lag_s)
    return x + ux * d, y + uy * d
