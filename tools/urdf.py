"""Generate the Navig8-UAM URDF (params/navig8_uam.urdf) from params/vehicle.yaml, the one source of truth.

`navig8-urdf` prints it, `navig8-urdf --write` rewrites the packaged file, `navig8-urdf --check` exits 1 when the
committed file differs from what the vehicle file gives now (a unit test does the same).

Axis convention (docs/urdf.md): the URDF root `base_link` IS the body frame of the whole project, FRD with its
origin at the UAV's own centre of mass, so every number here is the vehicle file's, unconverted. A fixed child
`base_link_flu` (roll pi) gives ROS tools the REP-103 forward-left-up body. Foxglove shows the vehicle upright when
the log's `world` frame is ENU (z up) and the `world -> base_link` transform carries the FRD body's pose in it.

Tree (frame names the log transforms use; * = movable joint, the log publishes it):
    base_link -> base_link_flu
    base_link -*duct_1_tilt-> duct_1,  base_link -*duct_3_tilt-> duct_3,  base_link -> tail
    base_link -> arm_mount -*joint_1-> link_1 -*joint_2-> link_2 -*joint_3-> link_3 -> gripper -> object

Joint positions are the project's own variables: duct tilts alpha1, alpha3 (rad, > 0 tilts the thrust forward)
and arm angles q1..q3 (rad, q = 0 points down, > 0 swings forward; the arm kinematics of docs/model.md).
Masses: the UAV of Table 1 (ducts and tail included) on base_link, one slender rod per link; the frames
duct_*, tail, arm_mount, gripper and object carry no mass, so the URDF's total equals the model's m_UAM.
Sizes used only for drawing (duct and propeller radii, rod thickness) are navig8_fc.viz.DisplaySizes
(the Foxglove scene draws with them too).
"""

from __future__ import annotations

import argparse
import math
import sys
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

from navig8_fc.core.vehicle import N_LINKS, VehicleConfig
from navig8_fc.viz import DisplaySizes, uav_size_m  # one copy: the Foxglove scene draws the same sizes

URDF_FILE_NAME = "navig8_uam.urdf"
ROBOT_NAME = "navig8_uam"


def default_urdf_path() -> Path:
    """The packaged URDF (params/navig8_uam.urdf in a source checkout)."""
    return Path(str(files("navig8_params") / URDF_FILE_NAME))


def _vehicle_text(vehicle_path: Path | None) -> str:
    if vehicle_path is None:
        return (files("navig8_params") / "vehicle.yaml").read_text()
    return vehicle_path.read_text()


def _num(x: float) -> str:
    # repr round-trips every float exactly, so the file reproduces the YAML's values to the last bit.
    text = repr(float(x) + 0.0)  # + 0.0 turns -0.0 into 0.0
    return text[:-2] if text.endswith(".0") else text


def _vec(v: Sequence[float]) -> str:
    return " ".join(_num(x) for x in v)


def _origin(parent: ET.Element, xyz_m: Sequence[float] = (0.0, 0.0, 0.0),
            rpy_rad: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
    ET.SubElement(parent, "origin", xyz=_vec(xyz_m), rpy=_vec(rpy_rad))


@dataclass(frozen=True)
class _Shape:
    """One primitive drawn and collided at an offset in its link's frame."""

    kind: str  # box | cylinder (axis along the frame's z) | sphere
    dims: dict[str, str]
    xyz_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    material: str = "grey"


def _box(size_m: Sequence[float], xyz_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
         material: str = "grey") -> _Shape:
    return _Shape("box", {"size": _vec(size_m)}, xyz_m, material)


def _cylinder(radius_m: float, length_m: float, xyz_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
              material: str = "grey") -> _Shape:
    return _Shape("cylinder", {"radius": _num(radius_m), "length": _num(length_m)}, xyz_m, material)


def _link(robot: ET.Element, name: str, shape: _Shape | None = None, mass_kg: float | None = None,
          com_m: Sequence[float] = (0.0, 0.0, 0.0), inertia_kgm2: Sequence[Sequence[float]] | None = None) -> None:
    link = ET.SubElement(robot, "link", name=name)
    if mass_kg is not None and inertia_kgm2 is not None:
        inertial = ET.SubElement(link, "inertial")
        _origin(inertial, com_m)
        ET.SubElement(inertial, "mass", value=_num(mass_kg))
        j = inertia_kgm2
        # URDF stores the tensor's entries (ixz = J13), in the link frame, about com_m.
        ET.SubElement(inertial, "inertia", ixx=_num(j[0][0]), ixy=_num(j[0][1]), ixz=_num(j[0][2]),
                      iyy=_num(j[1][1]), iyz=_num(j[1][2]), izz=_num(j[2][2]))
    if shape is not None:
        for tag in ("visual", "collision"):
            el = ET.SubElement(link, tag)
            _origin(el, shape.xyz_m)
            ET.SubElement(ET.SubElement(el, "geometry"), shape.kind, **shape.dims)
            if tag == "visual":
                ET.SubElement(el, "material", name=shape.material)


def _joint(robot: ET.Element, name: str, kind: str, parent: str, child: str, xyz_m: Sequence[float] = (0.0, 0.0, 0.0),
           rpy_rad: Sequence[float] = (0.0, 0.0, 0.0), axis: Sequence[float] | None = None,
           limit_rad: tuple[float, float] | None = None) -> None:
    joint = ET.SubElement(robot, "joint", name=name, type=kind)
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=child)
    _origin(joint, xyz_m, rpy_rad)
    if axis is not None:
        ET.SubElement(joint, "axis", xyz=_vec(axis))
    if limit_rad is not None:
        # URDF requires effort and velocity; the vehicle file has neither, 0 = not modelled.
        ET.SubElement(joint, "limit", lower=_num(limit_rad[0]), upper=_num(limit_rad[1]), effort="0", velocity="0")


_MATERIALS = {
    "body": (0.75, 0.75, 0.78, None),
    "duct": (0.15, 0.35, 0.75, 1.0),
    "tail": (0.85, 0.45, 0.10, 1.0),
    "arm": (0.20, 0.20, 0.20, 1.0),
    "gripper": (0.80, 0.10, 0.10, 1.0),
}


def build_urdf(cfg: VehicleConfig, size_m: tuple[float, float, float],
               display: DisplaySizes | None = None) -> ET.Element:
    """The URDF tree of the Navig8-UAM for the vehicle constants cfg and Table 1's body envelope size_m."""
    d = DisplaySizes() if display is None else display
    robot = ET.Element("robot", name=ROBOT_NAME)
    # XML comments cannot hold "--", so the command's option is spelled out.
    robot.append(ET.Comment(" Generated from params/vehicle.yaml by navig8-urdf (tools/urdf.py) with its write option:"
                            " do not edit. Frames and axes: docs/urdf.md. Root base_link = body FRD at the UAV CoM. "))
    for name, (r, g, b, a) in _MATERIALS.items():
        alpha = d.body_alpha if a is None else a
        ET.SubElement(ET.SubElement(robot, "material", name=name), "color", rgba=_vec((r, g, b, alpha)))

    # Body: Table 1's mass and inertia (tensor about O, FRD, J13 = -xz_table as the model reads it).
    _link(robot, "base_link", _box(size_m, material="body"), cfg.uav_mass_kg, (0.0, 0.0, 0.0), cfg.uav_inertia)
    _link(robot, "base_link_flu")
    _joint(robot, "base_link_flu_fixed", "fixed", "base_link", "base_link_flu", rpy_rad=(math.pi, 0.0, 0.0))

    # Ducts: the fixed roll is the dihedral (thrust canted inboard), the tilt turns about the rolled frame's -y so
    # that the joint position is alpha and the thrust axis (-z of duct_i) is the model's
    # d1 = [sin a1, -sin g cos a1, -cos g cos a1] (duct 1, right) and its mirror d3 (duct 3, left).
    duct_shape = _cylinder(d.duct_radius_m, d.duct_length_m, material="duct")
    right = cfg.duct_right_frd_m
    left = (right[0], -right[1], right[2])
    tilt_limits = (cfg.tilt_min_rad, cfg.tilt_max_rad)
    for name, pos, roll in (("duct_1", right, -cfg.dihedral_rad), ("duct_3", left, cfg.dihedral_rad)):
        _link(robot, name, duct_shape)
        _joint(robot, f"{name}_tilt", "revolute", "base_link", name, pos, (roll, 0.0, 0.0), (0.0, -1.0, 0.0),
               tilt_limits)

    # Tail propeller: a disc with its thrust axis along body z. Fixed: a spinning disc looks the same at every
    # angle, and a movable joint would need a transform in every log for nothing.
    _link(robot, "tail", _cylinder(d.tail_prop_radius_m, d.tail_prop_thickness_m, material="tail"))
    _joint(robot, "tail_fixed", "fixed", "base_link", "tail", cfg.tail_frd_m)

    # Arm: link i's frame sits at joint i with z along the rod, so link direction e(theta) = R_y(theta) z =
    # (sin theta, 0, cos theta) with theta the cumulative angle (arm_kinematics). Rods: mass at mid-length,
    # link_inertia about the transverse axes, 0 along the rod.
    half = 0.5 * d.mount_size_m
    _link(robot, "arm_mount", _box((d.mount_size_m,) * 3, (0.0, 0.0, -half), material="arm"))
    _joint(robot, "arm_mount_fixed", "fixed", "base_link", "arm_mount", cfg.mount_frd_m)
    length = cfg.link_length_m
    ia = cfg.link_inertia_kgm2
    rod_inertia = ((ia, 0.0, 0.0), (0.0, ia, 0.0), (0.0, 0.0, 0.0))
    parent, joint_xyz = "arm_mount", (0.0, 0.0, 0.0)
    for i in range(1, N_LINKS + 1):
        mid = (0.0, 0.0, 0.5 * length)
        _link(robot, f"link_{i}", _cylinder(d.link_radius_m, length, mid, material="arm"), cfg.link_mass_kg, mid,
              rod_inertia)
        _joint(robot, f"joint_{i}", "revolute", parent, f"link_{i}", joint_xyz, axis=(0.0, 1.0, 0.0),
               limit_rad=(-cfg.joint_limit_rad, cfg.joint_limit_rad))
        parent, joint_xyz = f"link_{i}", (0.0, 0.0, length)

    # Gripper frame at the tip of link 3; the object frame at the held object's centre (offset along the link).
    gx, gy, gz = d.gripper_size_m
    _link(robot, "gripper", _box((gx, gy, gz), (0.0, 0.0, -0.5 * gz), material="gripper"))
    _joint(robot, "gripper_fixed", "fixed", f"link_{N_LINKS}", "gripper", joint_xyz)
    _link(robot, "object")
    _joint(robot, "object_fixed", "fixed", "gripper", "object", (0.0, 0.0, cfg.object_offset_m))
    return robot


def render(vehicle_path: Path | None = None, display: DisplaySizes | None = None) -> str:
    """The URDF text for the vehicle file (default: the packaged params/vehicle.yaml)."""
    text = _vehicle_text(vehicle_path)
    cfg = VehicleConfig.load(vehicle_path)
    robot = build_urdf(cfg, uav_size_m(text), display)
    ET.indent(robot, space="  ")
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicle", type=Path, help="vehicle file (default: the packaged params/vehicle.yaml)")
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--write", nargs="?", type=Path, const=default_urdf_path(), metavar="PATH",
                       help="write the URDF (default: the packaged params/navig8_uam.urdf)")
    group.add_argument("--check", nargs="?", type=Path, const=default_urdf_path(), metavar="PATH",
                       help="exit 1 when the file (default: the packaged URDF) differs from a fresh generation")
    args = ap.parse_args(argv)
    text = render(args.vehicle)
    if args.write is not None:
        args.write.write_text(text)
        return 0
    if args.check is not None:
        current = args.check.read_text() if args.check.exists() else None
        if current != text:
            print(f"{args.check} is stale: run `navig8-urdf --write`", file=sys.stderr)
            return 1
        return 0
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
