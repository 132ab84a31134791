"""Stability analysis of the INDI loop's decoupled modes (paper Sec. 3.1-3.2, Eq. 7-13, Figs. 5-6).

Pure math (numpy/scipy only): no I/O, no clocks, no prints. Brent's root finder is roots.brentq (scipy.optimize's
steps without its import, ~0.4 s of every FC start).

The decoupled loop H_i(s) (Eq. 9-13). With A(s) = wn^2/(s^2 + 2 zeta wn s + wn^2) (Eq. 10),
L(s) = 1/(tau_L s + 1) (Eq. 11) and the first-order Pade delay P(s) = (2 - tau_s s)/(2 + tau_s s) (Eq. 12),

    H(s) = A / (lam + (1 - lam) A L P)                                                   (Eq. 9)
         = wn^2 (tau_s s + 2)(tau_L s + 1)
           / [lam D_A (tau_L s + 1)(tau_s s + 2) + (1 - lam) wn^2 (2 - tau_s s)]

with D_A = s^2 + 2 zeta wn s + wn^2. Expanding gives Eq. 13 (docs/stability.md: the flattened paper text
lost the minus sign of the "- wn^2 tau_s" term of the s^1 coefficient; otherwise it matches).
H maps the decoupled virtual input upsilon_i to s chi_i (an acceleration command to an acceleration),
so its step response (Fig. 6) tends to H(0) = 1 for every lam (the s^0 coefficients are both 2 wn^2).
Here: H's coefficients, poles and zeros, lambda_crit and lambda_upper, the variant with the model-based U0
(INDI_U0_SRC = 1) and the step response and its metrics.

lam may be complex: K Xi can have complex eigenvalue pairs (notes 6.1 item 4), and Eq. 9 still
defines H with complex coefficients; its poles are then not conjugate-symmetric but stability is still
"all poles in the open left half plane".

The rest of Sec. 3: sampled_loop.py checks this continuous analysis against the sampled loop the FC flies (one
mode, and all five rows of Eq. 7 coupled); k_xi.py has the eigenvalues of G_hat G^-1 = K Xi over the arm's
workspace and the K bounds (Eq. 14-20, Fig. 7).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from navig8_fc.core.roots import brentq

SETTLING_BAND = 0.02  # 2 % band around the final value for the settling time
_IMAG_TOL = 1e-9  # |Im| below this counts as a real pole (round-off of the polynomial roots)


# --------------------------------------------------------------------------------------
# H_i(s) of Eq. 13, its poles and the stability interval of lam
# --------------------------------------------------------------------------------------


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
    return edge_from_nominal(lambda lam: max_real_pole(lam, wn, zeta, ts, tl), lam_end, n_scan, if_none)


def edge_from_nominal(f, lam_end: float, n_scan: int, if_none: float, xtol: float = 1e-12) -> float:
    """First lam from 1 towards lam_end where f (>= 0: unstable) changes sign: geometric scan, then brentq."""
    bracket = _bracket_scan(f, np.geomspace(1.0, lam_end, n_scan))
    if bracket is None:
        return if_none
    a, b = sorted(bracket)
    return float(brentq(f, a, b, xtol=xtol, rtol=1e-12))


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
    return edge_from_nominal(f, lam_lo, n_scan, 0.0)


# --------------------------------------------------------------------------------------
# Step response of H_i(s) (Fig. 6)
# --------------------------------------------------------------------------------------


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
    from scipy import signal  # here, not at the top: it costs ~0.7 s to import, and the stability-floor worker
    # (lambda_crit, no step responses) must be ready within a second of the FC's start

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
