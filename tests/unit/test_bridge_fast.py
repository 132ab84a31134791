"""The bridge's per-step fast paths give the same bytes, answers and counters as the general ones."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.mavlink import dialect, seam
from sim_bridge.bridge import Bridge, BridgeOptions
from sim_bridge.params import PlantParams
from sim_bridge.plant import Plant
from sim_bridge.scenario import load_scenario


def test_wire_views_encode_byte_identical_to_sense_and_truth() -> None:
    cfg, params, scn = VehicleConfig.load(), PlantParams.load(), load_scenario("paper")
    a = Plant(cfg, params, scn, np.random.default_rng(5))
    b = Plant(cfg, params, scn, np.random.default_rng(5))
    ma = dialect.new_mav(1, dialect.COMPID_BRIDGE)
    mb = dialect.new_mav(1, dialect.COMPID_BRIDGE)
    cmd = a.trim_command()
    for step in range(80):  # > 256 frames: seq wraps
        if step == 40:
            a.command_gripper(True, 1.5)
            b.command_gripper(True, 1.5)
        want = seam.encode_bundle(ma, step, a.sense(), a.truth())
        sw, tw = b.sense_wire(), b.truth_wire()
        assert seam._truth_args(step, tw) == seam._truth_args(step, a.truth())
        assert all(type(v) is float for v in sw.gyro_frd + tw.pos_ned_m + tw.inertia_com_kgm2[2])
        assert seam.encode_bundle(mb, step, sw, tw) == want, step
        a.step_us(cmd, 10_000)
        b.step_us(cmd, 10_000)
    assert (ma.seq, ma.total_packets_sent, ma.total_bytes_sent) == (mb.seq, mb.total_packets_sent, mb.total_bytes_sent)
    assert np.array_equal(a._x, b._x)


@pytest.fixture()
def bridge():
    br = Bridge(BridgeOptions(scenario="paper", speed=0.0, bridge_port=0, fc_port=1))
    yield br
    br.close()


def _answers(br: Bridge) -> list[bytes]:
    fc = dialect.new_mav(br.opts.sysid, dialect.COMPID_FC)
    other = dialect.new_mav(br.opts.sysid + 1, dialect.COMPID_FC)
    cmd = br.plant.trim_command()
    tu = br.time_usec
    good = seam.pack_actuator_controls(fc, tu, cmd, br.limits, armed=True)
    zeros = seam.pack_actuator_controls(fc, tu, type(cmd)((0.0, 0.0), (0.0, 0.0, 0.0)), br.limits, armed=False)
    bad_crc = good[:-1] + bytes((good[-1] ^ 1,))
    d = dialect.load()
    status = seam.pack(fc, [seam.encode_sim_status(seam.SimStatus(tu, 1, 1, 0.0, 1.0, 0))])
    return [
        good,
        zeros,  # payload truncated to a few bytes
        seam.pack_actuator_controls(fc, tu + 10_000, cmd, br.limits, armed=True),  # stale
        seam.pack_actuator_controls(other, tu, cmd, br.limits, armed=True),  # foreign
        bad_crc,
        good[:-3],
        good + good,
        status,
        seam.pack(fc, [d.MAVLink_heartbeat_message(0, 0, 0, 0, 0, 3)]),
        b"\x00" * 5,
    ]


def test_handle_fast_path_equals_the_general_path(bridge: Bridge) -> None:
    for data in _answers(bridge):
        rx = bridge.rx
        bridge.counters = type(bridge.counters)()
        before = (rx.total_packets_received, rx.total_bytes_received)
        got = bridge._handle(data)
        fast = (dataclasses.asdict(bridge.counters), rx.total_packets_received - before[0],
                rx.total_bytes_received - before[1])
        bridge.counters = type(bridge.counters)()
        before = (rx.total_packets_received, rx.total_bytes_received)
        want = bridge._handle_general(data)
        general = (dataclasses.asdict(bridge.counters), rx.total_packets_received - before[0],
                   rx.total_bytes_received - before[1])
        assert got == want, data
        assert fast == general, data
    # the first three (ours, CRC good) never reach the general path
    good, zeros, stale = _answers(bridge)[:3]

    def general(_data: bytes) -> None:
        raise AssertionError("general path taken")

    bridge._handle_general = general  # type: ignore[method-assign]
    assert bridge._handle(good) is not None
    assert bridge._handle(zeros).tilt_rad == (0.0, 0.0)
    assert bridge._handle(stale) is None
