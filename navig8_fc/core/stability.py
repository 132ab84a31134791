"""Stability analysis of the adaptive INDI loop (paper Sec. 3.1-3.2, Eq. 7-20, Figs. 5-7).

Pure math (numpy/scipy only): no I/O, no clocks, no prints.

Part 1, the decoupled loop H_i(s) (Eq. 9-13). With A(s) = wn^2/(s^2 + 2 zeta wn s + wn^2) (Eq. 10),
L(s) = 1/(tau_L s + 1) (Eq. 11) and the first-order Pade delay P(s) = (2 - tau_s s)/(2 + tau_s s) (Eq. 12),

    H(s) = A / (lam + (1 - lam) A L P)                                                   (Eq. 9)
         = wn^2 (tau_s s + 2)(tau_L s + 1)
           / [lam D_A (tau_L s + 1)(tau_s s + 2) + (1 - lam) wn^2 (2 - tau_s s)]

with D_A = s^2 + 2 zeta wn s + wn^2. Expanding gives Eq. 13 (docs/stability.md: the flattened paper text
lost the minus sign of the "- wn^2 tau_s" term of the s^1 coefficient; otherwise it matches).
H maps the decoupled virtual input upsilon_i to s chi_i (an acceleration command to an acceleration),
so its step response (Fig. 6) tends to H(0) = 1 for every lam (the s^0 coefficients are both 2 wn^2).

Part 2, the bounds on K (Eq. 14-20, Fig. 7): eigenvalues of G_hat G^-1 = K Xi over arm poses, object
masses and K in [k_min, k_max]^4. Xi comes from navig8_fc.core.vehicle (Eq. 14).

lam may be complex in part 1: K Xi can have complex eigenvalue pairs (notes 6.1 item 4), and Eq. 9 still
defines H with complex coefficients; its poles are then not conjugate-symmetric but stability is still
"all poles in the open left half plane".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import optimize, signal
from scipy.linalg import expm as linalg_expm

from navig8_fc.core.vehicle import VehicleConfig, effectiveness_pair, mass_properties, reference_transform

# Paper Fig. 7 poses (deg): arm stretched forward and curled, both holding a 2 kg object.
POSE_STRETCHED_DEG: tuple[float, float, float] = (80.0, 10.0, 10.0)
POSE_CURLED_DEG: tuple[float, float, float] = (60.0, 60.0, 60.0)
FIG7_OBJECT_MASS_KG = 2.0

# Index sets of the 5 rows/columns [L, M, N, Fx, Fz] (= [P_dot, Q_dot, R_dot, a_x, a_z]).
LATERAL_IDX = (0, 2)  # roll and yaw: K1, K3 act here (lam_4, lam_5 of Eq. 18)
LONGITUDINAL_IDX = (1, 3, 4)  # pitch, Fx, Fz: K2, K4, K4 (lam_1..lam_3 of Eq. 17)

SETTLING_BAND = 0.02  # 2 % band around the final value for the settling time
_IMAG_TOL = 1e-9  # |Im| below this counts as a real eigenvalue (round-off of the 5x5 eig)


# ======================================================================================
# Part 1: H_i(s) of Eq. 13
# ======================================================================================


def _check_loop_params(wn: float, zeta: float, ts: float, tl: float) -> None:
    if not (wn > 0.0 and math.isfinite(wn)):
        raise ValueError(f"actuator natural frequency wn must be > 0 rad/s, got {wn}")
    if not (zeta > 0.0 and math.isfinite(zeta)):
        raise ValueError(f"actuator damping ratio zeta must be > 0, got {zeta}")
    if not (ts >= 0.0 and math.isfinite(ts)):
        raise ValueError(f"sampling time ts must be >= 0 s, got {ts}")
    if not (tl >= 0.0 and math.isfinite(tl)):
        raise ValueError(f"low-pass time constant tl must be >= 0 s, got {tl}")


def h_coefficients(
    lam: complex, wn: float, zeta: float, ts: float, tl: float
) -> tuple[np.ndarray, np.ndarray]:
    """(num, den) of H_i(s) (Eq. 13), highest power first (numpy.polyval / scipy.signal order).

    wn in rad/s, zeta dimensionless, ts = tau_s (sampling time, s), tl = tau_L (low-pass time constant, s).
    num has degree 2 and den degree 4 (lower when ts or tl is 0). Complex lam gives complex den.
    """
    _check_loop_params(wn, zeta, ts, tl)
    # Eq. 13 numerator: wn^2 (2 + tau_s s)(tau_L s + 1) -- the zeros at -2/tau_s (Pade) and -1/tau_L (LPF).
    num = wn**2 * np.array([ts * tl, 2.0 * tl + ts, 2.0])
    # Eq. 13 denominator, coefficient by coefficient (derived from Eq. 9-12 above).
    lam_c = complex(lam)
    den = np.array(
        [
            lam_c * ts * tl,  # s^4
            lam_c * (2.0 * ts * tl * zeta * wn + 2.0 * tl + ts),  # s^3
            lam_c * (ts * tl * wn**2 + 2.0 * zeta * wn * (2.0 * tl + ts) + 2.0),  # s^2
            # s^1: the printed Eq. 13 shows "+ wn^2 tau_s" here; the derivation gives "- wn^2 tau_s".
            2.0 * lam_c * wn**2 * tl + 2.0 * lam_c * wn**2 * ts + 4.0 * lam_c * zeta * wn - wn**2 * ts,
            2.0 * wn**2,  # s^0: lam 2 wn^2 + (1 - lam) 2 wn^2
        ]
    )
    if lam_c.imag == 0.0:
        den = den.real
    return num, den


def poles(lam: complex, wn: float, zeta: float, ts: float, tl: float) -> np.ndarray:
    """Roots of the Eq. 13 denominator, sorted by descending real part (the dominant pole first).

    No pole-zero cancellation is done: at lam = 1 the denominator contains the numerator's factors
    (H reduces to A(s)) and -1/tau_L, -2/tau_s appear both as poles and as zeros.
    """
    _, den = h_coefficients(lam, wn, zeta, ts, tl)
    p = np.roots(den)  # np.roots drops leading zeros (lam = 0, ts = 0 or tl = 0)
    return p[np.argsort(-p.real, kind="stable")]


def zeros(wn: float, zeta: float, ts: float, tl: float) -> np.ndarray:
    """Zeros of H_i(s) (Eq. 13), independent of lam: -1/tau_L (LPF) and -2/tau_s (Pade), sorted descending.

    A zero time constant removes the corresponding zero (its factor becomes a constant).
    """
    _check_loop_params(wn, zeta, ts, tl)
    z = [-1.0 / tc * k for tc, k in ((tl, 1.0), (ts, 2.0)) if tc > 0.0]
    return np.array(sorted(z, reverse=True), dtype=float)


def max_real_pole(lam: complex, wn: float, zeta: float, ts: float, tl: float) -> float:
    """Largest real part of the poles of H_i(s) (1/s); < 0 means H is stable at this lam."""
    return float(poles(lam, wn, zeta, ts, tl)[0].real)


def dominant_poles(lam: float, wn: float, zeta: float, ts: float, tl: float) -> np.ndarray:
    """The dominant pole (largest real part) and, if complex, its conjugate partner (Fig. 5)."""
    p = poles(lam, wn, zeta, ts, tl)
    if abs(p[0].imag) <= _IMAG_TOL * max(1.0, abs(p[0])):
        return p[:1]
    return p[:2]


def _check_nominal_stable(wn: float, zeta: float, ts: float, tl: float) -> None:
    # At lam = 1 (G_hat = G) Eq. 9 reduces to H = A(s): the denominator is D_A (tau_L s + 1)(tau_s s + 2),
    # stable for wn, zeta > 0. Every stability interval below is the one that contains lam = 1.
    p1 = max_real_pole(1.0, wn, zeta, ts, tl)
    if p1 >= 0.0:
        raise ValueError(f"H(s) is not stable at lam = 1 (max Re(pole) = {p1:.4g}); check the parameters")


def _bracket_scan(f, grid: np.ndarray) -> tuple[float, float] | None:
    """First adjacent pair of grid points where the sign of f changes from the sign at grid[0]."""
    unstable = np.array([f(lam) >= 0.0 for lam in grid])
    change = np.nonzero(unstable != unstable[0])[0]
    if change.size == 0:
        return None
    i = int(change[0])
    return float(grid[i - 1]), float(grid[i])


def lambda_crit(
    wn: float,
    zeta: float,
    ts: float,
    tl: float,
    lam_lo: float = 1e-6,
    n_scan: int = 120,
) -> float:
    """Critical eigenvalue (Sec. 3.1, Fig. 5): H_i(s) is stable for every lam in (lambda_crit, 1].

    The lower end of the stability interval of lam that contains the nominal lam = 1 (H = A there):
    the lam where the dominant pair crosses the imaginary axis. Found by scanning max_real_pole on a
    log grid from 1 down to lam_lo, then brentq (xtol 1e-12) on the first sign change.

    Returns 0.0 when H is stable on the whole scan [lam_lo, 1] (no crossing in the bracket). For ts > 0 a
    crossing always exists: as lam -> 0+ one pole tends to +2/tau_s.
    Raises ValueError if H is not stable at lam = 1 (impossible for wn, zeta > 0).
    Above 1 the loop may lose stability again for lightly damped, delayed actuators: see lambda_upper.
    """
    _check_loop_params(wn, zeta, ts, tl)
    if not 0.0 < lam_lo < 1.0:
        raise ValueError(f"need 0 < lam_lo < 1, got {lam_lo}")
    return _stability_edge(wn, zeta, ts, tl, lam_lo, n_scan, 0.0)


def lambda_upper(
    wn: float,
    zeta: float,
    ts: float,
    tl: float,
    lam_hi: float = 100.0,
    n_scan: int = 120,
) -> float:
    """Upper end of the stability interval containing lam = 1: H_i(s) is stable for lam in [1, lambda_upper).

    math.inf if H is stable on the whole scan [1, lam_hi] (the usual case: as lam grows the dominant pole
    only creeps towards the origin, Fig. 5). A finite value appears for lightly damped actuators with
    long delays (e.g. wn = 500, zeta = 0.1, ts = 0.05, tl = 0.005: unstable again above lam ~ 3.19).
    """
    _check_loop_params(wn, zeta, ts, tl)
    if not lam_hi > 1.0:
        raise ValueError(f"need lam_hi > 1, got {lam_hi}")
    return _stability_edge(wn, zeta, ts, tl, lam_hi, n_scan, math.inf)


def _stability_edge(wn: float, zeta: float, ts: float, tl: float, lam_end: float, n_scan: int,
                    if_none: float) -> float:
    """The lam between 1 and lam_end where the dominant pole of H_i crosses into the right half plane: a
    geometric scan from 1 brackets the first crossing, brentq refines it; if_none when the scan finds none."""
    _check_nominal_stable(wn, zeta, ts, tl)
    return _edge(lambda lam: max_real_pole(lam, wn, zeta, ts, tl), lam_end, n_scan, if_none)


def _edge(f, lam_end: float, n_scan: int, if_none: float, xtol: float = 1e-12) -> float:
    """First lam from 1 towards lam_end where f (>= 0: unstable) changes sign: geometric scan, then brentq."""
    bracket = _bracket_scan(f, np.geomspace(1.0, lam_end, n_scan))
    if bracket is None:
        return if_none
    a, b = sorted(bracket)
    return float(optimize.brentq(f, a, b, xtol=xtol, rtol=1e-12))


# --------------------------------------------------------------------------------------
# Model-based U0 (INDI_U0_SRC = 1) with a mismatched actuator model
# --------------------------------------------------------------------------------------
#
# Fig. 4 with U0 measured: u = U0 + G_hat^-1 (v - L P xdot), U0 = L P A u, xdot = G A u, which gives Eq. 7.
# With the model-based U0 the FC runs its actuator model A_m (ACT_WN, ACT_ZETA) on the command it flew last tick
# (e^(-tau_s s) u) and corrects the model's position toward the measured actuators (P A u) with gain
# c = 1/INDI_U0_TAU (a position-only correction, as indi.actuator_estimate does). In continuous time, with
# x_hat = (p_hat, r_hat):  p_hat' = r_hat + c (y - p_hat),  r_hat' = wm^2 (P u - p_hat) - 2 zm wm r_hat, so
#
#     p_hat = B(s) P u,   B = [wm^2 D_A + c (s + 2 zm wm) wp^2] / (D_c D_A),
#     D_c = s^2 + (2 zm wm + c) s + wm^2 + 2 zm wm c,
#
# (A = wp^2/D_A is the true actuator, D_m = s^2 + 2 zm wm s + wm^2 the model's denominator). c = 0 is the pure
# model (B = A_m), c -> inf the measurement alone (B = A). U0 = L B P u goes through the same low-pass. Then
# (1 - L P B) u + G_hat^-1 L P G A u = G_hat^-1 v; with y = G A u and G_hat G^-1 = M Lambda M^-1 (A, B scalar):
#
#     [G_hat G^-1 (1 - L P B) + L P A] y = A v,   H_i = A / (lam (1 - L P B) + L P A)
#
# which is Eq. 9 whenever B = A: the model-based U0 does not change the loop when the model is right (whatever c).
# With A_m != A, multiplying by D_L D_P D_c D_A:
#
#     den = lam D_L D_P D_c D_A - lam N_P [wm^2 D_A + c (s + 2 zm wm) wp^2] + wp^2 N_P D_c      (degree 6)
#     num = wp^2 D_L D_P D_c
#
# with D_L = tau_L s + 1, D_P = 2 + tau_s s, N_P = 2 - tau_s s. H(0) = 1 still (den(0) = num(0) = 2 wp^2 D_c(0)).


def model_u0_coefficients(
    lam: complex,
    wn: float,
    zeta: float,
    ts: float,
    tl: float,
    plant_wn: float,
    plant_zeta: float,
    u0_tau_s: float = math.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """(num, den) of H_i(s) with the model-based U0 (INDI_U0_SRC = 1), highest power first (see above).

    wn, zeta: the FC's actuator model (ACT_WN, ACT_ZETA); plant_wn, plant_zeta: the true actuators; u0_tau_s:
    INDI_U0_TAU (inf: the model alone, 0: the measurement alone, which is Eq. 13 with the true actuators).
    """
    _check_loop_params(wn, zeta, ts, tl)
    _check_loop_params(plant_wn, plant_zeta, ts, tl)
    if not u0_tau_s >= 0.0:
        raise ValueError(f"u0_tau_s must be >= 0 s (inf: the model alone), got {u0_tau_s}")
    if u0_tau_s == 0.0:
        return h_coefficients(lam, plant_wn, plant_zeta, ts, tl)
    c = 0.0 if math.isinf(u0_tau_s) else 1.0 / u0_tau_s
    wm, zm, wp = wn, zeta, plant_wn
    d_l, d_p, n_p = np.array([tl, 1.0]), np.array([ts, 2.0]), np.array([-ts, 2.0])
    d_a = np.array([1.0, 2.0 * plant_zeta * wp, wp**2])
    d_c = np.array([1.0, 2.0 * zm * wm + c, wm**2 + 2.0 * zm * wm * c])
    b_num = np.polyadd(wm**2 * d_a, c * wp**2 * np.array([1.0, 2.0 * zm * wm]))
    lam_c = complex(lam)
    lpca = np.polymul(np.polymul(d_l, d_p), np.polymul(d_c, d_a))
    den = np.polyadd(np.polyadd(lam_c * lpca, -lam_c * np.polymul(n_p, b_num)), wp**2 * np.polymul(n_p, d_c))
    num = wp**2 * np.polymul(np.polymul(d_l, d_p), d_c)
    if lam_c.imag == 0.0:
        den = den.real
    return num, den


def model_u0_poles(lam: complex, wn: float, zeta: float, ts: float, tl: float, plant_wn: float, plant_zeta: float,
                   u0_tau_s: float = math.inf) -> np.ndarray:
    """Roots of model_u0_coefficients' den, dominant first. The model's own poles (roots of D_c) are among them
    and cancel against zeros when the model is right; they are stable for wn, zeta > 0, c >= 0."""
    _, den = model_u0_coefficients(lam, wn, zeta, ts, tl, plant_wn, plant_zeta, u0_tau_s)
    p = np.roots(den)
    return p[np.argsort(-p.real, kind="stable")]


def lambda_crit_model_u0(
    wn: float,
    zeta: float,
    ts: float,
    tl: float,
    plant_wn: float,
    plant_zeta: float,
    u0_tau_s: float = math.inf,
    lam_lo: float = 1e-6,
    n_scan: int = 120,
) -> float:
    """lambda_crit (as `lambda_crit`) of the loop with the model-based U0 and true actuators (plant_wn, plant_zeta).

    Equals lambda_crit(wn, zeta, ts, tl) when the model is right (plant = model), for every u0_tau_s, and
    lambda_crit(plant_wn, plant_zeta, ts, tl) for u0_tau_s = 0. ValueError if the loop is unstable at lam = 1
    (a model far enough off that even the exact effectiveness does not fly).
    """
    if not 0.0 < lam_lo < 1.0:
        raise ValueError(f"need 0 < lam_lo < 1, got {lam_lo}")

    def f(lam: float) -> float:
        return float(model_u0_poles(lam, wn, zeta, ts, tl, plant_wn, plant_zeta, u0_tau_s)[0].real)

    p1 = f(1.0)
    if p1 >= 0.0:
        raise ValueError(f"H(s) with the model-based U0 is not stable at lam = 1 (max Re(pole) = {p1:.4g})")
    return _edge(f, lam_lo, n_scan, 0.0)


# --------------------------------------------------------------------------------------
# The sampled loop itself (no Pade): an independent check of the continuous analysis
# --------------------------------------------------------------------------------------

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
    """
    if channel not in CHANNELS:
        raise ValueError(f"channel must be one of {CHANNELS}, got {channel!r}")
    if u0_source not in ("model", "measured"):
        raise ValueError(f"u0_source must be 'model' or 'measured', got {u0_source!r}")
    if not (rate_hz > 0.0 and math.isfinite(rate_hz) and tl > 0.0 and lam != 0.0):
        raise ValueError(f"need rate_hz > 0, tl > 0, lam != 0; got {rate_hz}, {tl}, {lam}")
    dt = 1.0 / rate_hz
    m_p = _zoh_actuator(plant_wn if plant_wn is not None else wn, plant_zeta if plant_zeta is not None else zeta, dt)
    m_m = _zoh_actuator(wn, zeta, dt)
    alpha = 1.0 - math.exp(-dt / tl)
    g = 0.0 if math.isinf(u0_tau_s) else (1.0 if u0_tau_s == 0.0 else 1.0 - math.exp(-dt / u0_tau_s))
    rotational = channel == "rotational"

    def tick(x: np.ndarray) -> np.ndarray:
        p, r, ph, rh, u_prev, u0f, f = x
        p, r, dw = m_p[:3] @ np.array([p, r, 0.0, u_prev])
        ph, rh = m_m[:2] @ np.array([ph, rh, 0.0, u_prev])
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
        return np.array([p, r, ph, rh, u, u0f, f])

    return np.column_stack([tick(e) for e in np.eye(7)])


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
) -> float:
    """lambda_crit of the sampled loop (sampled_loop_matrix): where its spectral radius reaches 1, from lam = 1 down."""

    def f(lam: float) -> float:
        m = sampled_loop_matrix(lam, wn, zeta, rate_hz, tl, channel, plant_wn, plant_zeta, u0_source, u0_tau_s)
        return float(np.max(np.abs(np.linalg.eigvals(m)))) - 1.0

    if f(1.0) >= 0.0:
        raise ValueError("the sampled loop is not stable at lam = 1")
    return _edge(f, lam_lo, n_scan, 0.0, xtol=1e-10)


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


@dataclass(frozen=True)
class StepMetrics:
    """Step response of H_i(s) (Fig. 6): the acceleration response to a unit acceleration command."""

    lam: float
    stable: bool
    final_value: float  # H(0); 1 for every lam (Eq. 13 s^0 coefficients)
    overshoot_pct: float  # (peak - final)/final * 100, >= 0; inf if unstable
    peak_time_s: float  # time of the maximum; nan without overshoot
    settling_s: float  # last exit from the +-SETTLING_BAND (2 %) band around the final value; inf if unstable
    rise_time_s: float  # 10 % -> 90 % of the final value
    band_pct: float  # the settling band in percent (2.0)


def _step_grid(p: np.ndarray, max_samples: int) -> tuple[float, int]:
    """(t_end_s, n_samples) for the step response given the poles p of a stable H.

    Horizon: 12 time constants of the slowest pole (envelope e^-12 ~ 6e-6, far inside the 2 % band even
    with the residue amplification by the zero at -1/tau_L). Step: 1/20 of the fastest pole's time
    constant so the oscillation peaks are resolved, capped at max_samples.
    """
    mag = np.abs(p)
    t_end = 12.0 / float(np.min(np.abs(p.real)))
    dt = 1.0 / (20.0 * float(np.max(mag)))
    n = int(min(max_samples, max(2001, math.ceil(t_end / dt) + 1)))
    return t_end, n


def _zoh_step(num: np.ndarray, den: np.ndarray, dt_s: float, n: int) -> np.ndarray:
    """Unit-step response of num/den at t_k = k dt, k = 0..n-1, exact up to round-off.

    With a step input the zero-order-hold discretisation is exact: x_{k+1} = Ad x_k + bd, so
    x_k = sum_{j<k} Ad^j bd. The terms Ad^j bd are built by repeated squaring of Ad (log2(n) batched
    matrix products instead of an n-step Python loop, and no eigen-decomposition, which would fail
    for the double pole at lam = 1).
    """
    a, b, c, d = signal.tf2ss(num, den)
    ad, bd, cd, dd, _ = signal.cont2discrete((a, b, c, d), dt_s, method="zoh")
    v = np.empty((n, a.shape[0]))
    v[0] = bd[:, 0]
    power = ad  # Ad^m
    m = 1
    while m < n:
        k = min(m, n - m)
        v[m : m + k] = v[:k] @ power.T
        power = power @ power
        m += k
    x = np.zeros_like(v)
    np.cumsum(v[:-1], axis=0, out=x[1:])
    return x @ cd[0] + dd[0, 0]


def step_response(
    lam: float,
    wn: float,
    zeta: float,
    ts: float,
    tl: float,
    t_end_s: float | None = None,
    n_samples: int | None = None,
    max_samples: int = 400_001,
) -> tuple[np.ndarray, np.ndarray]:
    """(t_s, y) of the unit-step response of H_i(s) (Fig. 6).

    Default grid: horizon 12 / |slowest pole|, step 1/(20 |fastest pole|), at most max_samples points.
    Unstable lam needs an explicit t_end_s.
    """
    if isinstance(lam, complex) or np.iscomplexobj(lam):
        raise ValueError("the step response is defined for real lam only")
    num, den = h_coefficients(lam, wn, zeta, ts, tl)
    p = poles(lam, wn, zeta, ts, tl)
    if t_end_s is None:
        if p[0].real >= 0.0:
            raise ValueError(f"H is unstable at lam={lam}; give t_end_s explicitly")
        t_end_s, n_auto = _step_grid(p, max_samples)
    else:
        n_auto = int(min(max_samples, max(2001, math.ceil(t_end_s * 20.0 * float(np.max(np.abs(p)))) + 1)))
    n = n_auto if n_samples is None else int(n_samples)
    t = np.linspace(0.0, t_end_s, n)
    return t, _zoh_step(num, den, float(t[1] - t[0]), n)


def step_metrics(lam: float, wn: float, zeta: float, ts: float, tl: float) -> StepMetrics:
    """Overshoot and 2 % settling time of the step response of H_i(s) (Fig. 6; lam_min of Sec. 3.2)."""
    num, den = h_coefficients(lam, wn, zeta, ts, tl)
    final = float(num[-1] / den[-1])  # H(0)
    p = poles(lam, wn, zeta, ts, tl)
    if p[0].real >= 0.0:
        inf = math.inf
        return StepMetrics(float(lam), False, final, inf, inf, inf, inf, 100.0 * SETTLING_BAND)
    t, y = step_response(lam, wn, zeta, ts, tl)
    k_peak = int(np.argmax(y))
    overshoot = (float(y[k_peak]) - final) / final * 100.0
    # Below 1e-6 % the "peak" is round-off on a monotone response: no overshoot, no peak time.
    peak_time = float(t[k_peak]) if overshoot > 1e-6 else math.nan
    overshoot = overshoot if overshoot > 1e-6 else 0.0
    outside = np.nonzero(np.abs(y - final) > SETTLING_BAND * abs(final))[0]
    if outside.size == 0:
        settling = 0.0
    else:
        k = int(outside[-1])
        settling = float(t[min(k + 1, t.size - 1)])
    above10 = np.nonzero(y >= 0.1 * final)[0]
    above90 = np.nonzero(y >= 0.9 * final)[0]
    rise = float(t[above90[0]] - t[above10[0]]) if above90.size and above10.size else math.inf
    return StepMetrics(
        lam=float(lam),
        stable=True,
        final_value=final,
        overshoot_pct=overshoot,
        peak_time_s=peak_time,
        settling_s=settling,
        rise_time_s=rise,
        band_pct=100.0 * SETTLING_BAND,
    )


# ======================================================================================
# Part 2: eigenvalues of G_hat G^-1 = K Xi (Eq. 14-20, Fig. 7)
# ======================================================================================


REFERENCES = ("com", "o")


def xi_batch(cfg: VehicleConfig, poses_rad: np.ndarray, object_masses_kg: np.ndarray,
             reference: str = "com") -> np.ndarray:
    """Xi (Eq. 14) for every (pose, mass): array (n_poses, n_masses, 5, 5) (vehicle.effectiveness_pair).

    reference: the point whose acceleration the INDI force rows feed back. "com" (the true composite CoM):
    Eq. 14 as printed. "o" (the paper's specific force at O, INDI_ACC_REF = 0): the loop flies T(O - c) G, so
    G_hat G_flown^-1 = K Xi T^-1 (vehicle.reference_transform; T^-1 = 2 I - T)."""
    if reference not in REFERENCES:
        raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r}")
    poses = np.atleast_2d(np.asarray(poses_rad, dtype=float))
    masses = np.atleast_1d(np.asarray(object_masses_kg, dtype=float))
    out = np.empty((poses.shape[0], masses.size, 5, 5))
    for i, q in enumerate(poses):
        for j, m_o in enumerate(masses):
            out[i, j] = effectiveness_pair(cfg, q, float(m_o)).xi
            if reference == "o":
                c = mass_properties(cfg, q, float(m_o)).com_frd_m
                out[i, j] = out[i, j] @ (2.0 * np.eye(5) - reference_transform(-c))
    return out


def k_diagonals(k1: np.ndarray, k2: np.ndarray, k3: np.ndarray, k4: np.ndarray) -> np.ndarray:
    """Rows diag(K) = [K1, K2, K3, K4, K4] (Eq. 3) for broadcastable K arrays: shape (..., 5)."""
    k1, k2, k3, k4 = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (k1, k2, k3, k4)))
    return np.stack([k1, k2, k3, k4, k4], axis=-1)


def k_xi_eigenvalues(xi: np.ndarray, k_diag: np.ndarray) -> np.ndarray:
    """All 5 eigenvalues of K Xi (Eq. 14), batched: xi (..., 5, 5) and k_diag (..., 5) broadcast together.

    K Xi = diag(k) Xi scales the rows of Xi. Returned sorted by ascending real part along the last axis.
    """
    kxi = np.asarray(k_diag)[..., :, None] * np.asarray(xi)
    lam = np.linalg.eigvals(kxi)
    order = np.argsort(lam.real, axis=-1, kind="stable")
    return np.take_along_axis(lam, order, axis=-1)


def xi_block_coupling(xi: np.ndarray) -> float:
    """max |Xi[longitudinal rows, lateral columns]|.

    Zero means Xi (and K Xi, since K is diagonal) is block triangular in the order (lateral, longitudinal),
    so the eigenvalues split into the lateral pair (K1, K3: lam_4, lam_5, Eq. 18) and the longitudinal
    block (K2, K4: lam_1..lam_3, Eq. 17, upper triangular in our model).
    """
    x = np.asarray(xi)
    return float(np.max(np.abs(x[..., LONGITUDINAL_IDX, :][..., :, LATERAL_IDX])))


def pose_grid_rad(n_per_joint: int, q_max_rad: float = math.pi / 2) -> np.ndarray:
    """Full factorial grid of the 3 joint angles over [-q_max, q_max]: shape (n^3, 3)."""
    g = np.linspace(-q_max_rad, q_max_rad, n_per_joint)
    return np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)


def paper_poses_rad() -> np.ndarray:
    """The two poses of Fig. 7 (stretched 80/10/10 deg, curled 60/60/60 deg): shape (2, 3)."""
    return np.radians(np.array([POSE_STRETCHED_DEG, POSE_CURLED_DEG]))


@dataclass(frozen=True)
class KBoundsResult:
    """Worst case of the eigenvalues of K Xi (Sec. 3.2, Fig. 7) over the evaluated (pose, mass, K) set."""

    k_min: float
    k_max: float
    min_eigenvalue: float  # min over everything of Re(eig(K Xi))
    pose_rad: tuple[float, float, float]  # where the minimum occurs
    object_mass_kg: float
    k: tuple[float, float, float, float]  # (K1, K2, K3, K4)
    eigenvalues_at_min: tuple[complex, ...]  # all 5 eigenvalues at the minimum, ascending real part
    max_eigenvalue: float  # max of Re(eig(K Xi)): the slow side (Sec. 3.2, Eq. 19-20 upper bound on K)
    max_abs_imag: float  # largest |Im| of any eigenvalue (0 if K Xi always has real eigenvalues)
    max_imag_pose_rad: tuple[float, float, float]
    max_imag_object_mass_kg: float
    max_imag_k: tuple[float, float, float, float]
    max_imag_eigenvalue: complex  # the eigenvalue with the largest |Im| (upper half plane)
    complex_fraction: float  # share of evaluated (pose, mass, K) cases with a complex pair
    max_xi_block_coupling: float  # xi_block_coupling over all (pose, mass); ~0 => lateral/longitudinal split
    n_poses: int
    n_masses: int
    n_k: int  # K matrices evaluated per (pose, mass)
    n_cases: int  # total 5x5 eigenproblems


def _k_set(k_min: float, k_max: float, n_k: int) -> np.ndarray:
    """diag(K) rows: an n_k x n_k (K1, K3) grid at K2 = K4 = k_min, plus the 16 corners of [k_min, k_max]^4.

    K2 and K4 only enter the longitudinal eigenvalues, which are K2 Xi_11 and K4 Xi_33 = K4 Xi_44 (Eq. 17),
    so their minimum over the box is at K2 = K4 = k_min; the corners confirm that with full 5x5 eigenvalues
    instead of assuming the block structure.
    """
    g = np.linspace(k_min, k_max, n_k)
    k1, k3 = np.meshgrid(g, g, indexing="ij")
    grid = k_diagonals(k1.ravel(), k_min, k3.ravel(), k_min)
    c = np.array([k_min, k_max])
    corners = np.stack(np.meshgrid(c, c, c, c, indexing="ij"), axis=-1).reshape(-1, 4)
    # Corners with K2 = K4 = k_min are already on the grid.
    corners = corners[(corners[:, 1] != k_min) | (corners[:, 3] != k_min)]
    corner_rows = k_diagonals(corners[:, 0], corners[:, 1], corners[:, 2], corners[:, 3])
    return np.vstack([grid, corner_rows])


def _check_k_range(k_min: float, k_max: float) -> None:
    if not (0.0 < k_min <= k_max and math.isfinite(k_max)):
        raise ValueError(f"need 0 < k_min <= k_max, got k_min={k_min}, k_max={k_max}")


def _worst_case(
    xi: np.ndarray, k_rows: np.ndarray, poses: np.ndarray, masses: np.ndarray, k_min: float, k_max: float
) -> KBoundsResult:
    n_p, n_m = xi.shape[:2]
    # (n_p, n_m, n_k, 5): full 5x5 eigenvalues for every combination.
    lam = k_xi_eigenvalues(xi[:, :, None, :, :], k_rows[None, None, :, :])
    re = lam.real
    i_min = np.unravel_index(int(np.argmin(re[..., 0])), re.shape[:3])
    im = np.abs(lam.imag)
    i_im = np.unravel_index(int(np.argmax(im.max(axis=-1))), im.shape[:3])
    lam_im = lam[i_im]
    e_im = complex(lam_im[int(np.argmax(np.abs(lam_im.imag)))])
    e_im = complex(e_im.real, abs(e_im.imag))
    k_of = lambda row: (float(row[0]), float(row[1]), float(row[2]), float(row[3]))
    pose_of = lambda p: (float(p[0]), float(p[1]), float(p[2]))
    return KBoundsResult(
        k_min=float(k_min),
        k_max=float(k_max),
        min_eigenvalue=float(re[i_min][0]),
        pose_rad=pose_of(poses[i_min[0]]),
        object_mass_kg=float(masses[i_min[1]]),
        k=k_of(k_rows[i_min[2]]),
        eigenvalues_at_min=tuple(complex(v) for v in lam[i_min]),
        max_eigenvalue=float(re.max()),
        max_abs_imag=float(im[i_im].max()),
        max_imag_pose_rad=pose_of(poses[i_im[0]]),
        max_imag_object_mass_kg=float(masses[i_im[1]]),
        max_imag_k=k_of(k_rows[i_im[2]]),
        max_imag_eigenvalue=e_im,
        complex_fraction=float(np.mean(im.max(axis=-1) > _IMAG_TOL)),
        max_xi_block_coupling=xi_block_coupling(xi),
        n_poses=int(n_p),
        n_masses=int(n_m),
        n_k=int(k_rows.shape[0]),
        n_cases=int(re.shape[0] * re.shape[1] * re.shape[2]),
    )


def k_bounds_analysis(
    cfg: VehicleConfig,
    k_min: float,
    k_max: float,
    poses_rad: np.ndarray | None = None,
    object_masses_kg: Sequence[float] | np.ndarray | None = None,
    n_k: int = 9,
    reference: str = "com",
) -> KBoundsResult:
    """Fig. 7 / Sec. 3.2 worst case: min Re(eig(K Xi)) over poses, object masses and K in [k_min, k_max]^4.

    Defaults: every joint on a 7-point grid over +-90 deg (30 deg steps, 343 poses) plus the two Fig. 7
    poses; object masses 0, 0.5, 1, 1.5, 2 kg; (K1, K3) on an n_k x n_k grid at K2 = K4 = k_min plus the 16
    corners of the 4-D box. Every case is a full 5x5 eigenproblem (batched numpy.linalg.eigvals).
    reference "o": the matrix the paper's loop flies (xi_batch).
    """
    _check_k_range(k_min, k_max)
    if n_k < 2:
        raise ValueError(f"n_k must be >= 2 (the grid includes both ends), got {n_k}")
    poses = (
        np.vstack([pose_grid_rad(7), paper_poses_rad()])
        if poses_rad is None
        else np.atleast_2d(np.asarray(poses_rad, dtype=float))
    )
    if object_masses_kg is None:
        masses = np.linspace(0.0, 2.0, 5)
    else:
        masses = np.atleast_1d(np.asarray(object_masses_kg, dtype=float))
    xi = xi_batch(cfg, poses, masses, reference)
    return _worst_case(xi, _k_set(k_min, k_max, n_k), poses, masses, k_min, k_max)


def min_eigenvalue_over_workspace(cfg: VehicleConfig, k_min: float, k_max: float) -> float:
    """Cheap worst case of Re(eig(K Xi)) for the parameter registry's stability floor (well under 1 s).

    Coarse version of k_bounds_analysis: joints on {-90, -45, 0, 45, 90} deg (125 poses) plus the Fig. 7
    poses, object masses {0, 1, 2} kg, (K1, K3) on a 3 x 3 grid plus the K corners.
    At object mass 0, Xi = I and the result is exactly k_min, so the answer is never above k_min.
    """
    _check_k_range(k_min, k_max)
    poses = np.vstack([pose_grid_rad(5), paper_poses_rad()])
    masses = np.array([0.0, 1.0, 2.0])
    xi = xi_batch(cfg, poses, masses)
    lam = k_xi_eigenvalues(xi[:, :, None, :, :], _k_set(k_min, k_max, 3)[None, None, :, :])
    return float(lam.real.min())


@dataclass(frozen=True)
class LateralSurfaces:
    """lam_4 and lam_5 of G_hat G^-1 over the (K1, K3) plane at one pose and object mass (Fig. 7)."""

    k1: np.ndarray  # (n3, n1) meshgrid, K1 varies along axis 1
    k3: np.ndarray  # (n3, n1)
    lam4: np.ndarray  # (n3, n1) complex: the lateral eigenvalue with the smaller real part
    lam5: np.ndarray  # (n3, n1) complex: the other one (conjugate of lam4 when the pair is complex)
    xi_block_coupling: float  # ~0 justifies reading the pair off the lateral 2x2 block


def lateral_eigenvalue_surfaces(
    cfg: VehicleConfig,
    q_rad: np.ndarray,
    object_mass_kg: float,
    k1: np.ndarray,
    k3: np.ndarray,
) -> LateralSurfaces:
    """lam_4, lam_5 (Eq. 18) over the (K1, K3) grid for Fig. 7.

    Xi is block triangular (xi_block_coupling ~ 0, checked by the caller or the tests), so the two
    eigenvalues that depend on K1 and K3 are exactly the eigenvalues of the lateral 2x2 block
    diag(K1, K3) Xi[(0, 2), (0, 2)]; they do not depend on K2 or K4.
    """
    xi = xi_batch(cfg, np.asarray(q_rad, dtype=float)[None, :], np.array([object_mass_kg]))[0, 0]
    k1g, k3g = np.meshgrid(np.asarray(k1, dtype=float), np.asarray(k3, dtype=float))
    lat = xi[np.ix_(LATERAL_IDX, LATERAL_IDX)]
    kdiag = np.stack([k1g, k3g], axis=-1)
    lam = np.linalg.eigvals(kdiag[..., :, None] * lat)
    order = np.argsort(lam.real, axis=-1, kind="stable")
    lam = np.take_along_axis(lam, order, axis=-1)
    return LateralSurfaces(k1g, k3g, lam[..., 0], lam[..., 1], xi_block_coupling(xi))
