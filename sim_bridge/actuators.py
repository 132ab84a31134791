"""The plant's actuators (numba kernels): the exact second-order response to a held command, the hard stops, and
the propulsion wrench the actuator outputs make.

Each of alpha1, alpha3, w1, w2, w3 follows y'' = wn^2 (u - y) - 2 zeta wn y' (paper Sec. 3.1), discretised exactly
for a held command: [y, y'](t + tau) = Phi(tau) [y, y'](t) + Gamma(tau) u, with Phi, Gamma for tau = h and h/2 in
the parameter vector (plant.build_param_vector). Propulsion (notes §2.1-2.2) is linear in
U = [cos a1 w1|w1|, sin a1 w1|w1|, cos a3 w3|w3|, sin a3 w3|w3|, w2|w2|] with the per-input force and moment
columns about O taken from the FC's own model (vehicle.propulsion_per_input; a duct fault scales its columns).
"""

from __future__ import annotations

import math

from numba import njit

from sim_bridge.plant_layout import N_ACT, C, P, X


@njit(inline="always")  # the step's hot path: inlined into its njit_cached callers
def act_at(x, p, cmd, phi, gam, out):
    """Exact second-order actuator outputs after tau (phi, gam = P.PHI_H or P.PHI_H2 offsets)."""
    for i in range(N_ACT):
        y = x[X.ACT + i]
        yd = x[X.ACTD + i]
        u = cmd[C.ACT + i]
        out[i] = p[phi + 4 * i] * y + p[phi + 4 * i + 1] * yd + p[gam + 2 * i] * u


@njit(inline="always")  # the step's hot path: inlined into its njit_cached callers
def actuator_step(x, p, cmd, act1) -> None:
    """The actuator outputs and rates of x one physics step on (outputs act1 = act_at over h), then the hard stops:
    an output beyond a limit is held at it and its rate into the stop zeroed."""
    for i in range(N_ACT):
        yd = (p[P.PHI_H + 4 * i + 2] * x[X.ACT + i] + p[P.PHI_H + 4 * i + 3] * x[X.ACTD + i]
              + p[P.GAM_H + 2 * i + 1] * cmd[C.ACT + i])
        y = act1[i]
        if y > p[P.ACT_MAX + i]:
            y = p[P.ACT_MAX + i]
            if yd > 0.0:
                yd = 0.0
        elif y < p[P.ACT_MIN + i]:
            y = p[P.ACT_MIN + i]
            if yd < 0.0:
                yd = 0.0
        x[X.ACT + i] = y
        x[X.ACTD + i] = yd


@njit(inline="always")  # the step's hot path: inlined into its njit_cached callers
def propulsion(act, p):
    """Propulsive force (N, FRD) and moment about O (N m) of the actuator outputs act (5): (fx, fy, fz, mx, my, mz).
    Thrust grows with w|w|, so a reversed propeller pushes back."""
    a1 = act[0]
    a3 = act[1]
    w1 = act[2]
    w2 = act[3]
    w3 = act[4]
    w1s = w1 * abs(w1)
    w3s = w3 * abs(w3)
    u0 = math.cos(a1) * w1s
    u1 = math.sin(a1) * w1s
    u2 = math.cos(a3) * w3s
    u3 = math.sin(a3) * w3s
    u4 = w2 * abs(w2)
    fpx = p[P.PF + 0] * u0 + p[P.PF + 1] * u1 + p[P.PF + 2] * u2 + p[P.PF + 3] * u3 + p[P.PF + 4] * u4
    fpy = p[P.PF + 5] * u0 + p[P.PF + 6] * u1 + p[P.PF + 7] * u2 + p[P.PF + 8] * u3 + p[P.PF + 9] * u4
    fpz = p[P.PF + 10] * u0 + p[P.PF + 11] * u1 + p[P.PF + 12] * u2 + p[P.PF + 13] * u3 + p[P.PF + 14] * u4
    mpx = p[P.PM + 0] * u0 + p[P.PM + 1] * u1 + p[P.PM + 2] * u2 + p[P.PM + 3] * u3 + p[P.PM + 4] * u4
    mpy = p[P.PM + 5] * u0 + p[P.PM + 6] * u1 + p[P.PM + 7] * u2 + p[P.PM + 8] * u3 + p[P.PM + 9] * u4
    mpz = p[P.PM + 10] * u0 + p[P.PM + 11] * u1 + p[P.PM + 12] * u2 + p[P.PM + 13] * u3 + p[P.PM + 14] * u4
    return fpx, fpy, fpz, mpx, mpy, mpz
