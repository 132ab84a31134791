"""The codec against pymavlink, the oracle: byte-identical frames, equal fields, bad input counted and dropped."""

from __future__ import annotations

import random

import numpy as np
import pytest
from mavlink_oracle import random_args, same, same_fields

from navig8_fc.mavlink import codec, dialect

NAMES = codec.SEAM_MESSAGES


@pytest.fixture(scope="module")
def d():
    return dialect.load()


@pytest.fixture(scope="module")
def c() -> codec.Codec:
    return codec.seam_codec()


def _cls(d, name: str):
    return d.mavlink_map[getattr(d, f"MAVLINK_MSG_ID_{name}")]


@pytest.mark.parametrize("name", NAMES)
def test_layout_is_the_generated_class_layout(d, c, name: str) -> None:
    spec, cls = c.specs[name], _cls(d, name)
    assert (spec.msg_id, spec.crc_extra, spec.size) == (cls.id, cls.crc_extra, cls.unpacker.size)
    assert spec.fieldnames == tuple(cls.fieldnames)
    assert spec.struct.format == cls.unpacker.format


@pytest.mark.parametrize("name", NAMES)
def test_frames_are_byte_identical_to_pymavlink(d, c, name: str) -> None:
    rng = random.Random(name)
    cls = _cls(d, name)
    enc = codec.Encoder(c, 9, 200)
    ref = dialect.new_mav(9, 200)
    for _ in range(300):  # > 256: the sequence number wraps
        args = random_args(rng, cls)
        want = cls(*args).pack(ref)
        ref.seq = (ref.seq + 1) % 256  # pack() alone does not advance it
        assert enc.frame(name, args) == want
        assert enc.seq == ref.seq


@pytest.mark.parametrize("name", NAMES)
def test_pack_fields_equals_pack_values(d, c, name: str) -> None:
    rng = random.Random(name + "fields")
    cls = _cls(d, name)
    args = random_args(rng, cls)
    spec = c.specs[name]
    assert spec.pack_fields(dict(zip(cls.fieldnames, args, strict=True))) == spec.pack_values(args)


@pytest.mark.parametrize("name", NAMES)
def test_decode_equals_pymavlink_decode(d, c, name: str) -> None:
    rng = random.Random(name + "decode")
    cls = _cls(d, name)
    tx, rx = dialect.new_mav(3, 25), dialect.new_mav(1, 1)
    counts = codec.ParseCounters()
    for i in range(200):
        tx.seq = i % 256
        frame = cls(*random_args(rng, cls)).pack(tx)
        want = rx.decode(bytearray(frame))
        got = c.parse(frame, counts)
        assert len(got) == 1
        m = got[0]
        assert (m.name, m.sysid, m.compid, m.seq) == (want.get_type(), 3, 25, i % 256)
        assert same_fields(m.fields, want)
        again = c.decode_frame(frame)
        assert again is not None and (again.name, again.keys, again.sysid, again.compid, again.seq) == (
            m.name, m.keys, m.sysid, m.compid, m.seq)
        assert same(again.values, m.values)
    assert counts == codec.ParseCounters()


def test_a_datagram_of_frames_decodes_in_order(d, c) -> None:
    rng = random.Random(5)
    tx = dialect.new_mav(1, 25)
    msgs = [_cls(d, n)(*random_args(rng, _cls(d, n))) for n in NAMES for _ in range(2)]
    data = b""
    for m in msgs:
        data += m.pack(tx)
        tx.seq = (tx.seq + 1) % 256
    got = c.parse(data, codec.ParseCounters())
    want = dialect.new_mav(1, 1).parse_buffer(data)
    assert [m.name for m in got] == [w.get_type() for w in want] == [m.get_type() for m in msgs]
    assert all(same_fields(g.fields, w) for g, w in zip(got, want, strict=True))


def test_encoder_frames_equal_pymavlink_packs_back_to_back(d, c) -> None:
    rng = random.Random(8)
    enc, ref = codec.Encoder(c, 1, 25), dialect.new_mav(1, 25)
    enc.seq = ref.seq = 250
    records = [(n, random_args(rng, _cls(d, n))) for n in NAMES]
    want = b""
    for n, args in records:
        want += _cls(d, n)(*args).pack(ref)
        ref.seq = (ref.seq + 1) % 256
    assert enc.frames(records) == want
    assert (enc.seq, enc.frames_out, enc.bytes_out) == (ref.seq, len(records), len(want))


def test_truncated_zero_payloads_are_padded(d, c) -> None:
    tx = dialect.new_mav(1, 1)
    frame = d.MAVLink_hil_actuator_controls_message(5, [0.0] * 16, 0, 0).pack(tx)
    assert frame[1] == 1  # only the low byte of time_usec survives the truncation
    assert codec.Encoder(c, 1, 1).frame("HIL_ACTUATOR_CONTROLS", (5, [0.0] * 16, 0, 0)) == frame
    m = c.decode_frame(frame)
    assert m is not None and m.fields == {"time_usec": 5, "controls": (0.0,) * 16, "mode": 0, "flags": 0}
    empty = d.MAVLink_hil_actuator_controls_message(0, [0.0] * 16, 0, 0).pack(tx)
    assert empty[1] == 1 and c.decode_frame(empty).fields["time_usec"] == 0  # one zero byte is always kept


def test_longer_payloads_are_cut_to_the_message(d, c) -> None:
    """A newer dialect's extension fields (a longer payload, CRC over all of it) are ignored, as pymavlink does."""
    tx = dialect.new_mav(1, 1)
    frame = bytearray(d.MAVLink_navig8_sim_status_message(1, 2, 1, 1.0, 3.0, 7).pack(tx))
    spec = c.specs["NAVIG8_SIM_STATUS"]
    body = bytes([frame[1] + 2]) + bytes(frame[2:-2]) + b"\x01\x02"
    longer = b"\xfd" + body + codec.crc16(body + spec.crc_extra_byte).to_bytes(2, "little")
    assert c.decode_frame(longer).fields == c.decode_frame(bytes(frame)).fields


def test_every_corrupt_byte_is_counted_and_dropped(d, c) -> None:
    tx = dialect.new_mav(1, 1)
    frame = d.MAVLink_navig8_sim_status_message(1, 2, 1, 1.0, 3.0, 0).pack(tx)
    for i in range(len(frame)):
        for flip in (0x01, 0x41, 0xFF):
            bad = bytearray(frame)
            bad[i] ^= flip
            counts = codec.ParseCounters()
            assert c.parse(bytes(bad), counts) == [], (i, flip)
            assert counts.bad_frames + counts.garbage_bytes > 0, (i, flip)


def test_bad_input_counters(d, c) -> None:
    tx = dialect.new_mav(1, 1)
    good = d.MAVLink_navig8_sim_status_message(1, 2, 1, 1.0, 3.0, 0).pack(tx)
    bad_crc = good[:-1] + bytes((good[-1] ^ 1,))
    unknown = d.MAVLink_statustext_message(6, b"hi").pack(tx)  # valid, but not a message this codec handles
    counts = codec.ParseCounters()
    got = c.parse(b"\x00\x01xyz" + good + bad_crc + unknown + good + good[:7], counts)
    assert [m.name for m in got] == ["NAVIG8_SIM_STATUS"] * 2
    assert counts == codec.ParseCounters(garbage_bytes=5, truncated=1, bad_crc=1, unknown_id=1)
    assert counts.bad_frames == 3


def test_signed_and_unknown_flag_frames_are_skipped(d, c) -> None:
    tx = dialect.new_mav(1, 1)
    tx.signing.secret_key = bytes(range(32))
    tx.signing.sign_outgoing = True
    tx.signing.link_id = 0
    tx.signing.timestamp = 1
    signed = d.MAVLink_navig8_sim_status_message(1, 2, 1, 1.0, 3.0, 0).pack(tx)
    assert signed[2] & codec.IFLAG_SIGNED and len(signed) == codec.V2_OVERHEAD + signed[1] + codec.SIGNATURE_LEN
    plain = d.MAVLink_navig8_sim_status_message(1, 2, 1, 1.0, 3.0, 0).pack(dialect.new_mav(1, 1))
    counts = codec.ParseCounters()
    assert [m.name for m in c.parse(signed + plain, counts)] == ["NAVIG8_SIM_STATUS"]  # the next frame survives
    assert counts == codec.ParseCounters(signed=1)
    flagged = bytearray(plain)
    flagged[2] = 0x02  # an incompat flag MAVLink 2 does not define (the CRC covers it: recompute)
    spec = c.specs["NAVIG8_SIM_STATUS"]
    flagged[-2:] = codec.crc16(bytes(flagged[1:-2]) + spec.crc_extra_byte).to_bytes(2, "little")
    counts = codec.ParseCounters()
    assert c.parse(bytes(flagged), counts) == [] and counts == codec.ParseCounters(bad_flags=1)


def test_mavlink1_frames_decode(d, c) -> None:
    tx = dialect.new_mav(4, 7)
    rng = random.Random(1)
    for name in ("HIL_SENSOR", "HIL_ACTUATOR_CONTROLS", "HEARTBEAT"):
        cls = _cls(d, name)
        frame = cls(*random_args(rng, cls)).pack(tx, force_mavlink1=True)
        assert frame[0] == codec.V1_MAGIC
        m = c.decode_frame(frame)
        assert m is not None and (m.name, m.sysid, m.compid) == (name, 4, 7)
        assert same_fields(m.fields, dialect.new_mav(1, 1).decode(bytearray(frame)))


def test_random_bytes_never_raise_and_never_hide_the_next_datagram(d, c) -> None:
    good = d.MAVLink_navig8_sim_status_message(1, 2, 1, 1.0, 3.0, 0).pack(dialect.new_mav(1, 1))
    rng = np.random.default_rng(0)
    for _ in range(500):
        noise = rng.integers(0, 256, int(rng.integers(0, 300)), dtype=np.uint8).tobytes()
        c.parse(noise, codec.ParseCounters())
        if rng.random() < 0.5:  # frame starts in the noise
            c.parse(noise + b"\xfd" + noise, codec.ParseCounters())
    assert [m.name for m in c.parse(good, codec.ParseCounters())] == ["NAVIG8_SIM_STATUS"]


def test_decode_frame_wants_exactly_one_frame(d, c) -> None:
    good = d.MAVLink_navig8_sim_status_message(1, 2, 1, 1.0, 3.0, 0).pack(dialect.new_mav(1, 1))
    assert c.decode_frame(good) is not None
    for bad in (good + good, good + b"\x00", good[:-1], b"", b"\xfd"):
        assert c.decode_frame(bad) is None


def test_char_messages_are_left_to_pymavlink(d) -> None:
    with pytest.raises(ValueError, match="char"):
        codec.Codec(["STATUSTEXT"])


def test_split_frames_handles_garbage_truncation_and_both_versions() -> None:
    m = dialect.new_mav(1, 1)
    d = dialect.load()
    hb = d.MAVLink_heartbeat_message(2, 8, 0, 0, 0, 3).pack(m)
    st = d.MAVLink_statustext_message(6, b"hello").pack(m)
    v1 = bytes([0xFE, 0]) + bytes(6)  # a zero-length MAVLink 1 frame (garbage content, right size)
    frames, garbage, truncated = codec.split_frames(b"xx" + hb + st + v1 + hb[:5])
    assert frames == [hb, st, v1] and garbage == 2 and truncated == 1
    signed = bytearray(hb)
    signed[2] |= 0x01
    frames, _, truncated = codec.split_frames(bytes(signed) + bytes(13))
    assert len(frames) == 1 and len(frames[0]) == len(hb) + 13 and truncated == 0


def test_crc_is_pymavlinks_x25(d) -> None:
    rng = random.Random(11)
    for n in (0, 1, 9, 100, 280):
        data = bytes(rng.randrange(256) for _ in range(n))
        assert codec.crc16(data) == d.x25crc(data).crc
    assert codec.crc16(b"123456789") == 0x6F91  # the CRC-16/MCRF4XX check value


def test_signed_frames_verify_with_pymavlink_and_only_with_their_key(d, c) -> None:
    """The sim link's session signing (MAVLink 2 signing): pymavlink with the same key accepts every frame, the
    codec decodes them only with that key (`Message.signed`), a frame signed before the key is signed again."""
    key, other = bytes(range(32)), bytes(32)
    enc = codec.Encoder(c, 3, 25, signing=codec.FrameSigning(key))
    records = [("NAVIG8_SIM_STATUS", (11, 1, 2, 1.0, 0.5, 0)), ("HIL_ACTUATOR_CONTROLS", (7, [0.25] * 16, 128, 0))]
    data = enc.frames(records)
    ref = d.MAVLink(None)
    ref.signing.secret_key = key
    got = ref.parse_buffer(data) or []
    assert [m.get_type() for m in got] == ["NAVIG8_SIM_STATUS", "HIL_ACTUATOR_CONTROLS"]
    assert ref.signing.goodsig_count == 2 and ref.signing.badsig_count == 0
    counts = codec.ParseCounters()
    assert [(m.name, m.signed) for m in c.parse(data, counts, key)] == [("NAVIG8_SIM_STATUS", True),
                                                                        ("HIL_ACTUATOR_CONTROLS", True)]
    assert c.parse(data, counts, other) == [] and c.parse(data, counts) == [] and counts.signed == 4
    plain = codec.Encoder(c, 3, 25).frames(records)
    assert [m.signed for m in c.parse(plain, counts, key)] == [False, False]  # unsigned: decoded, not authenticated
    assert [m.signed for m in c.parse(enc.resign(plain), counts, key)] == [True, True]
    assert c.decode_frame(enc.frame(*records[0])).values == records[0][1]  # our own frame read back for the log
