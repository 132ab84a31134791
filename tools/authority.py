"""navig8-authority: the actuator set's moment authority at hover, and the physical limit it puts on pitch
during the paper's arm reversal (issue 10).

    navig8-authority [--tail-max-thrust N] [--masses 0,1,2] [--pitch-deg 45] [--lag] [--json] [--no-reversal]

1. **Static authority.** For an arm pose q and object mass m_o, the largest pure pitch (roll) moment about the
   composite CoM that the real actuator set (duct speeds 0..w_max, duct tilts within their limits, reversible
   tail speed) can hold at hover: maximise M (L) over U subject to G_C(c) U = [L, M, N, Fx, Fz] with the other
   moments 0, Fz = -m g and Fx = 0 ("Fx held") or Fx free (the tilt lever: common duct tilt x the duct height
   below the CoM). With the body pitched by theta (`--pitch-deg`, the paper's 45 deg phase) the hover force in
   body axes is m g (sin theta, 0, -cos theta): "Fx held" then holds Fx = m g sin theta.
   Each duct's (U_cos, U_sin) = w^2 (cos a, sin a) lies in a disk sector of radius w_max^2 and
   the tilt range; a range wider than 180 deg is not convex, but it is the union of two half disks, so the
   optimum is the best of the 4 linear programs over the pieces of the two ducts (exact up to the inscribed
   polygon of the disk, whose solutions are all flyable).
2. **Reversal bound.** During the arm's reversal the arm's angular momentum relative to the composite CoM,
   h(q, q'), changes; about the CoM gravity has no moment, so d/dt (I_yy(q) theta' + h) = M_act. With
   |M_act| inside the static authority of the current pose, the smallest peak |theta| any controller can
   reach is a linear program over the moment history (exact discretisation of the momentum, trapezoid for
   theta, ending at rest). It ignores the actuator lag, the noise and the hover-force coupling of a tilted
   body, so it is a lower bound: no controller flying this actuator set can do better.
3. **With the actuators' lag** (`--lag`). The same LP with the delivered moment the commanded moment history
   through the actuators' second-order response (omega_n, zeta of params/plant.yaml: 120 rad/s, 1), the command
   inside the static authority (zeta = 1 does not overshoot, so the delivered moment stays inside it too), in two
   variants: *preview* (the command may start before the reaction: the controller knows the arm's plan) and
   *causal* (the command stays at trim until one control tick after the reaction starts: a controller that
   sees the reaction only when it happens). The moment is a nonlinear function of the actuator states (thrust
   ~ w|w|, the tail reversing through zero speed has none), so the linear lag of the moment is a model, not an
   exact bound; the numbers say how much of the flown error the lag alone explains.

Everything is the model of navig8_fc.core.vehicle (the same G_C the controller uses) and the plant's joint servo
(sim_bridge._kernels._servo_accel). See docs/model.md ("Pitch authority").
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import linprog

from navig8_fc.core.vehicle import N_LINKS, VehicleConfig, control_effectiveness_gc, mass_properties

ROWS = {"roll": 0, "pitch": 1}  # G_C rows [L, M, N, Fx, Fz]
POLYGON_SIDES = 256  # the speed disk as its inscribed polygon: at most 1 - cos(pi/n) = 7.5e-5 inside


@dataclass(frozen=True)
class Authority:
    """The largest and smallest pure moment (N m, about the composite CoM) at hover, and the U reaching them
    (every limit respected; the speed disk as its inscribed polygon, at most 1 - cos(pi/n) below the circle)."""

    max_nm: float
    min_nm: float
    u_at_max: np.ndarray
    u_at_min: np.ndarray


def with_tail_thrust(cfg: VehicleConfig, tail_max_thrust_n: float) -> VehicleConfig:
    """The vehicle with a tail propeller of the given maximum thrust (N) at its speed limit; K_Q2/K_T2 kept."""
    w = max(abs(cfg.tail_speed_min), abs(cfg.tail_speed_max))
    kt = float(tail_max_thrust_n) / (w * w)
    return dataclasses.replace(cfg, k_thrust_tail=kt, k_torque_tail=cfg.k_torque_tail * kt / cfg.k_thrust_tail)


def tail_max_thrust_n(cfg: VehicleConfig) -> float:
    w = max(abs(cfg.tail_speed_min), abs(cfg.tail_speed_max))
    return cfg.k_thrust_tail * w * w


def _tilt_pieces(cfg: VehicleConfig) -> list[tuple[float, float]]:
    """Convex pieces (angle intervals of at most 180 deg) whose union is the duct's tilt range."""
    lo, hi = cfg.tilt_min_rad, cfg.tilt_max_rad
    if hi - lo <= math.pi:
        return [(lo, hi)]
    if hi - lo > 2.0 * math.pi - 1e-12:
        raise ValueError("tilt range wider than 360 deg")
    return [(lo, lo + math.pi), (hi - math.pi, hi)]  # two half disks covering the sector


def _duct_constraints(cfg: VehicleConfig, pieces: tuple[tuple[float, float], ...],
                      n: int) -> tuple[np.ndarray, np.ndarray]:
    """A_ub U <= b_ub: each duct's (U_cos, U_sin) in the inscribed n-gon of its speed disk and in one convex
    piece of its tilt sector (two half-planes through the origin)."""
    if cfg.duct_speed_min != 0.0:
        raise ValueError("the authority LP assumes duct_speed_min = 0 (an annulus is not convex)")
    r2 = cfg.duct_speed_max**2
    # vertices on the circle at angles 2 pi k / n: edge normals half way between, at distance r2 cos(pi/n)
    phi = (np.arange(n) + 0.5) * (2.0 * np.pi / n)
    rows, rhs = [], []
    for (ic, is_), (a_lo, a_hi) in zip(((0, 1), (2, 3)), pieces, strict=True):
        for ph in phi:
            a = np.zeros(5)
            a[ic], a[is_] = math.cos(ph), math.sin(ph)
            rows.append(a)
            rhs.append(r2 * math.cos(math.pi / n))
        # angle >= a_lo: cross(dir(a_lo), U) >= 0; angle <= a_hi: cross(U, dir(a_hi)) >= 0
        for ang, sgn in ((a_lo, 1.0), (a_hi, -1.0)):
            a = np.zeros(5)
            a[ic], a[is_] = sgn * math.sin(ang), -sgn * math.cos(ang)
            rows.append(a)
            rhs.append(0.0)
    return np.array(rows), np.array(rhs)


def hover_authority(cfg: VehicleConfig, q_rad: Sequence[float], object_mass_kg: float, axis: str = "pitch",
                    fx_free: bool = False, sides: int = POLYGON_SIDES, body_pitch_rad: float = 0.0) -> Authority:
    """Largest/smallest pure moment about the composite CoM the actuator set holds at hover, the body pitched by
    body_pitch_rad (0: level): the actuators hold -m g_body = m g (sin theta, 0, -cos theta) in FRD.

    Raises ValueError if the actuator set cannot even trim there."""
    row = ROWS[axis]
    mp = mass_properties(cfg, q_rad, object_mass_kg)
    gc = control_effectiveness_gc(cfg, mp.com_frd_m)
    fixed = [r for r in range(5) if r != row and not (fx_free and r == 3)]
    target = np.zeros(5)
    target[3] = mp.mass_kg * cfg.gravity_m_s2 * math.sin(body_pitch_rad)
    target[4] = -mp.mass_kg * cfg.gravity_m_s2 * math.cos(body_pitch_rad)
    u5 = (math.copysign(cfg.tail_speed_min**2, cfg.tail_speed_min),
          math.copysign(cfg.tail_speed_max**2, cfg.tail_speed_max))
    bounds = [(None, None)] * 4 + [u5]
    best: dict[float, tuple[float, np.ndarray]] = {}
    pieces = _tilt_pieces(cfg)
    for combo in itertools.product(pieces, repeat=2):
        a_ub, b_ub = _duct_constraints(cfg, combo, sides)
        for sgn in (1.0, -1.0):
            res = linprog(-sgn * gc[row], A_ub=a_ub, b_ub=b_ub, A_eq=gc[fixed], b_eq=target[fixed],
                          bounds=bounds, method="highs")
            if res.status == 2:  # infeasible with this pair of pieces
                continue
            if res.status != 0:
                raise ValueError(f"authority LP failed: {res.message}")
            val = float(gc[row] @ res.x)
            if sgn not in best or sgn * val > sgn * best[sgn][0]:
                best[sgn] = (val, np.asarray(res.x))
    if not best:
        raise ValueError(f"hover is infeasible at q = {list(q_rad)}, m_o = {object_mass_kg}")
    return Authority(best[1.0][0], best[-1.0][0], best[1.0][1], best[-1.0][1])


# --------------------------------------------------------------------------------------
# The arm reversal
# --------------------------------------------------------------------------------------


def servo_profile(q_from: float, q_to: float, v_max: float, a_max: float, h_s: float,
                  duration_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Joint angle and rate of the plant's servo (sim_bridge._kernels._servo_accel) after a step command,
    sampled every h_s (its servo period; exact constant-acceleration steps, as the plant integrates them)."""
    from sim_bridge._kernels import _servo_accel

    n = int(round(duration_s / h_s)) + 1
    q, qd = np.empty(n), np.empty(n)
    q[0], qd[0] = q_from, 0.0
    for k in range(n - 1):
        a = _servo_accel(q_to - q[k], qd[k], h_s, a_max, v_max)
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
class ReversalBound:
    """The smallest peak pitch excursion (rad) any controller reaches during one arm reversal."""

    min_peak_pitch_rad: float
    t_s: np.ndarray
    pitch_rad: np.ndarray  # the optimal excursion history
    moment_nm: np.ndarray  # the actuator moment about the CoM that achieves it
    disturbance_nm: np.ndarray  # -dh/dt: the arm's reaction moment about the CoM
    authority_max_nm: np.ndarray
    authority_min_nm: np.ndarray


def lag_matrix(dt_s: float, n: int, omega_n: float, zeta: float) -> np.ndarray:
    """L (n x n, lower triangular): the delivered moment over step k, L @ u, for a commanded moment u held over
    each step and a second-order actuator (unit gain, at rest at trim before step 0); the delivered value of
    step k is the response at the step's middle (the step response s(t) differenced at (k - j + 1/2) dt)."""
    def step(t: np.ndarray) -> np.ndarray:
        t = np.maximum(t, 0.0)
        if abs(zeta - 1.0) < 1e-9:
            return 1.0 - np.exp(-omega_n * t) * (1.0 + omega_n * t)
        if zeta > 1.0:
            r = math.sqrt(zeta * zeta - 1.0)
            p1, p2 = omega_n * (zeta - r), omega_n * (zeta + r)
            return 1.0 - (p2 * np.exp(-p1 * t) - p1 * np.exp(-p2 * t)) / (p2 - p1)
        wd = omega_n * math.sqrt(1.0 - zeta * zeta)
        return 1.0 - np.exp(-zeta * omega_n * t) * (np.cos(wd * t) + zeta * omega_n / wd * np.sin(wd * t))

    lag = np.arange(n)[:, None] - np.arange(n)[None, :]  # k - j
    g = step((lag + 0.5) * dt_s) - step((lag - 0.5) * dt_s)
    return np.where(lag >= 0, g, 0.0)


def min_pitch_excursion(t_s: np.ndarray, inertia_yy: np.ndarray, h_y: np.ndarray, m_max: np.ndarray,
                        m_min: np.ndarray, lag: np.ndarray | None = None,
                        hold_until: int = 0) -> tuple[float, np.ndarray, np.ndarray]:
    """min over moment histories u (held over each step, m_min <= u <= m_max) of max_k |theta_k|, for
    d/dt (I theta' + h) = u_delivered, theta(0) = theta'(0) = 0, theta' = 0 at the end; u_delivered = u, or
    lag @ u (`lag_matrix`, (n-1) x (n-1)) with the actuators' lag; u = 0 (trim) on the first hold_until steps.

    The momentum P = I theta' + h is exact under a held u (P_{k+1} = P_k + dt u_k); theta integrates theta'
    with the trapezoid rule. Returns (peak, theta history, u commanded)."""
    n = len(t_s)
    dt = np.diff(t_s)
    # P_k = h_0 + sum_{j<k} dt_j u_j  ->  theta'_k = (P_k - h_k)/I_k = (C u)_k + e_k
    c = np.zeros((n, n - 1))
    for k in range(1, n):
        c[k, :k] = dt[:k]
    if lag is not None:
        c = c @ lag
    c /= inertia_yy[:, None]
    e = (h_y[0] - h_y) / inertia_yy
    # theta_k = sum_{j<k} dt_j (theta'_j + theta'_{j+1})/2
    tr = np.zeros((n, n))
    for k in range(1, n):
        tr[k, :k] += 0.5 * dt[:k]
        tr[k, 1:k + 1] += 0.5 * dt[:k]
    a_th, b_th = tr @ c, tr @ e
    # variables [u (n-1), s]; minimise s with -s <= theta <= s; theta'_end = 0
    nv = n
    cost = np.zeros(nv)
    cost[-1] = 1.0
    a_ub = np.block([[a_th, -np.ones((n, 1))], [-a_th, -np.ones((n, 1))]])
    b_ub = np.concatenate([-b_th, b_th])
    a_eq = np.concatenate([c[-1], [0.0]])[None, :]
    b_eq = np.array([-e[-1]])
    bounds = [(0.0, 0.0) if k < hold_until else (lo, hi)
              for k, (lo, hi) in enumerate(zip(m_min[:-1], m_max[:-1], strict=True))] + [(0.0, None)]
    res = linprog(cost, A_ub=a_ub, b_ub=b_ub, A_eq=a_eq, b_eq=b_eq, bounds=bounds, method="highs")
    if res.status != 0:
        raise ValueError(f"the reversal LP failed: {res.message}")
    u = res.x[:-1]
    return float(res.x[-1]), a_th @ u + b_th, u


def reversal_bound(cfg: VehicleConfig, q_from_rad: float, q_to_rad: float, object_mass_kg: float,
                   v_max: float, a_max: float, fx_free: bool = False, dt_s: float = 0.002,
                   settle_s: float = 1.0, grid: int = 17, actuator: tuple[float, float] | None = None,
                   causal_delay_s: float | None = None, pre_s: float = 0.0,
                   body_pitch_rad: float = 0.0) -> ReversalBound:
    """The paper's reversal (all three joints from q_from to q_to through the plant's servo, starting at pre_s),
    about a hover pitched by body_pitch_rad (the excursion is counted from there).
    actuator = (omega_n, zeta): the delivered moment lags its command (module docstring, 3.); causal_delay_s: the
    command stays at trim until this long after the reversal starts (None: free from t = 0, a preview)."""
    move_s = abs(q_to_rad - q_from_rad) / v_max + v_max / a_max + 0.05
    qj, qdj = servo_profile(q_from_rad, q_to_rad, v_max, a_max, dt_s, move_s + settle_s)
    n_pre = int(round(pre_s / dt_s))
    qj = np.concatenate([np.full(n_pre, q_from_rad), qj])
    qdj = np.concatenate([np.zeros(n_pre), qdj])
    t = np.arange(len(qj)) * dt_s
    q3, qd3 = np.repeat(qj[:, None], N_LINKS, axis=1), np.repeat(qdj[:, None], N_LINKS, axis=1)
    h = arm_momentum_y(cfg, q3, qd3, object_mass_kg)
    iyy = np.array([mass_properties(cfg, qq, object_mass_kg).inertia_com[1, 1] for qq in q3])
    # static authority on a grid of the (equal) joint angle, interpolated along the path
    grid_q = np.linspace(min(q_from_rad, q_to_rad), max(q_from_rad, q_to_rad), grid)
    auth = [hover_authority(cfg, [g] * N_LINKS, object_mass_kg, "pitch", fx_free, body_pitch_rad=body_pitch_rad)
            for g in grid_q]
    m_max = np.interp(qj, grid_q, [a.max_nm for a in auth])
    m_min = np.interp(qj, grid_q, [a.min_nm for a in auth])
    lag = lag_matrix(dt_s, len(t) - 1, *actuator) if actuator is not None else None
    hold = 0 if causal_delay_s is None else n_pre + int(round(causal_delay_s / dt_s))
    peak, theta, u = min_pitch_excursion(t, iyy, h, m_max, m_min, lag, hold)
    dist = -np.gradient(h, t)
    return ReversalBound(peak, t, theta, u, dist, m_max, m_min)


# --------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------

POSES_DEG = {"q=0": (0.0, 0.0, 0.0), "+20x3": (20.0, 20.0, 20.0), "-20x3": (-20.0, -20.0, -20.0),
             "80/10/10": (80.0, 10.0, 10.0), "60/60/60": (60.0, 60.0, 60.0)}


LAG_PRE_S = 0.2  # how early a preview may start commanding before the reversal (longer than the actuators' lag)
CAUSAL_DELAY_S = 0.01  # one control tick at 100 Hz: the first tick that can see the reaction


def analyse(cfg: VehicleConfig, masses: Sequence[float], reversal: bool, v_max: float,
            a_max: float, amplitude_deg: float, actuator: tuple[float, float] | None = None,
            pitch_deg: float = 0.0) -> dict[str, Any]:
    th = math.radians(pitch_deg)
    static = []
    for name, pose in POSES_DEG.items():
        q = [math.radians(v) for v in pose]
        for m in masses:
            row: dict[str, Any] = {"pose": name, "object_kg": m}
            for axis in ("pitch", "roll"):
                for fx_free in (False, True):
                    if axis == "roll" and fx_free:
                        continue
                    key = f"{axis}{'_fx_free' if fx_free else ''}"
                    try:
                        a = hover_authority(cfg, q, m, axis, fx_free, body_pitch_rad=th)
                    except ValueError:  # this actuator set cannot even trim there
                        row[key] = None
                        continue
                    row[key] = [a.min_nm, a.max_nm]
            static.append(row)
    rev = []
    if reversal:
        amp = math.radians(amplitude_deg)
        for m in masses:
            for q0, q1 in ((amp, -amp), (-amp, amp)):
                for fx_free in (False, True):
                    b = reversal_bound(cfg, q0, q1, m, v_max, a_max, fx_free, body_pitch_rad=th)
                    row = {"object_kg": m, "from_deg": math.degrees(q0), "to_deg": math.degrees(q1),
                           "fx_free": fx_free, "min_peak_pitch_deg": math.degrees(b.min_peak_pitch_rad),
                           "peak_reaction_nm": float(np.max(np.abs(b.disturbance_nm))),
                           "authority_nm": [float(np.min(b.authority_min_nm)), float(np.max(b.authority_max_nm))]}
                    if actuator is not None:
                        for key, delay in (("lag_preview_deg", None), ("lag_causal_deg", CAUSAL_DELAY_S)):
                            bl = reversal_bound(cfg, q0, q1, m, v_max, a_max, fx_free, actuator=actuator,
                                                causal_delay_s=delay, pre_s=LAG_PRE_S, body_pitch_rad=th)
                            row[key] = math.degrees(bl.min_peak_pitch_rad)
                    rev.append(row)
    return {"tail_max_thrust_n": tail_max_thrust_n(cfg), "body_pitch_deg": pitch_deg, "static": static,
            "reversal": rev}


def render_text(rep: dict[str, Any]) -> str:
    lines = [f"tail: +-{rep['tail_max_thrust_n']:.0f} N; body pitch {rep['body_pitch_deg']:g} deg",
             "static pure-moment authority at hover about the composite CoM, N m [min, max] (inner LP)",
             f"{'pose':>9} {'m_o':>4} | {'pitch, Fx held':>17} | {'pitch, Fx free':>17} | {'roll':>17}"]
    for r in rep["static"]:
        p, pf, ro = r["pitch"], r["pitch_fx_free"], r["roll"]
        if p is None or pf is None or ro is None:
            lines.append(f"{r['pose']:>9} {r['object_kg']:4.1f} | cannot hover (no trim inside the limits)")
            continue
        lines.append(f"{r['pose']:>9} {r['object_kg']:4.1f} | {p[0]:7.1f} {p[1]:8.1f} | {pf[0]:7.1f} {pf[1]:8.1f}"
                     f" | {ro[0]:7.1f} {ro[1]:8.1f}")
    if rep["reversal"]:
        lines.append("arm reversal: smallest peak pitch excursion any controller reaches (lower bound)")
        for r in rep["reversal"]:
            lag = ""
            if "lag_preview_deg" in r:
                lag = (f"; with the actuators' lag {r['lag_preview_deg']:6.2f} (preview)"
                       f" {r['lag_causal_deg']:6.2f} (causal)")
            lines.append(f"  m_o {r['object_kg']:.1f} kg {r['from_deg']:+.0f} -> {r['to_deg']:+.0f} deg"
                         f" Fx {'free' if r['fx_free'] else 'held'}: {r['min_peak_pitch_deg']:6.2f} deg"
                         f" (peak reaction {r['peak_reaction_nm']:.1f} N m){lag}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    from sim_bridge.params import PlantParams

    plant = PlantParams.load()
    ap = argparse.ArgumentParser(prog="navig8-authority", description=__doc__.split("\n\n")[0])
    ap.add_argument("--tail-max-thrust", type=float, default=None, metavar="N",
                    help="evaluate a tail of this maximum thrust (N) instead of params/vehicle.yaml's")
    ap.add_argument("--masses", default="0,1,2", help="object masses, kg, comma separated")
    ap.add_argument("--amplitude-deg", type=float, default=20.0, help="reversal amplitude (Eq. 26: 20 deg)")
    ap.add_argument("--pitch-deg", type=float, default=0.0,
                    help="hover with the body pitched (the paper's 45 deg phase); default level")
    ap.add_argument("--no-reversal", action="store_true", help="static authority only")
    ap.add_argument("--json", action="store_true", help="one JSON object instead of the table")
    ap.add_argument("--lag", action="store_true",
                    help="also the reversal bound with the actuators' second-order lag (preview and causal)")
    args = ap.parse_args(argv)
    cfg = VehicleConfig.load()
    if args.tail_max_thrust is not None:
        if not args.tail_max_thrust > 0.0:
            print("navig8-authority: --tail-max-thrust must be > 0", file=sys.stderr)
            return 2
        cfg = with_tail_thrust(cfg, args.tail_max_thrust)
    try:
        masses = [float(v) for v in args.masses.split(",")]
        act = (plant.speed_dynamics.omega_n_rad_s, plant.speed_dynamics.zeta) if args.lag else None
        rep = analyse(cfg, masses, not args.no_reversal, plant.joint_v_max_rad_s, plant.joint_a_max_rad_s2,
                      args.amplitude_deg, act, args.pitch_deg)
    except ValueError as e:
        print(f"navig8-authority: {e}", file=sys.stderr)
        return 2
    print(json.dumps(rep, allow_nan=False) if args.json else render_text(rep))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
