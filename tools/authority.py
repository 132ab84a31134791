"""navig8-authority: the actuator set's moment authority at hover, and the physical limit it puts on pitch while
the arm moves: during the paper's arm reversal, or during every move of a flown run (its log).

    navig8-authority [--tail-max-thrust N] [--masses 0,1,2] [--pitch-deg 45] [--lag] [--json] [--no-reversal]
    navig8-authority --log RUN.mcap [--scenario S] [--world NAME=VALUE ...] [--preview] [--json]

1. **Static authority.** For an arm pose q and object mass m_o, the largest pure pitch (roll) moment about the
   composite CoM that the real actuator set (duct speeds 0..w_max, duct tilts within their limits, reversible
   tail speed) can hold at hover: maximise M (L) over U subject to G_C(c) U = [L, M, N, Fx, Fz] with the other
   moments 0, Fz = -m g and Fx = 0 ("Fx held") or Fx free (the tilt lever: common duct tilt x the duct height
   below the CoM). With the body pitched by theta (`--pitch-deg`, the paper's 45 deg phase) the hover force in
   body axes is m g (sin theta, 0, -cos theta): "Fx held" then holds Fx = m g sin theta.
   Each duct's (U_cos, U_sin) = w^2 (cos a, sin a) lies in a disk sector of radius w_max^2 and
   the tilt range; a range wider than 180 deg is not convex, but it is the union of two half disks, so the
   optimum is the best of the 4 linear programs over the pieces of the two ducts (exact up to the inscribed
   polygon of the disk, whose solutions are all flyable). The pose enters only through the composite CoM c and
   the total mass (G_C(c) is affine in c), so `authority_at_coms` solves it at CoM points, all of them and all
   pieces in one block-diagonal LP.
2. **Reversal bound.** During the arm's reversal the arm's angular momentum relative to the composite CoM,
   h(q, q'), changes; about the CoM gravity has no moment, so d/dt (I_yy(q) theta' + h) = M_act. With
   |M_act| inside the static authority of the current pose, the smallest peak |theta| any controller can
   reach is a linear program over the moment history (`min_pitch_excursion`: exact momentum under a held
   moment, trapezoid for theta, ending at rest; sparse, so a window of many seconds is cheap). It ignores the
   actuator lag, the noise and the hover-force coupling of a tilted body, so it is a lower bound: no controller
   flying this actuator set can do better. `reversal_bound` is `window_bound` on the plant's servo profile.
3. **With the actuators' lag** (`--lag`). The same LP with the delivered moment the commanded moment history
   through the actuators' second-order response (omega_n, zeta of params/plant.yaml: 120 rad/s, 1), the command
   inside the static authority (zeta = 1 does not overshoot, so the delivered moment stays inside it too), in two
   variants: *preview* (the command may start before the reaction: the controller knows the arm's plan) and
   *causal* (the command stays at trim until one control tick after the reaction starts: a controller that
   sees the reaction only when it happens). The moment is a nonlinear function of the actuator states (thrust
   ~ w|w|, the tail reversing through zero speed has none), so the linear lag of the moment is a model, not an
   exact bound; the numbers say how much of the flown error the lag alone explains.
4. **Authority bound of a flown run** (`bound_from_log`, `--log`). The run's log gives q(t), q'(t), m_o(t) and
   the commanded pitch; the run is split into the arm's moves (windows where h changes) and 2.-3. run on each,
   with the static authority along the window from `AuthorityMap` (the LP on a lattice of CoM points, bilinear
   in between: conservative, see there); the bound of the run is the worst window's. Docstring of
   `bound_from_log` for what each number means and where it is not a strict bound.

Everything is the model of navig8_fc.core.vehicle (the same G_C and mass properties the controller uses) and the
plant's joint servo (sim_bridge._kernels._servo_accel). See docs/model.md ("Pitch authority", "Authority bound of
a flown run").
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import hashlib
import itertools
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import sparse
from scipy.linalg import expm
from scipy.optimize import linprog

from navig8_fc.core import g_c
from navig8_fc.core.vehicle import N_LINKS, VehicleConfig, mass_properties, model_geometry, propulsion_per_input

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


@functools.lru_cache(maxsize=64)
def _duct_constraints(cfg: VehicleConfig, pieces: tuple[tuple[float, float], ...], n: int,
                      outer: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """A_ub U <= b_ub: each duct's (U_cos, U_sin) in the inscribed n-gon of its speed disk (outer: the
    circumscribed one, a relaxation) and in one convex piece of its tilt sector (two half-planes through the
    origin)."""
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
            rhs.append(r2 if outer else r2 * math.cos(math.pi / n))
        # angle >= a_lo: cross(dir(a_lo), U) >= 0; angle <= a_hi: cross(U, dir(a_hi)) >= 0
        for ang, sgn in ((a_lo, 1.0), (a_hi, -1.0)):
            a = np.zeros(5)
            a[ic], a[is_] = sgn * math.sin(ang), -sgn * math.cos(ang)
            rows.append(a)
            rhs.append(0.0)
    a_ub, b_ub = np.array(rows), np.array(rhs)
    a_ub.setflags(write=False)
    b_ub.setflags(write=False)
    return a_ub, b_ub


@functools.lru_cache(maxsize=64)
def _propulsion(cfg: VehicleConfig) -> tuple[np.ndarray, np.ndarray]:
    return propulsion_per_input(cfg)


_Block = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # c, A_ub, b_ub, A_eq, b_eq


def _solve_blocks(blocks: list[_Block], bounds: list[tuple[float | None, float | None]]) -> list[np.ndarray | None]:
    """Independent LPs of the same size, solved as one block-diagonal LP (one solver call: the per-call overhead
    is most of a small LP's time); if that fails (one block infeasible), halves are solved apart. None for an
    infeasible block."""
    if not blocks:
        return []
    nv = len(bounds)
    res = linprog(np.concatenate([b[0] for b in blocks]),
                  A_ub=sparse.block_diag([b[1] for b in blocks], format="csr"),
                  b_ub=np.concatenate([b[2] for b in blocks]),
                  A_eq=sparse.block_diag([b[3] for b in blocks], format="csr"),
                  b_eq=np.concatenate([b[4] for b in blocks]), bounds=bounds * len(blocks), method="highs")
    if res.status == 0:
        return list(np.asarray(res.x).reshape(len(blocks), nv))
    if len(blocks) > 1:
        mid = len(blocks) // 2
        return _solve_blocks(blocks[:mid], bounds) + _solve_blocks(blocks[mid:], bounds)
    if res.status == 2:
        return [None]
    raise ValueError(f"authority LP failed: {res.message}")


def authority_at_coms(cfg: VehicleConfig, coms_xz_m: np.ndarray, mass_kg: float, axis: str = "pitch",
                      fx_free: bool = False, sides: int = POLYGON_SIDES, body_pitch_rad: float = 0.0,
                      outer: bool = False) -> list[Authority | None]:
    """`hover_authority` at composite CoM points (k x 2: x, z in FRD, m) of a vehicle of total mass mass_kg: the
    pose enters the LP only through them. None where the actuator set cannot hold the hover force at all.
    outer: the speed disk as its circumscribed polygon (a relaxation: the moments are upper bounds on what is
    flyable, at most 1/cos(pi/n) - 1 beyond; the U are then not all flyable)."""
    row = ROWS[axis]
    fixed = [r for r in range(5) if r != row and not (fx_free and r == 3)]
    target = np.zeros(5)
    target[3] = mass_kg * cfg.gravity_m_s2 * math.sin(body_pitch_rad)
    target[4] = -mass_kg * cfg.gravity_m_s2 * math.cos(body_pitch_rad)
    u5 = (math.copysign(cfg.tail_speed_min**2, cfg.tail_speed_min),
          math.copysign(cfg.tail_speed_max**2, cfg.tail_speed_max))
    bounds: list[tuple[float | None, float | None]] = [(None, None)] * 4 + [u5]
    cons = [_duct_constraints(cfg, combo, sides, outer)
            for combo in itertools.product(tuple(_tilt_pieces(cfg)), repeat=2)]
    blocks: list[_Block] = []
    owner: list[tuple[int, float, np.ndarray]] = []
    f, m0 = _propulsion(cfg)
    for i, (cx, cz) in enumerate(np.asarray(coms_xz_m, dtype=float).reshape(-1, 2)):
        gc = np.empty((5, 5))
        g_c.gc_about(f, m0, float(cx), float(cz), gc)  # control_effectiveness_gc with the per-input wrench kept
        for a_ub, b_ub in cons:
            for sgn in (1.0, -1.0):
                blocks.append((-sgn * gc[row], a_ub, b_ub, gc[fixed], target[fixed]))
                owner.append((i, sgn, gc[row]))
    best: list[dict[float, tuple[float, np.ndarray]]] = [{} for _ in range(len(blocks) // (2 * len(cons)))]
    for (i, sgn, g), x in zip(owner, _solve_blocks(blocks, bounds), strict=True):
        if x is None:  # infeasible with this pair of pieces
            continue
        val = float(g @ x)
        if sgn not in best[i] or sgn * val > sgn * best[i][sgn][0]:
            best[i][sgn] = (val, x)
    return [Authority(b[1.0][0], b[-1.0][0], b[1.0][1], b[-1.0][1]) if b else None for b in best]


def hover_authority(cfg: VehicleConfig, q_rad: Sequence[float], object_mass_kg: float, axis: str = "pitch",
                    fx_free: bool = False, sides: int = POLYGON_SIDES, body_pitch_rad: float = 0.0) -> Authority:
    """Largest/smallest pure moment about the composite CoM the actuator set holds at hover, the body pitched by
    body_pitch_rad (0: level): the actuators hold -m g_body = m g (sin theta, 0, -cos theta) in FRD.

    Raises ValueError if the actuator set cannot even trim there."""
    mp = mass_properties(cfg, q_rad, object_mass_kg)
    (a,) = authority_at_coms(cfg, np.array([[mp.com_frd_m[0], mp.com_frd_m[2]]]), mp.mass_kg, axis, fx_free, sides,
                             body_pitch_rad)
    if a is None:
        raise ValueError(f"hover is infeasible at q = {list(q_rad)}, m_o = {object_mass_kg}")
    return a


# --------------------------------------------------------------------------------------
# The static authority along a path of the CoM
# --------------------------------------------------------------------------------------

MAP_SPACING_M = 0.05  # lattice of CoM points of AuthorityMap (the paper reversal's bounds within 0.01 deg of 1 cm's)
MAP_SIDES = 64  # its speed disk: the circumscribed 64-gon (at most 1.2e-3 beyond the circle)
TRIM_TOL_NM = 1e-6
EXCURSION_LP_METHOD = "highs"  # HiGHS' own choice: on this sparse banded LP 2x faster than dual simplex or IPM forced


class AuthorityMap:
    """The static pitch authority [min, max] (N m about the composite CoM) at one total mass and body pitch, as a
    function of the CoM (x, z): the LP (`authority_at_coms`, the disk as its circumscribed polygon) at the nodes of
    a square lattice of CoM points, each solved when first needed and kept, and bilinear in between.

    Why that is conservative (never narrower than the LP at the point itself): about the CoM c the pitch moment
    is M_O - c_z Fx + c_x Fz, affine in c for each U, and the constraints depend on c only through the dihedral's
    side force in the roll and yaw rows (L = L_O + c_z Fy, N = N_O - c_x Fy). Without that coupling the set of U is
    the same for every c, so max M(c) is a maximum of affine functions of c, convex, and min M(c) concave; a
    bilinear interpolant is a convex combination of the cell's corners that reproduces c itself, so by Jensen it
    lies above a convex function and below a concave one. The 10 deg dihedral makes it approximate: against the
    LP at random CoM points (tests/unit/test_authority.py) the interpolant is never narrower by more than ~2e-4
    N m, and it is exact (to that) with Fx held, where the authority is affine in c; with Fx free it is wider by
    up to ~0.4 N m near the LP's kinks at the default 5 cm lattice. A node where hover is infeasible
    makes its cells fall back to the LP at the point (CoM rounded to 1 mm); NaN there if that is infeasible too."""

    def __init__(self, cfg: VehicleConfig, mass_kg: float, body_pitch_rad: float, fx_free: bool,
                 spacing_m: float = MAP_SPACING_M, sides: int = MAP_SIDES) -> None:
        self.cfg, self.mass_kg, self.body_pitch_rad, self.fx_free = cfg, mass_kg, body_pitch_rad, fx_free
        self.spacing_m, self.sides = spacing_m, sides
        self._nodes: dict[tuple[int, int], tuple[float, float]] = {}
        self._points: dict[tuple[int, int], tuple[float, float]] = {}
        self.lp_points = 0  # how many CoM points were solved (for the timing report)

    def _solve(self, keys: list[tuple[int, int]], scale: float,
               store: dict[tuple[int, int], tuple[float, float]]) -> None:
        missing = sorted({k for k in keys if k not in store})
        if not missing:
            return
        res = authority_at_coms(self.cfg, np.array(missing, dtype=float) * scale, self.mass_kg, "pitch",
                                self.fx_free, self.sides, self.body_pitch_rad, outer=True)
        self.lp_points += len(missing)
        for k, a in zip(missing, res, strict=True):
            store[k] = (math.nan, math.nan) if a is None else (a.min_nm, a.max_nm)

    def bounds(self, com_x_m: np.ndarray, com_z_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """[min, max] at each CoM point (1-d arrays)."""
        gx = np.ravel(np.asarray(com_x_m, dtype=float)) / self.spacing_m
        gz = np.ravel(np.asarray(com_z_m, dtype=float)) / self.spacing_m
        ix, iz = np.floor(gx).astype(np.int64), np.floor(gz).astype(np.int64)
        fx, fz = gx - ix, gz - iz
        cells, inv = np.unique(np.column_stack([ix, iz]), axis=0, return_inverse=True)
        inv = inv.ravel()
        offsets = ((0, 0), (1, 0), (0, 1), (1, 1))
        self._solve([(int(a) + dx, int(b) + dz) for a, b in cells for dx, dz in offsets], self.spacing_m,
                    self._nodes)
        corner = np.array([[self._nodes[(int(a) + dx, int(b) + dz)] for dx, dz in offsets] for a, b in cells])
        weights = np.column_stack([(1 - fx) * (1 - fz), fx * (1 - fz), (1 - fx) * fz, fx * fz])
        lo = np.sum(weights * corner[inv, :, 0], axis=1)
        hi = np.sum(weights * corner[inv, :, 1], axis=1)
        bad = np.flatnonzero(~(np.isfinite(lo) & np.isfinite(hi)))
        if bad.size:  # a corner cannot hover: the LP at the point itself
            pts = [(round(float(x) * 1000.0), round(float(z) * 1000.0))
                   for x, z in zip(np.ravel(com_x_m)[bad], np.ravel(com_z_m)[bad], strict=True)]
            self._solve(pts, 1e-3, self._points)
            lo[bad] = [self._points[p][0] for p in pts]
            hi[bad] = [self._points[p][1] for p in pts]
        return lo, hi


_MAPS: dict[tuple[Any, ...], AuthorityMap] = {}
_WINDOWS: dict[tuple[Any, ...], tuple[float, float | None]] = {}  # bound_from_log's windows: (peak, untrimmable)


def authority_map(cfg: VehicleConfig, mass_kg: float, body_pitch_rad: float, fx_free: bool,
                  spacing_m: float = MAP_SPACING_M) -> AuthorityMap:
    """The AuthorityMap of (vehicle, total mass, body pitch, Fx held/free), kept for the process (a campaign worker
    reuses it across runs of the same vehicle, mass and pitch)."""
    key = (cfg, round(mass_kg, 6), round(body_pitch_rad, 6), fx_free, spacing_m)
    m = _MAPS.get(key)
    if m is None:
        if len(_MAPS) >= 256:
            _MAPS.clear()
        m = _MAPS[key] = AuthorityMap(cfg, round(mass_kg, 6), round(body_pitch_rad, 6), fx_free, spacing_m)
    return m


# --------------------------------------------------------------------------------------
# The arm's motion and its reaction
# --------------------------------------------------------------------------------------

SERVO_STEP_S = 0.001  # the plant's joint-servo period (params/plant.yaml servo_rate_hz = 1000)


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
class ArmMotion:
    """The arm's motion on a time grid (s), the object held (kg) and the commanded body pitch (rad) per sample."""

    t_s: np.ndarray
    q_rad: np.ndarray  # (n, 3)
    qd_rad_s: np.ndarray  # (n, 3)
    object_mass_kg: np.ndarray  # (n,)
    body_pitch_rad: np.ndarray  # (n,)


def _mass_terms(cfg: VehicleConfig, q: np.ndarray, object_mass_kg: np.ndarray) -> np.ndarray:
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
    mt = _mass_terms(cfg, q, mo)
    h = _momentum(cfg, q, qd, mo)
    iyy_end, h_end = mt[1:, 0].copy(), h[1:].copy()
    chg = np.flatnonzero(mo[1:] != mo[:-1])
    if chg.size:
        iyy_end[chg] = _mass_terms(cfg, q[chg + 1], mo[chg])[:, 0]
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
    nz = 0 if actuator is None else 2
    iu, iw, ith, i_s, iz = 0, ns, ns + n, ns + 2 * n, ns + 2 * n + 1
    nv = iz + nz * n
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
                             shape=((2 + nz) * ns, nv))
    # -s <= theta_k <= s
    kk = np.arange(n)
    a_ub = sparse.csr_matrix((np.concatenate([np.ones(n), -np.ones(n), -np.ones(n), -np.ones(n)]),
                              (np.concatenate([kk, kk, n + kk, n + kk]),
                               np.concatenate([ith + kk, np.full(n, i_s), ith + kk, np.full(n, i_s)]))),
                             shape=(2 * n, nv))
    lb, ub = np.full(nv, -np.inf), np.full(nv, np.inf)
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
    cost = np.zeros(nv)
    cost[i_s] = 1.0
    for method in dict.fromkeys((EXCURSION_LP_METHOD, "highs-ipm", "highs-ds")):
        # a simplex can stop on numerical trouble here (seen once in the reversals) or stall on a degenerate piece
        # whose optimum is ~0 (a slow sweep; it normally takes < 0.2 s): interior point then solves it
        opts = {} if method == "highs-ipm" else {"time_limit": 0.5 + 2e-4 * nv}
        res = linprog(cost, A_ub=a_ub, b_ub=np.zeros(2 * n), A_eq=a_eq, b_eq=np.concatenate(b_eq),
                      bounds=np.column_stack([lb, ub]), method=method, options=opts)
        if res.status in (0, 2):
            break
    if res.status != 0:
        raise ValueError(f"the excursion LP failed: {res.message}")
    x = np.asarray(res.x)
    return float(x[i_s]), x[ith:ith + n].copy(), x[iu:iu + ns].copy()


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


# --------------------------------------------------------------------------------------
# The bound of a flown run
# --------------------------------------------------------------------------------------

LAG_PRE_S = 0.2  # how early a preview may start commanding before the reversal (longer than the actuators' lag)
CAUSAL_DELAY_S = 0.01  # one control tick at 100 Hz: the first tick that can see the reaction
RATE_EPS_RAD_S = 1e-6  # a joint faster than this is moving (the plant's servo holds exactly still)
SETTLE_S = 0.5  # a window ends at rest this long after the arm stops (the bound of the paper's reversal is the same
# with 1 s to 1e-3 deg)
MIN_SETTLE_S = 0.2  # a window may end this soon after the arm stops when the next move follows
CHUNK_S, CHUNK_OVERLAP_S = 1.5, 0.5  # a longer window is bounded in pieces this long, overlapping this much
LONG_DT_S = 0.01  # and on this grid (the log's): the paper reversal's bounds 0.1-0.3 deg lower than on 2 ms


def moment_lag(plant: Any) -> tuple[float, float]:
    """(omega_n, zeta) of the actuators' response that the moment lag models (PlantParams): the faster of the duct
    tilt and the propeller speed dynamics (the pitch moment has parts from both; the faster keeps the bound low)."""
    return max((plant.tilt_dynamics.omega_n_rad_s, plant.tilt_dynamics.zeta),
               (plant.speed_dynamics.omega_n_rad_s, plant.speed_dynamics.zeta))


def arm_windows(t_s: np.ndarray, qd_rad_s: np.ndarray, pre_s: float = LAG_PRE_S, settle_s: float = SETTLE_S,
                min_settle_s: float = MIN_SETTLE_S, rate_eps: float = RATE_EPS_RAD_S) -> list[dict[str, Any]]:
    """The arm's moves: runs of samples with a joint moving (h changes only then: it is linear in q'), each from the
    last sample at rest before it (its onset) to the first at rest after it (its stop). A window runs from pre_s
    before its onset to settle_s after its stop, cut short pre_s before the next onset when the arm rests at least
    min_settle_s between (the next window starts there, at rest); moves closer than that share one window, which
    keeps its first onset ("moves" counts them)."""
    t = np.asarray(t_s, dtype=float)
    moving = np.any(np.abs(np.nan_to_num(qd_rad_s)) > rate_eps, axis=1)
    idx = np.flatnonzero(moving)
    if idx.size == 0:
        return []
    cut = np.flatnonzero(np.diff(idx) > 1)
    first, last = idx[np.r_[0, cut + 1]], idx[np.r_[cut, idx.size - 1]]
    out: list[dict[str, Any]] = []
    for a, b in zip(first, last, strict=True):
        onset, stop = float(t[max(a - 1, 0)]), float(t[min(b + 1, len(t) - 1)])
        start = max(onset - pre_s, float(t[0]))
        if out and start < out[-1]["t_stop_s"] + min_settle_s:
            out[-1]["t_stop_s"] = stop
            out[-1]["moves"] += 1
            continue
        out.append({"t_start_s": start, "t_onset_s": onset, "t_stop_s": stop, "moves": 1})
    for i, w in enumerate(out):
        nxt = out[i + 1]["t_start_s"] if i + 1 < len(out) else math.inf
        w["t_end_s"] = min(w["t_stop_s"] + settle_s, nxt, float(t[-1]))
    return out


def _resample(t_log: np.ndarray, q: np.ndarray, qd: np.ndarray, t_grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """q, q' at t_grid: cubic Hermite through the logged (q, q') (the servo's rest stays exactly at rest)."""
    from scipy.interpolate import CubicHermiteSpline

    sp = CubicHermiteSpline(t_log, q, qd, axis=0)
    return sp(t_grid), sp(t_grid, 1)


def bound_from_log(run_log: Any, vehicle_cfg: VehicleConfig, plant: Any = None, *,
                   actuator: tuple[float, float] | None = None, dt_s: float = 0.005, pre_s: float = LAG_PRE_S,
                   settle_s: float = SETTLE_S, causal_delay_s: float = CAUSAL_DELAY_S, preview: bool = False,
                   spacing_m: float = MAP_SPACING_M) -> dict[str, Any]:
    """What physics allows on a flown run: the smallest peak pitch excursion any controller could reach on the
    arm's moves of this run, with this (true) vehicle's actuators.

    run_log: as `navig8_tools.logdata.load_run` returns it (anything with `topics` and `[topic]` giving Series with
    `t` and `field(name, width)`); read: /truth joint_pos_rad, joint_rate_rad_s, object_mass_kg and, when the log
    has no /fc/setpoint, euler_rad; /fc/setpoint pitch_rad (the commanded pitch). vehicle_cfg: the TRUE vehicle
    (`sim_bridge.world.load_world(...).vehicle`). plant: its PlantParams (`.plant`), for the actuators'
    omega_n/zeta (`moment_lag`: the faster of tilt and speed dynamics); actuator = (omega_n, zeta) overrides it;
    neither: params/plant.yaml.

    Method: the run is split into the arm's moves (`arm_windows`: where h changes, pre_s before and settle_s after);
    each window is resampled every dt_s (cubic Hermite through the logged q, q'; the object and the commanded
    pitch held from the last sample) and `window_bound` gives its smallest peak |theta - theta_start|, starting at
    rest at trim (theta = theta' = 0) and ending at rest, in these variants (degrees):

    - lag_free_fx_held / lag_free_fx_free: no actuator lag, the command free from the move's onset;
    - causal_fx_held / causal_fx_free: with the actuators' second-order lag, the command at trim until
      causal_delay_s (one control tick) after the onset;
    - preview_fx_held / preview_fx_free (preview=True): with the lag, the command free from pre_s before the onset.

    bound_deg = causal_fx_free, the worst window's: what a controller that sees the reaction when it happens (no
    plan of the arm's motion) could do at best with these actuators, giving up forward force (the tilt lever) for
    pitch, which is what it must do to hold attitude. It is the number to set against a flown attitude error: the
    lag-free numbers ignore the ~10 ms the actuators need, which any loop pays (docs/model.md: 7-10 deg on the
    paper's reversal), and F_x held throws away a lever any controller may use, so they would call avoidable
    losses unavoidable (lag-free) or unavoidable ones avoidable (held).

    Where it is not a strict bound: (1) the lag is linear in the moment while the thrust is ~ w|w| (a duct's
    thrust cut is faster, the tail's reversal through zero slower), and F_z is held at m g exactly while a real
    allocation may trade it for pitch for a few ticks; so the causal numbers are a model of the lag (the flown
    paper reversals have beaten the level causal F_x-free number by a few degrees); (2) the authority between
    lattice nodes relies on its convexity in the CoM, exact without the dihedral's side force (AuthorityMap);
    (3) each window starts at rest at the commanded attitude (a vehicle still swinging from an earlier move is
    not modelled: moves resting less than pre_s + MIN_SETTLE_S apart share one window instead, inside which the
    LP knows the later moves in advance, so its bound is lower, still a lower bound) and ends at rest settle_s
    after the arm stops (unless the log ends first, or the next window starts); a window longer than CHUNK_S
    (continuous motion) is bounded on the log's 10 ms grid in overlapping pieces, the first from rest, the later
    ones with their state free (a relaxation: each piece's number is at most the whole window's LP), because the
    LP's cost grows faster than its length; (4) a commanded pitch step during a move changes the
    authority but is not itself a demand on it; the excursion is the arm's, about the commanded attitude.

    Returns a dict: bound_deg (math.inf when trim_feasible is False), trim_feasible (False when at some pose,
    object and commanded pitch flown the actuator set cannot hold the hover wrench with F_x held: no moment
    range containing 0), untrimmable_t_s (the first such time, else None), worst_t_s (the onset of the worst
    window; the first untrimmable time when there is one; the log's start when the arm never moves), the
    variants' worst over windows (*_deg), windows (one dict per window: times, moves, object and pitch, peak
    reaction, the variants), actuator, tail_max_thrust_n, pitch_source, dt_s, lp_points (static LP points solved
    for it: the maps are kept per process), compute_s (wall) and cpu_s (this process's CPU time).
    """
    t0, c0 = time.perf_counter(), time.process_time()
    if actuator is None:
        if plant is None:
            from sim_bridge.params import PlantParams

            plant = PlantParams.load()
        actuator = moment_lag(plant)
    tr = run_log["/truth"]
    t = np.asarray(tr.t, dtype=float)
    q = tr.field("joint_pos_rad", N_LINKS)
    qd = tr.field("joint_rate_rad_s", N_LINKS)
    mo = np.nan_to_num(tr.field("object_mass_kg"))
    if "/fc/setpoint" in run_log.topics and len(run_log["/fc/setpoint"].t):
        sp = run_log["/fc/setpoint"]
        idx = np.clip(np.searchsorted(sp.t, t, side="right") - 1, 0, len(sp.t) - 1)
        pitch = np.radians(np.round(np.degrees(np.nan_to_num(sp.field("pitch_rad"))[idx]), 3))  # map keys
        pitch_source = "/fc/setpoint"
    else:
        pitch = np.round(np.nan_to_num(tr.field("euler_rad", 3)[:, 1]) / math.radians(1.0)) * math.radians(1.0)
        pitch_source = "/truth euler (flown, to 1 deg)"
    ok = np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(qd), axis=1)
    t, q, qd, mo, pitch = t[ok], q[ok], qd[ok], mo[ok], pitch[ok]
    maps_before = {k: m.lp_points for k, m in _MAPS.items()}

    # trim: every sample flown, F_x held
    every = ArmMotion(t, q, qd, mo, pitch)
    mt = _mass_terms(vehicle_cfg, q, mo)
    terms = {"com_x": mt[:, 1], "com_z": mt[:, 2], "mass": mt[:, 3]}
    lo, hi = authority_along(vehicle_cfg, every, terms, False, spacing_m)
    bad = ~((lo <= TRIM_TOL_NM) & (hi >= -TRIM_TOL_NM))
    untrimmable = float(t[np.argmax(bad)]) if np.any(bad) else None

    variants = [("lag_free", None, "onset"), ("causal", actuator, "causal")]
    if preview:
        variants.append(("preview", actuator, "start"))
    windows = arm_windows(t, qd, pre_s, settle_s)
    for w in windows:
        # a window of continuous motion longer than one piece on a coarser grid (its LPs grow faster than n)
        dt_w = dt_s if w["t_end_s"] - w["t_start_s"] <= CHUNK_S else max(dt_s, LONG_DT_S)
        n = int(math.floor((w["t_end_s"] - w["t_start_s"]) / dt_w + 1e-9)) + 1
        tg = w["t_start_s"] + dt_w * np.arange(n)
        i0 = max(int(np.searchsorted(t, w["t_start_s"], side="right")) - 1, 0)
        i1 = min(int(np.searchsorted(t, w["t_end_s"], side="left")) + 1, len(t))
        qg, qdg = _resample(t[i0:i1], q[i0:i1], qd[i0:i1], tg)
        j = np.clip(np.searchsorted(t, tg + 1e-9, side="right") - 1, 0, len(t) - 1)
        motion = ArmMotion(tg, qg, qdg, mo[j], pitch[j])
        onset = int(np.searchsorted(tg, w["t_onset_s"] - 1e-9))
        hold = {"onset": onset, "causal": onset + int(round(causal_delay_s / dt_w)), "start": 0}
        end_at_rest = w["t_end_s"] - w["t_stop_s"] >= min(settle_s, MIN_SETTLE_S) - 1e-9  # else the log ends first
        w.update({"object_kg": [float(np.min(mo[j])), float(np.max(mo[j]))],
                  "pitch_cmd_deg": [math.degrees(float(np.min(pitch[j]))), math.degrees(float(np.max(pitch[j])))],
                  "end_at_rest": bool(end_at_rest)})
        terms = motion_terms(vehicle_cfg, motion)
        w["peak_reaction_nm"] = float(np.max(np.abs(np.gradient(terms["h"], tg))))
        # a long window (continuous motion) in overlapping pieces, each after the first with its state free
        step, span = int(round((CHUNK_S - CHUNK_OVERLAP_S) / dt_w)), int(round(CHUNK_S / dt_w))
        starts = [0]
        while starts[-1] + span < n - 1:
            starts.append(starts[-1] + step)
        pieces = [(k, min(k + span + 1, n)) for k in starts]
        w["pieces"], w["dt_s"] = len(pieces), dt_w
        for name, act, when in variants:
            for fx_free in (False, True):
                worst = 0.0
                for k_a, k_b in pieces:
                    last = k_b == n
                    sl = slice(k_a, k_b)
                    piece = ArmMotion(tg[sl], qg[sl], qdg[sl], mo[j][sl], pitch[j][sl])
                    p_terms = {key: v[k_a:k_b] if len(v) == n else v[k_a:k_b - 1] for key, v in terms.items()}
                    flags = (hold[when] if k_a == 0 else 0, end_at_rest and last, k_a > 0)
                    digest = hashlib.sha1(b"".join(np.ascontiguousarray(np.round(x, 9)).tobytes() for x in (
                        piece.q_rad, piece.qd_rad_s, piece.object_mass_kg, piece.body_pitch_rad,
                        piece.t_s - piece.t_s[0]))).hexdigest()
                    key = (vehicle_cfg, act, flags, spacing_m, fx_free, digest)
                    if key not in _WINDOWS:  # a repeated move (a square wave's) is solved once
                        if len(_WINDOWS) >= 4096:
                            _WINDOWS.clear()
                        b = window_bound(vehicle_cfg, piece, fx_free, act, flags[0], flags[1], spacing_m, p_terms,
                                         flags[2])
                        u_t = None if b.untrimmable_t_s is None else b.untrimmable_t_s - float(piece.t_s[0])
                        _WINDOWS[key] = (b.min_peak_pitch_rad, u_t)
                    peak, u_t = _WINDOWS[key]
                    worst = max(worst, peak)
                    if u_t is not None and (untrimmable is None or u_t + float(piece.t_s[0]) < untrimmable):
                        untrimmable = u_t + float(piece.t_s[0])
                w[f"{name}_fx_{'free' if fx_free else 'held'}_deg"] = math.degrees(worst)
    keys = [f"{name}_fx_{fx}_deg" for name, _, _ in variants for fx in ("held", "free")]
    out: dict[str, Any] = {k: max((w[k] for w in windows), default=0.0) for k in keys}
    trim_ok = untrimmable is None
    if windows:
        worst = max(windows, key=lambda w: w["causal_fx_free_deg"])
        worst_t = worst["t_onset_s"]
    else:
        worst_t = float(t[0]) if len(t) else 0.0
    out.update({
        "bound_deg": out["causal_fx_free_deg"] if trim_ok else math.inf,
        "trim_feasible": trim_ok,
        "untrimmable_t_s": untrimmable,
        "worst_t_s": float(worst_t if trim_ok else untrimmable),
        "windows": windows,
        "actuator": {"omega_n_rad_s": float(actuator[0]), "zeta": float(actuator[1])},
        "tail_max_thrust_n": tail_max_thrust_n(vehicle_cfg),
        "pitch_source": pitch_source,
        "dt_s": dt_s,
        "lp_points": sum(m.lp_points - maps_before.get(k, 0) for k, m in _MAPS.items()),
        "compute_s": time.perf_counter() - t0,
        "cpu_s": time.process_time() - c0,
    })
    return out


# --------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------

POSES_DEG = {"q=0": (0.0, 0.0, 0.0), "+20x3": (20.0, 20.0, 20.0), "-20x3": (-20.0, -20.0, -20.0),
             "80/10/10": (80.0, 10.0, 10.0), "60/60/60": (60.0, 60.0, 60.0)}


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
                           "fx_free": fx_free, "min_peak_pitch_deg": _finite(math.degrees(b.min_peak_pitch_rad)),
                           "peak_reaction_nm": float(np.max(np.abs(b.disturbance_nm))),
                           "authority_nm": [float(np.min(b.authority_min_nm)), float(np.max(b.authority_max_nm))]}
                    if actuator is not None:
                        for key, delay in (("lag_preview_deg", None), ("lag_causal_deg", CAUSAL_DELAY_S)):
                            bl = reversal_bound(cfg, q0, q1, m, v_max, a_max, fx_free, actuator=actuator,
                                                causal_delay_s=delay, pre_s=LAG_PRE_S, body_pitch_rad=th)
                            row[key] = _finite(math.degrees(bl.min_peak_pitch_rad))
                    rev.append(row)
    return {"tail_max_thrust_n": tail_max_thrust_n(cfg), "body_pitch_deg": pitch_deg, "static": static,
            "reversal": rev}


def _finite(v: float) -> float | None:
    return v if math.isfinite(v) else None


def _deg(v: float | None) -> str:
    return "  untrimmable" if v is None or not math.isfinite(v) else f"{v:6.2f}"


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
                lag = (f"; with the actuators' lag {_deg(r['lag_preview_deg'])} (preview)"
                       f" {_deg(r['lag_causal_deg'])} (causal)")
            lines.append(f"  m_o {r['object_kg']:.1f} kg {r['from_deg']:+.0f} -> {r['to_deg']:+.0f} deg"
                         f" Fx {'free' if r['fx_free'] else 'held'}: {_deg(r['min_peak_pitch_deg'])} deg"
                         f" (peak reaction {r['peak_reaction_nm']:.1f} N m){lag}")
    return "\n".join(lines)


def render_log_text(rep: dict[str, Any]) -> str:
    act = rep["actuator"]
    lines = [f"{rep['log']}: scenario {rep['scenario']}, world {rep['world'] or '{}'}",
             f"tail +-{rep['tail_max_thrust_n']:.0f} N; moment lag omega_n {act['omega_n_rad_s']:g} rad/s, zeta"
             f" {act['zeta']:g}; commanded pitch from {rep['pitch_source']}"]
    if rep["trim_feasible"]:
        lines.append("trim: the actuator set holds the hover at every pose, object and commanded pitch flown")
    else:
        lines.append(f"trim: NOT feasible from {rep['untrimmable_t_s']:.2f} s (no controller can hold this hover)")
    lines.append(f"bound (causal with the actuators' lag, F_x free): {_deg(rep['bound_deg'])} deg,"
                 f" worst at {rep['worst_t_s']:.2f} s")
    pv = "preview_fx_free_deg" in rep
    head = (f"{'onset s':>8} {'stop s':>7} {'moves':>5} {'m_o kg':>9} {'pitch':>7} {'react Nm':>8} |"
            f" {'lag-free held':>13} {'free':>6} | {'causal held':>11} {'free':>6}")
    lines += ["windows (smallest peak |pitch excursion|, deg):", head + (" | preview held   free" if pv else "")]
    for w in rep["windows"]:
        mo = w["object_kg"]
        line = (f"{w['t_onset_s']:8.2f} {w['t_stop_s']:7.2f} {w['moves']:5d} {mo[0]:4.2f}-{mo[1]:<4.2f}"
                f" {w['pitch_cmd_deg'][1]:7.1f} {w['peak_reaction_nm']:8.1f} | {_deg(w['lag_free_fx_held_deg']):>13}"
                f" {_deg(w['lag_free_fx_free_deg'])} | {_deg(w['causal_fx_held_deg']):>11}"
                f" {_deg(w['causal_fx_free_deg'])}")
        if pv:
            line += f" | {_deg(w['preview_fx_held_deg']):>12} {_deg(w['preview_fx_free_deg'])}"
        lines.append(line)
    lines.append(f"({rep['lp_points']} static LP points, {rep['compute_s']:.2f} s wall, {rep['cpu_s']:.2f} s CPU)")
    return "\n".join(lines)


def _jsonable(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_jsonable(x) for x in v]
    return v


def log_main(args: argparse.Namespace) -> int:
    """--log: the bound of one flown run, in the world it flew (the log's metadata; --scenario/--world on top)."""
    from navig8_tools.logdata import load_run
    from sim_bridge.world import load_world, parse_world_items

    run = load_run(args.log, topics=["/truth", "/fc/setpoint"])
    meta = run.metadata.get("run", {})
    scenario = args.scenario or meta.get("scenario") or "paper"
    world = {str(k): float(v) for k, v in (meta.get("world") or {}).items()}
    world.update(parse_world_items(args.world))
    w = load_world(scenario, world)
    rep = bound_from_log(run, w.vehicle, w.plant, preview=args.preview)
    rep.update({"log": str(args.log), "scenario": scenario, "world": world})
    print(json.dumps(_jsonable(rep), allow_nan=False) if args.json else render_log_text(rep))
    return 0


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
    ap.add_argument("--log", default=None, metavar="RUN.mcap",
                    help="the authority bound of a flown run instead (bound_from_log), in the world of the log's"
                         " metadata (navig8-sim records it) with --scenario/--world on top")
    ap.add_argument("--scenario", default=None, help="with --log: the run's scenario (default: the log's, or paper)")
    ap.add_argument("--world", action="append", default=[], metavar="NAME=VALUE",
                    help="with --log: a world override the run flew with (sim_bridge/world.py names)")
    ap.add_argument("--preview", action="store_true", help="with --log: also the preview variants")
    args = ap.parse_args(argv)
    if args.log is not None:
        try:
            return log_main(args)
        except (ValueError, KeyError, OSError) as e:
            print(f"navig8-authority: {e}", file=sys.stderr)
            return 2
    cfg = VehicleConfig.load()
    if args.tail_max_thrust is not None:
        if not args.tail_max_thrust > 0.0:
            print("navig8-authority: --tail-max-thrust must be > 0", file=sys.stderr)
            return 2
        cfg = with_tail_thrust(cfg, args.tail_max_thrust)
    try:
        masses = [float(v) for v in args.masses.split(",")]
        act = moment_lag(plant) if args.lag else None
        rep = analyse(cfg, masses, not args.no_reversal, plant.joint_v_max_rad_s, plant.joint_a_max_rad_s2,
                      args.amplitude_deg, act, args.pitch_deg)
    except ValueError as e:
        print(f"navig8-authority: {e}", file=sys.stderr)
        return 2
    print(json.dumps(rep, allow_nan=False) if args.json else render_text(rep))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
