"""Navig8-UAM model: arm kinematics, composite mass properties, the inertia rate and G_C, G_I, G.

Pure math (numpy only). Body frame FRD with origin O at the UAV's own centre of mass.
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
class ArmKinematics:
    """Positions (FRD, m) of the arm bodies relative to O, with their first and second time derivatives."""

    theta: np.ndarray  # (3,) absolute link angles
    joints: np.ndarray  # (4, 3) joint 1..3 positions and the tip
    link_com: np.ndarray  # (3, 3) link centres of mass
    object_pos: np.ndarray  # (3,) object centre
    link_com_vel: np.ndarray  # (3, 3)
    object_vel: np.ndarray  # (3,)
    link_com_acc: np.ndarray  # (3, 3)
    object_acc: np.ndarray  # (3,)


def _e(theta: float) -> np.ndarray:
    return np.array([math.sin(theta), 0.0, math.cos(theta)])


def _de(theta: float) -> np.ndarray:
    return np.array([math.cos(theta), 0.0, -math.sin(theta)])


def arm_kinematics(
    cfg: VehicleConfig,
    q: np.ndarray,
    qd: np.ndarray | None = None,
    qdd: np.ndarray | None = None,
) -> ArmKinematics:
    """Planar forward kinematics of the 3-link arm relative to the body (notes 3.1)."""
    q = np.asarray(q, dtype=float)
    qd = np.zeros(N_LINKS) if qd is None else np.asarray(qd, dtype=float)
    qdd = np.zeros(N_LINKS) if qdd is None else np.asarray(qdd, dtype=float)
    theta = np.cumsum(q)
    thd = np.cumsum(qd)
    thdd = np.cumsum(qdd)
    L = cfg.link_length_m
    joints = np.zeros((N_LINKS + 1, 3))
    joints[0] = cfg.mount_frd_m
    jv = np.zeros((N_LINKS + 1, 3))
    ja = np.zeros((N_LINKS + 1, 3))
    com = np.zeros((N_LINKS, 3))
    cv = np.zeros((N_LINKS, 3))
    ca = np.zeros((N_LINKS, 3))
    for i in range(N_LINKS):
        e, de = _e(theta[i]), _de(theta[i])
        # d/dt e = thd de ; d2/dt2 e = thdd de - thd^2 e
        vel_dir = thd[i] * de
        acc_dir = thdd[i] * de - thd[i] ** 2 * e
        com[i] = joints[i] + 0.5 * L * e
        cv[i] = jv[i] + 0.5 * L * vel_dir
        ca[i] = ja[i] + 0.5 * L * acc_dir
        joints[i + 1] = joints[i] + L * e
        jv[i + 1] = jv[i] + L * vel_dir
        ja[i + 1] = ja[i] + L * acc_dir
    d = cfg.object_offset_m
    e3, de3 = _e(theta[-1]), _de(theta[-1])
    obj = joints[-1] + d * e3
    obj_v = jv[-1] + d * thd[-1] * de3
    obj_a = ja[-1] + d * (thdd[-1] * de3 - thd[-1] ** 2 * e3)
    return ArmKinematics(theta, joints, com, obj, cv, obj_v, ca, obj_a)


@dataclass(frozen=True)
class MassProperties:
    """Composite mass properties of UAV + arm (+ object)."""

    mass_kg: float
    com_frd_m: np.ndarray  # (3,) relative to O
    inertia_com: np.ndarray  # (3,3) tensor about the composite CoM, body axes
    inertia_o: np.ndarray  # (3,3) tensor about O


def _rod_inertia(cfg: VehicleConfig, theta: float) -> np.ndarray:
    """Link tensor about its own CoM: Ia (E - e e^T) for a slender rod along e(theta)."""
    e = _e(theta)
    return cfg.link_inertia_kgm2 * (np.eye(3) - np.outer(e, e))


def _point_inertia(m: float, r: np.ndarray) -> np.ndarray:
    return m * (float(r @ r) * np.eye(3) - np.outer(r, r))


def mass_properties(
    cfg: VehicleConfig, q: np.ndarray, object_mass_kg: float = 0.0
) -> MassProperties:
    """Mass, CoM and inertia tensor (about the CoM) for arm pose q and an object in the gripper."""
    kin = arm_kinematics(cfg, q)
    m_l = cfg.link_mass_kg
    m = cfg.uam_mass_kg + object_mass_kg
    first = m_l * kin.link_com.sum(axis=0) + object_mass_kg * kin.object_pos
    com = first / m
    j_o = cfg.uav_inertia_array.copy()
    for i in range(N_LINKS):
        j_o += _rod_inertia(cfg, kin.theta[i]) + _point_inertia(m_l, kin.link_com[i])
    if object_mass_kg > 0.0:
        j_o += object_inertia_kgm2(cfg, object_mass_kg) * np.eye(3)
        j_o += _point_inertia(object_mass_kg, kin.object_pos)
    # Parallel-axis theorem back to the composite CoM.
    j_c = j_o - _point_inertia(m, com)
    return MassProperties(m, com, j_c, j_o)


def inertia_rate(
    cfg: VehicleConfig, q: np.ndarray, qd: np.ndarray, object_mass_kg: float = 0.0
) -> np.ndarray:
    """Time derivative of the inertia tensor about the (moving) composite CoM, body axes (Eq. 22's I-dot).

    I_c = I_O - m (|c|^2 E - c c^T)  =>  dI_c/dt = dI_O/dt - m (2 c.cdot E - cdot c^T - c cdot^T).
    """
    kin = arm_kinematics(cfg, q, qd)
    thd = np.cumsum(np.asarray(qd, dtype=float))
    m_l = cfg.link_mass_kg
    m = cfg.uam_mass_kg + object_mass_kg
    dj_o = np.zeros((3, 3))
    for i in range(N_LINKS):
        th, w = kin.theta[i], thd[i]
        e, de = _e(th), _de(th)
        # rod: d/dt[Ia (E - e e^T)] = -Ia w (de e^T + e de^T)
        dj_o += -cfg.link_inertia_kgm2 * w * (np.outer(de, e) + np.outer(e, de))
        r, v = kin.link_com[i], kin.link_com_vel[i]
        dj_o += m_l * (2.0 * float(r @ v) * np.eye(3) - np.outer(v, r) - np.outer(r, v))
    if object_mass_kg > 0.0:
        r, v = kin.object_pos, kin.object_vel
        dj_o += object_mass_kg * (2.0 * float(r @ v) * np.eye(3) - np.outer(v, r) - np.outer(r, v))
    c = (m_l * kin.link_com.sum(axis=0) + object_mass_kg * kin.object_pos) / m
    cd = (m_l * kin.link_com_vel.sum(axis=0) + object_mass_kg * kin.object_vel) / m
    return dj_o - m * (2.0 * float(c @ cd) * np.eye(3) - np.outer(cd, c) - np.outer(c, cd))


# --------------------------------------------------------------------------------------
# Propulsion (notes 2.1-2.2)
# --------------------------------------------------------------------------------------


def _force_moment_per_input(cfg: VehicleConfig, ref_frd_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Force (3x5) and moment about ref (3x5) per unit of each U component; the wrench is linear in U."""
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
    arms = [r1 - ref_frd_m, r1 - ref_frd_m, r3 - ref_frd_m, r3 - ref_frd_m, r2 - ref_frd_m]
    mom = np.zeros((3, 5))
    for k in range(5):
        mom[:, k] = np.cross(arms[k], f[:, k]) + tq[:, k]
    return f, mom


def propulsion_wrench(
    cfg: VehicleConfig, u: np.ndarray, ref_frd_m: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Total propulsive force (N, FRD) and moment (N m) about ref (default O) for inputs U."""
    ref = np.zeros(3) if ref_frd_m is None else np.asarray(ref_frd_m, dtype=float)
    f, mom = _force_moment_per_input(cfg, ref)
    u = np.asarray(u, dtype=float)
    return f @ u, mom @ u


def control_effectiveness_gc(cfg: VehicleConfig, com_frd_m: np.ndarray) -> np.ndarray:
    """G_C (5x5): rows [L, M, N, Fx, Fz] about the CoM, columns U1..U5 (Eq. 1-2, notes 2.2)."""
    f, mom = _force_moment_per_input(cfg, np.asarray(com_frd_m, dtype=float))
    return np.vstack([mom, f[0:1], f[2:3]])


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


def ghat_ginv_eigenvalues_from_estimate(
    pair: EffectivenessPair, gi_hat: np.ndarray
) -> np.ndarray:
    """Eigenvalues of G_hat G^-1 for an arbitrary G_hat_I: G_hat^-1 = G_C,UAM^-1 G_hat_I (Eq. 4)."""
    ghat = np.linalg.solve(gi_hat, pair.gc_uam)
    g = np.linalg.solve(pair.gi_true, pair.gc_true)
    lam = np.linalg.eigvals(ghat @ np.linalg.inv(g))
    return lam[np.argsort(lam.real)]


# --------------------------------------------------------------------------------------
# U <-> actuators (Sec. 3)
# --------------------------------------------------------------------------------------


def actuators_to_u(alpha1: float, alpha3: float, w1: float, w2: float, w3: float) -> np.ndarray:
    """U = [cos a1 w1^2, sin a1 w1^2, cos a3 w3^2, sin a3 w3^2, sign(w2) w2^2] (Sec. 3)."""
    return np.array(
        [
            math.cos(alpha1) * w1 * w1,
            math.sin(alpha1) * w1 * w1,
            math.cos(alpha3) * w3 * w3,
            math.sin(alpha3) * w3 * w3,
            math.copysign(w2 * w2, w2),
        ]
    )


def u_to_actuators(u: np.ndarray) -> tuple[float, float, float, float, float]:
    """(alpha1, alpha3, w1, w2, w3) from U (Sec. 3): alpha = atan2, w = (U_c^2 + U_s^2)^(1/4)."""
    u1, u2, u3, u4, u5 = (float(v) for v in u)
    a1 = math.atan2(u2, u1)
    a3 = math.atan2(u4, u3)
    w1 = math.hypot(u1, u2) ** 0.5
    w3 = math.hypot(u3, u4) ** 0.5
    w2 = math.copysign(abs(u5) ** 0.5, u5)
    return a1, a3, w1, w2, w3


def hover_trim(cfg: VehicleConfig, q: np.ndarray, object_mass_kg: float) -> np.ndarray:
    """U that produces zero moment about the true CoM, Fx = 0 and Fz = -m g with the body level."""
    mp = mass_properties(cfg, q, object_mass_kg)
    gc = control_effectiveness_gc(cfg, mp.com_frd_m)
    target = np.array([0.0, 0.0, 0.0, 0.0, -mp.mass_kg * cfg.gravity_m_s2])
    return np.linalg.solve(gc, target)


# --------------------------------------------------------------------------------------
# Fast per-tick model of the UAM without object (the controller's view), plain floats
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
    """Precomputed propulsion geometry plus plain-float planar arm maths for the 100 Hz loop.

    Equivalent to mass_properties / inertia_rate / control_effectiveness_gc (tests compare them) but
    ~10x cheaper: the reference functions use numpy on 3-vectors, which is overhead-bound.
    The moment rows of G_C about a point c follow from those about O: M_c = M_O - c x F (notes 2.5).
    """

    def __init__(self, cfg: VehicleConfig) -> None:
        self.cfg = cfg
        f, m0 = _force_moment_per_input(cfg, np.zeros(3))
        self._f = f
        self._m0 = m0
        self._fl = f.tolist()  # plain-float copies for gc_about (5-element rows: lists beat numpy)
        self._m0l = m0.tolist()
        j = cfg.uav_inertia_array
        self._jb = (float(j[0, 0]), float(j[1, 1]), float(j[2, 2]), float(j[0, 2]))

    def gc_about(self, cx: float, cz: float) -> np.ndarray:
        """G_C rows [L, M, N, Fx, Fz] about c = (cx, 0, cz): M_c = M_O - c x F."""
        (f0, f1, f2), (m00, m01, m02) = self._fl, self._m0l
        # c x F with c_y = 0: [-cz Fy, cz Fx - cx Fz, cx Fy]
        return np.array([
            [a + cz * b for a, b in zip(m00, f1, strict=True)],
            [a - (cz * b - cx * c) for a, b, c in zip(m01, f0, f2, strict=True)],
            [a - cx * b for a, b in zip(m02, f1, strict=True)],
            f0,
            f2,
        ])

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
        cfg = self.cfg
        L, ml, ia = cfg.link_length_m, cfg.link_mass_kg, cfg.link_inertia_kgm2
        mx, mz = cfg.mount_frd_m[0], cfg.mount_frd_m[2]
        th = thd = thdd = 0.0
        jx, jz, jvx, jvz, jax, jaz = mx, mz, 0.0, 0.0, 0.0, 0.0
        s1 = s1z = 0.0  # sum m x, sum m z
        v1x = v1z = a1x = a1z = 0.0  # sum m xdot, sum m zdot, sum m xddot, sum m zddot
        j11 = j22 = j33 = j13 = 0.0
        d11 = d22 = d33 = d13 = 0.0
        qdd = (0.0, 0.0, 0.0) if qdd is None else qdd
        for i in range(N_LINKS):
            th += float(q[i])
            thd += float(qd[i])
            thdd += float(qdd[i])
            s, c = math.sin(th), math.cos(th)
            # e = (s, c), e' = (c, -s); d/dt e = thd e'; d2/dt2 e = thdd e' - thd^2 e
            vx, vz = thd * c, -thd * s
            ax, az = thdd * c - thd * thd * s, -thdd * s - thd * thd * c
            h = 0.5 * L
            x, z = jx + h * s, jz + h * c
            xd, zd = jvx + h * vx, jvz + h * vz
            xdd, zdd = jax + h * ax, jaz + h * az
            s1 += ml * x
            s1z += ml * z
            v1x += ml * xd
            v1z += ml * zd
            a1x += ml * xdd
            a1z += ml * zdd
            j11 += ia * c * c + ml * z * z
            j22 += ia + ml * (x * x + z * z)
            j33 += ia * s * s + ml * x * x
            j13 += -ia * s * c - ml * x * z
            s2, c2 = 2.0 * s * c, c * c - s * s
            d11 += -ia * s2 * thd + 2.0 * ml * z * zd
            d22 += 2.0 * ml * (x * xd + z * zd)
            d33 += ia * s2 * thd + 2.0 * ml * x * xd
            d13 += -ia * c2 * thd - ml * (xd * z + x * zd)
            jx, jz = jx + L * s, jz + L * c
            jvx, jvz = jvx + L * vx, jvz + L * vz
            jax, jaz = jax + L * ax, jaz + L * az
        m = cfg.uam_mass_kg
        cx, cz = s1 / m, s1z / m
        cxd, czd = v1x / m, v1z / m
        jb11, jb22, jb33, jb13 = self._jb
        i11 = jb11 + j11 - m * cz * cz
        i22 = jb22 + j22 - m * (cx * cx + cz * cz)
        i33 = jb33 + j33 - m * cx * cx
        i13 = jb13 + j13 + m * cx * cz
        r11 = d11 - 2.0 * m * cz * czd
        r22 = d22 - 2.0 * m * (cx * cxd + cz * czd)
        r33 = d33 - 2.0 * m * cx * cxd
        r13 = d13 + m * (cxd * cz + cx * czd)
        inertia = np.array([[i11, 0.0, i13], [0.0, i22, 0.0], [i13, 0.0, i33]])
        rate = np.array([[r11, 0.0, r13], [0.0, r22, 0.0], [r13, 0.0, r33]])
        # Tip acceleration for a point object (estimated mass) in the CoM-acceleration term.
        mo = max(object_mass_kg, 0.0)
        m_tot = m + mo
        arm_ax = (a1x + mo * jax) / m_tot
        arm_az = (a1z + mo * jaz) / m_tot
        return UamState(
            mass_kg=m,
            com_frd_m=np.array([cx, 0.0, cz]),
            inertia_com=inertia,
            inertia_rate=rate,
            gc=self.gc_about(cx, cz),
            arm_accel_xz=(arm_ax, arm_az),
        )


def _eig_inputs(
    model: UamModel,
    q_est_rad: Sequence3,
    gi_hat_flat: Sequence[float],
    com_true_frd_m: Sequence3,
    inertia_true: np.ndarray,
    mass_true_kg: float,
    gc_uam_flat: Sequence[float] | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    gc_uam = (model.evaluate(q_est_rad, (0.0, 0.0, 0.0)).gc if gc_uam_flat is None
              else np.array(gc_uam_flat, dtype=float).reshape(5, 5))
    gi_hat = np.array(gi_hat_flat, dtype=float).reshape(5, 5)
    gc_true = model.gc_about(float(com_true_frd_m[0]), float(com_true_frd_m[2]))
    gi_true = inertia_matrix_gi(np.asarray(inertia_true, dtype=float), float(mass_true_kg))
    return gi_hat, gc_uam, gc_true, gi_true


def _eig_record(lam_re: Sequence[float], lam_im: Sequence[float], gi_true: np.ndarray, mass_true_kg: float,
                lambda_min: float, lambda_crit: float) -> dict[str, Any]:
    return {
        "eig_real": list(lam_re),
        "eig_imag": list(lam_im),
        "lambda_min": float(lambda_min),
        "lambda_crit": float(lambda_crit),
        "true_inertia_mass": [float(gi_true[0, 0]), float(gi_true[1, 1]), float(gi_true[2, 2]), float(mass_true_kg)],
    }


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
    *,
    compiled: bool = True,
) -> dict[str, Any]:
    """Eigenvalues of G_hat G^-1 (Eq. 14) with G from the plant's truth, as the /analysis/eig log record.

    G_hat^-1 = G_C,UAM(q_est)^-1 G_hat_I (Eq. 4) and G^-1 = G_C,true^-1 G_I,true, so
    G_hat G^-1 = (G_hat_I^-1 G_C,UAM)(G_C,true^-1 G_I,true). gc_uam_flat: the G_C,UAM(q_est) the controller
    used this tick (ControllerStatus.gc_uam), else it is evaluated here. The linear algebra runs in a numba
    kernel (every logged tick needs it); compiled=False runs the numpy reference the tests compare it with.
    Used by the in-process runner and the SITL FC.
    """
    gi_hat, gc_uam, gc_true, gi_true = _eig_inputs(model, q_est_rad, gi_hat_flat, com_true_frd_m, inertia_true,
                                                   mass_true_kg, gc_uam_flat)
    if compiled:
        from navig8_fc.core import _kernels as _k  # numba: imported on first use, not by every user of the model

        re, im = np.empty(5), np.empty(5)
        _k.ghat_ginv_eigs(gi_hat, gc_uam, gc_true, gi_true, re, im)
        return _eig_record(re.tolist(), im.tolist(), gi_true, mass_true_kg, lambda_min, lambda_crit)
    lam = np.linalg.eigvals(np.linalg.solve(gi_hat, gc_uam) @ np.linalg.solve(gc_true, gi_true))
    lam = lam[np.argsort(lam.real)]
    return _eig_record(lam.real.tolist(), lam.imag.tolist(), gi_true, mass_true_kg, lambda_min, lambda_crit)
