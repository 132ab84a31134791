"""The UAM's composite mass properties and its control effectiveness G_C, as numba kernels.

The model is written once, here (vehicle.py wraps these kernels for Python callers and builds their inputs):
`mass_props` (composite mass, CoM, inertia about the CoM and its rate, the arm's reaction, notes 3.1-3.2),
`gc_about` (G_C, Eq. 2, about any point on the body's x-z plane), `uam_model` (the controller's per-tick view of
the UAM without object, with G_C^-1), the map between U and the actuators (Sec. 3) and the eigenvalues of
G_hat G^-1 (Eq. 14). Plain float maths on flat float64 vectors whose slots the layouts below name
(navig8_fc.core.layout). tests/unit/test_vehicle.py and test_fc_kernels.py check them against independent
oracles (a vector-form model, finite differences, numpy/scipy). Pure: no I/O, no clocks.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from navig8_fc.core import linalg
from navig8_fc.core.jit import njit_cached
from navig8_fc.core.layout import layout
from navig8_fc.core.linalg import inv_gauss_jordan

# Vehicle geometry the model kernels take (vehicle.model_geometry builds it from a VehicleConfig).
GEO = layout("GEO", link_len=1, link_mass=1, link_inertia=1, mount_x=1, mount_z=1, uam_mass=1,
             j11=1, j22=1, j33=1, j13=1,  # UAV inertia about O (x-z symmetric)
             obj_offset=1, obj_radius=1)  # object centre beyond the tip along link 3; sphere radius
# Mass properties (mass_props): the 3x3 inertia about the CoM and its rate go to their own arrays.
MP = layout("MP", mass=1, cx=1, cz=1,
            ma_x=1, ma_z=1,  # sum_k m_k r''_k over the arm bodies (first moment's second derivative)
            tip_ax=1, tip_az=1,  # acceleration of the arm's tip (link 3's end)
            obj_x=1, obj_z=1,  # position of the object's centre (tip + offset along link 3), relative to O
            hdc=1,  # d/dt of the bodies' pitch angular momentum relative to the body, about the composite CoM
            jo=4)  # inertia about O: xx, yy, zz, xz
_N_MP = int(MP.SIZE)  # np.empty takes an int, not an IntEnum member
# UAM model + G_C^-1 (uam_model), the controller's per-tick view
UO = layout("UO", mass=1, cx=1, cz=1, arm_ax=1, arm_az=1,
            hdc=1,  # MP.HDC with the estimated object: the arm's reaction pitch moment about the CoM is -hdc
            cex=1, cez=1,  # CoM of the UAM with a point object of the estimated mass at the tip (the reference point)
            obj_rate=3,  # diagonal of d/dt of that composite's inertia minus J's I-dot: the estimated object's share
            singular=1,  # 1.0 when G_C could not be inverted (the caller then falls back to numpy)
            obj_ixz=1,  # that composite's I_xz (about its CoM) minus J13: the estimated object's share
            obj_ixz_dm=1,  # d obj_ixz / d(object mass) at the estimated mass (CKF_IXZ_MOD 2)
            ce_dm=2)  # d(cex, cez) / d(object mass) at the estimated mass, m/kg (CKF_CZ_DM)

_N_BODY_ACC = 15  # sum m x, m z, m xd, m zd, m xdd, m zdd; J11 J22 J33 J13 about O; their rates; h' about O


@njit(cache=True)
def _add_body(acc, m, x, z, xd, zd, xdd, zdd, o11, o22, o33, o13, r11, r22, r33, r13, oh):
    """Add one arm body of mass m at (x, 0, z) FRD (with its velocity and acceleration) to the accumulators acc:
    its first moments, its inertia about O (own inertia o.. about its CoM + parallel axis) and that inertia's
    rate (own rate r.. + the moving point's), and its share of d/dt of the pitch angular momentum about O with
    the body not rotating: m (r x r'')_y + oh (oh = own I_yy theta'')."""
    acc[0] += m * x
    acc[1] += m * z
    acc[2] += m * xd
    acc[3] += m * zd
    acc[4] += m * xdd
    acc[5] += m * zdd
    acc[6] += o11 + m * z * z
    acc[7] += o22 + m * (x * x + z * z)
    acc[8] += o33 + m * x * x
    acc[9] += o13 - m * x * z
    acc[10] += r11 + 2.0 * m * z * zd
    acc[11] += r22 + 2.0 * m * (x * xd + z * zd)
    acc[12] += r33 + 2.0 * m * x * xd
    acc[13] += r13 - m * (xd * z + x * zd)
    acc[14] += m * (z * xdd - x * zdd) + oh  # (r x r'')_y = z x'' - x z''


@njit(cache=True)
def mass_props(q, qd, qdd, object_mass_kg, geo, inertia, rate, mp):
    """Composite mass properties of UAV + 3 links (+ the object) at the arm state (q, q-dot, q-ddot) (notes 3.1-3.2).

    Planar arm in the body x-z plane through O (mount y = 0): link k's centre r_k = joint_k + L/2 e(theta_k),
    e = [sin, 0, cos]; rod inertia Ia (E - e e^T) about its centre; the object (object_mass_kg > 0) a point at
    geo[OBJ_OFFSET] beyond the tip along link 3 with sphere inertia 0.4 m r^2. Writes inertia (3x3, about the
    composite CoM) and rate (its time derivative about the moving CoM, Eq. 22's I-dot), and mp (MP layout).
    """
    L, ml, ia = geo[GEO.LINK_LEN], geo[GEO.LINK_MASS], geo[GEO.LINK_INERTIA]
    th = thd = thdd = 0.0
    jx, jz, jvx, jvz, jax, jaz = geo[GEO.MOUNT_X], geo[GEO.MOUNT_Z], 0.0, 0.0, 0.0, 0.0
    acc = np.zeros(_N_BODY_ACC)  # first moments, inertia about O and its rate of the arm bodies (_BA_*)
    s = c = 0.0
    h = 0.5 * L
    for i in range(3):
        th += q[i]
        thd += qd[i]
        thdd += qdd[i]
        s, c = math.sin(th), math.cos(th)
        # d/dt e = thd e', e' = [cos, 0, -sin]; d2/dt2 e = thdd e' - thd^2 e
        vx, vz = thd * c, -thd * s
        ax, az = thdd * c - thd * thd * s, -thdd * s - thd * thd * c
        x, z = jx + h * s, jz + h * c
        xd, zd = jvx + h * vx, jvz + h * vz
        xdd, zdd = jax + h * ax, jaz + h * az
        s2, c2 = 2.0 * s * c, c * c - s * s
        # own inertia of the rod (about its CoM, in the x-z plane) and its rate
        _add_body(acc, ml, x, z, xd, zd, xdd, zdd, ia * c * c, ia, ia * s * s, -ia * s * c,
                  -ia * s2 * thd, 0.0, ia * s2 * thd, -ia * c2 * thd, ia * thdd)
        jx, jz = jx + L * s, jz + L * c
        jvx, jvz = jvx + L * vx, jvz + L * vz
        jax, jaz = jax + L * ax, jaz + L * az
    m = geo[GEO.UAM_MASS]
    mo = object_mass_kg
    if mo > 0.0:
        d = geo[GEO.OBJ_OFFSET]
        io = 0.4 * mo * geo[GEO.OBJ_RADIUS] * geo[GEO.OBJ_RADIUS]
        x, z = jx + d * s, jz + d * c
        xd, zd = jvx + d * thd * c, jvz - d * thd * s
        xdd, zdd = jax + d * (thdd * c - thd * thd * s), jaz + d * (-thdd * s - thd * thd * c)
        _add_body(acc, mo, x, z, xd, zd, xdd, zdd, io, io, io, 0.0, 0.0, 0.0, 0.0, 0.0, io * thdd)  # isotropic
        m = m + mo
    s1, s1z, v1x, v1z, a1x, a1z, j11, j22, j33, j13, d11, d22, d33, d13, hd = (
        acc[0], acc[1], acc[2], acc[3], acc[4], acc[5], acc[6], acc[7], acc[8], acc[9], acc[10], acc[11], acc[12],
        acc[13], acc[14])
    cx, cz = s1 / m, s1z / m
    cxd, czd = v1x / m, v1z / m
    # Parallel-axis theorem from O to the CoM (c_y = 0): I_c = I_O - m (|c|^2 E - c c^T), and its rate.
    inertia[:, :] = 0.0
    rate[:, :] = 0.0
    inertia[0, 0] = geo[GEO.J11] + j11 - m * cz * cz
    inertia[1, 1] = geo[GEO.J22] + j22 - m * (cx * cx + cz * cz)
    inertia[2, 2] = geo[GEO.J33] + j33 - m * cx * cx
    i13 = geo[GEO.J13] + j13 + m * cx * cz
    inertia[0, 2] = i13
    inertia[2, 0] = i13
    rate[0, 0] = d11 - 2.0 * m * cz * czd
    rate[1, 1] = d22 - 2.0 * m * (cx * cxd + cz * czd)
    rate[2, 2] = d33 - 2.0 * m * cx * cxd
    r13 = d13 + m * (cxd * cz + cx * czd)
    rate[0, 2] = r13
    rate[2, 0] = r13
    mp[MP.MASS] = m
    mp[MP.CX] = cx
    mp[MP.CZ] = cz
    mp[MP.MA_X] = a1x
    mp[MP.MA_Z] = a1z
    mp[MP.TIP_AX] = jax
    mp[MP.TIP_AZ] = jaz
    mp[MP.OBJ_X] = jx + geo[GEO.OBJ_OFFSET] * s
    # about the CoM: sum m (r - c) x (r'' - c'') = sum m r x r'' - m c x c''
    mp[MP.HDC] = hd - (s1z * a1x - s1 * a1z) / m
    mp[MP.OBJ_Z] = jz + geo[GEO.OBJ_OFFSET] * c
    mp[MP.JO] = geo[GEO.J11] + j11
    mp[MP.JO + 1] = geo[GEO.J22] + j22
    mp[MP.JO + 2] = geo[GEO.J33] + j33
    mp[MP.JO + 3] = geo[GEO.J13] + j13


@njit(cache=True)
def gc_about(f, m0, cx, cz, gc):
    """G_C (Eq. 2) about the point c = (cx, 0, cz): rows [L, M, N, Fx, Fz] from the per-input force f (3x5) and
    moment about O m0 (3x5), M_c = M_O - c x F (notes 2.5); c x F with c_y = 0 is [-cz Fy, cz Fx - cx Fz, cx Fy]."""
    for j in range(5):
        gc[0, j] = m0[0, j] + cz * f[1, j]
        gc[1, j] = m0[1, j] - (cz * f[0, j] - cx * f[2, j])
        gc[2, j] = m0[2, j] - cx * f[1, j]
        gc[3, j] = f[0, j]
        gc[4, j] = f[2, j]


@njit_cached(linalg)
def gc_inv_about(f, m0, cx, cz, gc, gc_inv):
    """G_C about c = (cx, 0, cz) (gc_about) and its inverse into gc, gc_inv; False when G_C is singular."""
    gc_about(f, m0, cx, cz, gc)
    return inv_gauss_jordan(gc, gc_inv)


@njit_cached(linalg)
def uam_model(q, qd, qdd, object_mass_kg, geo, f, m0, inertia, rate, gc, gc_inv, uo):
    """The controller's model of the UAM without object at the arm state: mass_props, G_C about the UAM CoM and
    its inverse, and the arm's CoM-acceleration term sum_k m_k r''_k / m with a point object of object_mass_kg
    (the estimate) at the tip (notes 3.3 option b). Writes inertia, rate (3x3), gc, gc_inv (5x5) and uo (UO)."""
    mp = np.empty(_N_MP)
    mass_props(q, qd, qdd, 0.0, geo, inertia, rate, mp)
    m, cx, cz = mp[MP.MASS], mp[MP.CX], mp[MP.CZ]
    mo = max(object_mass_kg, 0.0)
    m_tot = m + mo
    uo[UO.MASS] = m
    uo[UO.CX] = cx
    uo[UO.CZ] = cz
    uo[UO.ARM_AX] = (mp[MP.MA_X] + mo * mp[MP.TIP_AX]) / m_tot
    uo[UO.ARM_AZ] = (mp[MP.MA_Z] + mo * mp[MP.TIP_AZ]) / m_tot
    uo[UO.CEX] = (m * cx + mo * mp[MP.OBJ_X]) / m_tot
    if mo > 0.0:  # the reaction and inertia with the estimated object (G_C, G_I above stay those without it)
        mp2 = np.empty(_N_MP)
        ic = np.empty((3, 3))
        ic_rate = np.empty((3, 3))
        mass_props(q, qd, qdd, mo, geo, ic, ic_rate, mp2)
        uo[UO.HDC] = mp2[MP.HDC]
        for i in range(3):
            uo[UO.OBJ_RATE + i] = ic_rate[i, i] - rate[i, i]
        uo[UO.OBJ_IXZ] = ic[0, 2] - inertia[0, 2]
    else:
        uo[UO.HDC] = mp[MP.HDC]
        for i in range(3):
            uo[UO.OBJ_RATE + i] = 0.0
        uo[UO.OBJ_IXZ] = 0.0
    uo[UO.CEZ] = (m * cz + mo * mp[MP.OBJ_Z]) / m_tot
    # A point object (the sphere's own inertia is isotropic) moves the composite's I_xz about its CoM by
    # -mu dx dz, mu = m mo / (m + mo) the reduced mass, d the object's offset from the UAM's CoM; its slope in mo is
    # -dx dz m^2 / (m + mo)^2, defined at mo = 0 too (right after a grasp the mass estimate is still the UAM's)
    uo[UO.OBJ_IXZ_DM] = -(mp[MP.OBJ_X] - cx) * (mp[MP.OBJ_Z] - cz) * (m / m_tot) ** 2
    # the reference point's slope: d/dmo (m c + mo r_obj) / (m + mo) = m (r_obj - c) / (m + mo)^2
    uo[UO.CE_DM] = m * (mp[MP.OBJ_X] - cx) / (m_tot * m_tot)
    uo[UO.CE_DM + 1] = m * (mp[MP.OBJ_Z] - cz) / (m_tot * m_tot)
    gc_about(f, m0, cx, cz, gc)
    uo[UO.SINGULAR] = 0.0 if inv_gauss_jordan(gc, gc_inv) else 1.0


# G_C's input U and the actuators (Sec. 3)


@njit_cached()  # one compilation whatever constant `at` a kernel passes (jit.py)
def actuators_to_u(alpha1, alpha3, w1, w2, w3, out, at):
    """U = [cos a1 w1^2, sin a1 w1^2, cos a3 w3^2, sin a3 w3^2, sign(w2) w2^2] (Sec. 3) into out[at:at + 5]."""
    out[at] = math.cos(alpha1) * w1 * w1
    out[at + 1] = math.sin(alpha1) * w1 * w1
    out[at + 2] = math.cos(alpha3) * w3 * w3
    out[at + 3] = math.sin(alpha3) * w3 * w3
    out[at + 4] = math.copysign(w2 * w2, w2)


@njit(cache=True)
def u_to_actuators(u, out, at):
    """(alpha1, alpha3, w1, w2, w3) from U (Sec. 3) into out[at:at + 5]: alpha = atan2, w = (U_c^2 + U_s^2)^(1/4)."""
    out[at] = math.atan2(u[1], u[0])
    out[at + 1] = math.atan2(u[3], u[2])
    out[at + 2] = math.hypot(u[0], u[1]) ** 0.5
    out[at + 3] = math.copysign(abs(u[4]) ** 0.5, u[4])
    out[at + 4] = math.hypot(u[2], u[3]) ** 0.5


# The eigenvalues the stability criterion is stated on (Eq. 14), against the plant's truth in flight


@njit(cache=True)
def ghat_ginv_eigs(gi_hat: np.ndarray, gc_uam: np.ndarray, gc_true: np.ndarray, gi_true: np.ndarray,
                   out_re: np.ndarray, out_im: np.ndarray) -> None:
    """Eigenvalues of G_hat G^-1 = (G_hat_I^-1 G_C,UAM)(G_C,true^-1 G_I,true) (Eq. 14), sorted by real part.

    K Xi can have complex pairs (~1 % of poses): real eigvals first, complex arithmetic when that fails.
    tests/unit/test_vehicle.py checks it against scipy.linalg.eigvals."""
    a = np.linalg.solve(gi_hat, gc_uam) @ np.linalg.solve(gc_true, gi_true)
    if _real_eigvals_sorted(a, out_re):  # the usual case, ~3x cheaper than the complex path
        out_im[:] = 0.0
        return
    lam = np.linalg.eigvals(a.astype(np.complex128))
    order = np.argsort(lam.real)
    for i in range(lam.size):
        out_re[i] = lam[order[i]].real
        out_im[i] = lam[order[i]].imag


@njit(cache=True)
def ghat_ginv_eigs_truth(gi_hat, gc_uam, f, m0, cx, cz, inertia, mass, has_ref, ref_x, ref_z, out_re, out_im):
    """ghat_ginv_eigs with G from the truth, in one call: G_C,true about the true CoM c = (cx, 0, cz)
    (gc_about), G_I,true = blkdiag(J, m, m) (J the 3x3 inertia about c), and with has_ref the flown
    G_I,true (2 I - T(d)), d = ref - c: [3, 1] = m (-d_z), [4, 1] = m d_x (vehicle.ghat_ginv_eig_record)."""
    gc_true = np.empty((5, 5))
    gc_about(f, m0, cx, cz, gc_true)
    gi_true = np.zeros((5, 5))
    gi_true[:3, :3] = inertia
    gi_true[3, 3] = mass
    gi_true[4, 4] = mass
    if has_ref:
        gi_true[3, 1] = 0.0 + mass * (0.0 - (ref_z - cz))
        gi_true[4, 1] = 0.0 + mass * (0.0 - (0.0 - (ref_x - cx)))
    ghat_ginv_eigs(gi_hat, gc_uam, gc_true, gi_true, out_re, out_im)


@njit(cache=True)
def _real_eigvals_sorted(a: np.ndarray, out_re: np.ndarray) -> bool:
    """Sorted eigenvalues of `a` into out_re when all are real; False (out_re untouched) when some are not:
    numba's real eigvals raises on a complex result."""
    try:
        lam = np.linalg.eigvals(a)
    except Exception:  # noqa: BLE001 - complex pair: the caller takes the complex path
        return False
    lam.sort()
    out_re[:] = lam
    return True
