"""The sampled INDI loop itself, without the Pade delay: an independent check of the continuous analysis of
stability.py (paper Sec. 3.1, Eq. 7-13), one decoupled mode at a time (sampled_loop_matrix, sampled_lambda_crit)
and with all five rows of Eq. 7 coupled (coupled_loop_parts: the loop flown while K varies, varying_k.py).

Pure math (numpy/scipy only): no I/O, no clocks, no prints. docs/stability.md, "The flown configuration".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm as linalg_expm

from navig8_fc.core.stability import edge_from_nominal

CHANNELS = ("rotational", "force")


def _zoh_actuator(wn: float, zeta: float, dt_s: float) -> np.ndarray:
    """exp(M dt) for [p, r, w, u]: the actuator p'' = wn^2 (u - p) - 2 zeta wn p' under a held u, and the
    integral w of p over the period (the body rate a rotational mode's gyro sees, in mode units)."""
    a = np.zeros((4, 4))
    a[0, 1] = 1.0
    a[1, 0], a[1, 1], a[1, 3] = -wn**2, -2.0 * zeta * wn, wn**2
    a[2, 0] = 1.0
    return np.asarray(linalg_expm(a * dt_s))


def sampled_loop_matrix(
    lam: float,
    wn: float,
    zeta: float,
    rate_hz: float,
    tl: float,
    channel: str = "rotational",
    plant_wn: float | None = None,
    plant_zeta: float | None = None,
    u0_source: str = "model",
    u0_tau_s: float = math.inf,
    link_delay_ticks: int = 0,
    model_told: bool = True,
) -> np.ndarray:
    """The one-tick state-transition matrix of one decoupled mode of the FC's sampled INDI loop (v = 0).

    What the FC does each tick (lockstep: the bundle at t_k, the command held over [t_k, t_k+1)), in the units of
    one eigen-mode of G_hat G^-1 (Ghat = lam G there): the actuators (true: plant_wn/zeta, default the model's)
    advance under the held command; the feedback is the sampled acceleration through the exact first-order
    low-pass (alpha = 1 - exp(-dt/tau_L)), for a "force" mode directly, for a "rotational" mode as the backward
    difference of the low-passed gyro (IndiController.measure); U0 is the measured actuator or ("model") the
    actuator model run on the last command with the position corrected toward the measurement by
    alpha(u0_tau_s) (indi.actuator_estimate), through the same low-pass; u = U0 + (v - Acc_f)/lam (Eq. 5-6).
    State [p, r, p_hat, r_hat, u_prev, U0_f, f] with f = the force filter's output or the gyro filter's lag e.

    link_delay_ticks d: the command answered to the sample at t_k is flown from t_k+1+d (a real-time link answers a
    period late, docs/hil.md); the d commands in flight follow as states, oldest first, and u_prev is the one flown.
    model_told: the actuator model advances on the command flown (the bridge's echo, IndiController.fly_applied);
    else on the FC's own last command (a link that does not say which it flew).
    """
    if channel not in CHANNELS:
        raise ValueError(f"channel must be one of {CHANNELS}, got {channel!r}")
    if u0_source not in ("model", "measured"):
        raise ValueError(f"u0_source must be 'model' or 'measured', got {u0_source!r}")
    if not (rate_hz > 0.0 and math.isfinite(rate_hz) and tl > 0.0 and lam != 0.0):
        raise ValueError(f"need rate_hz > 0, tl > 0, lam != 0; got {rate_hz}, {tl}, {lam}")
    if link_delay_ticks < 0 or int(link_delay_ticks) != link_delay_ticks:
        raise ValueError(f"link_delay_ticks must be an integer >= 0, got {link_delay_ticks}")
    d_link = int(link_delay_ticks)
    dt = 1.0 / rate_hz
    m_p = _zoh_actuator(plant_wn if plant_wn is not None else wn, plant_zeta if plant_zeta is not None else zeta, dt)
    m_m = _zoh_actuator(wn, zeta, dt)
    alpha = 1.0 - math.exp(-dt / tl)
    g = 0.0 if math.isinf(u0_tau_s) else (1.0 if u0_tau_s == 0.0 else 1.0 - math.exp(-dt / u0_tau_s))
    rotational = channel == "rotational"

    def tick(x: np.ndarray) -> np.ndarray:
        p, r, ph, rh, u_prev, u0f, f = x[:7]
        in_flight = list(x[7:])  # the commands answered, not yet flown: oldest first
        u_model = u_prev if model_told or not in_flight else in_flight[-1]
        p, r, dw = m_p[:3] @ np.array([p, r, 0.0, u_prev])
        ph, rh = m_m[:2] @ np.array([ph, rh, 0.0, u_model])
        ph = ph + g * (p - ph)
        src = ph if u0_source == "model" else p
        u0f = u0f + alpha * (src - u0f)
        if rotational:
            d = dw + f  # w_k - w_f,k-1: the rate increment plus the filter's lag
            acc, f = alpha * d / dt, (1.0 - alpha) * d
        else:
            f = f + alpha * (p - f)
            acc = f
        u = u0f - acc / lam
        queue = [*in_flight, u]
        return np.array([p, r, ph, rh, queue[0], u0f, f, *queue[1:]])

    return np.column_stack([tick(e) for e in np.eye(7 + d_link)])


def sampled_lambda_crit(
    wn: float,
    zeta: float,
    rate_hz: float,
    tl: float,
    channel: str = "rotational",
    plant_wn: float | None = None,
    plant_zeta: float | None = None,
    u0_source: str = "model",
    u0_tau_s: float = math.inf,
    lam_lo: float = 1e-4,
    n_scan: int = 200,
    link_delay_ticks: int = 0,
    model_told: bool = True,
) -> float:
    """lambda_crit of the sampled loop (sampled_loop_matrix): where its spectral radius reaches 1, from lam = 1 down.

    The matrix is affine in 1/lam (lam enters only through u = U0 - Acc/lam, Eq. 6): built twice, at lam = 1 and 1/2,
    as A + B/lam, so each point of the scan is one eigenvalue problem (the registry's floor over a delayed link)."""
    args = (wn, zeta, rate_hz, tl, channel, plant_wn, plant_zeta, u0_source, u0_tau_s, link_delay_ticks, model_told)
    m_1 = sampled_loop_matrix(1.0, *args)
    m_b = sampled_loop_matrix(0.5, *args) - m_1  # B: the step from 1/lam = 1 to 2
    m_a = m_1 - m_b

    def f(lam: float) -> float:
        return float(np.max(np.abs(np.linalg.eigvals(m_a + m_b / lam)))) - 1.0

    if f(1.0) >= 0.0:
        raise ValueError("the sampled loop is not stable at lam = 1")
    return edge_from_nominal(f, lam_lo, n_scan, 0.0, xtol=1e-10)


def link_lambda_crit(
    wn: float,
    zeta: float,
    rate_hz: float,
    tl: float,
    u0_source: str,
    u0_tau_s: float,
    link_delay_ticks: int,
    model_told: bool = True,
) -> float:
    """lambda_crit of the loop flown over a link whose answers fly link_delay_ticks ticks later than in lockstep: the
    larger of the rotational and force modes' sampled_lambda_crit (the guaranteed eigenvalue bounds both)."""
    return max(sampled_lambda_crit(wn, zeta, rate_hz, tl, ch, None, None, u0_source, u0_tau_s,
                                   link_delay_ticks=link_delay_ticks, model_told=model_told) for ch in CHANNELS)


# --------------------------------------------------------------------------------------
# The coupled multi-channel sampled loop (all five rows of Eq. 7 at once, no eigen-decomposition)
# --------------------------------------------------------------------------------------
#
# Eq. 8 decouples Eq. 7 with G_hat G^-1 = M Lambda M^-1, which needs a diagonalisable, fixed G_hat G^-1. While K
# varies the modes of one tick are not the modes of the next, so the loop flown is the coupled one. In the units of
# the accelerations (w = G u: the actuators are identical second-order systems, Eq. 10, so G commutes with them and
# with the low-passes of Eq. 11), the FC's increment u = U0 + G_hat^-1 (v - Acc_f) (Eq. 5-6) reads
#
#     w = W0 + (G_hat G^-1)^-1 (v - Acc_f),
#
# so every row i of [P_dot, Q_dot, R_dot, a_x, a_z] carries the seven states of sampled_loop_matrix and the rows
# are coupled only through Lambda^-1 = (G_hat G^-1)^-1 in the increment. With x the stacked states (channel-major)
# the one-tick map is x+ = (A_free - B Lambda^-1 C) x: A_free the tick with the increment left out, C the rows
# that give each channel's filtered acceleration, B puts the increment into each channel's command state.

LOOP_STATES = ("p", "r", "p_hat", "r_hat", "u_prev", "u0_f", "f")  # per channel, sampled_loop_matrix's order
N_LOOP_STATES = len(LOOP_STATES)
# Rows of Eq. 7 in the FC's order [P_dot, Q_dot, R_dot, a_x, a_z]: the body rates are fed back as the backward
# difference of the low-passed gyro, the two accelerations through the low-pass directly (IndiController.measure).
INDI_CHANNELS: tuple[str, ...] = ("rotational", "rotational", "rotational", "force", "force")


@dataclass(frozen=True)
class CoupledLoopParts:
    """x+ = (a_free - b @ lam_inv @ c) x for the stacked channel-major state (N_LOOP_STATES per channel)."""

    a_free: np.ndarray  # (7n, 7n): block diagonal, the tick with the increment G_hat^-1 (v - Acc_f) left out
    b: np.ndarray  # (7n, n): the increment into each channel's command state u_prev
    c: np.ndarray  # (n, 7n): each channel's filtered acceleration Acc_f after the tick, from the state before it
    channels: tuple[str, ...]


def _channel_rows(m_p: np.ndarray, m_m: np.ndarray, alpha: float, g: float, rotational: bool, model_u0: bool,
                  dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(A_free 7x7, c 7) of one channel: each new state as a row over [p, r, p_hat, r_hat, u_prev, u0_f, f]."""
    ip, ir, iph, irh, iu, iu0, iff = range(N_LOOP_STATES)
    n = N_LOOP_STATES
    a = np.zeros((n, n))
    # The true actuator over the tick under the held command (ZOH, exact): p+, r+ and the integral of p (dw).
    for row, k in ((ip, 0), (ir, 1)):
        a[row, ip], a[row, ir], a[row, iu] = m_p[k, 0], m_p[k, 1], m_p[k, 3]
    dw = np.zeros(n)
    dw[ip], dw[ir], dw[iu] = m_p[2, 0], m_p[2, 1], m_p[2, 3]
    # The FC's actuator model on the same command, its position pulled toward the measured p+ by g.
    model_p = np.zeros(n)
    model_p[iph], model_p[irh], model_p[iu] = m_m[0, 0], m_m[0, 1], m_m[0, 3]
    a[iph] = (1.0 - g) * model_p + g * a[ip]
    a[irh, iph], a[irh, irh], a[irh, iu] = m_m[1, 0], m_m[1, 1], m_m[1, 3]
    # U0 through the feedback's low-pass (Eq. 11): the model's position or the measured one.
    a[iu0] = alpha * (a[iph] if model_u0 else a[ip])
    a[iu0, iu0] += 1.0 - alpha
    if rotational:
        d = dw.copy()  # the gyro's increment over the tick plus the filter's lag
        d[iff] += 1.0
        c = alpha * d / dt_s
        a[iff] = (1.0 - alpha) * d
    else:
        a[iff] = alpha * a[ip]
        a[iff, iff] += 1.0 - alpha
        c = a[iff].copy()
    a[iu] = a[iu0]  # the command: U0, plus the increment that b, c add
    return a, c


def coupled_loop_parts(
    wn: float,
    zeta: float,
    rate_hz: float,
    tl: float,
    channels: Sequence[str] = INDI_CHANNELS,
    plant_wn: float | None = None,
    plant_zeta: float | None = None,
    u0_source: str = "model",
    u0_tau_s: float = math.inf,
) -> CoupledLoopParts:
    """A_free, B, C of the coupled sampled loop (see above): the loop at G_hat G^-1 = Lambda is A_free - B Lambda^-1 C.

    The arguments mean what they mean in sampled_loop_matrix; channels gives each row's feedback (INDI_CHANNELS:
    the FC's three rotational rows, then the two force rows).
    """
    if any(ch not in CHANNELS for ch in channels):
        raise ValueError(f"every channel must be one of {CHANNELS}, got {tuple(channels)}")
    if u0_source not in ("model", "measured"):
        raise ValueError(f"u0_source must be 'model' or 'measured', got {u0_source!r}")
    if not (rate_hz > 0.0 and math.isfinite(rate_hz) and tl > 0.0):
        raise ValueError(f"need rate_hz > 0, tl > 0; got {rate_hz}, {tl}")
    dt = 1.0 / rate_hz
    m_p = _zoh_actuator(plant_wn if plant_wn is not None else wn, plant_zeta if plant_zeta is not None else zeta, dt)
    m_m = _zoh_actuator(wn, zeta, dt)
    alpha = 1.0 - math.exp(-dt / tl)
    g = 0.0 if math.isinf(u0_tau_s) else (1.0 if u0_tau_s == 0.0 else 1.0 - math.exp(-dt / u0_tau_s))
    n, k = len(channels), N_LOOP_STATES
    a_free, b, c = np.zeros((k * n, k * n)), np.zeros((k * n, n)), np.zeros((n, k * n))
    for i, ch in enumerate(channels):
        a_i, c_i = _channel_rows(m_p, m_m, alpha, g, ch == "rotational", u0_source == "model", dt)
        a_free[k * i : k * (i + 1), k * i : k * (i + 1)] = a_i
        c[i, k * i : k * (i + 1)] = c_i
        b[k * i + LOOP_STATES.index("u_prev"), i] = 1.0  # u = U0 - Lambda^-1 Acc_f (v = 0)
    return CoupledLoopParts(a_free, b, c, tuple(channels))


def coupled_loop_matrix(lam_matrix: np.ndarray, parts: CoupledLoopParts) -> np.ndarray:
    """The one-tick transition matrix of the coupled loop at G_hat G^-1 = lam_matrix (n x n, any invertible matrix:
    not assumed diagonalisable or normal). Batched: lam_matrix (..., n, n) gives (..., 7n, 7n)."""
    lam_inv = np.linalg.inv(np.asarray(lam_matrix, dtype=float))
    return coupled_loop_matrix_from_inverse(lam_inv, parts)


def coupled_loop_matrix_from_inverse(lam_inv: np.ndarray, parts: CoupledLoopParts) -> np.ndarray:
    """As coupled_loop_matrix, from (G_hat G^-1)^-1 = G G_hat^-1 directly: the loop is affine in it."""
    return parts.a_free - parts.b @ np.asarray(lam_inv, dtype=float) @ parts.c
