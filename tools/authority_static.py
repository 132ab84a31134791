"""The actuator set's static moment authority at hover (navig8-authority, tools/authority.py, item 1): for an arm
pose and object (they enter only through the composite CoM and the total mass), the largest and smallest pure
pitch (roll) moment about the composite CoM that the ducts and the tail can hold at hover, the body level or
pitched, F_x held or free: the best of the linear programs over the convex pieces of the two ducts' tilt
sectors, all CoM points and pieces in one block-diagonal LP (`authority_at_coms`, `hover_authority`); and the
same along a path of the CoM (`AuthorityMap`: the LP on a lattice of CoM points, bilinear in between, kept per
process). docs/model.md, "Pitch authority".
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import sparse
from scipy.optimize import linprog

from navig8_fc.core import g_c
from navig8_fc.core.vehicle import VehicleConfig, mass_properties, propulsion_per_input

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


_MAPS: dict[tuple[Any, ...], AuthorityMap] = {}  # authority_map's, per process


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


def map_lp_points() -> dict[tuple[Any, ...], int]:
    """How many CoM points each kept AuthorityMap has solved so far (for the timing report)."""
    return {k: m.lp_points for k, m in _MAPS.items()}
