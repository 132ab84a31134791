"""The plant's joint servo (numba kernels): the arm schedule's targets and the time-optimal rate- and
acceleration-limited tracker (docs/plant.md, "Joint servo").

At the start of each servo period `servo_update` picks every joint's q'' (held over the period) from its target
(the command's override or the scenario's schedule, clamped to +-qlim); the joints then move exactly for constant
acceleration (`joints_at`). A jammed joint (P.STALL_J from P.STALL_US on) stops within one servo period.

Arm schedule rows: [t0_us, t1_us, qa1, qa2, qa3, qb1, qb2, qb3]; target(t) interpolates linearly from qa at t0 to
qb at t1 (a step is a zero-length segment's neighbour). Before the first row the first qa holds, after the last row
the last qb holds.
"""

from __future__ import annotations

import math

from numba import njit

from sim_bridge.plant_layout import C, P, X

N_SCHED_COLS = 8


@njit(cache=True)
def servo_accel(e: float, v: float, h: float, amax: float, vmax: float) -> float:
    """Joint acceleration for the next servo period h: time-optimal, rate- and acceleration-limited.

    e = target - q, v = q'. Far from the target the law rides the continuous braking curve
    v = sign(e) sqrt(2 a_max |e|), which is invariant under exact constant-acceleration steps, so the
    motion is the bang-coast-bang trapezoid that hits both limits (notes §3.4: 4 rad/s, 42 rad/s^2).
    Close to the target it switches to the two-step deadbeat law a = (e - 1.5 v h)/h^2, which lands
    exactly on (e, v) = (0, 0) and gives a = 0 at rest, so the servo does not chatter.
    """
    # deadbeat terminal: a0 now, a1 = -v/h - a0 next period; use it when both fit the limits
    a0 = (e - 1.5 * v * h) / (h * h)
    a1 = -v / h - a0
    if abs(a0) <= amax and abs(a1) <= amax and abs(v + a0 * h) <= vmax:
        return a0
    # braking curve: the next-period velocity that puts the state on v = sign(e) sqrt(2 A |e|)
    s = e - 0.5 * v * h
    ah = amax * h
    v1 = math.sqrt(ah * ah + 8.0 * amax * abs(s)) - ah
    v1 = 0.5 * v1 if s >= 0.0 else -0.5 * v1
    if v1 > vmax:
        v1 = vmax
    elif v1 < -vmax:
        v1 = -vmax
    a = (v1 - v) / h
    if a > amax:
        a = amax
    elif a < -amax:
        a = -amax
    return a


@njit(cache=True)
def schedule_target(sched, t_us: float, j: int) -> float:
    """Joint j's target at t_us from the arm schedule's rows (N_SCHED_COLS columns, sorted by t0)."""
    n = sched.shape[0]
    if t_us < sched[0, 0]:
        return sched[0, 2 + j]
    # binary search for the last row with t0 <= t
    lo = 0
    hi = n - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if sched[mid, 0] <= t_us:
            lo = mid
        else:
            hi = mid - 1
    t0 = sched[lo, 0]
    t1 = sched[lo, 1]
    if t_us >= t1:
        return sched[lo, 5 + j]
    return sched[lo, 2 + j] + (sched[lo, 5 + j] - sched[lo, 2 + j]) * (t_us - t0) / (t1 - t0)


@njit(inline="always")  # the step's hot path: inlined into its njit_cached callers
def servo_update(x, p, cmd, sched, t_us) -> None:
    """The servo's new period at t_us: every joint's target into x[X.QTGT] and its q'' for the period into x[X.QDD]
    (a joint at rest on its target is snapped onto it)."""
    hs = p[P.H] * int(p[P.SERVO_N])
    amax = p[P.AMAX]
    vmax = p[P.VMAX]
    qlim = p[P.QLIM]
    stall_j = int(p[P.STALL_J])
    stall_us = p[P.STALL_US]
    for j in range(3):
        if cmd[C.JOVR] > 0.5:
            tgt = cmd[C.JTGT + j]
        else:
            tgt = schedule_target(sched, float(t_us), j)
        if tgt > qlim:
            tgt = qlim
        elif tgt < -qlim:
            tgt = -qlim
        x[X.QTGT + j] = tgt
        if j == stall_j and t_us >= stall_us:
            # a jammed joint: stopped within one servo period (its reaction is in the dynamics), whatever it is told
            # from then on
            x[X.QDD + j] = -x[X.QD + j] / hs
        elif abs(tgt - x[X.Q + j]) <= 1e-12 and abs(x[X.QD + j]) <= 1e-9:
            # arrived: snap the round-off residue of the deadbeat law so the joint rests exactly
            x[X.Q + j] = tgt
            x[X.QD + j] = 0.0
            x[X.QDD + j] = 0.0
        else:
            x[X.QDD + j] = servo_accel(tgt - x[X.Q + j], x[X.QD + j], hs, amax, vmax)


@njit(inline="always")  # the step's hot path: inlined into its njit_cached callers
def joints_at(x, qdd, tau, q, qd) -> None:
    """Joint angles and rates tau after the state x with q'' held (exact for constant acceleration)."""
    for j in range(3):
        q[j] = x[X.Q + j] + x[X.QD + j] * tau + 0.5 * qdd[j] * tau * tau
        qd[j] = x[X.QD + j] + qdd[j] * tau
