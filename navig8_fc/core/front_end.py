"""The controller's per-tick sensor front end, one numba kernel (`fc_front`): the complementary joint-angle
observer, backward differences of the joint rates (q-ddot) and of the gyro (omega-dot), the UAM model at the
estimated arm state (g_c.uam_model), the measured acceleration Acc_m of Eq. 23 and U from the measured actuators.

FlightControllerCore packs its sensors into the TIN vector and keeps the front end's state (FST); the output (FO)
feeds the adaptive law and the INDI. The scalar filters of the loop are in filters.py. Pure: no I/O.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from navig8_fc.core import g_c, linalg
from navig8_fc.core.g_c import UO, actuators_to_u, uam_model
from navig8_fc.core.jit import njit_cached
from navig8_fc.core.layout import layout

# The tick's input vector (FlightControllerCore packs FcSensors into it): the sensors fc_front reads, then the
# outer loops' inputs (packed only when engaged).
TIN = layout("TIN", gyro=3, accel=3,  # specific force at O
             tilt=2, speed=3, jpos=3, jrate=3,  # alpha1, alpha3; w1, w2, w3; joint angles and rates
             pos=3, vel=3, quat=4, sp=5)  # pos_ned, vel_ned, quat_wxyz, setpoint (outer_loop.OSP layout)
# Front-end state `fst` and output `fo`
FST = layout("FST", qest=3,  # joint-angle estimate
             qd_prev=3, gyro_prev=3,  # previous joint rate and gyro (backward differences)
             init=1,  # 1.0 after the first sample
             n_seen=1)  # joint samples so far (the observer's running-mean start, mean_start)
FO = layout("FO", qest=3, qdd=3,
            acc_m=5,  # [P_dot, Q_dot, R_dot, a_x + arm, a_z + arm] (Eq. 23)
            arm_hdc=1,  # UO.HDC: minus the arm's reaction pitch moment about the CoM (CKF_ARM_WRENCH)
            u_meas=5)  # U0 from the measured actuators



@njit(cache=True)
def com_accel_offset(p, q, r, qdot, cx, cz):
    """(x, z) of a_c - a_O for a rigid body: omega-dot x c + omega x (omega x c) with c = (cx, 0, cz) the composite
    CoM (FRD, from O) and omega-dot = (., qdot, .) (the planar arm keeps c_y = 0, so only Q-dot enters x and z).
    (omega-dot x c)_x = Qdot c_z, _z = -Qdot c_x; omega x (omega x c) = omega (omega . c) - c |omega|^2."""
    wc = p * cx + r * cz  # omega . c
    w2 = p * p + q * q + r * r
    return qdot * cz + p * wc - cx * w2, -qdot * cx + r * wc - cz * w2


@njit_cached(g_c, linalg)
def fc_front(fst, dt, obs_gain, inv_dt, sens, object_mass_kg, geo, f, m0, inertia, rate, gc, gc_inv, uo, fo,
             acc_ref=0.0, mean_start=0.0):
    """FlightControllerCore's per-tick front end: the complementary joint observer (q_est), backward
    differences of the joint rates (q-ddot) and of the gyro (omega-dot), uam_model at (q_est, q-dot, q-ddot),
    Acc_m (Eq. 23) and U0 = actuators_to_u(measured). All state in fst; first sample: q_est = q, zeros out of
    the differences. sens: TIN (only its sensor part is read).

    acc_ref = 0 (the paper): Acc_m's force rows are the specific force at O plus the arm's c-ddot_rel.
    acc_ref = 1 (INDI_ACC_REF): they are the acceleration of the estimated composite CoM c
    (uo CEX, CEZ): a_c = f_O + omega-dot x c + omega x (omega x c) + c-ddot_rel (the Coriolis term
    2 omega x c-dot_rel is left out), the point G_C's force rows and the flown loop refer to.

    mean_start = 1 (CKF_LPF_SEED): the observer's n-th correction has the gain max(obs_gain, 1/n), a running mean of
    the measured joints (each carried forward by the rates) until obs_gain takes over, instead of the first sample
    alone: one reading of the 0.08 rad joint sensor put J11 12 % off at q1 60 deg, decaying with the observer's 1 s."""
    q = np.empty(3)
    qd = sens[TIN.JRATE:TIN.JRATE + 3]
    qdd = np.empty(3)
    if fst[FST.INIT] == 0.0:
        for i in range(3):
            fst[FST.QEST + i] = sens[TIN.JPOS + i]
            qdd[i] = 0.0
            fo[FO.ACC_M + i] = 0.0
        fst[FST.INIT] = 1.0
        fst[FST.N_SEEN] = 1.0
    else:
        fst[FST.N_SEEN] += 1.0
        gain = obs_gain
        if mean_start != 0.0 and 1.0 / fst[FST.N_SEEN] > gain:
            gain = 1.0 / fst[FST.N_SEEN]
        for i in range(3):
            pred = fst[FST.QEST + i] + dt * qd[i]
            fst[FST.QEST + i] = pred + gain * (sens[TIN.JPOS + i] - pred)
            qdd[i] = (qd[i] - fst[FST.QD_PREV + i]) * inv_dt
            fo[FO.ACC_M + i] = (sens[TIN.GYRO + i] - fst[FST.GYRO_PREV + i]) * inv_dt
    for i in range(3):
        fst[FST.QD_PREV + i] = qd[i]
        fst[FST.GYRO_PREV + i] = sens[TIN.GYRO + i]
        q[i] = fst[FST.QEST + i]
        fo[FO.QEST + i] = q[i]
        fo[FO.QDD + i] = qdd[i]
    uam_model(q, qd, qdd, object_mass_kg, geo, f, m0, inertia, rate, gc, gc_inv, uo)
    fo[FO.ARM_HDC] = uo[UO.HDC]
    fo[FO.ACC_M + 3] = sens[TIN.ACCEL] + uo[UO.ARM_AX]
    fo[FO.ACC_M + 4] = sens[TIN.ACCEL + 2] + uo[UO.ARM_AZ]
    if acc_ref != 0.0:
        dx, dz = com_accel_offset(sens[TIN.GYRO], sens[TIN.GYRO + 1], sens[TIN.GYRO + 2], fo[FO.ACC_M + 1],
                                  uo[UO.CEX], uo[UO.CEZ])
        fo[FO.ACC_M + 3] += dx
        fo[FO.ACC_M + 4] += dz
    actuators_to_u(sens[TIN.TILT], sens[TIN.TILT + 1], sens[TIN.SPEED], sens[TIN.SPEED + 1], sens[TIN.SPEED + 2],
                   fo, FO.U_MEAS)
