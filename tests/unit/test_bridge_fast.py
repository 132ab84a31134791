"""The bridge's wire: the plant's plain-float views encode like sense()/truth(); one datagram handler whose
answers and counters follow pymavlink's reading of the same bytes; pairing with one FC by its announcement."""

from __future__ import annotations

import dataclasses
import socket
import time

import numpy as np
import pytest

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.links.sim_guard import REPAIR_SILENCE_S, pairing_heartbeat, session_key
from navig8_fc.mavlink import codec, dialect, seam
from sim_bridge.bridge_options import BridgeOptions
from sim_bridge.fc_link import BridgeCounters
from sim_bridge.lockstep import Bridge
from sim_bridge.params import PlantParams
from sim_bridge.plant import Plant
from sim_bridge.scenario import load_scenario


def test_wire_views_encode_byte_identical_to_sense_and_truth() -> None:
    cfg, params, scn = VehicleConfig.load(), PlantParams.load(), load_scenario("paper")
    a = Plant(cfg, params, scn, np.random.default_rng(5))
    b = Plant(cfg, params, scn, np.random.default_rng(5))
    ma = codec.Encoder(codec.seam_codec(), 1, dialect.COMPID_BRIDGE)
    mb = codec.Encoder(codec.seam_codec(), 1, dialect.COMPID_BRIDGE)
    cmd = a.trim_command()
    for step in range(80):  # > 256 frames: seq wraps
        if step == 40:
            a.command_gripper(True, 1.5)
            b.command_gripper(True, 1.5)
        want = seam.encode_bundle(ma, step, a.sense(), a.truth())
        sw, tw = b.sense_wire(), b.truth_floats()
        assert seam.truth_message_record(step, tw) == seam.truth_message_record(step, a.truth())
        assert all(type(v) is float for v in sw.gyro_frd_rad_s + tw.pos_ned_m + tw.inertia_com_kgm2[2])
        assert seam.encode_bundle(mb, step, sw, tw) == want, step
        a.step_us(cmd, 10_000)
        b.step_us(cmd, 10_000)
    assert (ma.seq, ma.frames_out, ma.bytes_out) == (mb.seq, mb.frames_out, mb.bytes_out)
    assert np.array_equal(a.state_vector, b.state_vector)


FC_ADDR = ("127.0.0.1", 40001)


def _feed(br: Bridge, data: bytes, addr: tuple[str, int], now: float | None = None) -> seam.ActuatorControls | None:
    """One datagram from addr into the bridge's link, as its socket loop hands it over (for the current step)."""
    return br.link.handle_datagram(data, addr, br.time_usec, now)


def _announce(br: Bridge, nonce: int) -> bytes:
    return codec.Encoder(codec.seam_codec(), br.opts.sysid, dialect.COMPID_FC).frame(*pairing_heartbeat(nonce))


@pytest.fixture()
def bridge():
    br = Bridge(BridgeOptions(scenario="paper", speed=0.0, bridge_port=0, fc_port=1))
    _feed(br, _announce(br, 0x1234), FC_ADDR)  # paired with the FC at FC_ADDR
    assert (br.link.fc_addr, br.link.fc_nonce, br.counters.sessions) == (FC_ADDR, 0x1234, 1)
    yield br
    br.close()


def _answers(br: Bridge, nonce: int | None = None) -> dict[str, bytes]:
    """The FC's frames, signed with the session key of `nonce` (None: unsigned, as before any pairing)."""
    signing = None if nonce is None else codec.FrameSigning(session_key(nonce, br.opts.sysid))
    fc = codec.Encoder(codec.seam_codec(), br.opts.sysid, dialect.COMPID_FC, signing=signing)
    other = codec.Encoder(codec.seam_codec(), br.opts.sysid + 1, dialect.COMPID_FC, signing=signing)
    plain = codec.Encoder(codec.seam_codec(), br.opts.sysid, dialect.COMPID_FC)
    cmd = br.plant.trim_command()
    tu = br.time_usec
    good = seam.pack_actuator_controls(fc, tu, cmd, br.limits, armed=True)
    zeros = seam.pack_actuator_controls(fc, tu, type(cmd)((0.0, 0.0), (0.0, 0.0, 0.0)), br.limits, armed=False)
    at = -1 if signing is None else -codec.SIGNATURE_LEN - 1  # the CRC's last byte, before any signature
    bad_crc = good[:at] + bytes((good[at] ^ 1,)) + (good[at + 1:] if at != -1 else b"")
    return {
        "good": good,
        "zeros": zeros,  # payload truncated to a few bytes
        "stale": seam.pack_actuator_controls(fc, tu + 10_000, cmd, br.limits, armed=True),
        "foreign": seam.pack_actuator_controls(other, tu, cmd, br.limits, armed=True),
        "bad_crc": bad_crc,
        "truncated": good[:-3],
        "twice": good + good,
        "status": fc.frame(*seam.encode_sim_status(seam.SimStatus(tu, 1, 1, 0.0, 1.0, 0))),
        "heartbeat": fc.frame(*seam.announce_record()),
        "garbage": b"\x00" * 5,
        "arm": fc.frame(*seam.encode_arm_cmd(seam.ArmCommand(tu, (0.1, 0.2, 0.3), seam.GRIPPER_GRAB))),
        # the paired FC's address without its key (a spoofed source): never an answer
        "unsigned": seam.pack_actuator_controls(plain, tu, cmd, br.limits, armed=True),
    }


def test_handle_answers_and_counts_as_pymavlink_reads_the_bytes(bridge: Bridge) -> None:
    d = dialect.load()
    want_counts = {
        "good": dict(answers=1), "zeros": dict(answers=1), "stale": dict(stale_answers=1),
        "foreign": dict(foreign_frames=1), "bad_crc": dict(bad_frames=1), "truncated": dict(bad_frames=1),
        "twice": dict(answers=1, stale_answers=1), "status": dict(other_frames=1), "heartbeat": dict(other_frames=1),
        "garbage": dict(garbage_bytes=5), "arm": dict(arm_cmds=1), "unsigned": dict(unauthenticated=1),
    }
    for label, data in _answers(bridge, 0x1234).items():
        bridge.link.counters = BridgeCounters()
        got = _feed(bridge, data, FC_ADDR)
        assert dataclasses.asdict(bridge.counters) == dataclasses.asdict(
            BridgeCounters(datagrams_in=1, **want_counts[label])), label
        ref = dialect.new_mav(1, 1).parse_buffer(data) or []
        answers = [m for m in ref if m.get_type() == "HIL_ACTUATOR_CONTROLS" and m.get_srcSystem() == bridge.opts.sysid
                   and m.time_usec == bridge.time_usec]
        if not answers or label == "unsigned":
            assert got is None, label
            continue
        m, lim = answers[0], bridge.limits
        assert got == seam.ActuatorControls(  # pymavlink's decode, scaled by hand
            m.time_usec, (m.controls[0] * lim.tilt_max_abs_rad, m.controls[1] * lim.tilt_max_abs_rad),
            (m.controls[2] * lim.duct_speed_max_rad_s, m.controls[3] * lim.tail_speed_max_rad_s,
             m.controls[4] * lim.duct_speed_max_rad_s), bool(m.mode & 128)), label
    assert bridge.arm.pending_gripper == [seam.GRIPPER_GRAB]
    assert bridge.arm.joint_targets_rad == pytest.approx((0.1, 0.2, 0.3), rel=1e-7)
    assert d.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS == 93


def test_pairing_with_one_fc() -> None:
    """The bridge pairs with the FC that announces itself with a nonce and echoes it; answers count only from that
    address; another FC's announcement is refused while the paired one is live, accepted once it has been silent
    REPAIR_SILENCE_S; the paired address itself may re-pair at once (a restarted FC on its port)."""
    br = Bridge(BridgeOptions(scenario="ground", speed=0.0, bridge_port=0, fc_port=0))
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", 0))
    listener.settimeout(5.0)
    fc_addr = listener.getsockname()
    try:
        assert br.link.fc_addr is None
        br.link.send(b"nothing to send to")  # no address: dropped quietly
        data = _answers(br, 77)  # signed with the session key of the pairing below
        _feed(br, data["foreign"], ("127.0.0.1", 40001))
        _feed(br, data["bad_crc"], ("127.0.0.1", 40002))
        _feed(br, data["unsigned"], fc_addr)  # an answer before pairing: not from a paired FC
        assert br.link.fc_addr is None and br.counters.wrong_sender == 1
        _feed(br, _announce(br, 77), fc_addr)  # the FC's announcement: pair, echo the nonce
        assert (br.link.fc_addr, br.link.fc_nonce) == (fc_addr, 77)
        echo = codec.seam_codec().parse(listener.recvfrom(4096)[0], codec.ParseCounters())
        assert [(m.name, m.compid, m.fields["custom_mode"]) for m in echo] == [("HEARTBEAT", dialect.COMPID_BRIDGE, 77)]
        _feed(br, _announce(br, 77), fc_addr)  # the same announcement again: our echo was lost, echo again
        got = [codec.seam_codec().parse(listener.recvfrom(4096)[0], codec.ParseCounters()) for _ in range(2)]
        assert [(m.name, m.fields["custom_mode"]) for m in got[1]] == [("HEARTBEAT", 77)]  # after the pairing's status
        assert (br.counters.sessions, br.counters.echoes_repeated) == (1, 1)
        assert _feed(br, data["good"], ("127.0.0.1", 40004)) is None  # the right ids from the wrong address
        assert br.counters.wrong_sender == 2 and br.link.fc_addr == fc_addr
        assert _feed(br, data["good"], fc_addr) is not None
        _feed(br, _announce(br, 99), ("127.0.0.1", 40005))  # another "FC" while ours is live
        assert br.counters.pair_refused == 1 and (br.link.fc_addr, br.link.fc_nonce) == (fc_addr, 77)
        _feed(br, _announce(br, 5), fc_addr)  # our FC restarted on its port: a new session at once
        assert (br.link.fc_addr, br.link.fc_nonce, br.counters.sessions) == (fc_addr, 5, 2)
        later = time.perf_counter() + REPAIR_SILENCE_S  # ours silent that long: another may pair
        _feed(br, _announce(br, 6), ("127.0.0.1", 40006), now=later)
        assert (br.link.fc_addr, br.link.fc_nonce, br.counters.sessions) == (("127.0.0.1", 40006), 6, 3)
    finally:
        br.close()
        listener.close()
