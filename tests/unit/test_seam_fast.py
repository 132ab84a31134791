"""The seam's fast frame codec agrees byte for byte (encode) and field for field (decode) with pymavlink."""

from __future__ import annotations

import math
import random
import struct
from types import SimpleNamespace

import numpy as np
import pytest

from navig8_fc.mavlink import dialect, seam
from navig8_fc.shell.mavlink_link import split_frames

SEAM_MESSAGES = seam._FAST_MESSAGES


@pytest.fixture(scope="module")
def d():
    return dialect.load()


def _value(rng: random.Random, typ: str) -> float | int:
    if rng.random() < 0.3:  # zeros everywhere, so payloads end in zeros and get truncated
        return 0.0 if typ in ("float", "double") else 0
    if typ == "float":
        return rng.choice([rng.uniform(-1e3, 1e3), rng.uniform(-1e-3, 1e-3), math.inf, -math.inf, math.nan, 1e30])
    if typ == "double":
        return rng.uniform(-1e6, 1e6)
    bits = int("".join(ch for ch in typ if ch.isdigit()))
    if typ.startswith("u"):
        return rng.randrange(0, 1 << bits)
    return rng.randrange(-(1 << (bits - 1)), 1 << (bits - 1))


def _random_args(rng: random.Random, cls) -> list:
    args = []
    for typ, fname in zip(cls.fieldtypes, cls.fieldnames, strict=True):
        n = cls.array_lengths[cls.ordered_fieldnames.index(fname)]
        args.append([_value(rng, typ) for _ in range(n)] if n else _value(rng, typ))
    return args


def _vec(rng: random.Random, n: int) -> np.ndarray:
    return np.array([0.0 if rng.random() < 0.3 else rng.uniform(-50, 50) for _ in range(n)])


def _sensors(rng: random.Random, step: int) -> SimpleNamespace:
    return SimpleNamespace(
        time_us=step * 10_000, gyro_frd=_vec(rng, 3), accel_frd=_vec(rng, 3), pos_ned=_vec(rng, 3),
        vel_ned=_vec(rng, 3), quat_wxyz=_vec(rng, 4), duct_tilt_rad=_vec(rng, 2), prop_speed_rad_s=_vec(rng, 3),
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


def test_encode_bundle_is_byte_identical_to_pymavlink_pack() -> None:
    rng = random.Random(7)
    fast = dialect.new_mav(1, dialect.COMPID_BRIDGE)
    ref = dialect.new_mav(1, dialect.COMPID_BRIDGE)
    for step in range(300):  # > 256 frames: seq wraps
        sensors = _sensors(rng, step)
        truth = _truth(rng, step) if step % 7 else None
        got = seam.encode_bundle(fast, step, sensors, truth)
        want = seam.pack(ref, seam.bundle_messages(step, sensors, truth))
        assert got == want, step
    assert (fast.seq, fast.total_packets_sent, fast.total_bytes_sent) == (
        ref.seq, ref.total_packets_sent, ref.total_bytes_sent)


@pytest.mark.parametrize("name", SEAM_MESSAGES)
def test_fast_pack_matches_pymavlink_for_random_messages(d, name: str) -> None:
    rng = random.Random(name)
    cls = d.mavlink_map[getattr(d, f"MAVLINK_MSG_ID_{name}")]
    fast, ref = dialect.new_mav(9, 200), dialect.new_mav(9, 200)
    for _ in range(200):
        args = _random_args(rng, cls)
        want = cls(*args).pack(ref)
        ref.seq = (ref.seq + 1) % 256
        assert seam.fast_pack(fast, name, args) == want


def _same(a, b) -> bool:
    if isinstance(a, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float):
        return isinstance(b, float) and struct.pack("<d", a) == struct.pack("<d", b)
    return type(a) is type(b) and a == b


@pytest.mark.parametrize("name", SEAM_MESSAGES)
def test_fast_decode_equals_pymavlink_decode(d, name: str) -> None:
    rng = random.Random(name + "decode")
    cls = d.mavlink_map[getattr(d, f"MAVLINK_MSG_ID_{name}")]
    tx, rx = dialect.new_mav(3, 25), dialect.new_mav(1, 1)
    for i in range(200):
        tx.seq = i % 256
        frame = cls(*_random_args(rng, cls)).pack(tx)
        got = seam.fast_decode(frame)
        want = rx.decode(bytearray(frame))
        assert got is not None and type(got) is type(want)
        assert set(vars(got)) == set(vars(want))
        for k, v in vars(want).items():
            if k == "_header":
                assert vars(got._header) == vars(v)
            else:
                assert _same(getattr(got, k), v) or getattr(got, k) == v, k
        assert got == want or "nan" in str(want)  # pymavlink's __eq__: NaN != NaN
        assert (got.get_type(), got.get_srcSystem(), got.get_srcComponent(), got.get_msgId(), got.get_seq()) == (
            want.get_type(), want.get_srcSystem(), want.get_srcComponent(), want.get_msgId(), want.get_seq())
        assert got.to_dict().keys() == want.to_dict().keys()


def test_fast_decode_pads_truncated_payloads(d) -> None:
    tx = dialect.new_mav(1, 1)
    frame = d.MAVLink_hil_actuator_controls_message(5, [0.0] * 16, 0, 0).pack(tx)
    assert frame[1] == 1  # only the low byte of time_usec survives the truncation
    m = seam.fast_decode(frame)
    assert m is not None and m.time_usec == 5 and m.controls == [0.0] * 16 and m.mode == 0 and m.flags == 0


def test_fast_decode_declines_what_it_does_not_know(d) -> None:
    tx = dialect.new_mav(1, 1)
    frame = bytearray(d.MAVLink_navig8_sim_status_message(1, 2, 1, 1.0, 3.0, 0).pack(tx))
    assert seam.fast_decode(bytes(frame)) is not None
    for i in range(1, len(frame)):  # any corrupt byte: bad CRC or bad header, never a wrong message
        bad = bytearray(frame)
        bad[i] ^= 0x41
        assert seam.fast_decode(bytes(bad)) is None, i
    assert seam.fast_decode(bytes(frame[:-1])) is None  # truncated frame
    assert seam.fast_decode(d.MAVLink_heartbeat_message(1, 2, 3, 4, 5, 3).pack(tx)) is None  # not a seam message
    v1 = dialect.new_mav(1, 1)
    assert seam.fast_decode(d.MAVLink_heartbeat_message(1, 2, 3, 4, 5, 3).pack(v1, force_mavlink1=True)) is None
    signed = bytearray(frame)
    signed[2] = 1
    assert seam.fast_decode(bytes(signed)) is None


def test_parse_datagram_fast_path_equals_pymavlink(d) -> None:
    rng = random.Random(3)
    tx = dialect.new_mav(1, 25)
    data = seam.encode_bundle(tx, 4, _sensors(rng, 4), _truth(rng, 4))
    data += d.MAVLink_hil_actuator_controls_message(5, [0.5] * 16, 128, 0).pack(tx)
    fast = seam.parse_datagram(dialect.new_mav(1, 1), data)
    ref = seam.ParsedDatagram([m for m in dialect.new_mav(1, 1).parse_buffer(data)], 0)
    assert fast.bad == 0 and [m.get_type() for m in fast.messages] == [m.get_type() for m in ref.messages]
    for a, b in zip(fast.messages, ref.messages, strict=True):
        assert a.to_dict() == b.to_dict() or "nan" in str(b)
    # a heartbeat in the datagram: the whole datagram goes through pymavlink (same messages)
    mixed = data + d.MAVLink_heartbeat_message(1, 2, 3, 4, 5, 3).pack(tx)
    assert [m.get_type() for m in seam.parse_datagram(dialect.new_mav(1, 1), mixed).messages][-1] == "HEARTBEAT"
    # a corrupt frame still counts as bad
    bad = bytearray(data)
    bad[20] ^= 0xFF
    assert seam.parse_datagram(dialect.new_mav(1, 1), bytes(bad)).bad >= 1


def test_pack_actuator_controls_matches_pymavlink_pack() -> None:
    # The FC's per-step answer: fast path vs the pymavlink message packed by pymavlink, byte for byte.
    from navig8_fc.core.vehicle import VehicleConfig

    veh = VehicleConfig.load()
    rng = np.random.default_rng(3)
    fast, ref = dialect.new_mav(2, 1), dialect.new_mav(2, 1)
    for i in range(100):
        tilt = rng.uniform(-2, 2, 2).tolist()
        speed = rng.uniform(-900, 900, 3).tolist()
        if i % 10 == 0:
            speed[1] = math.nan
        cmd = SimpleNamespace(tilt_rad=tilt, speed_rad_s=speed)
        t_us = 1_700_000_000_000_000 + 10_000 * i
        want = seam.encode_actuator_controls(t_us, cmd, veh, armed=bool(i % 2)).pack(ref)
        ref.seq = (ref.seq + 1) % 256
        assert seam.pack_actuator_controls(fast, t_us, cmd, veh, armed=bool(i % 2)) == want


def _assembled(d, data: bytes):
    """The bundle the frame-by-frame path gives: pymavlink decode of each frame + BundleAssembler."""
    mav = d.MAVLink(None)
    asm, out = seam.BundleAssembler(), None
    for fr in split_frames(data)[0]:
        b = asm.add(mav.decode(bytearray(fr)))
        out = b if b is not None else out
    return out


def test_decode_step_datagram_equals_the_frame_by_frame_path(d) -> None:
    from dataclasses import replace

    rng = random.Random(21)
    tx = dialect.new_mav(1, dialect.COMPID_BRIDGE)
    for step in range(120):
        truth = _truth(rng, step) if step % 5 else None
        data = seam.encode_bundle(tx, step, _sensors(rng, step), truth)
        got = seam.decode_step_datagram(data)
        want = _assembled(d, data)
        assert got is not None and want is not None
        bundle, n_frames, fields = got
        assert n_frames == (5 if truth is not None else 4) == len(fields)
        for m in (d.MAVLink(None).decode(bytearray(fr)) for fr in split_frames(data)[0]):  # pymavlink's decode
            want_fields = m.to_dict()
            assert want_fields.pop("mavpackettype") == m.get_type()
            assert _same(list(fields[m.get_type()].values()), list(want_fields.values()))
            assert list(fields[m.get_type()]) == list(want_fields)
        assert _same(list(vars(replace(bundle, truth=None)).values()), list(vars(replace(want, truth=None)).values()))
        if truth is None:
            assert bundle.truth is None and want.truth is None
        else:
            assert _same(list(seam.truth_record(bundle.truth).values()), list(seam.truth_record(want.truth).values()))


def test_decode_step_datagram_declines_anything_but_a_clean_bundle(d) -> None:
    rng = random.Random(22)
    tx = dialect.new_mav(1, dialect.COMPID_BRIDGE)
    data = seam.encode_bundle(tx, 3, _sensors(rng, 3), _truth(rng, 3))
    frames = split_frames(data)[0]
    assert seam.decode_step_datagram(data) is not None
    bad_crc = bytearray(data)
    bad_crc[20] ^= 0x01
    other = seam.encode_bundle(tx, 4, _sensors(rng, 4), None)
    status = seam.pack(tx, [seam.encode_sim_status(seam.SimStatus(1, 2, seam.SIM_STATE_RUNNING, 0.0, 1.0, 0))])
    cases = {
        "bad CRC": bytes(bad_crc),
        "trailing garbage": data + b"\x01\x02",
        "truncated": data[:-3],
        "out of order": b"".join([frames[1], frames[0], *frames[2:]]),
        "no HIL_SENSOR": b"".join(frames[:-1]),
        "mixed steps": b"".join([split_frames(other)[0][0], *frames[1:]]),
        "a status message": status,
        "status then bundle": status + data,
        "two bundles": data + data,
        "empty": b"",
    }
    for label, dgram in cases.items():
        assert seam.decode_step_datagram(dgram) is None, label


def test_frame_fields_equals_pymavlink_decode_and_declines_bad_frames(d) -> None:
    from navig8_fc.core.vehicle import VehicleConfig

    veh = VehicleConfig.load()
    rng = np.random.default_rng(4)
    tx, mav = dialect.new_mav(2, 1), d.MAVLink(None)
    for i in range(50):
        cmd = SimpleNamespace(tilt_rad=rng.uniform(-1, 1, 2).tolist(), speed_rad_s=rng.uniform(-900, 900, 3).tolist())
        frame = seam.pack_actuator_controls(tx, 1_700_000_000_000_000 + 10_000 * i, cmd, veh, armed=i % 2 == 0)
        name, fields = seam.frame_fields(frame)
        want = mav.decode(bytearray(frame)).to_dict()
        assert name == want.pop("mavpackettype") == "HIL_ACTUATOR_CONTROLS"
        assert _same(list(fields.values()), list(want.values())) and list(fields) == list(want)
    bad = bytearray(frame)
    bad[15] ^= 0x10
    assert seam.frame_fields(bytes(bad)) is None
    assert seam.frame_fields(frame[:-1]) is None
    assert seam.frame_fields(b"") is None
