"""params/navig8_uam.urdf: current, a valid tree, and the same vehicle as the model.

The kinematic and mass checks walk the URDF with their own homogeneous transforms (rpy and Rodrigues from the XML
text, written here independently of tools/urdf.py) and compare with the vector-form model
(tests/unit/model_oracle.py) arm_kinematics for the frames, and with navig8_fc.core.vehicle's propulsion_wrench
for the thrust axes and mass_properties for mass, CoM and inertia.
"""

from __future__ import annotations

import math
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from model_oracle import arm_kinematics

from navig8_fc.core.vehicle import VehicleConfig, mass_properties, propulsion_wrench
from navig8_tools.urdf import default_urdf_path, main, render

ROOT = Path(__file__).resolve().parents[2]
URDF = ROOT / "params" / "navig8_uam.urdf"
TOL_M = 1e-9  # positions: the file holds the YAML's floats exactly, so only rounding in the walk remains
TOL_DIR = 1e-12  # unit vectors
N_POSES = 200


# ---- an independent URDF reader and forward-kinematics walk ------------------------------------------------------


@dataclass(frozen=True)
class Joint:
    name: str
    kind: str
    parent: str
    child: str
    xyz: np.ndarray
    rpy: np.ndarray
    axis: np.ndarray | None
    limits: tuple[float, float] | None


@dataclass(frozen=True)
class Inertial:
    mass_kg: float
    com_m: np.ndarray  # in the link frame
    rot: np.ndarray  # inertial frame -> link frame
    tensor: np.ndarray  # about com_m, inertial-frame axes


def _floats(text: str) -> np.ndarray:
    return np.array([float(t) for t in text.split()])


def _parse(text: str) -> tuple[dict[str, ET.Element], dict[str, Joint]]:
    robot = ET.fromstring(text)
    assert robot.tag == "robot"
    links = {el.get("name"): el for el in robot.findall("link")}
    joints: dict[str, Joint] = {}
    for el in robot.findall("joint"):
        origin = el.find("origin")
        axis = el.find("axis")
        limit = el.find("limit")
        joints[el.get("name")] = Joint(
            name=el.get("name"),
            kind=el.get("type"),
            parent=el.find("parent").get("link"),
            child=el.find("child").get("link"),
            xyz=_floats(origin.get("xyz", "0 0 0")) if origin is not None else np.zeros(3),
            rpy=_floats(origin.get("rpy", "0 0 0")) if origin is not None else np.zeros(3),
            axis=_floats(axis.get("xyz")) if axis is not None else None,
            limits=(float(limit.get("lower")), float(limit.get("upper"))) if limit is not None else None,
        )
    return links, joints


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rpy(rpy: np.ndarray) -> np.ndarray:
    """URDF fixed-axis roll, pitch, yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    return _rot_z(rpy[2]) @ _rot_y(rpy[1]) @ _rot_x(rpy[0])


def _rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    k = axis / np.linalg.norm(axis)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * kx @ kx


def _homogeneous(rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = pos
    return t


def _pose(joints: dict[str, Joint], frame: str, positions: dict[str, float]) -> np.ndarray:
    """4x4 transform frame -> root, composing each joint's origin and its motion about its axis."""
    by_child = {j.child: j for j in joints.values()}
    t = np.eye(4)
    while frame in by_child:
        j = by_child[frame]
        motion = np.eye(4)
        if j.kind in ("revolute", "continuous"):
            motion = _homogeneous(_rodrigues(j.axis, positions.get(j.name, 0.0)), np.zeros(3))
        t = _homogeneous(_rpy(j.rpy), j.xyz) @ motion @ t
        frame = j.parent
    return t


def _inertial(link: ET.Element) -> Inertial | None:
    el = link.find("inertial")
    if el is None:
        return None
    origin = el.find("origin")
    i = el.find("inertia").attrib
    v = {k: float(x) for k, x in i.items()}
    tensor = np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]], [v["ixz"], v["iyz"], v["izz"]]])
    return Inertial(
        mass_kg=float(el.find("mass").get("value")),
        com_m=_floats(origin.get("xyz", "0 0 0")) if origin is not None else np.zeros(3),
        rot=_rpy(_floats(origin.get("rpy", "0 0 0"))) if origin is not None else np.eye(3),
        tensor=tensor,
    )


@pytest.fixture(scope="module")
def urdf() -> tuple[dict[str, ET.Element], dict[str, Joint]]:
    return _parse(URDF.read_text())


def _arm_positions(q: np.ndarray) -> dict[str, float]:
    return {f"joint_{i + 1}": float(q[i]) for i in range(3)}


def _random_arm_poses(joints: dict[str, Joint], n: int) -> np.ndarray:
    rng = np.random.default_rng(14)
    lo = np.array([joints[f"joint_{i}"].limits[0] for i in (1, 2, 3)])
    hi = np.array([joints[f"joint_{i}"].limits[1] for i in (1, 2, 3)])
    return rng.uniform(lo, hi, size=(n, 3))


# ---- the file and the tool ---------------------------------------------------------------------------------------


def test_committed_urdf_is_current() -> None:
    assert URDF.read_text() == render(), "params/navig8_uam.urdf is stale: run `navig8-urdf --write`"
    assert default_urdf_path().read_text() == URDF.read_text()


def test_check_and_write(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "uam.urdf"
    assert main(["--check", str(out)]) == 1  # missing
    assert main(["--write", str(out)]) == 0
    assert out.read_text() == URDF.read_text()
    assert main(["--check", str(out)]) == 0
    out.write_text(out.read_text().replace('<mass value="5" />', '<mass value="5.1" />'))
    assert main(["--check", str(out)]) == 1
    assert "stale" in capsys.readouterr().err
    # A changed vehicle file changes the URDF: the YAML is the source.
    vehicle = tmp_path / "vehicle.yaml"
    yaml_text = (ROOT / "params" / "vehicle.yaml").read_text()
    vehicle.write_text(yaml_text.replace("link_length_m: 0.3", "link_length_m: 0.4"))
    assert main(["--vehicle", str(vehicle), "--check", str(URDF)]) == 1


def test_packaged_with_a_console_script() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert project["project"]["scripts"]["navig8-urdf"] == "navig8_tools.urdf:main"
    assert "*.urdf" in project["tool"]["setuptools"]["package-data"]["navig8_params"]


# ---- structure ---------------------------------------------------------------------------------------------------


def test_urdf_is_a_tree(urdf) -> None:
    links, joints = urdf
    assert len(joints) == len(links) - 1
    children = [j.child for j in joints.values()]
    assert len(set(children)) == len(children), "a link with two parents"
    for j in joints.values():
        assert j.parent in links and j.child in links, j.name
    roots = set(links) - set(children)
    assert roots == {"base_link"}
    # Every link reaches the root without revisiting a link (no cycles).
    by_child = {j.child: j.parent for j in joints.values()}
    for name in links:
        seen = {name}
        while name in by_child:
            name = by_child[name]
            assert name not in seen, f"cycle through {name}"
            seen.add(name)
        assert name == "base_link"
    expected = {"base_link", "base_link_flu", "duct_1", "duct_3", "tail", "arm_mount", "link_1", "link_2", "link_3",
                "gripper", "object"}
    assert set(links) == expected
    movable = {j.name: (j.parent, j.child) for j in joints.values() if j.kind != "fixed"}
    assert movable == {"duct_1_tilt": ("base_link", "duct_1"), "duct_3_tilt": ("base_link", "duct_3"),
                       "joint_1": ("arm_mount", "link_1"), "joint_2": ("link_1", "link_2"),
                       "joint_3": ("link_2", "link_3")}
    for j in joints.values():
        if j.kind == "revolute":
            assert j.limits is not None and j.limits[0] < j.limits[1]
            assert abs(np.linalg.norm(j.axis) - 1.0) < TOL_DIR
    for name, link in links.items():
        for tag in ("visual", "collision"):
            if name not in ("base_link_flu", "object"):
                assert link.find(f"{tag}/geometry") is not None, (name, tag)


def test_limits_are_the_vehicle_files(urdf, cfg: VehicleConfig) -> None:
    _, joints = urdf
    for i in (1, 2, 3):
        assert joints[f"joint_{i}"].limits == (-cfg.joint_limit_rad, cfg.joint_limit_rad)
    for name in ("duct_1_tilt", "duct_3_tilt"):
        assert joints[name].limits == (cfg.tilt_min_rad, cfg.tilt_max_rad)


def test_base_link_flu_is_forward_left_up(urdf) -> None:
    _, joints = urdf
    rot = _pose(joints, "base_link_flu", {})[:3, :3]
    np.testing.assert_allclose(rot, np.diag([1.0, -1.0, -1.0]), atol=TOL_DIR)


# ---- kinematics --------------------------------------------------------------------------------------------------


def test_arm_frames_follow_arm_kinematics(urdf, cfg: VehicleConfig) -> None:
    links, joints = urdf
    for q in _random_arm_poses(joints, N_POSES):
        kin = arm_kinematics(cfg, q)
        pos = _arm_positions(q)
        for i in (1, 2, 3):
            t = _pose(joints, f"link_{i}", pos)
            np.testing.assert_allclose(t[:3, 3], kin.joints[i - 1], rtol=0, atol=TOL_M)
            com = t @ np.append(_inertial(links[f"link_{i}"]).com_m, 1.0)
            np.testing.assert_allclose(com[:3], kin.link_com[i - 1], rtol=0, atol=TOL_M)
            # the rod (link z) points along e(theta_i) = (sin theta, 0, cos theta)
            th = kin.theta[i - 1]
            np.testing.assert_allclose(t[:3, 2], [math.sin(th), 0.0, math.cos(th)], rtol=0, atol=TOL_DIR)
        np.testing.assert_allclose(_pose(joints, "gripper", pos)[:3, 3], kin.joints[-1], rtol=0, atol=TOL_M)
        e3 = np.array([math.sin(kin.theta[-1]), 0.0, math.cos(kin.theta[-1])])
        object_pos = _pose(joints, "object", pos)[:3, 3]
        np.testing.assert_allclose(object_pos, kin.joints[-1] + cfg.object_offset_m * e3, rtol=0, atol=TOL_M)
        np.testing.assert_allclose(object_pos, kin.object_pos, rtol=0, atol=TOL_M)


def test_q_zero_hangs_straight_down(urdf, cfg: VehicleConfig) -> None:
    _, joints = urdf
    tip = _pose(joints, "gripper", {})[:3, 3]
    expected = np.array(cfg.mount_frd_m) + np.array([0.0, 0.0, 3 * cfg.link_length_m])  # +z FRD = down
    np.testing.assert_allclose(tip, expected, rtol=0, atol=TOL_M)


def test_ducts_and_tail_match_the_propulsion_model(urdf, cfg: VehicleConfig) -> None:
    """Duct centres from the YAML; each duct's -z (thrust) axis at tilt alpha is the model's thrust direction."""
    _, joints = urdf
    right = np.array(cfg.duct_right_frd_m)
    np.testing.assert_allclose(_pose(joints, "duct_1", {})[:3, 3], right, rtol=0, atol=TOL_M)
    np.testing.assert_allclose(_pose(joints, "duct_3", {})[:3, 3], right * [1.0, -1.0, 1.0], rtol=0, atol=TOL_M)
    np.testing.assert_allclose(_pose(joints, "tail", {})[:3, 3], cfg.tail_frd_m, rtol=0, atol=TOL_M)
    rng = np.random.default_rng(3)
    for alpha in np.concatenate([[0.0, cfg.tilt_min_rad, cfg.tilt_max_rad], rng.uniform(cfg.tilt_min_rad,
                                                                                         cfg.tilt_max_rad, 50)]):
        c, s = math.cos(alpha), math.sin(alpha)
        for name, u in (("duct_1", [c, s, 0.0, 0.0, 0.0]), ("duct_3", [0.0, 0.0, c, s, 0.0])):
            force, _ = propulsion_wrench(cfg, np.array(u))
            t = _pose(joints, name, {f"{name}_tilt": float(alpha)})
            np.testing.assert_allclose(t[:3, 3], _pose(joints, name, {})[:3, 3], rtol=0, atol=TOL_M)  # tilts in place
            np.testing.assert_allclose(-t[:3, 2], force / cfg.k_thrust_duct, rtol=0, atol=TOL_DIR)
    force, _ = propulsion_wrench(cfg, np.array([0.0, 0.0, 0.0, 0.0, 1.0]))
    np.testing.assert_allclose(-_pose(joints, "tail", {})[:3, 2], force / cfg.k_thrust_tail, rtol=0, atol=TOL_DIR)


# ---- mass properties ---------------------------------------------------------------------------------------------


def _urdf_mass_properties(links, joints, q: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Total mass, CoM (base_link) and inertia tensor about the CoM from the URDF's inertials at arm pose q."""
    pos = _arm_positions(q)
    bodies = []
    for name, link in links.items():
        inertial = _inertial(link)
        if inertial is None:
            continue
        t = _pose(joints, name, pos)
        rot = t[:3, :3] @ inertial.rot
        bodies.append((inertial.mass_kg, t[:3, :3] @ inertial.com_m + t[:3, 3], rot @ inertial.tensor @ rot.T))
    m = sum(b[0] for b in bodies)
    com = sum(b[0] * b[1] for b in bodies) / m
    tensor = np.zeros((3, 3))
    for mi, ri, ji in bodies:
        d = ri - com
        tensor += ji + mi * (float(d @ d) * np.eye(3) - np.outer(d, d))
    return m, com, tensor


def test_mass_and_com_equal_the_model(urdf, cfg: VehicleConfig) -> None:
    links, joints = urdf
    for q in np.vstack([np.zeros((1, 3)), _random_arm_poses(joints, 20)]):
        m, com, tensor = _urdf_mass_properties(links, joints, q)
        mp = mass_properties(cfg, q, 0.0)
        assert abs(m - mp.mass_kg) < 1e-9
        np.testing.assert_allclose(com, mp.com_frd_m, rtol=0, atol=1e-9)
        np.testing.assert_allclose(tensor, mp.inertia_com, rtol=0, atol=1e-9)
