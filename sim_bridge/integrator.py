"""The plant's integration step (numba kernels): RK4 at the physics rate with the exact joint and actuator
trajectories inside each step, the divergence guard, and the derived quantities at the current state.

Per physics step h (docs/plant.md, "Integrator and physics rate"): the joint servo picks q'' at the start of each
servo period (joint_servo); the actuator outputs at t, t + h/2 and t + h are exact for the held command
(actuators); RK4 integrates the 13 base states (rigid_body.dynamics) with the joint motion evaluated at the stage
times, so the only integration error is the base's; then the quaternion is renormalised, the joints move exactly
and the actuators step exactly into their hard stops. Everything works in caller-owned scratch (W): no allocation.
"""

from __future__ import annotations

import math

from navig8_fc.core.jit import njit_cached
from navig8_fc.core.layout import layout
from sim_bridge import actuators, arm_dynamics, ground_contact, joint_servo, plant_layout, rigid_body
from sim_bridge.actuators import act_at, actuator_step
from sim_bridge.arm_dynamics import N_BODIES, N_SC
from sim_bridge.joint_servo import joints_at, servo_update
from sim_bridge.plant_layout import N_ACT, N_BASE, N_X, P, X
from sim_bridge.rigid_body import dynamics

# Scratch for advance()/evaluate(), owned by the caller (no allocation in the hot path).
W = layout("W", xb=N_BASE, xs=N_BASE, k1=N_BASE, k2=N_BASE, k3=N_BASE, k4=N_BASE, q=3, qd=3, qdd=3,
           act0=N_ACT, acth=N_ACT, act1=N_ACT, sc=N_BODIES * N_SC, backup=N_X)
N_WORK = int(W.SIZE)

# every module whose kernels advance() and evaluate() reach: a change in any recompiles them
_REACHED = (plant_layout, rigid_body, arm_dynamics, actuators, ground_contact, joint_servo)


@njit_cached(plant_layout)
def stage_state(xb, tau, k, xs) -> None:
    """An RK4 stage's base state: xs = xb + tau k."""
    for i in range(N_BASE):
        xs[i] = xb[i] + tau * k[i]


@njit_cached(*_REACHED)
def advance(x, p, cmd, sched, n_steps, t0_us, base_mode, d, w) -> int:
    """Advance the state x in place by n_steps physics steps from time t0_us (an integer on the
    physics grid). w is caller-owned scratch (N_WORK) so the hot path does not allocate.
    Returns 0, or 1 if the state became non-finite (x is then left as it was)."""
    h = p[P.H]
    h_us = int(p[P.H_US])
    servo_n = int(p[P.SERVO_N])
    xb = w[W.XB:W.XB + N_BASE]
    xs = w[W.XS:W.XS + N_BASE]
    k1 = w[W.K1:W.K1 + N_BASE]
    k2 = w[W.K2:W.K2 + N_BASE]
    k3 = w[W.K3:W.K3 + N_BASE]
    k4 = w[W.K4:W.K4 + N_BASE]
    q = w[W.Q:W.Q + 3]
    qd = w[W.QD:W.QD + 3]
    qdd = w[W.QDD:W.QDD + 3]
    act0 = w[W.ACT0:W.ACT0 + N_ACT]
    acth = w[W.ACTH:W.ACTH + N_ACT]
    act1 = w[W.ACT1:W.ACT1 + N_ACT]
    sc = w[W.SC:W.SC + N_BODIES * N_SC]
    backup = w[W.BACKUP:W.BACKUP + N_X]
    for i in range(N_X):
        backup[i] = x[i]
    mobj = x[X.MOBJ]
    for n in range(n_steps):
        t_us = t0_us + n * h_us
        if (t_us // h_us) % servo_n == 0:  # the joint servo: a new q'' at the start of each servo period
            servo_update(x, p, cmd, sched, t_us)
        for i in range(N_BASE):
            xb[i] = x[i]
        for j in range(3):
            qdd[j] = x[X.QDD + j]
        # ---- actuator outputs at t, t + h/2, t + h (exact, ZOH command) ---------------------
        for i in range(N_ACT):
            act0[i] = x[X.ACT + i]
        act_at(x, p, cmd, P.PHI_H2, P.GAM_H2, acth)
        act_at(x, p, cmd, P.PHI_H, P.GAM_H, act1)
        # ---- RK4 on the base with the exact joint and actuator trajectories -----------------
        for j in range(3):
            q[j] = x[X.Q + j]
            qd[j] = x[X.QD + j]
        dynamics(xb, q, qd, qdd, act0, mobj, p, base_mode, k1, sc, d, False)
        th = 0.5 * h
        joints_at(x, qdd, th, q, qd)
        stage_state(xb, th, k1, xs)
        dynamics(xs, q, qd, qdd, acth, mobj, p, base_mode, k2, sc, d, False)
        stage_state(xb, th, k2, xs)
        dynamics(xs, q, qd, qdd, acth, mobj, p, base_mode, k3, sc, d, False)
        joints_at(x, qdd, h, q, qd)
        stage_state(xb, h, k3, xs)
        dynamics(xs, q, qd, qdd, act1, mobj, p, base_mode, k4, sc, d, False)
        for i in range(N_BASE):
            x[i] = xb[i] + (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        qw, qx, qy, qz = x[X.QUAT], x[X.QUAT + 1], x[X.QUAT + 2], x[X.QUAT + 3]
        qn = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        for i in range(4):
            x[X.QUAT + i] /= qn
        # ---- joints: exact for constant q'' ---------------------------------------------------
        for j in range(3):
            x[X.Q + j] = q[j]
            x[X.QD + j] = qd[j]
        # ---- actuators: exact discretisation, then the hard stops ----------------------------
        actuator_step(x, p, cmd, act1)
    for i in range(N_X):
        if not math.isfinite(x[i]):
            for j in range(N_X):
                x[j] = backup[j]
            return 1
    evaluate(x, p, base_mode, d, w)
    return 0


@njit_cached(*_REACHED)
def evaluate(x, p, base_mode, d, w) -> None:
    """Fill the derived quantities d at the current state (q'' = the current servo period's)."""
    dynamics(x[0:N_BASE], x[X.Q:X.Q + 3], x[X.QD:X.QD + 3], x[X.QDD:X.QDD + 3], x[X.ACT:X.ACT + N_ACT],
             x[X.MOBJ], p, base_mode, w[W.XS:W.XS + N_BASE], w[W.SC:W.SC + N_BODIES * N_SC], d, True)
