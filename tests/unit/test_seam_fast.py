"""The seam's per-step wire (bundle out, actuator answer back) against pymavlink: the same bytes as pymavlink packs
from the same messages, and the same values as pymavlink decodes (the FC's one decode path: codec + assembler)."""

from __future__ import annotations

import math
import random
from types import SimpleNamespace

import numpy as np
import pytest
from mavlink_oracle import same, same_fields

from navig8_fc.logrecords import log_truth_record, mavlink_record_json
from navig8_fc.mavlink import codec, dialect, seam


@pytest.fixture(scope="module")
def d():
    return dialect.load()


def _vec(rng: random.Random, n: int) -> np.ndarray:
    return np.array([0.0 if rng.random() < 0.3 else rng.uniform(-50, 50) for _ in range(n)])


def _sensors(rng: random.Random, step: int) -> SimpleNamespace:
    return SimpleNamespace(
        time_us=step * 10_000, gyro_frd_rad_s=_vec(rng, 3), accel_frd_m_s2=_vec(rng, 3), pos_ned_m=_vec(rng, 3),
        vel_ned_m_s=_vec(rng, 3), quat_wxyz=_vec(rng, 4), duct_tilt_rad=_vec(rng, 2), prop_speed_rad_s=_vec(rng, 3),
        joint_pos_rad=_vec(rng, 3), joint_rate_rad_s=_vec(rng, 3), gripper_closed=rng.random() < 0.5,
        updated=rng.choice([0, 1, 3]),
    )


def _truth(rng: random.Random, step: int) -> SimpleNamespace:
    zero_tail = rng.random() < 0.5  # every trailing field zero: a long truncation
    return SimpleNamespace(
        time_us=step * 10_000, pos_ned_m=_vec(rng, 3), vel_ned_m_s=_vec(rng, 3), quat_wxyz=_vec(rng, 4),
        rate_frd_rad_s=_vec(rng, 3), accel_frd_m_s2=_vec(rng, 3), actuator_pos=_vec(rng, 5),
        joint_pos_rad=_vec(rng, 3), joint_rate_rad_s=_vec(rng, 3), joint_accel_rad_s2=_vec(rng, 3),
        object_mass_kg=rng.uniform(0, 1), mass_kg=rng.uniform(1, 5), com_frd_m=_vec(rng, 3),
        inertia_com_kgm2=np.diag(_vec(rng, 3)) + 0.01,
        reaction_force_frd_n=np.zeros(3) if zero_tail else _vec(rng, 3),
        reaction_moment_mount_frd_nm=np.zeros(3) if zero_tail else _vec(rng, 3),
        cmd_clamped_count=0 if zero_tail else rng.randrange(0, 1 << 40), cmd_nonfinite_count=0,
    )


def _pymavlink_bundle(d, ref, step: int, s, t) -> list:
    """The bundle's messages built with pymavlink's constructors, field by field from the plant's names (an
    independent spelling of seam.bundle_records' mapping)."""
    tu = s.time_us + 1
    cov = [math.nan] + [0.0] * 20
    msgs = [
        d.MAVLink_odometry_message(tu, d.MAV_FRAME_LOCAL_NED, d.MAV_FRAME_LOCAL_NED, *s.pos_ned_m, list(s.quat_wxyz),
                                   *s.vel_ned_m_s, *s.gyro_frd_rad_s, cov, cov, 0, d.MAV_ESTIMATOR_TYPE_MOCAP, 0),
        d.MAVLink_navig8_actuator_state_message(tu, step, list(s.duct_tilt_rad), list(s.prop_speed_rad_s)),
        d.MAVLink_navig8_arm_state_message(tu, step, list(s.joint_pos_rad), list(s.joint_rate_rad_s),
                                           int(s.gripper_closed)),
    ]
    if t is not None:
        j = t.inertia_com_kgm2
        msgs.append(d.MAVLink_navig8_truth_message(
            tu, step, list(t.pos_ned_m), list(t.vel_ned_m_s), list(t.quat_wxyz), list(t.rate_frd_rad_s),
            list(t.accel_frd_m_s2), list(t.actuator_pos), list(t.joint_pos_rad), list(t.joint_rate_rad_s),
            list(t.joint_accel_rad_s2), t.object_mass_kg, t.mass_kg, list(t.com_frd_m),
            [j[0, 0], j[1, 1], j[2, 2], j[0, 1], j[0, 2], j[1, 2]], list(t.reaction_force_frd_n),
            list(t.reaction_moment_mount_frd_nm), t.cmd_clamped_count & 0xFFFFFFFF, t.cmd_nonfinite_count))
    msgs.append(d.MAVLink_hil_sensor_message(tu, *s.accel_frd_m_s2, *s.gyro_frd_rad_s, 0, 0, 0, 0, 0, 0, 0,
                                             0b111111 if s.updated & 1 else 0, 0))
    out = b""
    for m in msgs:
        out += m.pack(ref)
        ref.seq = (ref.seq + 1) % 256
    return out


def test_encode_bundle_is_byte_identical_to_pymavlink(d) -> None:
    rng = random.Random(7)
    enc = codec.Encoder(codec.seam_codec(), 1, dialect.COMPID_BRIDGE)
    ref = dialect.new_mav(1, dialect.COMPID_BRIDGE)
    for step in range(300):  # > 256 frames: seq wraps
        sensors = _sensors(rng, step)
        truth = _truth(rng, step) if step % 7 else None
        assert seam.encode_bundle(enc, step, sensors, truth) == _pymavlink_bundle(d, ref, step, sensors, truth), step
    assert enc.seq == ref.seq


def test_pack_actuator_controls_matches_pymavlink_pack(d) -> None:
    from navig8_fc.core.vehicle import VehicleConfig

    veh = VehicleConfig.load()
    lim = seam.ControlsScale.from_vehicle(veh)
    rng = np.random.default_rng(3)
    enc, ref = codec.Encoder(codec.seam_codec(), 2, 1), dialect.new_mav(2, 1)
    for i in range(100):
        tilt = rng.uniform(-2, 2, 2).tolist()
        speed = rng.uniform(-900, 900, 3).tolist()
        if i % 10 == 0:
            speed[1] = math.nan
        cmd = SimpleNamespace(tilt_rad=tilt, speed_rad_s=speed)
        t_us = 1_700_000_000_000_000 + 10_000 * i
        controls = [tilt[0] / lim.tilt_max_abs_rad, tilt[1] / lim.tilt_max_abs_rad, speed[0] / lim.duct_speed_max_rad_s,
                    speed[1] / lim.tail_speed_max_rad_s, speed[2] / lim.duct_speed_max_rad_s] + [0.0] * 11
        want = d.MAVLink_hil_actuator_controls_message(t_us, controls, 128 if i % 2 else 0, 0).pack(ref)
        ref.seq = (ref.seq + 1) % 256
        assert seam.pack_actuator_controls(enc, t_us, cmd, veh, armed=bool(i % 2)) == want


def test_the_fc_decode_path_equals_pymavlink_decode(d) -> None:
    """codec.parse + BundleAssembler (the FC's only path) against pymavlink's decode of the same datagram, mapped
    to a StepBundle here by hand."""
    rng = random.Random(21)
    enc = codec.Encoder(codec.seam_codec(), 1, dialect.COMPID_BRIDGE)
    asm = seam.BundleAssembler()
    for step in range(120):
        truth = _truth(rng, step) if step % 5 else None
        data = seam.encode_bundle(enc, step, _sensors(rng, step), truth)
        counts = codec.ParseCounters()
        msgs = codec.seam_codec().parse(data, counts)
        bundles = [b for b in (asm.add(m) for m in msgs) if b is not None]
        ref = {m.get_type(): m for m in dialect.new_mav(1, 1).parse_buffer(data)}
        assert counts == codec.ParseCounters() and len(bundles) == 1
        assert [m.name for m in msgs] == list(ref) == list(asm.completed)
        for name, m in asm.completed.items():
            assert same_fields(m.fields, ref[name])
        b = bundles[0]
        o, a, r, h = ref["ODOMETRY"], ref["NAVIG8_ACTUATOR_STATE"], ref["NAVIG8_ARM_STATE"], ref["HIL_SENSOR"]
        want = [a.step, h.time_usec, [h.xgyro, h.ygyro, h.zgyro], [h.xacc, h.yacc, h.zacc],
                h.fields_updated == 0b111111, [o.x, o.y, o.z], [o.vx, o.vy, o.vz], o.q, a.duct_tilt, a.prop_speed,
                r.joint_pos, r.joint_rate, bool(r.gripper_closed)]
        got = [b.step, b.time_usec, b.gyro_frd_rad_s, b.accel_frd_m_s2, b.imu_fresh, b.pos_ned_m, b.vel_ned_m_s,
               b.quat_wxyz,
               b.duct_tilt_rad, b.prop_speed_rad_s, b.joint_pos_rad, b.joint_rate_rad_s, b.gripper_closed]
        assert all(same(x, y) for x, y in zip(got, want, strict=True)), step
        if truth is None:
            assert b.truth is None
        else:
            t = ref["NAVIG8_TRUTH"]  # pymavlink's decoding, by the wire's names
            want_truth = seam.truth_floats_of_message(t.to_dict())
            assert all(same(getattr(b.truth, k), getattr(want_truth, k)) for k in vars(want_truth)), step
            assert same(list(log_truth_record(b.truth).values()), list(log_truth_record(want_truth).values()))


def test_the_log_records_equal_pymavlink_to_dict(d) -> None:
    """The /mavlink/sim/... records (codec fields + mavpackettype) serialise like pymavlink's to_dict."""
    import orjson

    rng = random.Random(4)
    data = seam.encode_bundle(codec.Encoder(codec.seam_codec(), 1, 25), 3, _sensors(rng, 3), _truth(rng, 3))
    msgs = codec.seam_codec().parse(data, codec.ParseCounters())
    for m, ref in zip(msgs, dialect.new_mav(1, 1).parse_buffer(data), strict=True):
        want = ref.to_dict()
        got = orjson.loads(mavlink_record_json(m))
        assert got.keys() == want.keys()
        assert got == orjson.loads(orjson.dumps(want))


def test_assembler_declines_anything_but_a_whole_bundle(d) -> None:
    rng = random.Random(22)
    enc = codec.Encoder(codec.seam_codec(), 1, dialect.COMPID_BRIDGE)
    c = codec.seam_codec()
    msgs = c.parse(seam.encode_bundle(enc, 3, _sensors(rng, 3), _truth(rng, 3)), codec.ParseCounters())
    other = c.parse(seam.encode_bundle(enc, 4, _sensors(rng, 4), None), codec.ParseCounters())
    status = c.parse(enc.frame(*seam.encode_sim_status(seam.SimStatus(1, 2, seam.SIM_STATE_RUNNING, 0.0, 1.0, 0))),
                     codec.ParseCounters())
    assert seam.decode_bundle(msgs) is not None
    cases = {
        "no HIL_SENSOR": msgs[:-1],
        "HIL_SENSOR first": [msgs[-1], *msgs[:-1]],
        "no ODOMETRY": msgs[1:],
        "mixed steps": [other[0], *msgs[1:]],
        "a status message": status,
        "empty": [],
    }
    for label, seq in cases.items():
        asm = seam.BundleAssembler()
        assert [b for b in (asm.add(m) for m in seq) if b is not None] == [], label
    asm = seam.BundleAssembler()
    for m in [other[0], *msgs[1:]]:
        asm.add(m)
    assert asm.incomplete == 1
