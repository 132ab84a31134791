"""The adaptive law's low-passes and window increments (Eq. 23's increments of 0.7 s low-passed signals): one numba
kernel, `lpf_increments`, over named layouts, for U0, Acc_m, the arm's h' and the gyroscopic moment alike (one filter,
one running-mean start, one set of windows). adaptive_law.AdaptiveLaw runs it once a tick. Pure: no I/O."""

from __future__ import annotations

from numba import njit

from navig8_fc.core.ckf_config import N_MEAS
from navig8_fc.core.layout import layout

__all__ = ["LAW_OUT", "LAW_STATE", "lpf_increments"]


# Filter state of lpf_increments: the low-passed U0, Acc_m, arm h' (arm_hdc) and gyroscopic moment (CKF_GYRO), their
# values at the start of the current increment window, the steps counted in it and whether the INDI saturated in it.
LAW_STATE = layout("LAW_STATE", u_f=N_MEAS, acc_f=N_MEAS, hd_f=1, u_w=N_MEAS, acc_w=N_MEAS, hd_w=1, count=1,
                   sat=1, sat_hold=1, started=1, n_seen=1, gy_f=3, gy_w=3)
LS_UF = LAW_STATE.U_F  # low-passed U0
LS_AF = LAW_STATE.ACC_F  # low-passed Acc_m
LS_HF = LAW_STATE.HD_F  # low-passed arm h'
LS_UW = LAW_STATE.U_W  # u_f at the window's start
LS_AW = LAW_STATE.ACC_W
LS_HW = LAW_STATE.HD_W
LS_COUNT = LAW_STATE.COUNT  # steps since the window's start
LS_SAT = LAW_STATE.SAT  # 1.0 when a step of the window reported INDI saturation (or was within the hold after one)
LS_HOLD = LAW_STATE.SAT_HOLD  # steps left in which the filters still carry a saturated step (sat_hold_steps)
LS_STARTED = LAW_STATE.STARTED  # 1.0 after the first sample
LS_NSEEN = LAW_STATE.N_SEEN  # samples filtered so far (the running-mean start, mean_start)
LS_GF = LAW_STATE.GY_F  # low-passed w x (I w) (N m, body FRD)
LS_GW = LAW_STATE.GY_W
# Its output: the increments fed to the KF (Eq. 23), and whether a window closed this step
LAW_OUT = layout("LAW_OUT", delta_u=N_MEAS, delta_acc=N_MEAS, delta_hd=1, ready=1, saturated=1, delta_gyro=3)
LO_DU = LAW_OUT.DELTA_U
LO_DA = LAW_OUT.DELTA_ACC
LO_DH = LAW_OUT.DELTA_HD
LO_READY = LAW_OUT.READY  # 1.0: a window closed, the increments are its own (0.0: they are zeros)
LO_SAT = LAW_OUT.SATURATED  # 1.0: the INDI saturated during the window that closed
LO_DG = LAW_OUT.DELTA_GYRO


@njit(cache=True)
def lpf_increments(st, alpha, n_window, u_meas, acc_m, hdc, gyro, sat, sat_hold_steps, out, mean_start=0.0):
    """The first-order low-passes of U0, Acc_m, h' and the gyroscopic moment w x (I w) (gyro, (3,); zeros when
    CKF_GYRO is off) (y += alpha (x - y); the first sample sets y) and their
    increments over windows of n_window steps, y[k] - y[k - n_window], every n_window-th step (ready = 1), zeros in
    between and on the first sample. sat (0/1, the INDI's saturation flag) is or-ed over the window, and a saturated
    step keeps flagging the following sat_hold_steps steps (the low-passed signals still carry it). With
    n_window = 1 the increments are the one-step differences y[k] - y[k-1] every step. st: LAW_STATE; out: LAW_OUT.

    mean_start = 1 (CKF_LPF_SEED): the n-th sample is weighted max(alpha, 1/n), so the filters start as the running
    mean of the samples so far and become the low-pass once 1/n < alpha (~1/alpha samples): the first sample alone,
    one noisy reading, does not seed them (its error would decay only as exp(-t/tau) through the first windows)."""
    if st[LS_STARTED] == 0.0:
        for i in range(N_MEAS):
            st[LS_UF + i] = u_meas[i]
            st[LS_AF + i] = acc_m[i]
            st[LS_UW + i] = u_meas[i]
            st[LS_AW + i] = acc_m[i]
        st[LS_HF] = hdc
        st[LS_HW] = hdc
        for i in range(3):
            st[LS_GF + i] = gyro[i]
            st[LS_GW + i] = gyro[i]
        st[LS_COUNT] = 0.0
        st[LS_SAT] = 0.0
        st[LS_HOLD] = 0.0
        st[LS_STARTED] = 1.0
        st[LS_NSEEN] = 1.0
        for i in range(LAW_OUT.SIZE):
            out[i] = 0.0
        return
    st[LS_NSEEN] += 1.0
    if mean_start != 0.0 and 1.0 / st[LS_NSEEN] > alpha:
        alpha = 1.0 / st[LS_NSEEN]
    for i in range(N_MEAS):
        y = st[LS_UF + i]
        st[LS_UF + i] = y + alpha * (u_meas[i] - y)
        y = st[LS_AF + i]
        st[LS_AF + i] = y + alpha * (acc_m[i] - y)
    y = st[LS_HF]
    st[LS_HF] = y + alpha * (hdc - y)
    for i in range(3):
        y = st[LS_GF + i]
        st[LS_GF + i] = y + alpha * (gyro[i] - y)
    st[LS_COUNT] += 1.0
    if sat != 0.0:
        st[LS_SAT] = 1.0
        st[LS_HOLD] = sat_hold_steps
    elif st[LS_HOLD] > 0.0:
        st[LS_SAT] = 1.0
        st[LS_HOLD] -= 1.0
    if st[LS_COUNT] < n_window:
        for i in range(LAW_OUT.SIZE):
            out[i] = 0.0
        return
    for i in range(N_MEAS):
        out[LO_DU + i] = st[LS_UF + i] - st[LS_UW + i]
        out[LO_DA + i] = st[LS_AF + i] - st[LS_AW + i]
        st[LS_UW + i] = st[LS_UF + i]
        st[LS_AW + i] = st[LS_AF + i]
    out[LO_DH] = st[LS_HF] - st[LS_HW]
    st[LS_HW] = st[LS_HF]
    for i in range(3):
        out[LO_DG + i] = st[LS_GF + i] - st[LS_GW + i]
        st[LS_GW + i] = st[LS_GF + i]
    out[LO_READY] = 1.0
    out[LO_SAT] = st[LS_SAT]
    st[LS_COUNT] = 0.0
    st[LS_SAT] = 0.0
