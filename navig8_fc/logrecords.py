"""Log records (docs/logs.md): the one place that maps what the processes know to what the MCAP log holds.

- `/truth`: `log_truth_record(t)` from the plant's LogTruth (navig8-sim, in-process; the same bytes as
  `truth_record` of its Truth) and `wire_truth_record(t)` from a decoded NAVIG8_TRUTH (navig8-fc in SITL); the
  same keys, so navig8-plot and the summary read both.
  The wire record lacks what NAVIG8_TRUTH does not carry (ang_accel, the reaction moment about O and the
  no-gravity variants).
- `/mavlink/<link>/<dir>/<NAME>`: `mavlink_record_json(name, fields)` (the decoded message as JSON, with
  `mavpackettype`, as pymavlink's to_dict names it) and `mavlink_json_schema(cls)` (the channel's JSON schema,
  from the message definition).

Pure: no sockets, no clocks, no files.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import orjson

from navig8_fc.core.rotation import quat_to_euler


def _truth(pos: Any, vel: Any, quat: Any, euler: Any, rate: Any, accel: Any, ang_accel: Any, act: Any, jq: Any,
           jqd: Any, jqdd: Any, mobj: Any, mass: Any, com: Any, inertia_diag: Any, f_mount: Any, m_mount: Any,
           extra: dict[str, Any], nonfinite: int, clamped: int) -> dict[str, Any]:
    rec: dict[str, Any] = {
        "pos_ned_m": pos,
        "vel_ned_m_s": vel,
        "quat_wxyz": quat,
        "euler_rad": euler,
        "rate_frd_rad_s": rate,
        "accel_frd_m_s2": accel,
    }
    if ang_accel is not None:
        rec["ang_accel_frd_rad_s2"] = ang_accel
    rec.update({
        "tilt_rad": act[:2],
        "speed_rad_s": act[2:],
        "joint_pos_rad": jq,
        "joint_rate_rad_s": jqd,
        "joint_accel_rad_s2": jqdd,
        "object_mass_kg": mobj,
        "mass_kg": mass,
        "com_frd_m": com,
        "inertia_diag_kgm2": inertia_diag,
        # Headline reaction wrench (Fig. 10): about the mount, gravity included.
        "reaction_force_mount_n": f_mount,
        "reaction_torque_mount_nm": m_mount,
    })
    rec.update(extra)
    rec["cmd_nonfinite_count"] = nonfinite
    rec["cmd_clamped_count"] = clamped
    return rec


def truth_record(tr: Any) -> dict[str, Any]:
    """The /truth record of a plant Truth (sim_bridge.messages.Truth; numpy arrays are logged as they are)."""
    return _truth(
        tr.pos_ned_m, tr.vel_ned_m_s, tr.quat_wxyz, tr.euler_rad, tr.rate_frd_rad_s, tr.accel_frd_m_s2,
        tr.ang_accel_frd_rad_s2, np.asarray(tr.actuator_pos, dtype=float), tr.joint_pos_rad, tr.joint_rate_rad_s,
        tr.joint_accel_rad_s2, tr.object_mass_kg, tr.mass_kg, tr.com_frd_m, np.diag(np.asarray(tr.inertia_com_kgm2)),
        tr.reaction_force_frd_n, tr.reaction_moment_mount_frd_nm,
        {"reaction_torque_o_nm": tr.reaction_moment_o_frd_nm, "reaction_force_nog_n": tr.reaction_force_nog_frd_n,
         "reaction_torque_mount_nog_nm": tr.reaction_moment_mount_nog_frd_nm},
        tr.cmd_nonfinite_count, tr.cmd_clamped_count,
    )


def log_truth_record(t: Any) -> dict[str, Any]:
    """The /truth record of a plant's LogTruth (sim_bridge.messages: plain floats in lists; the same keys and
    numbers as truth_record of its Truth, at a third of the cost)."""
    act, jc = t.actuator_pos, t.inertia_com_kgm2
    return _truth(
        t.pos_ned_m, t.vel_ned_m_s, t.quat_wxyz, t.euler_rad, t.rate_frd_rad_s, t.accel_frd_m_s2,
        t.ang_accel_frd_rad_s2, act, t.joint_pos_rad, t.joint_rate_rad_s, t.joint_accel_rad_s2, t.object_mass_kg,
        t.mass_kg, t.com_frd_m, [jc[0][0], jc[1][1], jc[2][2]], t.reaction_force_frd_n,
        t.reaction_moment_mount_frd_nm,
        {"reaction_torque_o_nm": t.reaction_moment_o_frd_nm, "reaction_force_nog_n": t.reaction_force_nog_frd_n,
         "reaction_torque_mount_nog_nm": t.reaction_moment_mount_nog_frd_nm},
        t.cmd_nonfinite_count, t.cmd_clamped_count,
    )


def wire_truth_record(t: Any) -> dict[str, Any]:
    """The /truth record of a decoded NAVIG8_TRUTH (its fields as attributes: seam.StepBundle.truth; arrays as
    tuples, which serialise as JSON arrays like lists)."""
    return _truth(
        t.pos_ned, t.vel_ned, t.quat, list(quat_to_euler(t.quat)), t.rate_frd, t.accel_frd, None, t.actuators,
        t.joint_pos, t.joint_rate, t.joint_accel, t.object_mass, t.mass, t.com_frd, t.inertia[:3], t.reaction_force,
        t.reaction_moment_mount, {}, t.cmd_nonfinite, t.cmd_clamped,
    )


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


__all__ = ["dialect_json_schema", "log_truth_record", "mavlink_json_schema", "mavlink_record_json", "truth_record",
           "wire_truth_record"]
