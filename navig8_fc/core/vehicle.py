"""Navig8-UAM model: arm kinematics, composite mass properties, the inertia rate and G_C, G_I, G.

Pure math; the model itself is written once, in numba kernels (g_c.mass_props, gc_about, uam_model),
and the functions here bind a VehicleConfig to them. Body frame FRD with origin O at the UAV's own centre of mass.
The arm moves in the body x-z plane: joint angles q (rad), q = 0 points down (+z),
q > 0 swings the link forward (+x). Absolute link angle theta_i = q_1 + ... + q_i and
link direction e(theta) = [sin theta, 0, cos theta].

The control-effectiveness rows are [L, M, N, Fx, Fz] (roll, pitch, yaw moments about the
reference point, body x and z forces); the inputs are the paper's
U = [cos a1 w1^2, sin a1 w1^2, cos a3 w3^2, sin a3 w3^2, sign(w2) w2^2] (Sec. 3).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from navig8_fc.core import g_c

N_LINKS = 3
Sequence3 = Sequence[float] | np.ndarray


@dataclass(frozen=True)
class VehicleConfig:
    """Vehicle constants (params/vehicle.yaml). Lengths in m, masses in kg, inertias in kg m^2."""

    uav_mass_kg: float
    uav_inertia: tuple[tuple[float, float, float], ...]  # 3x3 tensor about O, FRD
    link_length_m: float
    link_mass_kg: float
    link_inertia_kgm2: float  # Ixx = Iyy of a slender rod (Izz = 0 along the link)
    mount_frd_m: tuple[float, float, float]
    joint_limit_rad: float
    object_radius_m: float
    object_offset_m: float
    duct_right_frd_m: tuple[float, float, float]
    tail_frd_m: tuple[float, float, float]
    dihedral_rad: float
    k_thrust_duct: float
    k_torque_duct: float
    spin_duct1: float
    k_thrust_tail: float
    k_torque_tail: float
    spin_tail: float
    tilt_min_rad: float
    tilt_max_rad: float
    duct_speed_min: float
    duct_speed_max: float
    tail_speed_min: float
    tail_speed_max: float
    gravity_m_s2: float

    @staticmethod
    def from_dict(d: dict[str, Any]) -> VehicleConfig:
        uav, arm, obj, prop, lim = d["uav"], d["arm"], d["object"], d["propulsion"], d["limits"]
        if int(arm["n_links"]) != N_LINKS:
            raise ValueError(f"the model has exactly {N_LINKS} arm links, vehicle file says {arm['n_links']}")
        i = uav["inertia_kgm2"]
        # Table 1 lists "I_xz" = 0.0147; the tensor entry is J13 = -I_xz (docs/model.md, notes 2.4).
        j13 = -float(i["xz_table"])
        inertia = (
            (float(i["xx"]), 0.0, j13),
            (0.0, float(i["yy"]), 0.0),
            (j13, 0.0, float(i["zz"])),
        )
        if obj.get("inertia_model", "solid_sphere") != "solid_sphere":
            raise ValueError("only the solid_sphere object inertia model is implemented")
        return VehicleConfig(
            uav_mass_kg=float(uav["mass_kg"]),
            uav_inertia=inertia,
            link_length_m=float(arm["link_length_m"]),
            link_mass_kg=float(arm["link_mass_kg"]),
            link_inertia_kgm2=float(arm["link_inertia_kgm2"]),
            mount_frd_m=tuple(float(v) for v in arm["mount_frd_m"]),  # type: ignore[arg-type]
            joint_limit_rad=float(arm["joint_limit_rad"]),
            object_radius_m=float(obj["radius_m"]),
            object_offset_m=float(obj["offset_from_tip_m"]),
            duct_right_frd_m=tuple(float(v) for v in prop["duct_right_frd_m"]),  # type: ignore[arg-type]
            tail_frd_m=tuple(float(v) for v in prop["tail_frd_m"]),  # type: ignore[arg-type]
            dihedral_rad=math.radians(float(prop["dihedral_deg"])),
            k_thrust_duct=float(prop["k_thrust_duct"]),
            k_torque_duct=float(prop["k_torque_duct"]),
            spin_duct1=float(prop["spin_duct1"]),
            k_thrust_tail=float(prop["k_thrust_tail"]),
            k_torque_tail=float(prop["k_torque_tail"]),
            spin_tail=float(prop["spin_tail"]),
            tilt_min_rad=float(lim["duct_tilt_rad"][0]),
            tilt_max_rad=float(lim["duct_tilt_rad"][1]),
            duct_speed_min=float(lim["duct_speed_rad_s"][0]),
            duct_speed_max=float(lim["duct_speed_rad_s"][1]),
            tail_speed_min=float(lim["tail_speed_rad_s"][0]),
            tail_speed_max=float(lim["tail_speed_rad_s"][1]),
            gravity_m_s2=float(d["environment"]["gravity_m_s2"]),
        )

    @staticmethod
    def load(path: str | Path | None = None) -> VehicleConfig:
        """Load the vehicle file (default: the packaged params/vehicle.yaml)."""
        if path is None:
            from importlib.resources import files

            text = (files("navig8_params") / "vehicle.yaml").read_text()
        else:
            text = Path(path).read_text()
        return VehicleConfig.from_dict(yaml.safe_load(text))

    @property
    def uav_inertia_array(self) -> np.ndarray:
        return np.array(self.uav_inertia, dtype=float)

    @property
    def arm_mass_kg(self) -> float:
        return N_LINKS * self.link_mass_kg

    @property
    def uam_mass_kg(self) -> float:
        """Mass of UAV + arm without any object (the paper's m_UAM)."""
        return self.uav_mass_kg + self.arm_mass_kg


def object_inertia_kgm2(cfg: VehicleConfig, mass_kg: float) -> float:
    """Solid-sphere inertia 0.4 m r^2 about any axis through its centre (docs/model.md)."""
    return 0.4 * mass_kg * cfg.object_radius_m**2


@dataclass(frozen=True)
class MassProperties:
    """Composite mass properties of UAV + arm (+ object)."""

    mass_kg: float
    com_frd_m: np.ndarray  # (3,) relative to O
    inertia_com: np.ndarray  # (3,3) tensor about the composite CoM, body axes
    inertia_o: np.ndarray  # (3,3) tensor about O


def model_geometry(cfg: VehicleConfig) -> np.ndarray:
    """The vehicle constants the model kernels take (g_c.GEO layout)."""
    if cfg.mount_frd_m[1] != 0.0:
        raise ValueError("the model's arm moves in the body x-z plane through O: mount_frd_m[1] must be 0")
    j = cfg.uav_inertia_array
    return g_c.GEO.pack(link_len=cfg.link_length_m, link_mass=cfg.link_mass_kg, link_inertia=cfg.link_inertia_kgm2,
                       mount_x=cfg.mount_frd_m[0], mount_z=cfg.mount_frd_m[2], uam_mass=cfg.uam_mass_kg,
                       j11=j[0, 0], j22=j[1, 1], j33=j[2, 2], j13=j[0, 2], obj_offset=cfg.object_offset_m,
                       obj_radius=cfg.object_radius_m)


def arm_state(q: Sequence3, qd: Sequence3 | None, qdd: Sequence3 | None) -> tuple[np.ndarray, ...]:
    zero = np.zeros(N_LINKS)
    # copies: writable whatever the caller passed (a read-only array is another type, another compilation)
    return tuple(zero if v is None else np.array(v, dtype=float).reshape(N_LINKS) for v in (q, qd, qdd))


def _mass_props(cfg: VehicleConfig, q: Sequence3, qd: Sequence3 | None,
                object_mass_kg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    inertia, rate, mp = np.empty((3, 3)), np.empty((3, 3)), g_c.MP.zeros()
    g_c.mass_props(*arm_state(q, qd, None), float(object_mass_kg), model_geometry(cfg), inertia, rate, mp)
    return inertia, rate, mp


def mass_properties(
    cfg: VehicleConfig, q: Sequence3, object_mass_kg: float = 0.0
) -> MassProperties:
    """Mass, CoM and inertia tensor (about the CoM) for arm pose q and an object in the gripper (mass_props)."""
    inertia, _, mp = _mass_props(cfg, q, None, object_mass_kg)
    jo = mp[g_c.MP.JO.sl]
    return MassProperties(
        mass_kg=float(mp[g_c.MP.MASS]),
        com_frd_m=np.array([mp[g_c.MP.CX], 0.0, mp[g_c.MP.CZ]]),
        inertia_com=inertia,
        inertia_o=np.array([[jo[0], 0.0, jo[3]], [0.0, jo[1], 0.0], [jo[3], 0.0, jo[2]]]),
    )


def inertia_rate(
    cfg: VehicleConfig, q: Sequence3, qd: Sequence3, object_mass_kg: float = 0.0
) -> np.ndarray:
    """Time derivative of the inertia tensor about the (moving) composite CoM, body axes (Eq. 22's I-dot)."""
    return _mass_props(cfg, q, qd, object_mass_kg)[1]


# --------------------------------------------------------------------------------------
# Propulsion (notes 2.1-2.2)
# --------------------------------------------------------------------------------------


def propulsion_per_input(cfg: VehicleConfig) -> tuple[np.ndarray, np.ndarray]:
    """Force (3x5) and moment about O (3x5) per unit of each U component; the wrench is linear in U."""
    kt, kq = cfg.k_thrust_duct, cfg.k_torque_duct
    sg, cg = math.sin(cfg.dihedral_rad), math.cos(cfg.dihedral_rad)
    s1 = cfg.spin_duct1
    r1 = np.array(cfg.duct_right_frd_m)
    r3 = r1 * np.array([1.0, -1.0, 1.0])
    r2 = np.array(cfg.tail_frd_m)
    # d1 = [sin a1, -sin g cos a1, -cos g cos a1]: U1 multiplies the cos part, U2 the sin part.
    f = np.zeros((3, 5))
    f[:, 0] = kt * np.array([0.0, -sg, -cg])
    f[:, 1] = kt * np.array([1.0, 0.0, 0.0])
    f[:, 2] = kt * np.array([0.0, sg, -cg])
    f[:, 3] = kt * np.array([1.0, 0.0, 0.0])
    f[:, 4] = np.array([0.0, 0.0, -cfg.k_thrust_tail])  # U5 > 0 pushes up (-z)
    # Drag torques: duct 1 -s1 K_Q w^2 d1, duct 3 +s1 K_Q w^2 d3, tail s2 K_Q2 U5 z.
    tq = np.zeros((3, 5))
    tq[:, 0] = -s1 * kq * np.array([0.0, -sg, -cg])
    tq[:, 1] = -s1 * kq * np.array([1.0, 0.0, 0.0])
    tq[:, 2] = s1 * kq * np.array([0.0, sg, -cg])
    tq[:, 3] = s1 * kq * np.array([1.0, 0.0, 0.0])
    tq[:, 4] = np.array([0.0, 0.0, cfg.spin_tail * cfg.k_torque_tail])
    arms = [r1, r1, r3, r3, r2]
    mom = np.zeros((3, 5))
    for k in range(5):
        mom[:, k] = np.cross(arms[k], f[:, k]) + tq[:, k]
    return f, mom


def propulsion_wrench(
    cfg: VehicleConfig, u: np.ndarray, ref_frd_m: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Total propulsive force (N, FRD) and moment (N m) about ref (default O) for inputs U: M_ref = M_O - ref x F."""
    f, mom = propulsion_per_input(cfg)
    u = np.asarray(u, dtype=float)
    force, moment = f @ u, mom @ u
    if ref_frd_m is not None:
        moment = moment - np.cross(np.asarray(ref_frd_m, dtype=float), force)
    return force, moment


def control_effectiveness_gc(cfg: VehicleConfig, com_frd_m: Sequence3) -> np.ndarray:
    """G_C (5x5): rows [L, M, N, Fx, Fz] about the CoM, columns U1..U5 (Eq. 1-2, notes 2.2; g_c.gc_about).

    The CoM lies in the body x-z plane (the arm moves in it)."""
    if float(com_frd_m[1]) != 0.0:
        raise ValueError("control_effectiveness_gc: the model's CoM has y = 0")
    f, m0 = propulsion_per_input(cfg)
    gc = np.empty((5, 5))
    g_c.gc_about(f, m0, float(com_frd_m[0]), float(com_frd_m[2]), gc)
    return gc


def inertia_matrix_gi(inertia_com: np.ndarray, mass_kg: float) -> np.ndarray:
    """G_I = blkdiag(J_xz, m, m) (Eq. 2): the 3x3 inertia tensor (x-z symmetric) and the mass twice."""
    gi = np.zeros((5, 5))
    gi[:3, :3] = inertia_com
    gi[3, 3] = gi[4, 4] = mass_kg
    return gi


def estimated_gi(inertia_uam: np.ndarray, x_hat: np.ndarray) -> np.ndarray:
    """G_hat_I (Eq. 4) from the estimate x_hat = [Ixx, Iyy, Izz, m].

    K^-1 scales the columns of G_I,UAM: I_hat_xz = I_hat_zz J13/J33, I_hat_zx = I_hat_xx J13/J11.
    """
    j = inertia_uam
    ixx, iyy, izz, m = (float(v) for v in x_hat)
    gi = np.zeros((5, 5))
    gi[0, 0] = ixx
    gi[1, 1] = iyy
    gi[2, 2] = izz
    gi[0, 2] = izz * j[0, 2] / j[2, 2]
    gi[2, 0] = ixx * j[0, 2] / j[0, 0]
    gi[3, 3] = gi[4, 4] = m
    return gi


def k_from_estimate(inertia_uam: np.ndarray, mass_uam_kg: float, x_hat: np.ndarray) -> np.ndarray:
    """Weighting factors [K1, K2, K3, K4] implied by x_hat (Eq. 4: I_hat = I_UAM / K)."""
    base = np.array([inertia_uam[0, 0], inertia_uam[1, 1], inertia_uam[2, 2], mass_uam_kg])
    return base / np.asarray(x_hat, dtype=float)


def estimate_bounds(inertia_uam: np.ndarray, mass_uam_kg: float, k_min: float, k_max: float):
    """Eq. 21: I_UAM / K_max <= I_hat <= I_UAM / K_min for [Ixx, Iyy, Izz, m]."""
    base = np.array([inertia_uam[0, 0], inertia_uam[1, 1], inertia_uam[2, 2], mass_uam_kg])
    return base / k_max, base / k_min


def k_matrix(k: np.ndarray) -> np.ndarray:
    """K = diag(K1, K2, K3, K4, K4) (Eq. 3)."""
    k1, k2, k3, k4 = (float(v) for v in k)
    return np.diag([k1, k2, k3, k4, k4])


@dataclass(frozen=True)
class EffectivenessPair:
    """The controller's model (UAM without object) and the truth (UAM with object) at one pose."""

    gc_uam: np.ndarray
    gi_uam: np.ndarray
    gc_true: np.ndarray
    gi_true: np.ndarray

    @property
    def xi(self) -> np.ndarray:
        """Xi = G_I,UAM^-1 G_C,UAM G_C,UAM&o^-1 G_I,UAM&o (Eq. 14)."""
        return np.linalg.solve(self.gi_uam, self.gc_uam) @ np.linalg.solve(self.gc_true, self.gi_true)


def effectiveness_pair(cfg: VehicleConfig, q: np.ndarray, object_mass_kg: float) -> EffectivenessPair:
    uam = mass_properties(cfg, q, 0.0)
    true = mass_properties(cfg, q, object_mass_kg)
    return EffectivenessPair(
        gc_uam=control_effectiveness_gc(cfg, uam.com_frd_m),
        gi_uam=inertia_matrix_gi(uam.inertia_com, uam.mass_kg),
        gc_true=control_effectiveness_gc(cfg, true.com_frd_m),
        gi_true=inertia_matrix_gi(true.inertia_com, true.mass_kg),
    )


def ghat_ginv_eigenvalues(pair: EffectivenessPair, k: np.ndarray) -> np.ndarray:
    """Eigenvalues of G_hat G^-1 = K Xi (Eq. 14), sorted by real part."""
    lam = np.linalg.eigvals(k_matrix(k) @ pair.xi)
    return lam[np.argsort(lam.real)]


# --------------------------------------------------------------------------------------
# U <-> actuators (Sec. 3)
# --------------------------------------------------------------------------------------


def actuators_to_u(alpha1: float, alpha3: float, w1: float, w2: float, w3: float) -> np.ndarray:
    """U = [cos a1 w1^2, sin a1 w1^2, cos a3 w3^2, sin a3 w3^2, sign(w2) w2^2] (Sec. 3)."""
    u = np.empty(5)
    g_c.actuators_to_u(float(alpha1), float(alpha3), float(w1), float(w2), float(w3), u, 0)
    return u


def u_to_actuators(u: Sequence[float] | np.ndarray) -> tuple[float, float, float, float, float]:
    """(alpha1, alpha3, w1, w2, w3) from U (Sec. 3): alpha = atan2, w = (U_c^2 + U_s^2)^(1/4)."""
    out = np.empty(5)
    g_c.u_to_actuators(np.asarray(u, dtype=float), out, 0)
    a1, a3, w1, w2, w3 = out.tolist()
    return a1, a3, w1, w2, w3


def hover_trim(cfg: VehicleConfig, q: np.ndarray, object_mass_kg: float) -> np.ndarray:
    """U that produces zero moment about the true CoM, Fx = 0 and Fz = -m g with the body level."""
    mp = mass_properties(cfg, q, object_mass_kg)
    gc = control_effectiveness_gc(cfg, mp.com_frd_m)
    target = np.array([0.0, 0.0, 0.0, 0.0, -mp.mass_kg * cfg.gravity_m_s2])
    return np.linalg.solve(gc, target)


# --------------------------------------------------------------------------------------
# The controller's per-tick model of the UAM without object
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class UamState:
    """What the controller needs each tick from the measured arm state (UAM without object)."""

    mass_kg: float
    com_frd_m: np.ndarray  # (3,)
    inertia_com: np.ndarray  # (3,3) about the UAM CoM
    inertia_rate: np.ndarray  # (3,3) Eq. 22's I-dot
    gc: np.ndarray  # (5,5) G_C,UAM about the UAM CoM (Eq. 2)
    arm_accel_xz: tuple[float, float]  # sum_k m_k r''_k / m of the arm (+ estimated object), body x and z


class UamModel:
    """The controller's model of the UAM without object (g_c.uam_model) with the vehicle's constants bound.

    The moment rows of G_C about a point c follow from those about O: M_c = M_O - c x F (notes 2.5).
    """

    def __init__(self, cfg: VehicleConfig) -> None:
        self.cfg = cfg
        self.geometry = model_geometry(cfg)  # g_c.GEO
        f, m0 = propulsion_per_input(cfg)
        self.force_per_input = np.ascontiguousarray(f)
        self.moment_o_per_input = np.ascontiguousarray(m0)

    def gc_about(self, cx: float, cz: float) -> np.ndarray:
        """G_C rows [L, M, N, Fx, Fz] about c = (cx, 0, cz)."""
        gc = np.empty((5, 5))
        g_c.gc_about(self.force_per_input, self.moment_o_per_input, float(cx), float(cz), gc)
        return gc

    def evaluate(
        self,
        q: Sequence3,
        qd: Sequence3,
        qdd: Sequence3 | None = None,
        object_mass_kg: float = 0.0,
    ) -> UamState:
        """Mass properties, I-dot, G_C and the arm's CoM acceleration for the measured arm state.

        object_mass_kg > 0 adds a point object at the tip for the CoM-acceleration term only
        (the controller's G_C and G_I stay those of the UAM without object, as in the paper).
        """
        inertia, rate = np.empty((3, 3)), np.empty((3, 3))
        gc, gc_inv, uo = np.empty((5, 5)), np.empty((5, 5)), g_c.UO.zeros()
        g_c.uam_model(*arm_state(q, qd, qdd), float(object_mass_kg), self.geometry, self.force_per_input,
                     self.moment_o_per_input, inertia, rate, gc, gc_inv, uo)
        o = uo.tolist()
        return UamState(
            mass_kg=o[g_c.UO.MASS],
            com_frd_m=np.array([o[g_c.UO.CX], 0.0, o[g_c.UO.CZ]]),
            inertia_com=inertia,
            inertia_rate=rate,
            gc=gc,
            arm_accel_xz=(o[g_c.UO.ARM_AX], o[g_c.UO.ARM_AZ]),
        )


def reference_transform(ref_minus_com_frd_m: Sequence3) -> np.ndarray:
    """T (5x5) with [omega-dot, a_p,x, a_p,z] = T [omega-dot, a_c,x, a_c,z] for a point p = c + d of the rigid body:
    a_p = a_c + omega-dot x d + (terms without U), and with d_y = 0 (omega-dot x d)_x = Qdot d_z,
    (omega-dot x d)_z = -Qdot d_x. The loop that feeds back the acceleration of p flies T G (INDI_ACC_REF)."""
    t = np.eye(5)
    t[3, 1] = float(ref_minus_com_frd_m[2])
    t[4, 1] = -float(ref_minus_com_frd_m[0])
    return t


def flown_effectiveness(gc_true: np.ndarray, gi_true: np.ndarray, ref_minus_com_frd_m: Sequence3) -> np.ndarray:
    """G of the loop actually flown: U -> [omega-dot, a_p,x, a_p,z] = T(p - c) G_I^-1 G_C (Eq. 1-2)."""
    return reference_transform(ref_minus_com_frd_m) @ np.linalg.solve(gi_true, gc_true)


def ghat_ginv_eig_record(
    model: UamModel,
    q_est_rad: Sequence3,
    gi_hat_flat: Sequence[float],
    com_true_frd_m: Sequence3,
    inertia_true: np.ndarray,
    mass_true_kg: float,
    lambda_min: float,
    lambda_crit: float,
    gc_uam_flat: Sequence[float] | None = None,
    ref_frd_m: Sequence3 | None = None,
) -> dict[str, Any]:
    """Eigenvalues of G_hat G^-1 (Eq. 14) with G from the plant's truth, as the /analysis/eig log record.

    G_hat^-1 = G_C,UAM(q_est)^-1 G_hat_I (Eq. 4) and G^-1 = G_C,true^-1 G_I,true, so
    G_hat G^-1 = (G_hat_I^-1 G_C,UAM)(G_C,true^-1 G_I,true). gc_uam_flat: the G_C,UAM(q_est) the controller
    used this tick (ControllerStatus.gc_uam), else it is evaluated here. The linear algebra runs in a numba
    kernel (g_c.ghat_ginv_eigs: every logged tick needs it). Used by the in-process runner and the SITL FC.

    ref_frd_m: the point whose acceleration the loop feeds back (ControllerStatus.ref_frd_m, INDI_ACC_REF = 1);
    then G is the flown T(p - c) G (flown_effectiveness) and G^-1 = G_C,true^-1 G_I,true T^-1, T^-1 = 2 I - T
    (T - I is nilpotent). None: the paper's Eq. 14 matrix.
    """
    gc_uam = (model.evaluate(q_est_rad, (0.0, 0.0, 0.0)).gc if gc_uam_flat is None
              else np.array(gc_uam_flat, dtype=float).reshape(5, 5))
    gi_hat = np.array(gi_hat_flat, dtype=float).reshape(5, 5)
    j = np.array(inertia_true, dtype=float)  # writable: a read-only array is another type, another compilation
    m = float(mass_true_kg)
    # G_I,true @ (2 I - T(d)) in closed form inside the kernel (the matrix product cost ~5 us per logged tick):
    # G_I,true is blkdiag(J, m, m) and 2 I - T differs from I only at [3, 1] = -d_z and [4, 1] = d_x, so the
    # product is G_I,true with [3, 1] = m (-d_z) and [4, 1] = m d_x (every other element is a product with 1 or 0
    # added to zeros, as the matrix product computes it: the same values). One kernel call for G_C,true, G_I,true
    # and the eigenvalues: every logged tick needs it.
    re, im = np.empty(5), np.empty(5)
    rx, rz = (0.0, 0.0) if ref_frd_m is None else (float(ref_frd_m[0]), float(ref_frd_m[2]))
    g_c.ghat_ginv_eigs_truth(gi_hat, gc_uam, model.force_per_input, model.moment_o_per_input,
                             float(com_true_frd_m[0]), float(com_true_frd_m[2]), j, m, ref_frd_m is not None, rx, rz,
                             re, im)
    return {
        "eig_real": re.tolist(),
        "eig_imag": im.tolist(),
        "lambda_min": float(lambda_min),
        "lambda_crit": float(lambda_crit),
        "true_inertia_mass": [float(j[0, 0]), float(j[1, 1]), float(j[2, 2]), m],
    }
