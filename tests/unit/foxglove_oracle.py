"""Independent checks of the Foxglove channels in an MCAP log (tests of docs/foxglove.md).

- Every channel whose schema is named `foxglove.*` is checked against Foxglove's published JSON schema of that
  name (vendored, unmodified, in tests/foxglove_schemas: see its README) with `jsonschema`, plus strictly: every
  key a record has is a property of Foxglove's schema (their schemas do not forbid extra keys, Foxglove ignores
  them: a misspelt field would pass silently) and every record has every property the schema lists at the top level.
- The transforms are composed with this file's own homogeneous matrices (quaternion -> rotation matrix written
  here) and compared with the arm kinematics of model_oracle and the truth's pose.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
from mcap.reader import make_reader
from model_oracle import arm_kinematics

from navig8_fc.core.vehicle import VehicleConfig

SCHEMA_DIR = Path(__file__).resolve().parents[1] / "foxglove_schemas"


def foxglove_schema(name: str) -> dict[str, Any]:
    """Foxglove's published JSON schema of `foxglove.<Name>`."""
    return json.loads((SCHEMA_DIR / f"{name.removeprefix('foxglove.')}.json").read_text())


def _strict_keys(rec: Any, schema: dict[str, Any], where: str) -> None:
    if isinstance(rec, dict) and "properties" in schema:
        props = schema["properties"]
        extra = set(rec) - set(props)
        assert not extra, f"{where}: keys not in Foxglove's schema: {sorted(extra)}"
        for k, v in rec.items():
            _strict_keys(v, props[k], f"{where}.{k}")
    elif isinstance(rec, list) and "items" in schema:
        for i, v in enumerate(rec):
            _strict_keys(v, schema["items"], f"{where}[{i}]")


def validate(name: str, rec: dict[str, Any]) -> None:
    schema = foxglove_schema(name)
    jsonschema.validate(rec, schema)
    _strict_keys(rec, schema, name)
    missing = set(schema["properties"]) - set(rec)
    assert not missing, f"{name}: top-level fields missing: {sorted(missing)}"


def read_log(path: Path) -> tuple[dict[str, tuple[str, str, str]], list[tuple[str, int, Any]]]:
    """(topic -> (schema name, schema encoding, message encoding)), [(topic, log time ns, decoded JSON)] with the
    `mcap` library's reader."""
    channels: dict[str, tuple[str, str, str]] = {}
    msgs: list[tuple[str, int, Any]] = []
    with open(path, "rb") as fh:
        for schema, channel, msg in make_reader(fh).iter_messages():
            channels[channel.topic] = (schema.name if schema else "", schema.encoding if schema else "",
                                       channel.message_encoding)
            if channel.message_encoding == "json":
                msgs.append((channel.topic, msg.log_time, json.loads(msg.data)))
    return channels, msgs


def rot(q: dict[str, float]) -> np.ndarray:
    """Rotation matrix of a unit quaternion {x, y, z, w} (Hamilton, active: v' = R v)."""
    w, x, y, z = q["w"], q["x"], q["y"], q["z"]
    assert abs(w * w + x * x + y * y + z * z - 1.0) < 1e-9
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def homog(tf: dict[str, Any]) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = rot(tf["rotation"])
    t[:3, 3] = [tf["translation"][k] for k in "xyz"]
    return t


def chain(transforms: list[dict[str, Any]], root: str, leaf: str) -> np.ndarray:
    """root -> leaf (the pose of leaf in root) by walking parents up from leaf."""
    by_child = {tf["child_frame_id"]: tf for tf in transforms}
    t = np.eye(4)
    frame = leaf
    while frame != root:
        tf = by_child[frame]
        t = homog(tf) @ t
        frame = tf["parent_frame_id"]
    return t


def quat_ned_to_rot(q_wxyz: list[float]) -> np.ndarray:
    q_wxyz = list(np.asarray(q_wxyz, dtype=float) / np.linalg.norm(q_wxyz))  # the wire's float32 quaternion
    return rot({"w": q_wxyz[0], "x": q_wxyz[1], "y": q_wxyz[2], "z": q_wxyz[3]})


NED_TO_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def check_transforms(cfg: VehicleConfig, tf_msg: dict[str, Any], truth: dict[str, Any], tol_m: float = 1e-6) -> None:
    """The truth tree of one FrameTransforms against the truth record of the same time: the gripper and object
    in base_link equal the arm's forward kinematics; the gripper in the world equals the truth's pose applied to
    it (ENU); each duct's -z axis is the thrust direction d_i of the model (notes 2.1)."""
    tfs = tf_msg["transforms"]
    q = truth["joint_pos_rad"]
    kin = arm_kinematics(cfg, q)
    g_body = chain(tfs, "base_link", "gripper")[:3, 3]
    assert np.allclose(g_body, kin.joints[-1], atol=tol_m, rtol=0), (g_body, kin.joints[-1])
    o_body = chain(tfs, "base_link", "object")[:3, 3]
    assert np.allclose(o_body, kin.object_pos, atol=tol_m, rtol=0), (o_body, kin.object_pos)
    r_nb = quat_ned_to_rot(truth["quat_wxyz"])
    g_world = chain(tfs, "world", "gripper")[:3, 3]
    g_world_expected = NED_TO_ENU @ (np.asarray(truth["pos_ned_m"]) + r_nb @ kin.joints[-1])
    assert np.allclose(g_world, g_world_expected, atol=tol_m, rtol=0), (g_world, g_world_expected)
    g, (a1, a3) = cfg.dihedral_rad, truth["duct_tilt_rad"]
    d1 = np.array([np.sin(a1), -np.sin(g) * np.cos(a1), -np.cos(g) * np.cos(a1)])
    d3 = np.array([np.sin(a3), np.sin(g) * np.cos(a3), -np.cos(g) * np.cos(a3)])
    for name, d in (("duct_1", d1), ("duct_3", d3)):
        r = chain(tfs, "base_link", name)[:3, :3]
        assert np.allclose(-r[:, 2], d, atol=1e-9, rtol=0), (name, -r[:, 2], d)


def check_log(path: Path, cfg: VehicleConfig, min_counts: dict[str, int]) -> dict[str, int]:
    """Validate every foxglove.* channel of a log and the transforms against the truth; returns message counts
    per Foxglove topic."""
    channels, msgs = read_log(path)
    fox = {t: c for t, c in channels.items() if c[0].startswith("foxglove.")}
    assert fox, f"no Foxglove channels in {path}"
    for topic, (_name, enc, menc) in fox.items():
        assert (enc, menc) == ("jsonschema", "json"), (topic, enc, menc)
    counts = dict.fromkeys(fox, 0)
    truth_at = {t: rec for topic, t, rec in msgs if topic == "/truth"}
    n_checked = 0
    for topic, t_ns, rec in msgs:
        if topic not in fox:
            continue
        counts[topic] += 1
        validate(fox[topic][0], rec)
        if topic == "/foxglove/tf" and t_ns in truth_at:
            check_transforms(cfg, rec, truth_at[t_ns])
            frames = {tf["child_frame_id"] for tf in rec["transforms"]}
            assert {"est/base_link", "est/gripper", "est/duct_1", "est/object"} <= frames
            n_checked += 1
    for topic, n in min_counts.items():
        assert counts.get(topic, 0) >= n, (topic, counts)
    assert n_checked >= min_counts.get("/foxglove/tf", 1), n_checked
    return counts
