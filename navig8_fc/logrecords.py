"""Log records (docs/logs.md): the one place that maps what the processes know to what the MCAP log holds.

- `/truth`: `log_truth_record(t)` from the plant's truth as plain floats (seam.TruthFloats: Plant.truth_floats in
  navig8-sim, a decoded NAVIG8_TRUTH in navig8-fc), in Truth's vocabulary, so navig8-plot and the summary read
  both. The FC's record lacks what NAVIG8_TRUTH does not carry (ang_accel, the reaction moment about O and the
  no-gravity variants).
- `/analysis/eig`: `eig_record(model, status, t, ...)`, in both processes.
- `/mavlink/<link>/<dir>/<NAME>`: `mavlink_record_json(name, fields)` (the decoded message as JSON, with
  `mavpackettype`, as pymavlink's to_dict names it) and `mavlink_json_schema(cls)` (the channel's JSON schema,
  from the message definition).

Pure: no sockets, no clocks, no files.
"""

from __future__ import annotations

import functools
from typing import Any

import orjson

from navig8_fc.core.rotation import quat_to_euler
from navig8_fc.core.vehicle import UamModel, ghat_ginv_eig_record
from navig8_fc.mavlink.seam import TruthFloats


def log_truth_record(t: TruthFloats) -> dict[str, Any]:
    """The /truth record of the plant's truth as plain floats (seam.TruthFloats: Plant.truth_floats in navig8-sim,
    a decoded NAVIG8_TRUTH in navig8-fc). The keys are Truth's field names (sim_bridge.messages.Truth), except the
    actuator positions split into duct_tilt_rad and prop_speed_rad_s (as the sensors name them) and the inertia's
    diagonal; the roll, pitch, yaw (ZYX) from the quaternion. What the wire does not carry (None) is left out."""
    act, jc = t.actuator_pos, t.inertia_com_kgm2
    rec: dict[str, Any] = {
        "pos_ned_m": t.pos_ned_m,
        "vel_ned_m_s": t.vel_ned_m_s,
        "quat_wxyz": t.quat_wxyz,
        "euler_rad": quat_to_euler(t.quat_wxyz),
        "rate_frd_rad_s": t.rate_frd_rad_s,
        "accel_frd_m_s2": t.accel_frd_m_s2,
    }
    if t.ang_accel_frd_rad_s2 is not None:
        rec["ang_accel_frd_rad_s2"] = t.ang_accel_frd_rad_s2
    rec.update({
        "duct_tilt_rad": act[:2],
        "prop_speed_rad_s": act[2:],
        "joint_pos_rad": t.joint_pos_rad,
        "joint_rate_rad_s": t.joint_rate_rad_s,
        "joint_accel_rad_s2": t.joint_accel_rad_s2,
        "object_mass_kg": t.object_mass_kg,
        "mass_kg": t.mass_kg,
        "com_frd_m": t.com_frd_m,
        "inertia_diag_kgm2": [jc[0][0], jc[1][1], jc[2][2]],
        # the headline reaction wrench (Fig. 10): about the mount, gravity included
        "reaction_force_frd_n": t.reaction_force_frd_n,
        "reaction_moment_mount_frd_nm": t.reaction_moment_mount_frd_nm,
    })
    for key in ("reaction_moment_o_frd_nm", "reaction_force_nog_frd_n", "reaction_moment_mount_nog_frd_nm"):
        if (v := getattr(t, key)) is not None:
            rec[key] = v
    rec["cmd_nonfinite_count"] = t.cmd_nonfinite_count
    rec["cmd_clamped_count"] = t.cmd_clamped_count
    return rec


def eig_record(model: UamModel, status: Any, t: TruthFloats, lambda_min: float, lambda_crit: float
               ) -> dict[str, Any]:
    """The /analysis/eig record: the eigenvalues of G_hat G^-1 (Eq. 14) with G from the plant's truth and G_hat
    from the controller's status (core.controller.ControllerStatus) of the same step."""
    return ghat_ginv_eig_record(model, status.q_est_rad, status.gi_hat, t.com_frd_m, t.inertia_com_kgm2, t.mass_kg,
                                lambda_min, lambda_crit, status.gc_uam, status.ref_frd_m)


def mavlink_record_json(msg: Any) -> bytes:
    """A decoded message (codec.Message) as the JSON of its /mavlink/... channel: its fields and
    mavpackettype = its name (the keys of pymavlink's to_dict)."""
    return orjson.dumps(dict(zip(msg.keys, msg.values, strict=True), mavpackettype=msg.name))


@functools.lru_cache(maxsize=512)
def mavlink_json_schema(msg_cls: Any) -> dict[str, Any]:
    """JSON schema of a pymavlink message class, from its definition (field names, C types, array
    lengths, units, enums), so Foxglove knows every field of the decoded /mavlink/... channels."""
    props: dict[str, Any] = {"mavpackettype": {"type": "string"}}
    units = getattr(msg_cls, "fieldunits_by_name", {}) or {}
    enums = getattr(msg_cls, "fieldenums_by_name", {}) or {}
    # array_lengths follow the wire order (ordered_fieldnames), fieldtypes the declaration order (fieldnames)
    lengths = dict(zip(msg_cls.ordered_fieldnames, msg_cls.array_lengths, strict=True))
    for name, ctype in zip(msg_cls.fieldnames, msg_cls.fieldtypes, strict=True):
        n = lengths[name]
        if ctype == "char":
            item: dict[str, Any] = {"type": "string"}
        elif ctype.startswith(("float", "double")):
            item = {"type": ["number", "null"]}
        else:
            item = {"type": "integer"}
        if name in units:
            item["description"] = f"[{units[name]}]"
        if name in enums:
            item["description"] = (item.get("description", "") + f" enum {enums[name]}").strip()
        props[name] = item if (n == 0 or ctype == "char") else {"type": "array", "items": item, "maxItems": n}
    return {"type": "object", "title": msg_cls.msgname if hasattr(msg_cls, "msgname") else msg_cls.__name__,
            "properties": props}


def dialect_json_schema(name: str) -> dict[str, Any]:
    """mavlink_json_schema of a message of the navig8 dialect, by name (the /mavlink/sim/... channels)."""
    from navig8_fc.mavlink import dialect

    d = dialect.load()
    return mavlink_json_schema(d.mavlink_map[getattr(d, f"MAVLINK_MSG_ID_{name}")])


__all__ = ["dialect_json_schema", "eig_record", "log_truth_record", "mavlink_json_schema", "mavlink_record_json"]
