"""The constrained KF's nuisance states (kalman.py): each is a scalar the rows of Eq. 24 depend on but the estimate
does not hold, with a Gaussian prior while an object is held and zero (with zero variance) otherwise, stored as
(value, variance, covariance with x (4,)) in the NZ_* layout.

- The pitch row's CoM-height error c (m; CKF_CZ_SIG): kf_correct_pitch, the pitch row in moment space.
- The roll and yaw rows' product-of-inertia error d (kg m^2; CKF_IXZ_SIG): the true I_xz minus the modelled one
  (CKF_IXZ_MOD: J13 plus a point object of the estimated mass at the gripper). It enters Delta U as
  G_C^-1 [d Delta R-dot, 0, d Delta P-dot, 0, 0] (Eq. 24's roll and yaw rows), a fifth column of H
  (ixz_column); kalman.kf_correct updates it jointly with x (augment / unaugment).

Pure core: numpy and numba; no I/O, no clocks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit

from navig8_fc.core import linalg
from navig8_fc.core.jit import njit_cached

__all__ = ["NZ_COV", "NZ_SIZE", "NZ_VAR", "NZ_X", "augment", "ixz_column", "ixz_mass_column", "kf_correct_pitch",
           "known_ixz", "mul", "unaugment"]

# A nuisance state: its value, variance and covariance with x (4,)
NZ_X = 0
NZ_VAR = 1
NZ_COV = 2
NZ_SIZE = 6


@njit(cache=True)
def mul(a, b, out):
    """out = a @ b (plain loops: the summation order of every product here is fixed; b may be a transposed
    view)."""
    for i in range(a.shape[0]):
        for j in range(b.shape[1]):
            acc = 0.0
            for k in range(a.shape[1]):
                acc += a[i, k] * b[k, j]
            out[i, j] = acc


@njit(cache=True)
def ixz_column(gc_inv, da, h, col):
    """h[:, col] = d Delta U / d I_xz = G_C^-1 [Delta R-dot, 0, Delta P-dot, 0, 0] (Eq. 24: I_xz multiplies the yaw
    acceleration in the roll row and the roll acceleration in the yaw row)."""
    for i in range(5):
        h[i, col] = gc_inv[i, 0] * da[2] + gc_inv[i, 2] * da[0]


@njit(cache=True)
def augment(x, p, nx, xa, pa):
    """[x, d] into xa (5,) and its covariance into pa (5, 5), d the nuisance nx (NZ_* layout)."""
    for i in range(4):
        xa[i] = x[i]
        for j in range(4):
            pa[i, j] = p[i, j]
        pa[i, 4] = nx[NZ_COV + i]
        pa[4, i] = nx[NZ_COV + i]
    xa[4] = nx[NZ_X]
    pa[4, 4] = nx[NZ_VAR]


@njit(cache=True)
def unaugment(xa, pa, x, p, nx):
    """augment's inverse: x, p and nx from xa (5,), pa (5, 5)."""
    for i in range(4):
        x[i] = xa[i]
        for j in range(4):
            p[i, j] = pa[i, j]
        nx[NZ_COV + i] = pa[i, 4]
    nx[NZ_X] = xa[4]
    nx[NZ_VAR] = pa[4, 4]


@njit(cache=True)
def cov_transform(a, nz):
    """nz's covariance with x <- a[:4, :4] of it (an update that does not measure the nuisance: x <- A x + K nu)."""
    c = np.empty(4)
    for i in range(4):
        acc = 0.0
        for j in range(4):
            acc += a[i, j] * nz[NZ_COV + j]
        c[i] = acc
    for i in range(4):
        nz[NZ_COV + i] = c[i]


@njit(cache=True)
def _pitch_augment(x, p, nz, pa):
    """pa (5, 5) <- the covariance of [x, c] from p (4, 4) and the pitch nuisance nz (augment; c and its row zero
    when nz is None); returns c."""
    if nz is None:
        for i in range(4):
            for j in range(4):
                pa[i, j] = p[i, j]
        return 0.0
    xa = np.empty(5)
    augment(x, p, nz, xa, pa)
    return xa[4]


@njit_cached(linalg)
def kf_correct_pitch(x, p, pitch_r, gc_inv, du, dq_dot, nz=None, pitch_y=math.nan, nx=None, com_dm_x=0.0,
                     com_dm_z=0.0):
    """The pitch row of Eq. 24 in moment space: y = G_C[M, :] Delta U = I_yy Delta Q-dot + c Delta F_x + nu,
    nu ~ (0, pitch_r) (G_C = (G_C^-1)^-1, the moments about the point the caller's G_C refers to; G_I's pitch row is
    [0, I_yy, 0, 0, 0]; Delta F_x = G_C[F_x, :] Delta U). c (m) is the error of that point's height against the true
    CoM's (M_true = M_ref - (c_true - c_ref) x F), a nuisance state in nz (value, variance, covariance with x) that the
    caller gives a prior while an object is held (its CoM follows the mass estimate, which converges last) and zero
    otherwise; with nz None or its variance 0 the row is I_yy Delta Q-dot alone. A scalar update of I_yy and c (the
    other states held, Schmidt; Joseph form keeps the covariance exact). Why not in Delta U space with the others:
    there the pitch column G_C^-1[:, M] Delta Q-dot spreads over all five rows, so the force rows' errors (the
    accelerometer noise the INDI feeds back as force commands, the mass still converging) are read as pitch
    information through the diagonal R; in moment space the pitch row has I_yy alone.
    pitch_y, when not nan, is y itself (CKF_MOM_LPF: the increment of the low-passed moment, AdaptiveLaw).
    nx: the roll and yaw rows' I_xz nuisance (NZ_* layout, CKF_IXZ_SIG); not measured here, its covariance with x
    follows this update (its covariance with c taken as zero).
    com_dm_x, com_dm_z (m/kg; CKF_CZ_DM): the slope of the reference point in the mass estimate (the law's CoM is the
    UAM's with the estimated object at the gripper), so the CoM error has a part in the mass error,
    c = c_z' (m - m_hat) + nuisance: the row's mass column h_m = c_z' Delta F_x - c_x' Delta F_z (M_ref = M_O - c x F),
    linearised at m_hat (the innovation is unchanged), and m is updated by this row too. 0, 0: m held here.
    Returns False (x, P unchanged) when G_C^-1 is singular."""
    gc = np.empty((5, 5))
    if not linalg.inv_gauss_jordan(gc_inv, gc):
        return False
    y = 0.0
    fx = 0.0
    fz = 0.0
    for j in range(5):
        y += gc[1, j] * du[j]
        fx += gc[3, j] * du[j]
        fz += gc[4, j] * du[j]
    hm = com_dm_z * fx - com_dm_x * fz  # the row's mass column (0 without CKF_CZ_DM)
    if pitch_y == pitch_y:
        y = pitch_y
    # the augmented state [x, c] (5,), its covariance pa, the measurement row h = [0, dq_dot, 0, hm, fx]
    pa = np.zeros((5, 5))
    xc = _pitch_augment(x, p, nz, pa)
    h = np.zeros(5)
    h[1] = dq_dot
    h[3] = hm
    h[4] = fx
    pht = np.zeros(5)
    for i in range(5):
        pht[i] = pa[i, 1] * dq_dot + pa[i, 4] * fx
        if hm != 0.0:
            pht[i] += pa[i, 3] * hm
    s = dq_dot * pht[1] + fx * pht[4] + pitch_r
    if hm != 0.0:
        s += hm * pht[3]
    g = np.zeros(5)
    g[1] = pht[1] / s
    g[4] = pht[4] / s
    e = y - dq_dot * x[1] - fx * xc  # at m = m_hat the mass column adds nothing to the prediction
    x[1] += g[1] * e
    if hm != 0.0:
        g[3] = pht[3] / s
        x[3] += g[3] * e
    # Joseph form: Pa = (I - g h) Pa (I - g h)^T + g r g^T
    a = np.empty((5, 5))
    for i in range(5):
        for j in range(5):
            a[i, j] = (1.0 if i == j else 0.0) - g[i] * h[j]
    t1 = np.empty((5, 5))
    mul(a, pa, t1)
    pn = np.empty((5, 5))
    mul(t1, a.T, pn)
    for i in range(4):
        for j in range(4):
            p[i, j] = 0.5 * (pn[i, j] + pn[j, i]) + g[i] * pitch_r * g[j]
    if nx is not None:  # cov(x, d) <- A[:4, :4] cov(x, d): d is not measured by this row
        cov_transform(a, nx)
    if nz is not None:
        nz[NZ_X] = xc + g[4] * e
        nz[NZ_VAR] = pn[4, 4] + g[4] * pitch_r * g[4]
        for i in range(4):
            nz[NZ_COV + i] = 0.5 * (pn[i, 4] + pn[4, i]) + g[i] * pitch_r * g[4]
    return True


def known_ixz(du: np.ndarray, gc_inv: np.ndarray, da: Sequence[float], ixz: float) -> np.ndarray:
    """CKF_IXZ_MOD: z = Delta U - G_C^-1 [I_xz Delta R-dot, 0, I_xz Delta P-dot, 0, 0] with the modelled I_xz, so that
    the roll and yaw rows of Eq. 24 carry I_xx Delta P-dot and I_zz Delta R-dot alone (the caller passes
    rho_x = rho_z = 0). Eq. 24 writes I_xz as I_zz J13 / J33 (roll row) and I_xx J13 / J11 (yaw row): exact with no
    object, but a held object off the body's axis moves I_xz by -m (x z) about the CoM, not in proportion to I_xx or
    I_zz (at q1 60 deg with 0.5 kg: I_xz -0.357 kg m^2 against Eq. 24's -0.304 / -0.306)."""
    a1, a3 = da[0], da[2]
    return du - gc_inv[:, 0] * (ixz * a3) - gc_inv[:, 2] * (ixz * a1)


def ixz_mass_column(du: np.ndarray, gc_inv: np.ndarray, da: Sequence[float], dixz_dm: float,
                     m_hat: float) -> tuple[np.ndarray, np.ndarray]:
    """CKF_IXZ_MOD 2: the modelled object's I_xz taken out by known_ixz is that of the estimated mass, so the roll and
    yaw rows of Eq. 24 depend on m too: Delta U = H x + G_C^-1 [D Delta R-dot, 0, D Delta P-dot, 0, 0] (m - m_hat)
    to first order, D = dI_xz/dm (an extended KF's linearisation at m_hat). Returns (du + h m_hat, h), h the mass
    column's addition: the innovation is unchanged, and the gain now knows that a window read while m_hat was still
    off carries I_xx, I_zz information conditional on m, so a later mass correction moves them through P's
    cross-covariance (measured: with the product of inertia from m_hat alone, K3 held at q1 60 deg read 0.58-0.60
    in a batch fit against 0.52 true with 1 kg, 0.53-0.55 with the true I_xz; docs/model.md, "Estimator" item 11)."""
    h = dixz_dm * (gc_inv[:, 0] * da[2] + gc_inv[:, 2] * da[0])
    return du + h * m_hat, h


def refer_moment(mom: list[float], f_x: float, f_z: float, alpha: float, dc_x: float, dc_z: float) -> None:
    """CKF_MOM_MREF: the low-passed pitch moment mom = [M_f, M_f at the window's start, F_x,f, F_z,f] (N m, N)
    re-referred to a reference point moved by (dc_x, dc_z) (m, body x and z) since the last tick, then the forces
    low-passed (weight alpha) with this tick's F_x, F_z. About the moved point the moment is M - (dc_z F_x - dc_x F_z)
    (the y row of M - dc x F); the filter being linear, its state and the window's start move by the same of the
    low-passed forces, so only the pitch moment that happened enters the window's increment (Eq. 24's pitch row)."""
    shift = dc_x * mom[3] - dc_z * mom[2]
    mom[0] += shift
    mom[1] += shift
    mom[2] += alpha * (f_x - mom[2])
    mom[3] += alpha * (f_z - mom[3])
