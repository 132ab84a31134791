"""Independent oracles for the vehicle model (notes 3.1-3.2), written in vector form with numpy.

The model kernels (navig8_fc/core/g_c.py: mass_props, uam_model) sum the planar terms of notes 3.2 in
plain floats; these oracles build the same bodies as vectors and point masses instead, so a test that agrees
with them checks the kernel, not a transcription of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from navig8_fc.core.vehicle import N_LINKS, VehicleConfig


@dataclass(frozen=True)
class ArmKinematics:
    """Positions (FRD, m) of the arm bodies relative to O, with their first and second time derivatives."""

    theta: np.ndarray  # (3,) absolute link angles
    theta_dir: np.ndarray  # (3, 3) link directions e(theta)
    joints: np.ndarray  # (4, 3) joint 1..3 positions and the tip
    link_com: np.ndarray  # (3, 3) link centres of mass
    object_pos: np.ndarray  # (3,) object centre
    link_com_vel: np.ndarray  # (3, 3)
    object_vel: np.ndarray  # (3,)
    link_com_acc: np.ndarray  # (3, 3)
    object_acc: np.ndarray  # (3,)
    tip_acc: np.ndarray  # (3,) end of link 3


def _e(theta: float) -> np.ndarray:
    return np.array([math.sin(theta), 0.0, math.cos(theta)])


def _de(theta: float) -> np.ndarray:
    return np.array([math.cos(theta), 0.0, -math.sin(theta)])


def arm_kinematics(cfg: VehicleConfig, q, qd=None, qdd=None) -> ArmKinematics:
    """Planar forward kinematics of the 3-link arm relative to the body (notes 3.1): theta_i = q_1 + .. + q_i,
    e(theta) = [sin, 0, cos], d/dt e = theta' e', d2/dt2 e = theta'' e' - theta'^2 e."""
    q = np.asarray(q, dtype=float)
    qd = np.zeros(N_LINKS) if qd is None else np.asarray(qd, dtype=float)
    qdd = np.zeros(N_LINKS) if qdd is None else np.asarray(qdd, dtype=float)
    theta, thd, thdd = np.cumsum(q), np.cumsum(qd), np.cumsum(qdd)
    L = cfg.link_length_m
    joints, jv, ja = np.zeros((N_LINKS + 1, 3)), np.zeros((N_LINKS + 1, 3)), np.zeros((N_LINKS + 1, 3))
    joints[0] = cfg.mount_frd_m
    com, cv, ca = np.zeros((N_LINKS, 3)), np.zeros((N_LINKS, 3)), np.zeros((N_LINKS, 3))
    for i in range(N_LINKS):
        e, de = _e(theta[i]), _de(theta[i])
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
    dirs = np.array([_e(t) for t in theta])
    return ArmKinematics(theta, dirs, joints, com, obj, cv, obj_v, ca, obj_a, ja[-1])


def point_inertia(m: float, r: np.ndarray) -> np.ndarray:
    """m (|r|^2 E - r r^T): a point mass's inertia tensor about the origin of r."""
    return m * (float(r @ r) * np.eye(3) - np.outer(r, r))


def composite(cfg: VehicleConfig, points: list[tuple[float, np.ndarray]],
              own_inertia: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """UAV (inertia about O, its CoM) + point masses + extra own inertia: m, CoM, J about the CoM, J about O."""
    m = cfg.uav_mass_kg + sum(w for w, _ in points)
    c = sum((w * r for w, r in points), np.zeros(3)) / m
    j_o = cfg.uav_inertia_array + own_inertia + sum((point_inertia(w, r) for w, r in points), np.zeros((3, 3)))
    return m, c, j_o - point_inertia(m, c), j_o


def _object(cfg: VehicleConfig, kin: ArmKinematics, m_obj: float):
    if m_obj <= 0.0:
        return [], np.zeros((3, 3))
    return [(m_obj, kin.object_pos)], 0.4 * m_obj * cfg.object_radius_m**2 * np.eye(3)


def dumbbell_mass_properties(cfg: VehicleConfig, q, m_obj: float = 0.0):
    """Each link as two point masses m/2 at its centre +- d e with 2 (m/2) d^2 = Ia (the rod's transverse inertia
    exactly, none along the link); the object a point plus its sphere inertia. Returns m, c, J_c, J_O."""
    kin = arm_kinematics(cfg, q)
    d = math.sqrt(cfg.link_inertia_kgm2 / cfg.link_mass_kg)
    pts = []
    for i in range(N_LINKS):
        e = _e(kin.theta[i])
        pts += [(cfg.link_mass_kg / 2, kin.link_com[i] + d * e), (cfg.link_mass_kg / 2, kin.link_com[i] - d * e)]
    obj_pts, obj_j = _object(cfg, kin, m_obj)
    return composite(cfg, pts + obj_pts, obj_j)


def rod_mass_properties(cfg: VehicleConfig, q, m_obj: float, n: int):
    """Each link a row of n equal point masses at the midpoints of n equal segments (a uniform rod as n -> inf).

    Its transverse inertia about the link centre is m L^2 / 12 (1 - 1/n^2): the discretisation error per link
    is m L^2 / (12 n^2), the bound the convergence test states."""
    kin = arm_kinematics(cfg, q)
    L, ml = cfg.link_length_m, cfg.link_mass_kg
    pts = []
    for i in range(N_LINKS):
        e = _e(kin.theta[i])
        for k in range(n):
            s = (k + 0.5) / n * L
            pts.append((ml / n, kin.joints[i] + s * e))
    obj_pts, obj_j = _object(cfg, kin, m_obj)
    return composite(cfg, pts + obj_pts, obj_j)


def wrench_from_actuators(cfg: VehicleConfig, a1, a3, w1, w2, w3, ref) -> tuple[np.ndarray, np.ndarray]:
    """Propulsion force and moment about ref straight from the duct geometry (notes 2.1)."""
    g = cfg.dihedral_rad
    r1 = np.array(cfg.duct_right_frd_m)
    r3 = r1 * [1, -1, 1]
    r2 = np.array(cfg.tail_frd_m)
    d1 = np.array([math.sin(a1), -math.sin(g) * math.cos(a1), -math.cos(g) * math.cos(a1)])
    d3 = np.array([math.sin(a3), math.sin(g) * math.cos(a3), -math.cos(g) * math.cos(a3)])
    f1 = cfg.k_thrust_duct * w1 * w1 * d1
    f3 = cfg.k_thrust_duct * w3 * w3 * d3
    f2 = -cfg.k_thrust_tail * math.copysign(w2 * w2, w2) * np.array([0, 0, 1.0])
    t1 = -cfg.spin_duct1 * cfg.k_torque_duct * w1 * w1 * d1
    t3 = cfg.spin_duct1 * cfg.k_torque_duct * w3 * w3 * d3
    t2 = cfg.spin_tail * cfg.k_torque_tail * math.copysign(w2 * w2, w2) * np.array([0, 0, 1.0])
    f = f1 + f2 + f3
    m = np.cross(r1 - ref, f1) + np.cross(r3 - ref, f3) + np.cross(r2 - ref, f2) + t1 + t2 + t3
    return f, m
