"""Foxglove well-known records (JSON encoding) of the vehicle: what Foxglove's 3D panel draws (docs/foxglove.md).

- `foxglove.FrameTransforms`: world (ENU) -> base_link (FRD body) -> duct_1/duct_3 (tilt) / tail / arm_mount ->
  link_1 -> link_2 -> link_3 -> gripper -> object, the frame names and joint conventions of the URDF
  (docs/urdf.md, params/navig8_uam.urdf); a second tree with prefixed frame names (`est/base_link`, ...) from
  the flight controller's own view (its sensors' pose and tilts, its joint estimate q_est).
- `foxglove.SceneUpdate`: the vehicle drawn from its geometry (body box, duct and tail cylinders, arm rods, the
  gripper, the held object as a sphere whose volume follows its mass), thrust arrows, the setpoint as a ghost.
- `foxglove.PoseInFrame` / `foxglove.PosesInFrame`: the vehicle's pose, its path, the mission's waypoints.
- `foxglove.Log`: a STATUSTEXT.

Pure: numbers in, JSON-ready dicts out (no clocks, no sockets, no files). Positions in m, angles in rad,
quaternions (w, x, y, z) inside and Foxglove's {x, y, z, w} in the records.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from importlib.resources import files
from typing import Any

import yaml

from navig8_fc.core.rotation import euler_to_quat
from navig8_fc.core.vehicle import N_LINKS, VehicleConfig

Quat = tuple[float, float, float, float]  # (w, x, y, z)
Vec3 = tuple[float, float, float]

_H = math.sqrt(0.5)
# q_ENU<-NED: pi about the north-east bisector (swaps x and y, flips z), docs/urdf.md "Upright in Foxglove".
Q_ENU_FROM_NED: Quat = (0.0, _H, _H, 0.0)
_IDENTITY: Quat = (1.0, 0.0, 0.0, 0.0)
_ZERO: Vec3 = (0.0, 0.0, 0.0)
WORLD_FRAME = "world"
ESTIMATE_PREFIX = "est/"

# Foxglove schema names (https://docs.foxglove.dev/docs/visualization/message-schemas/introduction)
FRAME_TRANSFORMS = "foxglove.FrameTransforms"
SCENE_UPDATE = "foxglove.SceneUpdate"
POSE_IN_FRAME = "foxglove.PoseInFrame"
POSES_IN_FRAME = "foxglove.PosesInFrame"
LOG = "foxglove.Log"

# MAV_SEVERITY (0 EMERGENCY .. 7 DEBUG) -> foxglove.LogLevel (1 DEBUG, 2 INFO, 3 WARNING, 4 ERROR, 5 FATAL)
_LOG_LEVEL = (5, 5, 5, 4, 3, 2, 2, 1)


@dataclass(frozen=True)
class DisplaySizes:
    """Drawing-only dimensions [A] (no model uses them), in m, chosen to look like the paper's Fig. 1. The URDF
    (tools/urdf.py) and the scene here draw with the same sizes."""

    duct_radius_m: float = 0.10  # fits between the body's centre line and its 0.4 m half width
    duct_length_m: float = 0.12  # along the thrust axis
    tail_prop_radius_m: float = 0.10
    tail_prop_thickness_m: float = 0.01
    link_radius_m: float = 0.015
    mount_size_m: float = 0.04  # cube under the body at joint 1
    gripper_size_m: tuple[float, float, float] = (0.03, 0.08, 0.04)  # jaws: x, y (opening), z (along link 3)
    body_alpha: float = 0.35  # the body box is see-through: the ducts sit inside Table 1's envelope
    object_density_kg_m3: float = 1000.0  # the drawn object's volume = mass / density (water-like) [A]
    thrust_arrow_m_per_n: float = 0.015  # arrow length per newton of thrust (hover: ~0.5 m per duct)


def uav_size_m(vehicle_text: str) -> tuple[float, float, float]:
    """Table 1's body envelope (length x, width y, height z; m). VehicleConfig does not carry it."""
    size = yaml.safe_load(vehicle_text)["uav"]["size_m"]
    return float(size["length"]), float(size["width"]), float(size["height"])


def packaged_uav_size_m() -> tuple[float, float, float]:
    """uav_size_m of the packaged params/vehicle.yaml."""
    return uav_size_m((files("navig8_params") / "vehicle.yaml").read_text())


@dataclass(frozen=True)
class VehiclePose:
    """What the 3D view needs of the vehicle at one instant: pose (NED, body FRD -> NED attitude) and joints."""

    pos_ned_m: Vec3
    quat_wxyz: Quat
    duct_tilt_rad: tuple[float, float]  # alpha1 (duct 1, right), alpha3 (duct 3, left)
    joint_pos_rad: Vec3  # q1..q3


def _qx(a: float) -> Quat:
    return (math.cos(0.5 * a), math.sin(0.5 * a), 0.0, 0.0)


def _qy(a: float) -> Quat:
    return (math.cos(0.5 * a), 0.0, math.sin(0.5 * a), 0.0)


def _f(x: Any) -> float:
    return float(x)


def stamp(t_ns: int) -> dict[str, int]:
    """Foxglove's time {sec, nsec} (non-negative)."""
    t = max(int(t_ns), 0)
    return {"sec": t // 1_000_000_000, "nsec": t % 1_000_000_000}


def _vec(v: Sequence[float]) -> dict[str, float]:
    return {"x": _f(v[0]), "y": _f(v[1]), "z": _f(v[2])}


def _quat(q: Sequence[float]) -> dict[str, float]:
    return {"x": _f(q[1]), "y": _f(q[2]), "z": _f(q[3]), "w": _f(q[0])}


def _pose(p: Sequence[float] = _ZERO, q: Sequence[float] = _IDENTITY) -> dict[str, Any]:
    return {"position": _vec(p), "orientation": _quat(q)}


def _color(r: float, g: float, b: float, a: float = 1.0) -> dict[str, float]:
    return {"r": r, "g": g, "b": b, "a": a}


def enu_pose(pos_ned_m: Sequence[float], quat_wxyz: Sequence[float]) -> tuple[Vec3, Quat]:
    """The FRD body's pose in the ENU world: (east, north, up) and q_ENU<-NED (x) q_NED<-FRD (docs/urdf.md).

    The product with q_ENU<-NED = (0, h, h, 0), h = sqrt(1/2), written out: h (-x - y, w + z, w - z, y - x)
    (this runs 100 times a second of sim time; quat_mul is a numba kernel, whose call costs more than this).
    The input is normalised (the wire's quaternion is float32)."""
    w, x, y, z = (float(c) for c in quat_wxyz)
    k = _H / math.sqrt(w * w + x * x + y * y + z * z)
    return ((float(pos_ned_m[1]), float(pos_ned_m[0]), -float(pos_ned_m[2])),
            (k * (-x - y), k * (w + z), k * (w - z), k * (y - x)))


def _entity(ts: dict[str, int] | None, prefix: str, frame: str, eid: str,
            **prims: list[dict[str, Any]]) -> dict[str, Any]:
    """A foxglove.SceneEntity on `frame` (frame-locked unless it is the world), the primitives not given empty."""
    e: dict[str, Any] = {"timestamp": ts, "frame_id": prefix + frame if frame != WORLD_FRAME else frame,
                         "id": prefix + eid, "lifetime": {"sec": 0, "nsec": 0},
                         "frame_locked": frame != WORLD_FRAME, "metadata": []}
    for kind in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"):
        e[kind] = prims.get(kind, [])
    return e


_ARROW_COLOR = {"r": 1.0, "g": 0.85, "b": 0.1, "a": 1.0}


class VehicleViz:
    """The Foxglove records of one vehicle (its constants cfg, Table 1's body envelope, drawing sizes)."""

    def __init__(self, cfg: VehicleConfig, body_size_m: Vec3, display: DisplaySizes | None = None) -> None:
        self.cfg = cfg
        self.body_size_m = body_size_m
        self.d = DisplaySizes() if display is None else display
        right = tuple(_f(x) for x in cfg.duct_right_frd_m)
        self._duct_pos = (right, (right[0], -right[1], right[2]))
        # R_x(-/+ gamma): thrust canted inboard; (cos, sin) of the half angle of each duct's roll
        self._duct_half_roll = tuple((math.cos(0.5 * r), math.sin(0.5 * r))
                                     for r in (-cfg.dihedral_rad, cfg.dihedral_rad))
        self._L = _f(cfg.link_length_m)
        # The fixed joints, (parent, child, translation, rotation) without the prefix: built once.
        self._fixed = (
            ("base_link", "base_link_flu", _vec(_ZERO), _quat(_qx(math.pi))),
            ("base_link", "tail", _vec(cfg.tail_frd_m), _quat(_IDENTITY)),
            ("base_link", "arm_mount", _vec(cfg.mount_frd_m), _quat(_IDENTITY)),
            (f"link_{N_LINKS}", "gripper", _vec((0.0, 0.0, self._L)), _quat(_IDENTITY)),
            ("gripper", "object", _vec((0.0, 0.0, _f(cfg.object_offset_m))), _quat(_IDENTITY)),
        )
        self._link_xyz = tuple(_vec(_ZERO if i == 0 else (0.0, 0.0, self._L)) for i in range(N_LINKS))
        self._duct_xyz = tuple(_vec(p) for p in self._duct_pos)
        self._scene_fixed: dict[str, dict[str, dict[str, Any]]] = {}  # by prefix (scene_update)
        self._setpoint_key: tuple[Any, ...] | None = None
        self._setpoint_entity: dict[str, Any] = {}
        # thrust arrows along -z (R_y(pi/2) turns an arrow's +x onto -z), and +z for a negative thrust
        self._arrow_pose = (_pose(_ZERO, _qy(0.5 * math.pi)), _pose(_ZERO, _qy(-0.5 * math.pi)))

    # --- transforms ------------------------------------------------------------------------------
    def transform_list(self, t_ns: int, pose: VehiclePose, prefix: str = "") -> list[dict[str, Any]]:
        """The FrameTransform list of one tree (frames named prefix + the URDF's names), parent -> child.

        Each movable joint is its URDF origin followed by the rotation by the joint position about its axis:
        duct_i: R_x(-/+gamma) R_y(-alpha_i) (axis (0, -1, 0)); link_i: R_y(q_i) (axis (0, 1, 0))."""
        ts = stamp(t_ns)

        def tf(parent: str, child: str, p: dict[str, float], q: dict[str, float]) -> dict[str, Any]:
            return {"timestamp": ts, "parent_frame_id": parent, "child_frame_id": child, "translation": p,
                    "rotation": q}

        p_enu, q_enu = enu_pose(pose.pos_ned_m, pose.quat_wxyz)
        out = [tf(WORLD_FRAME, prefix + "base_link", _vec(p_enu), _quat(q_enu))]
        out.extend(tf(prefix + a, prefix + c, p, q) for a, c, p, q in self._fixed)
        for i, name in enumerate(("duct_1", "duct_3")):
            # q_x(roll) (x) q_y(-alpha) written out: (cr cb, sr cb, cr sb, sr sb) with b = -alpha / 2
            cr, sr = self._duct_half_roll[i]
            half = -0.5 * float(pose.duct_tilt_rad[i])
            cb, sb = math.cos(half), math.sin(half)
            out.append(tf(prefix + "base_link", prefix + name, self._duct_xyz[i],
                          {"x": sr * cb, "y": cr * sb, "z": sr * sb, "w": cr * cb}))
        parent = prefix + "arm_mount"
        for i in range(N_LINKS):
            child = f"{prefix}link_{i + 1}"
            half = 0.5 * float(pose.joint_pos_rad[i])  # R_y(q_i)
            out.append(tf(parent, child, self._link_xyz[i],
                          {"x": 0.0, "y": math.sin(half), "z": 0.0, "w": math.cos(half)}))
            parent = child
        return out

    def frame_transforms(self, t_ns: int, trees: Sequence[tuple[str, VehiclePose]]) -> dict[str, Any]:
        """foxglove.FrameTransforms of several trees: (frame-name prefix, pose) each."""
        out: list[dict[str, Any]] = []
        for prefix, pose in trees:
            out.extend(self.transform_list(t_ns, pose, prefix))
        return {"transforms": out}

    # --- scene -----------------------------------------------------------------------------------
    def object_diameter_m(self, object_mass_kg: float) -> float:
        """The drawn object's diameter: a sphere of mass / density (0 when nothing is held)."""
        m = max(_f(object_mass_kg), 0.0)
        return (6.0 * m / (math.pi * self.d.object_density_kg_m3)) ** (1.0 / 3.0)

    def scene_update(self, t_ns: int, speed_rad_s: Sequence[float], object_mass_kg: float,
                     setpoint_pos_ned_m: Sequence[float] | None = None, setpoint_pitch_rad: float = 0.0,
                     setpoint_yaw_rad: float = 0.0, prefix: str = "") -> dict[str, Any]:
        """foxglove.SceneUpdate: one entity per frame of the tree (frame_locked: it moves with its frame), thrust
        arrows along each propeller's thrust axis (duct: -z of duct_i, K_T w^2; tail: -z of tail, K_T2 w|w|), the
        setpoint as a ghost box in the world frame.

        What does not change between records (the body, the mount, the rods, the gripper, the duct and tail
        cylinders; the setpoint ghost while the setpoint holds) is built once and shared by the records: treat
        a record as read-only."""
        d, cfg, ts = self.d, self.cfg, stamp(t_ns)
        fixed = self._scene_fixed.get(prefix)
        if fixed is None:
            fixed = self._scene_fixed[prefix] = self._fixed_entities(prefix)

        def arrow(thrust_n: float) -> list[dict[str, Any]]:
            # An arrow points along +x of its pose; R_y(pi/2) turns +x onto -z (the thrust axis). Negative thrust
            # (the tail spinning backwards) points the other way.
            length = abs(thrust_n) * d.thrust_arrow_m_per_n
            if length < 1e-4:
                return []
            return [{"pose": self._arrow_pose[thrust_n < 0], "shaft_length": 0.8 * length,
                     "shaft_diameter": 0.02, "head_length": 0.2 * length, "head_diameter": 0.05,
                     "color": _ARROW_COLOR}]

        w1, w2, w3 = (_f(x) for x in speed_rad_s)
        ents = [dict(fixed["body"], timestamp=ts),
                dict(fixed["duct_1"], timestamp=ts, arrows=arrow(cfg.k_thrust_duct * w1 * w1)),
                dict(fixed["duct_3"], timestamp=ts, arrows=arrow(cfg.k_thrust_duct * w3 * w3)),
                dict(fixed["tail"], timestamp=ts, arrows=arrow(cfg.k_thrust_tail * w2 * abs(w2)))]
        ents.extend(dict(fixed[eid], timestamp=ts)
                    for eid in ("arm_mount", *(f"link_{i}" for i in range(1, N_LINKS + 1)), "gripper"))
        dia = self.object_diameter_m(object_mass_kg)
        ents.append(dict(fixed["object"], timestamp=ts,
                         spheres=[{"pose": _pose(), "size": _vec((dia, dia, dia)),
                                   "color": _color(0.1, 0.7, 0.2, 0.9)}] if dia > 0 else []))
        if setpoint_pos_ned_m is not None:
            key = (prefix, tuple(setpoint_pos_ned_m), setpoint_pitch_rad, setpoint_yaw_rad)
            if self._setpoint_key != key:
                p, q = enu_pose(setpoint_pos_ned_m, euler_to_quat(0.0, setpoint_pitch_rad, setpoint_yaw_rad))
                self._setpoint_key = key
                self._setpoint_entity = _entity(
                    None, prefix, WORLD_FRAME, "setpoint",
                    cubes=[{"pose": _pose(p, q), "size": _vec(self.body_size_m), "color": _color(0.2, 0.9, 0.9, 0.2)}],
                    arrows=[{"pose": _pose(p, q), "shaft_length": 0.6, "shaft_diameter": 0.02, "head_length": 0.15,
                             "head_diameter": 0.06, "color": _color(0.2, 0.9, 0.9, 0.5)}])
            ents.append(dict(self._setpoint_entity, timestamp=ts))
        return {"deletions": [], "entities": ents}

    def _fixed_entities(self, prefix: str) -> dict[str, dict[str, Any]]:
        """The scene's entities without their timestamp, by id, with what never changes drawn (scene_update)."""
        d = self.d

        def cyl(radius: float, length: float, center: Vec3, color: dict[str, float]) -> dict[str, Any]:
            return {"pose": _pose(center), "size": {"x": 2 * radius, "y": 2 * radius, "z": length},
                    "bottom_scale": 1.0, "top_scale": 1.0, "color": color}

        duct_c, tail_c, arm_c = _color(0.15, 0.35, 0.75), _color(0.85, 0.45, 0.10), _color(0.2, 0.2, 0.2)
        out = {
            "body": _entity(None, prefix, "base_link", "body", cubes=[{
                "pose": _pose(), "size": _vec(self.body_size_m), "color": _color(0.75, 0.75, 0.78, d.body_alpha)}]),
            "duct_1": _entity(None, prefix, "duct_1", "duct_1",
                              cylinders=[cyl(d.duct_radius_m, d.duct_length_m, _ZERO, duct_c)]),
            "duct_3": _entity(None, prefix, "duct_3", "duct_3",
                              cylinders=[cyl(d.duct_radius_m, d.duct_length_m, _ZERO, duct_c)]),
            "tail": _entity(None, prefix, "tail", "tail",
                            cylinders=[cyl(d.tail_prop_radius_m, d.tail_prop_thickness_m, _ZERO, tail_c)]),
            "arm_mount": _entity(None, prefix, "arm_mount", "arm_mount", cubes=[{
                "pose": _pose((0.0, 0.0, -0.5 * d.mount_size_m)), "size": _vec((d.mount_size_m,) * 3),
                "color": arm_c}]),
        }
        for i in range(1, N_LINKS + 1):
            out[f"link_{i}"] = _entity(None, prefix, f"link_{i}", f"link_{i}",
                                       cylinders=[cyl(d.link_radius_m, self._L, (0.0, 0.0, 0.5 * self._L), arm_c)])
        gx, gy, gz = d.gripper_size_m
        out["gripper"] = _entity(None, prefix, "gripper", "gripper", cubes=[{
            "pose": _pose((0.0, 0.0, -0.5 * gz)), "size": _vec((gx, gy, gz)), "color": _color(0.8, 0.1, 0.1)}])
        out["object"] = _entity(None, prefix, "object", "object")
        return out

    # --- poses -----------------------------------------------------------------------------------
    @staticmethod
    def pose_in_frame(t_ns: int, pos_ned_m: Sequence[float], quat_wxyz: Sequence[float]) -> dict[str, Any]:
        """foxglove.PoseInFrame: the body's pose in the ENU world."""
        p, q = enu_pose(pos_ned_m, quat_wxyz)
        return {"timestamp": stamp(t_ns), "frame_id": WORLD_FRAME, "pose": _pose(p, q)}

    @staticmethod
    def poses_in_frame(t_ns: int, poses: Sequence[tuple[Sequence[float], Sequence[float]]]) -> dict[str, Any]:
        """foxglove.PosesInFrame of (pos NED, q_NED<-FRD) poses in the ENU world: a path, or a mission's waypoints."""
        return poses_record(t_ns, [world_pose(p, q) for p, q in poses])


def world_pose(pos_ned_m: Sequence[float], quat_wxyz: Sequence[float]) -> dict[str, Any]:
    """A foxglove.Pose in the ENU world of a body pose (NED position, q_NED<-FRD)."""
    return _pose(*enu_pose(pos_ned_m, quat_wxyz))


def poses_record(t_ns: int, world_poses: list[dict[str, Any]]) -> dict[str, Any]:
    """foxglove.PosesInFrame of poses already in the world frame (world_pose): a path keeps them built."""
    return {"timestamp": stamp(t_ns), "frame_id": WORLD_FRAME, "poses": world_poses}


def log_record(t_ns: int, severity: int, text: str, name: str) -> dict[str, Any]:
    """foxglove.Log of a STATUSTEXT (MAV_SEVERITY mapped to Foxglove's levels)."""
    sev = min(max(int(severity), 0), 7)
    return {"timestamp": stamp(t_ns), "level": _LOG_LEVEL[sev], "message": str(text), "name": name, "file": "",
            "line": 0}


def waypoint_poses(points: Sequence[tuple[Sequence[float], float, float]]) -> list[tuple[Vec3, Quat]]:
    """(pos NED, pitch, yaw) waypoints as (pos, q_NED<-FRD) poses for poses_in_frame."""
    return [(tuple(_f(x) for x in p), euler_to_quat(0.0, _f(pitch), _f(yaw))) for p, pitch, yaw in points]


def _v3(title: str) -> dict[str, Any]:
    return {"title": title, "type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}


def _time() -> dict[str, Any]:
    return {"type": "object", "title": "time", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}


def _pose_schema() -> dict[str, Any]:
    return {"title": "foxglove.Pose", "type": "object",
            "properties": {"position": _v3("foxglove.Vector3"),
                           "orientation": {"title": "foxglove.Quaternion", "type": "object",
                                           "properties": {k: {"type": "number"} for k in "xyzw"}}}}


def channel_schema(name: str) -> dict[str, Any]:
    """The JSON schema the log's channel carries for a Foxglove schema name: its top-level fields (Foxglove
    recognises the well-known schema by its name; tests check the records against Foxglove's full schemas)."""
    if name == FRAME_TRANSFORMS:
        tf = {"title": "foxglove.FrameTransform", "type": "object",
              "properties": {"timestamp": _time(), "parent_frame_id": {"type": "string"},
                             "child_frame_id": {"type": "string"}, "translation": _v3("foxglove.Vector3"),
                             "rotation": _pose_schema()["properties"]["orientation"]}}
        return {"type": "object", "properties": {"transforms": {"type": "array", "items": tf}}}
    if name == SCENE_UPDATE:
        return {"type": "object", "properties": {"deletions": {"type": "array", "items": {"type": "object"}},
                                                 "entities": {"type": "array", "items": {"type": "object"}}}}
    if name == POSE_IN_FRAME:
        return {"type": "object", "properties": {"timestamp": _time(), "frame_id": {"type": "string"},
                                                 "pose": _pose_schema()}}
    if name == POSES_IN_FRAME:
        return {"type": "object", "properties": {"timestamp": _time(), "frame_id": {"type": "string"},
                                                 "poses": {"type": "array", "items": _pose_schema()}}}
    if name == LOG:
        return {"type": "object", "properties": {"timestamp": _time(), "level": {"type": "integer"},
                                                 "message": {"type": "string"}, "name": {"type": "string"},
                                                 "file": {"type": "string"}, "line": {"type": "integer"}}}
    raise KeyError(name)


__all__ = ["DisplaySizes", "ESTIMATE_PREFIX", "FRAME_TRANSFORMS", "LOG", "POSES_IN_FRAME", "POSE_IN_FRAME",
           "Q_ENU_FROM_NED", "SCENE_UPDATE", "VehiclePose", "VehicleViz", "WORLD_FRAME", "channel_schema",
           "enu_pose", "log_record", "packaged_uav_size_m", "poses_record", "stamp", "uav_size_m", "waypoint_poses",
           "world_pose"]
