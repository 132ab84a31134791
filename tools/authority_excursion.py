"""The arm's reaction and the smallest pitch excursion it forces (navig8-authority, tools/authority.py, items
2-3): the plant's joint-servo profile, the arm's angular momentum about the composite CoM (`arm_momentum_y`,
`motion_terms`), the static authority along a motion (`authority_along`), and the linear program over the moment
history (`min_pitch_excursion`, with or without the actuators' second-order lag) that gives the smallest peak
pitch any controller reaches during one motion (`window_bound`) or the paper's arm reversal (`reversal_bound`).
docs/model.md, "Pitch authority".
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from scipy import sparse
from scipy.linalg import expm
from scipy.optimize import linprog

from navig8_fc.core import g_c
from navig8_fc.core.vehicle import N_LINKS, VehicleConfig, model_geometry
from navig8_tools.authority_static import MAP_SPACING_M, TRIM_TOL_NM, authority_map

# --------------------------------------------------------------------------------------
# The arm's motion and its reaction
# --------------------------------------------------------------------------------------

EXCURSION_LP_METHOD = "highs"  # HiGHS' own choice: on this sparse banded LP 2x faster than dual simplex or IPM forced
SERVO_STEP_S = 0.001  # the plant's joint-servo period (params/plant.yaml servo_rate_hz = 1000)


def servo_profile(q_from: float, q_to: float, v_max: float, a_max: float, h_s: float,
                  duration_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Joint angle and rate of the plant's servo (sim_bridge.joint_servo.servo_accel) after a step command,
    sampled every h_s (its servo period; exact constant-acceleration steps, as the plant integrates them)."""
    from sim_bridge.joint_servo import servo_accel

    n = int(round(duration_s / h_s)) + 1
    q, qd = np.empty(n), np.empty(n)
    q[0], qd[0] = q_from, 0.0
    for k in range(n - 1):
        a = servo_accel(q_to - q[k], qd[k], h_s, a_max, v_max)
        q[k + 1] = q[k] + qd[k] * h_s + 0.5 * a * h_s * h_s
        qd[k + 1] = qd[k] + a * h_s
    return q, qd


def arm_momentum_y(cfg: VehicleConfig, q: np.ndarray, qd: np.ndarray, object_mass_kg: float) -> np.ndarray:
    """Pitch (body y) angular momentum of UAV + arm (+ object) relative to the body, about the composite CoM,
    for a body that does not rotate: sum m_k r_k x r'_k + I_k theta'_k - m c x c' (the UAV's CoM is O).

    q, qd: (n, 3) joint angles and rates; returns (n,). (a x b)_y = a_z b_x - a_x b_z."""
    q, qd = np.atleast_2d(q), np.atleast_2d(qd)
    th, thd = np.cumsum(q, axis=1), np.cumsum(qd, axis=1)
    L, ml, ia = cfg.link_length_m, cfg.link_mass_kg, cfg.link_inertia_kgm2
    jx = np.full(q.shape[0], cfg.mount_frd_m[0])
    jz = np.full(q.shape[0], cfg.mount_frd_m[2])
    jvx, jvz = np.zeros(q.shape[0]), np.zeros(q.shape[0])
    h = np.zeros(q.shape[0])
    s1 = np.zeros((q.shape[0], 2))  # sum m r (x, z)
    v1 = np.zeros((q.shape[0], 2))  # sum m r' (x, z)

    def add(m: float, x, z, vx, vz) -> None:
        nonlocal h
        h = h + m * (z * vx - x * vz)
        s1[:, 0] += m * x
        s1[:, 1] += m * z
        v1[:, 0] += m * vx
        v1[:, 1] += m * vz

    for i in range(N_LINKS):
        s, c = np.sin(th[:, i]), np.cos(th[:, i])
        ex, ez, dx, dz = s, c, thd[:, i] * c, -thd[:, i] * s  # e and its rate
        add(ml, jx + 0.5 * L * ex, jz + 0.5 * L * ez, jvx + 0.5 * L * dx, jvz + 0.5 * L * dz)
        h = h + ia * thd[:, i]
        jx, jz, jvx, jvz = jx + L * ex, jz + L * ez, jvx + L * dx, jvz + L * dz
    if object_mass_kg > 0.0:
        d = cfg.object_offset_m
        s, c = np.sin(th[:, -1]), np.cos(th[:, -1])
        add(object_mass_kg, jx + d * s, jz + d * c, jvx + d * thd[:, -1] * c, jvz - d * thd[:, -1] * s)
        h = h + 0.4 * object_mass_kg * cfg.object_radius_m**2 * thd[:, -1]
    m = cfg.uam_mass_kg + object_mass_kg
    cx, cz, cvx, cvz = s1[:, 0] / m, s1[:, 1] / m, v1[:, 0] / m, v1[:, 1] / m
    return h - m * (cz * cvx - cx * cvz)


@dataclass(frozen=True)
class ArmMotion:
    """The arm's motion on a time grid (s), the object held (kg) and the commanded body pitch (rad) per sample."""

    t_s: np.ndarray
    q_rad: np.ndarray  # (n, 3)
    qd_rad_s: np.ndarray  # (n, 3)
    object_mass_kg: np.ndarray  # (n,)
    body_pitch_rad: np.ndarray  # (n,)


def mass_terms(cfg: VehicleConfig, q: np.ndarray, object_mass_kg: np.ndarray) -> np.ndarray:
    """(n, 4): I_yy about the composite CoM, CoM x, CoM z, total mass at each pose (the model's mass_props)."""
    geo, zero = model_geometry(cfg), np.zeros(N_LINKS)
    inertia, rate, mp = np.empty((3, 3)), np.empty((3, 3)), g_c.MP.zeros()
    out = np.empty((len(q), 4))
    for i in range(len(q)):
        g_c.mass_props(np.ascontiguousarray(q[i], dtype=float), zero, zero, float(object_mass_kg[i]), geo, inertia,
                      rate, mp)
        out[i] = inertia[1, 1], mp[g_c.MP.CX], mp[g_c.MP.CZ], mp[g_c.MP.MASS]
    return out


def _momentum(cfg: VehicleConfig, q: np.ndarray, qd: np.ndarray, object_mass_kg: np.ndarray) -> np.ndarray:
    h = np.empty(len(q))
    for m in np.unique(object_mass_kg):
        sel = object_mass_kg == m
        h[sel] = arm_momentum_y(cfg, q[sel], qd[sel], float(m))
    return h


def motion_terms(cfg: VehicleConfig, motion: ArmMotion) -> dict[str, np.ndarray]:
    """I_yy, h, the CoM and the total mass at each sample, and I_yy, h at each step's end with the step's starting
    object (they differ where the object changes: the plant keeps the body rates continuous through a grasp or
    release, so the momentum about the CoM jumps there while theta' does not)."""
    q, qd, mo = motion.q_rad, motion.qd_rad_s, np.asarray(motion.object_mass_kg, dtype=float)
    mt = mass_terms(cfg, q, mo)
    h = _momentum(cfg, q, qd, mo)
    iyy_end, h_end = mt[1:, 0].copy(), h[1:].copy()
    chg = np.flatnonzero(mo[1:] != mo[:-1])
    if chg.size:
        iyy_end[chg] = mass_terms(cfg, q[chg + 1], mo[chg])[:, 0]
        h_end[chg] = _momentum(cfg, q[chg + 1], qd[chg + 1], mo[chg])
    return {"iyy": mt[:, 0], "com_x": mt[:, 1], "com_z": mt[:, 2], "mass": mt[:, 3], "h": h, "iyy_end": iyy_end,
            "h_end": h_end}


def authority_along(cfg: VehicleConfig, motion: ArmMotion, terms: dict[str, np.ndarray], fx_free: bool,
                    spacing_m: float = MAP_SPACING_M) -> tuple[np.ndarray, np.ndarray]:
    """The static pitch authority [min, max] (N m) at each sample of a motion (AuthorityMap per total mass and
    commanded pitch)."""
    lo, hi = np.empty(len(motion.t_s)), np.empty(len(motion.t_s))
    keys = np.column_stack([terms["mass"], motion.body_pitch_rad])
    for key in np.unique(keys, axis=0):
        sel = np.all(keys == key, axis=1)
        amap = authority_map(cfg, float(key[0]), float(key[1]), fx_free, spacing_m)
        lo[sel], hi[sel] = amap.bounds(terms["com_x"][sel], terms["com_z"][sel])
    return lo, hi


# --------------------------------------------------------------------------------------
# The smallest pitch excursion
# --------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=64)
def lag_discrete(dt_s: float, omega_n: float, zeta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The actuators' second-order response (unit gain) over one step of dt_s with the command held, in the state
    z = (y, y'/omega_n): z+ = Phi z + Gamma u, and the delivered value of the step, at its middle (as the
    momentum takes it for the whole step): y_mid = C z + D u. Returns (Phi, Gamma, C, D); exact (matrix
    exponential)."""
    a = np.array([[0.0, omega_n, 0.0], [-omega_n, -2.0 * zeta * omega_n, omega_n], [0.0, 0.0, 0.0]])
    full, half = expm(a * dt_s), expm(a * 0.5 * dt_s)
    return full[:2, :2], full[:2, 2], half[0, :2], float(half[0, 2])


def min_pitch_excursion(t_s: np.ndarray, inertia_yy: np.ndarray, h_y: np.ndarray, m_max: np.ndarray,
                        m_min: np.ndarray, actuator: tuple[float, float] | None = None, hold_until: int = 0,
                        inertia_end: np.ndarray | None = None, h_end: np.ndarray | None = None,
                        end_at_rest: bool = True, free_start: bool = False) -> tuple[float, np.ndarray, np.ndarray]:
    """min over moment histories u (held over each step, m_min <= u <= m_max) of max_k |theta_k|, for
    d/dt (I theta' + h) = u_delivered, theta(0) = theta'(0) = 0, theta' = 0 at the end (end_at_rest); u_delivered
    = u, or u through the actuators' second-order lag (actuator = (omega_n, zeta), `lag_discrete`, at rest at trim
    at t = 0); u = 0 (trim) on the first hold_until steps. m_max, m_min: per step (n - 1) or per sample (n: step k
    takes sample k's). inertia_end, h_end (n - 1): I and h at each step's end with the step's starting object
    (`motion_terms`; default the next sample's).

    The momentum P = I theta' + h is exact under a held u (P_{k+1} = P_k + dt u_k); theta integrates theta'
    with the trapezoid rule. A sparse LP in u, theta', theta (and the lag's state). free_start: a relaxation for a
    piece of a longer motion, the state at t_0 free (theta, theta'; the delivered moment inside the authority's
    envelope and its rate / omega_n within the envelope's largest |moment|, which bounds a critically or
    over-damped response to any command inside it). Returns (peak, theta history, u commanded)."""
    t = np.asarray(t_s, dtype=float)
    n = len(t)
    ns = n - 1
    dt = np.diff(t)
    iyy, h = np.asarray(inertia_yy, dtype=float), np.asarray(h_y, dtype=float)
    i_end = iyy[1:] if inertia_end is None else np.asarray(inertia_end, dtype=float)
    hh_end = h[1:] if h_end is None else np.asarray(h_end, dtype=float)
    hi, lo = np.asarray(m_max, dtype=float)[:ns], np.asarray(m_min, dtype=float)[:ns]
    lay = _ExcursionLayout.of(n, 0 if actuator is None else 2)
    a_eq, b_eq = _excursion_equalities(lay, dt, iyy, h, i_end, hh_end, actuator)
    # -s <= theta_k <= s
    kk = np.arange(n)
    a_ub = sparse.csr_matrix((np.concatenate([np.ones(n), -np.ones(n), -np.ones(n), -np.ones(n)]),
                              (np.concatenate([kk, kk, n + kk, n + kk]),
                               np.concatenate([lay.ith + kk, np.full(n, lay.i_s), lay.ith + kk,
                                               np.full(n, lay.i_s)]))),
                             shape=(2 * n, lay.nv))
    lb, ub = _excursion_bounds(lay, hi, lo, hold_until, end_at_rest, free_start)
    cost = np.zeros(lay.nv)
    cost[lay.i_s] = 1.0
    for method in dict.fromkeys((EXCURSION_LP_METHOD, "highs-ipm", "highs-ds")):
        # a simplex can stop on numerical trouble here (seen once in the reversals) or stall on a degenerate piece
        # whose optimum is ~0 (a slow sweep; it normally takes < 0.2 s): interior point then solves it
        opts = {} if method == "highs-ipm" else {"time_limit": 0.5 + 2e-4 * lay.nv}
        res = linprog(cost, A_ub=a_ub, b_ub=np.zeros(2 * n), A_eq=a_eq, b_eq=b_eq,
                      bounds=np.column_stack([lb, ub]), method=method, options=opts)
        if res.status in (0, 2):
            break
    if res.status != 0:
        raise ValueError(f"the excursion LP failed: {res.message}")
    x = np.asarray(res.x)
    return float(x[lay.i_s]), x[lay.ith:lay.ith + n].copy(), x[lay.iu:lay.iu + ns].copy()


class _ExcursionLayout(NamedTuple):
    """Where min_pitch_excursion's variables sit: u (per step), theta', theta, the peak s, the lag's state."""

    n: int  # samples
    ns: int  # steps
    nz: int  # the lag's states per sample (0 without the lag)
    iu: int
    iw: int
    ith: int
    i_s: int
    iz: int
    nv: int

    @staticmethod
    def of(n: int, nz: int) -> _ExcursionLayout:
        ns = n - 1
        iu, iw, ith, i_s, iz = 0, ns, ns + n, ns + 2 * n, ns + 2 * n + 1
        return _ExcursionLayout(n, ns, nz, iu, iw, ith, i_s, iz, iz + nz * n)


def _excursion_equalities(lay: _ExcursionLayout, dt: np.ndarray, iyy: np.ndarray, h: np.ndarray,
                          i_end: np.ndarray, hh_end: np.ndarray,
                          actuator: tuple[float, float] | None) -> tuple[Any, np.ndarray]:
    """min_pitch_excursion's equality rows: the momentum over each step, the lag's state update (with the
    actuator), theta's trapezoid rule. Returns (A_eq, b_eq)."""
    ns, nz, iu, iw, ith, iz = lay.ns, lay.nz, lay.iu, lay.iw, lay.ith, lay.iz
    k = np.arange(ns)
    rows, cols, vals = [], [], []

    def put(r: np.ndarray, c: np.ndarray, v: np.ndarray | float) -> None:
        rows.append(r)
        cols.append(c)
        vals.append(np.broadcast_to(np.asarray(v, dtype=float), r.shape))

    # momentum: I_end[k] w[k+1] - I[k] w[k] - dt_k d_k = h[k] - h_end[k]   (rows 0 .. ns-1)
    put(k, iw + k + 1, i_end)
    put(k, iw + k, -iyy[:-1])
    b_eq = [h[:-1] - hh_end]
    if actuator is None:
        put(k, iu + k, -dt)
    else:
        omega_n, zeta = actuator
        phi = np.empty((ns, 2, 2))
        gam, cc, dd = np.empty((ns, 2)), np.empty((ns, 2)), np.empty(ns)
        for step in np.unique(dt):
            sel = dt == step
            phi[sel], gam[sel], cc[sel], dd[sel] = lag_discrete(float(step), float(omega_n), float(zeta))
        put(k, iu + k, -dt * dd)
        for j in range(2):
            put(k, iz + 2 * k + j, -dt * cc[:, j])
        # lag: z[k+1] - Phi z[k] - Gamma u[k] = 0   (rows 2 ns .. 4 ns - 1)
        for j in range(2):
            r = 2 * ns + 2 * k + j
            put(r, iz + 2 * (k + 1) + j, 1.0)
            for m in range(2):
                put(r, iz + 2 * k + m, -phi[:, j, m])
            put(r, iu + k, -gam[:, j])
    # theta: th[k+1] - th[k] - dt/2 (w[k] + w[k+1]) = 0   (rows ns .. 2 ns - 1)
    put(ns + k, ith + k + 1, 1.0)
    put(ns + k, ith + k, -1.0)
    put(ns + k, iw + k, -0.5 * dt)
    put(ns + k, iw + k + 1, -0.5 * dt)
    b_eq += [np.zeros(ns), np.zeros(nz * ns)]
    a_eq = sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                             shape=((2 + nz) * ns, lay.nv))
    return a_eq, np.concatenate(b_eq)


def _excursion_bounds(lay: _ExcursionLayout, hi: np.ndarray, lo: np.ndarray, hold_until: int, end_at_rest: bool,
                      free_start: bool) -> tuple[np.ndarray, np.ndarray]:
    """min_pitch_excursion's variable bounds: the command inside the authority (at trim while held), at rest at the
    start (unless free_start: the relaxation's envelope) and at the end (end_at_rest), the peak non-negative."""
    n, ns, nz, iu, iw, ith, i_s, iz = lay.n, lay.ns, lay.nz, lay.iu, lay.iw, lay.ith, lay.i_s, lay.iz
    lb, ub = np.full(lay.nv, -np.inf), np.full(lay.nv, np.inf)
    lb[iu:iu + ns], ub[iu:iu + ns] = lo, hi
    lb[iu:iu + hold_until], ub[iu:iu + hold_until] = 0.0, 0.0
    if not free_start:
        lb[iw] = ub[iw] = 0.0
        lb[ith] = ub[ith] = 0.0
    if end_at_rest:
        lb[iw + n - 1] = ub[iw + n - 1] = 0.0
    lb[i_s] = 0.0
    if nz and free_start:
        big = float(max(np.max(np.abs(hi)), np.max(np.abs(lo))))
        lb[iz], ub[iz] = float(np.min(lo)), float(np.max(hi))
        lb[iz + 1], ub[iz + 1] = -big, big
    elif nz:
        lb[iz:iz + 2] = ub[iz:iz + 2] = 0.0
    return lb, ub


@dataclass(frozen=True)
class ExcursionBound:
    """The smallest peak pitch excursion (rad) any controller reaches during one arm motion (inf where the
    actuator set cannot hold the hover at some sample: untrimmable_t_s is then the first such time)."""

    min_peak_pitch_rad: float
    t_s: np.ndarray
    pitch_rad: np.ndarray  # the optimal excursion history
    moment_nm: np.ndarray  # the commanded actuator moment about the CoM that achieves it (per step)
    disturbance_nm: np.ndarray  # -dh/dt: the arm's reaction moment about the CoM
    authority_max_nm: np.ndarray  # the static authority at each sample
    authority_min_nm: np.ndarray
    untrimmable_t_s: float | None = None


def window_bound(cfg: VehicleConfig, motion: ArmMotion, fx_free: bool = False,
                 actuator: tuple[float, float] | None = None, hold_until: int = 0, end_at_rest: bool = True,
                 spacing_m: float = MAP_SPACING_M, terms: dict[str, np.ndarray] | None = None,
                 free_start: bool = False) -> ExcursionBound:
    """`min_pitch_excursion` over one arm motion: I_yy(q), h(q, q', m_o) from the model (`motion_terms`, or terms
    given), the authority of each step the envelope of its two samples' (AuthorityMap at the sample's CoM, mass and
    commanded pitch: with the authority convex in c, see AuthorityMap, the envelope of a step's ends covers the
    CoM's path in between). free_start: the relaxation of `min_pitch_excursion` (a piece of a longer motion)."""
    t = np.asarray(motion.t_s, dtype=float)
    terms = motion_terms(cfg, motion) if terms is None else terms
    lo, hi = authority_along(cfg, motion, terms, fx_free, spacing_m)
    dist = -np.gradient(terms["h"], t)
    bad = ~((lo <= TRIM_TOL_NM) & (hi >= -TRIM_TOL_NM))
    if np.any(bad):
        nan = np.full(len(t), np.nan)
        return ExcursionBound(math.inf, t, nan, nan[:-1], dist, hi, lo, float(t[np.argmax(bad)]))
    # the leading steps at rest with the command at trim change nothing (theta, theta' and the lag stay 0): the LP
    # starts at the last of them
    still = np.all(motion.q_rad == motion.q_rad[0], axis=1) & (motion.object_mass_kg == motion.object_mass_kg[0])
    still &= terms["h"] == terms["h"][0]
    k0 = min(int(np.argmin(still)) - 1 if not still.all() else len(t) - 2, hold_until)
    k0 = 0 if free_start else max(k0, 0)
    hi_s, lo_s = np.maximum(hi[:-1], hi[1:]), np.minimum(lo[:-1], lo[1:])
    if free_start and _holds_still(t, terms, hi_s, lo_s, actuator):
        return ExcursionBound(0.0, t, np.zeros(len(t)), np.zeros(len(t) - 1), dist, hi, lo)
    sl = slice(k0, None)
    peak, th, u = min_pitch_excursion(t[sl], terms["iyy"][sl], terms["h"][sl], hi_s[sl], lo_s[sl], actuator,
                                      0 if free_start else hold_until - k0, terms["iyy_end"][sl],
                                      terms["h_end"][sl], end_at_rest, free_start)
    theta, mom = np.zeros(len(t)), np.zeros(len(t) - 1)
    theta[sl], mom[sl] = th, u
    return ExcursionBound(peak, t, theta, mom, dist, hi, lo)


def _holds_still(t: np.ndarray, terms: dict[str, np.ndarray], hi: np.ndarray, lo: np.ndarray,
                  actuator: tuple[float, float] | None) -> bool:
    """Whether theta = theta' = 0 throughout is reachable in the free-start relaxation (then its peak is exactly 0,
    no LP needed): the moment it takes, (h_end - h) / dt per step, delivered by a command inside the authority (the
    lag inverted step by step from the delivered moment's first value, at rest)."""
    need = (terms["h_end"] - terms["h"][:-1]) / np.diff(t)
    if actuator is None:
        return bool(np.all((need <= hi) & (need >= lo)))
    z = np.array([need[0], 0.0])
    for k, dt in enumerate(np.diff(t)):
        phi, gam, cc, dd = lag_discrete(float(dt), float(actuator[0]), float(actuator[1]))
        u = (need[k] - cc @ z) / dd
        if not lo[k] <= u <= hi[k]:
            return False
        z = phi @ z + gam * u
    return True


def reversal_motion(q_from_rad: float, q_to_rad: float, object_mass_kg: float, v_max: float, a_max: float,
                    dt_s: float = 0.002, settle_s: float = 1.0, pre_s: float = 0.0, body_pitch_rad: float = 0.0,
                    servo_step_s: float = SERVO_STEP_S) -> ArmMotion:
    """The paper's reversal: all three joints from q_from to q_to through the plant's servo (integrated at about
    servo_step_s, sampled every dt_s), after pre_s at rest."""
    sub = max(1, round(dt_s / servo_step_s))
    move_s = abs(q_to_rad - q_from_rad) / v_max + v_max / a_max + 0.05
    qj, qdj = servo_profile(q_from_rad, q_to_rad, v_max, a_max, dt_s / sub, move_s + settle_s)
    qj, qdj = qj[::sub], qdj[::sub]
    n_pre = int(round(pre_s / dt_s))
    qj = np.concatenate([np.full(n_pre, q_from_rad), qj])
    qdj = np.concatenate([np.zeros(n_pre), qdj])
    n = len(qj)
    return ArmMotion(np.arange(n) * dt_s, np.repeat(qj[:, None], N_LINKS, axis=1),
                     np.repeat(qdj[:, None], N_LINKS, axis=1), np.full(n, float(object_mass_kg)),
                     np.full(n, float(body_pitch_rad)))


def reversal_bound(cfg: VehicleConfig, q_from_rad: float, q_to_rad: float, object_mass_kg: float,
                   v_max: float, a_max: float, fx_free: bool = False, dt_s: float = 0.002,
                   settle_s: float = 1.0, actuator: tuple[float, float] | None = None,
                   causal_delay_s: float | None = None, pre_s: float = 0.0,
                   body_pitch_rad: float = 0.0, spacing_m: float = MAP_SPACING_M) -> ExcursionBound:
    """The paper's reversal (`reversal_motion`, starting at pre_s), about a hover pitched by body_pitch_rad (the
    excursion is counted from there): `window_bound` on it.
    actuator = (omega_n, zeta): the delivered moment lags its command (module docstring, 3.); causal_delay_s: the
    command stays at trim until this long after the reversal starts (None: free from t = 0, a preview)."""
    motion = reversal_motion(q_from_rad, q_to_rad, object_mass_kg, v_max, a_max, dt_s, settle_s, pre_s,
                             body_pitch_rad)
    hold = 0 if causal_delay_s is None else int(round(pre_s / dt_s)) + int(round(causal_delay_s / dt_s))
    return window_bound(cfg, motion, fx_free, actuator, hold, spacing_m=spacing_m)
