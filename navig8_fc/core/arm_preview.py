"""Arm preview (INDI_ARM_FF = 2): the arm's reaction predicted from its commanded trajectory.

The arm reversal's reaction (≈ 60 rad/s² of pitch) arrives within one control tick, while the actuators (second
order, ωn = 120 rad/s, the tail reversing through zero speed) need ≈ 90 ms to deliver the counter-moment; a
feed-forward of the *measured* reaction (INDI_ARM_FF = 1) cannot beat that lag. But the FC knows what the arm was
told to do: the scenario's arm plan (joint targets in sim time, which the joint servo follows) or the last
arm-joint command. So the FC runs its own model of the joint servo forward from the measured joint state over
a lead time (INDI_ARM_LEAD, about the actuators' lag) and feeds forward the reaction the arm will produce then,
as a preview (reference-model) feed-forward does.

The servo model is the FC's own (parameters ARM_SERVO_VMAX, ARM_SERVO_AMAX, ARM_SERVO_HZ: the arm's data sheet,
not the plant's truth): a time-optimal rate- and acceleration-limited tracker that follows the braking curve
v = sign(e)·sqrt(2 a_max |e|), clipped to ±v_max, with the acceleration clipped to ±a_max (bang-coast-bang).
The reaction is ḣ of `g_c.mass_props` (MP.HDC: minus the arm's reaction pitch moment about the composite
CoM, the term CKF_ARM_WRENCH and INDI_ARM_FF = 1 use) at the predicted (q, q̇, q̈) with the estimated object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from navig8_fc.core import g_c
from navig8_fc.core.jit import njit_cached
from navig8_fc.core.layout import layout

_MP_HDC = int(g_c.MP.HDC)
_N_MP = int(g_c.MP.SIZE)

# A plan row: [t0_s, t1_s, q_start (3), q_end (3)]: the target moves linearly from q_start at t0 to q_end at t1
# (t1 == t0: a step); before the first row the first q_start holds, after a row's t1 its q_end until the next row.
PLAN_COLS = 8
# A joint within these of its target is taken as at rest on it: the joint-angle estimate's residual noise (σ ≈ 0.006
# rad, docs/model.md "Joint angles") would otherwise read as a target error the model's bang-bang law turns into
# ±a_max, i.e. a reaction the arm never produces (5σ of the angle estimate and of the 0.01 rad/s rate noise).
REST_TOL_RAD = 0.03
REST_TOL_RAD_S = 0.05
RESYNC_RAD = 0.2  # the reference model is put back on the measured joints when it is this far off


@njit(cache=True)
def plan_target(plan: np.ndarray, t_s: float, j: int) -> float:
    """Joint j's commanded angle (rad) at sim time t_s from the plan rows (linear scan: plans are short)."""
    n = plan.shape[0]
    if t_s < plan[0, 0]:
        return plan[0, 2 + j]
    i = 0
    while i + 1 < n and plan[i + 1, 0] <= t_s:
        i += 1
    t0, t1 = plan[i, 0], plan[i, 1]
    if t_s >= t1:
        return plan[i, 5 + j]
    return plan[i, 2 + j] + (t_s - t0) / (t1 - t0) * (plan[i, 5 + j] - plan[i, 2 + j])


@njit(cache=True)
def servo_model_accel(e: float, v: float, h: float, amax: float, vmax: float) -> float:
    """The FC's joint-servo model, the arm data sheet's time-optimal tracker: the acceleration over the next period
    h that puts (e, v) on the braking curve v = sign(e) sqrt(2 a_max |e|) (clipped to ±v_max) at the period's end,
    itself clipped to ±a_max (so bang-coast-bang); on arrival, when two periods can land on (e, v) = (0, 0) within
    the limits, the first of those two accelerations (so it does not chatter)."""
    a0 = (e - 1.5 * v * h) / (h * h)
    if abs(a0) <= amax and abs(v / h + a0) <= amax and abs(v + a0 * h) <= vmax:
        return a0
    # the velocity v1 at the end of the period that lands on the curve there: with e1 = e - (v + v1) h / 2,
    # v1 = sqrt(2 a_max e1) solves v1^2 + a_max h v1 - 2 a_max (e - v h / 2) = 0 (for e1 > 0; mirrored below)
    s_e = e - 0.5 * v * h
    ah = amax * h
    v1 = 0.5 * (math.sqrt(ah * ah + 8.0 * amax * abs(s_e)) - ah)
    if s_e < 0.0:
        v1 = -v1
    v1 = min(max(v1, -vmax), vmax)
    a = (v1 - v) / h
    return min(max(a, -amax), amax)


@njit(cache=True)
def servo_model_run(plan: np.ndarray, t_s: float, n: int, h_s: float, amax: float, vmax: float,
                    state: np.ndarray) -> None:
    """Run the servo model n periods h_s from state (q (3), q̇ (3), q̈ (3)) at sim time t_s toward the plan's
    targets (exact constant-acceleration steps); afterwards state[6:9] holds the acceleration of the period that
    starts at t_s + n h_s."""
    t = t_s
    for k in range(n + 1):
        for j in range(3):
            a = servo_model_accel(plan_target(plan, t, j) - state[j], state[3 + j], h_s, amax, vmax)
            state[6 + j] = a
            if k < n:
                state[j] += state[3 + j] * h_s + 0.5 * a * h_s * h_s
                state[3 + j] += a * h_s
        t += h_s


@njit(cache=True)
def reference_advance(plan: np.ndarray, t_s: float, dt_s: float, q: np.ndarray, qd: np.ndarray, h_s: float,
                      amax: float, vmax: float, ref: np.ndarray) -> float:
    """Advance the servo reference model to t_s and return how far it is from the measured joint rates.

    ref (10,) is the reference model's state, [q (3), q̇ (3), q̈ (3), valid], at t_s − dt_s: the servo model run
    open loop on the plan (the measured angle's noise, σ ≈ 0.006 rad, would move the predicted braking point by
    as much as the braking distance near the end of a move). It is advanced to t_s and put back on the
    measurement (q the joint-angle estimate, q̇ the measured rate) when it is not yet valid or a joint is more
    than RESYNC_RAD away (the arm did not do what it was told); a measured joint at rest within REST_TOL_* of its
    target starts at rest on the target. Returns max_j |q̇_model − q̇_measured| of the advanced model before any
    resync (the preview supervisor's consistency measure), or -1 when the model was not valid (nothing to compare).
    """
    err = -1.0
    if ref[9] > 0.5:
        servo_model_run(plan, t_s - dt_s, int(dt_s / h_s + 0.5), h_s, amax, vmax, ref)
        err = 0.0
        for j in range(3):
            err = max(err, abs(ref[3 + j] - qd[j]))
            if abs(ref[j] - q[j]) > RESYNC_RAD:
                ref[9] = 0.0
    if ref[9] <= 0.5:
        for j in range(3):
            tgt = plan_target(plan, t_s, j)
            if abs(tgt - q[j]) <= REST_TOL_RAD and abs(qd[j]) <= REST_TOL_RAD_S:
                ref[j] = tgt
                ref[3 + j] = 0.0
            else:
                ref[j] = q[j]
                ref[3 + j] = qd[j]
        ref[9] = 1.0
    return err


@njit_cached(g_c)  # it calls g_c.mass_props: a change there recompiles it
def preview_ahead(plan: np.ndarray, t_s: float, lead_s: float, h_s: float, amax: float, vmax: float,
                  object_mass_kg: float, geo: np.ndarray, ref: np.ndarray, ahead: np.ndarray) -> float:
    """ḣ (MP.HDC) the arm will produce at t_s + lead_s: the servo model run lead_s ahead from ref (at t_s);
    ahead (9,) receives the predicted q, q̇, q̈ there."""
    for i in range(9):
        ahead[i] = ref[i]
    servo_model_run(plan, t_s, int(lead_s / h_s + 0.5), h_s, amax, vmax, ahead)
    inertia = np.empty((3, 3))
    rate = np.empty((3, 3))
    mp = np.empty(_N_MP)
    g_c.mass_props(ahead[0:3], ahead[3:6], ahead[6:9], object_mass_kg, geo, inertia, rate, mp)
    return mp[_MP_HDC]


@njit_cached(g_c)  # through preview_ahead
def arm_preview_step(plan: np.ndarray, t_s: float, dt_s: float, lead_s: float, q: np.ndarray, qd: np.ndarray,
                     h_s: float, amax: float, vmax: float, object_mass_kg: float, geo: np.ndarray, ref: np.ndarray,
                     ahead: np.ndarray) -> float:
    """One control tick of the unsupervised preview: the reference model advanced to t_s (`reference_advance`),
    then ḣ at t_s + lead_s (`preview_ahead`)."""
    reference_advance(plan, t_s, dt_s, q, qd, h_s, amax, vmax, ref)
    return preview_ahead(plan, t_s, lead_s, h_s, amax, vmax, object_mass_kg, geo, ref, ahead)


# The preview supervisor's state (a flat vector, `preview_supervise`): the trust in the model (0: the measured
# reaction alone, INDI_ARM_FF = 1; 1: the preview), the last consistency error, the identified servo limits, and the
# current move's bookkeeping (the largest measured and modelled joint rate and acceleration, whether the model
# disagreed during it, the ticks at rest since it ended), the previous measured rates (q̈ by difference), the number
# of times trust was withdrawn and of identifications (edges the shell announces).
PS = layout("PS", trust=1, err=1, v_hat=1, a_hat=1, moving=1, bad_move=1, pk_v_meas=1, pk_a_meas=1,
               pk_v_model=1, rest_ticks=1, qd_prev=3, qdd_prev=3, qd_ok=1, drops=1, idents=1)
# Its configuration: consistency tolerance (absolute rad/s and relative to the measured rate), the trust's rise
# time while the arm moves consistently (s), identification on/off, the rate above which a joint counts as moving.
PSC = layout("PSC", tol_v=1, tol_rel=1, rise_s=1, ident=1, move_v=1, v_max0=1, a_max0=1)
MOVE_REST_TICKS = 5  # ticks with every joint at rest (model and measurement) that end a move


@njit(cache=True)
def preview_supervise(sup: np.ndarray, cfg: np.ndarray, err: float, qd: np.ndarray, ref: np.ndarray,
                      dt_s: float) -> None:
    """Check the servo model against the measured joints, one control tick (after `reference_advance`).

    Trust: a consistency error above tol_v + tol_rel·|q̇| withdraws it at once (the preview's prediction is a
    moment the arm may not produce: an arm slower than its model would be given a reaction it never makes); it is
    earned back at 1/rise_s per second only while the arm moves and the model has agreed since the move began, so a
    model that is wrong on every move never regains it.

    Identification (ident = 1): the servo's rate and acceleration limits from the measured joints. Upward at once
    (a joint faster than v_hat, or accelerating harder than a_hat, over two consecutive ticks: the 0.01 rad/s rate
    noise differenced at 100 Hz is ~1.4 rad/s² per sample); downward at the end of a move in which the model
    disagreed and reached its rate limit while the arm stayed well below it: the arm's own peak then is its limit.
    Floors: 5 % of the data sheet's limits (a stalled joint is not a servo of zero speed)."""
    vmeas = 0.0
    vmodel = 0.0
    for j in range(3):
        vmeas = max(vmeas, abs(qd[j]))
        vmodel = max(vmodel, abs(ref[3 + j]))
    amin_noise = 4.0  # rad/s² of differenced rate noise (about 3 sigma of the paper's 0.01 rad/s at 100 Hz)
    ameas = 0.0
    if sup[PS.QD_OK] > 0.5:
        for j in range(3):
            a_now = (qd[j] - sup[PS.QD_PREV + j]) / dt_s
            # the smaller of two consecutive differences of the same sign: one noisy sample does not count
            a_prev = sup[PS.QDD_PREV + j]
            if a_now * a_prev > 0.0:
                ameas = max(ameas, min(abs(a_now), abs(a_prev)))
            sup[PS.QDD_PREV + j] = a_now
    for j in range(3):
        sup[PS.QD_PREV + j] = qd[j]
    sup[PS.QD_OK] = 1.0
    move_v = cfg[PSC.MOVE_V]
    moving = vmeas > move_v or vmodel > move_v
    if moving:
        if sup[PS.MOVING] < 0.5:
            sup[PS.MOVING] = 1.0
            sup[PS.BAD_MOVE] = 0.0
            sup[PS.PK_V_MEAS] = 0.0
            sup[PS.PK_A_MEAS] = 0.0
            sup[PS.PK_V_MODEL] = 0.0
        sup[PS.REST_TICKS] = 0.0
        sup[PS.PK_V_MEAS] = max(sup[PS.PK_V_MEAS], vmeas)
        sup[PS.PK_A_MEAS] = max(sup[PS.PK_A_MEAS], ameas)
        sup[PS.PK_V_MODEL] = max(sup[PS.PK_V_MODEL], vmodel)
    elif sup[PS.MOVING] > 0.5:
        sup[PS.REST_TICKS] += 1.0
        if sup[PS.REST_TICKS] >= MOVE_REST_TICKS:
            sup[PS.MOVING] = 0.0
            if cfg[PSC.IDENT] > 0.5 and sup[PS.BAD_MOVE] > 0.5:
                v_hat = sup[PS.V_HAT]
                if sup[PS.PK_V_MODEL] >= 0.95 * v_hat and sup[PS.PK_V_MEAS] < 0.9 * v_hat:
                    sup[PS.V_HAT] = max(sup[PS.PK_V_MEAS], 0.05 * cfg[PSC.V_MAX0])
                    sup[PS.IDENTS] += 1.0
                a_pk = sup[PS.PK_A_MEAS]
                if a_pk > amin_noise and a_pk < 0.8 * sup[PS.A_HAT]:
                    sup[PS.A_HAT] = max(a_pk, 0.05 * cfg[PSC.A_MAX0])
                    sup[PS.IDENTS] += 1.0
    if cfg[PSC.IDENT] > 0.5:
        if vmeas > 1.05 * sup[PS.V_HAT] + 0.05:
            sup[PS.V_HAT] = vmeas
            sup[PS.IDENTS] += 1.0
        if ameas > 1.1 * sup[PS.A_HAT] + amin_noise:
            sup[PS.A_HAT] = ameas
            sup[PS.IDENTS] += 1.0
    if err < 0.0:
        return
    sup[PS.ERR] = err
    if err > cfg[PSC.TOL_V] + cfg[PSC.TOL_REL] * vmeas:
        if sup[PS.TRUST] > 0.0:
            sup[PS.DROPS] += 1.0
        sup[PS.TRUST] = 0.0
        if moving:
            sup[PS.BAD_MOVE] = 1.0
    elif moving and sup[PS.BAD_MOVE] < 0.5:
        sup[PS.TRUST] = min(1.0, sup[PS.TRUST] + dt_s / cfg[PSC.RISE_S])


def plan_rows(segments: tuple[tuple[float, float, tuple[float, float, float], tuple[float, float, float]], ...]
              ) -> np.ndarray:
    """Plan rows (PLAN_COLS) from (t0_s, t1_s, q_start_rad, q_end_rad) segments sorted by t0."""
    if not segments:
        raise ValueError("an arm plan needs at least one segment")
    rows = np.array([[t0, t1, *qa, *qb] for t0, t1, qa, qb in segments], dtype=np.float64)
    if rows.shape[1] != PLAN_COLS or not np.all(np.isfinite(rows)) or np.any(rows[:, 1] < rows[:, 0]) \
            or np.any(np.diff(rows[:, 0]) < 0.0):
        raise ValueError("arm plan segments must be finite, sorted by t0, with t1 >= t0")
    return rows


def hold_plan(q_rad: tuple[float, float, float]) -> np.ndarray:
    """A plan that holds q_rad from now on (an arm-joint command replaces the scenario's plan)."""
    return plan_rows(((0.0, 0.0, q_rad, q_rad),))


@dataclass(frozen=True)
class ArmPreviewConfig:
    """INDI_ARM_FF = 2's lead time, the FC's joint-servo model (module docstring) and its supervisor
    (`preview_supervise`)."""

    lead_s: float = 0.03  # INDI_ARM_LEAD (its registry default)
    servo_hz: float = 1000.0  # ARM_SERVO_HZ
    v_max_rad_s: float = 4.0  # ARM_SERVO_VMAX
    a_max_rad_s2: float = 42.0  # ARM_SERVO_AMAX
    check_tol_rad_s: float = 0.3  # ARM_CHK_TOL: consistency tolerance of the model's joint rates
    check_rel: float = 0.15  # ... plus this share of the measured joint rate
    trust_rise_s: float = 0.1  # ARM_TRUST_RISE: arm motion in agreement with the model that earns full trust
    identify: bool = True  # ARM_SERVO_ID: identify the servo's rate and acceleration limits online
    move_rad_s: float = 0.1  # a joint above this rate (measured or modelled) is moving

    def supervisor_config(self) -> np.ndarray:
        return PSC.pack(tol_v=self.check_tol_rad_s, tol_rel=self.check_rel, rise_s=self.trust_rise_s,
                        ident=float(self.identify), move_v=self.move_rad_s, v_max0=self.v_max_rad_s,
                        a_max0=self.a_max_rad_s2)

    def supervisor_state(self) -> np.ndarray:
        """A fresh supervisor: no trust yet (earned on the first consistent move), the data sheet's limits."""
        return PS.pack(trust=0.0, err=0.0, v_hat=self.v_max_rad_s, a_hat=self.a_max_rad_s2, moving=0.0, bad_move=0.0,
                       pk_v_meas=0.0, pk_a_meas=0.0, pk_v_model=0.0, rest_ticks=0.0, qd_prev=(0.0,) * 3,
                       qdd_prev=(0.0,) * 3, qd_ok=0.0, drops=0.0, idents=0.0)
