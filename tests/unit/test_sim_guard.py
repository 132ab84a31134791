"""The FC's sim-link guard (navig8_fc/links/sim_guard.py) on real bundles: the plant's sensors encoded by the
bridge's encoder and parsed by the codec, as the FC receives them. Pairing by nonce, strict sequencing, whole
bundles only, validation with the last good values, and rate-limited reports."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.flight.failsafe import BAD_DATA_FAILSAFE_S
from navig8_fc.links.sim_guard import (
    MOCAP_REANCHOR_SAMPLES,
    REPAIR_SILENCE_S,
    REPORT_PERIOD_S,
    STAMP_LEAP_CONFIRM,
    SensorLimits,
    SimGuard,
    pairing_heartbeat,
)
from navig8_fc.mavlink import codec, dialect, seam
from sim_bridge.params import PlantParams
from sim_bridge.plant import Plant
from sim_bridge.scenario import load_scenario

BRIDGE = ("127.0.0.1", 4560)
OTHER = ("127.0.0.1", 4999)
SYSID = 1


class Wire:
    """A plant behind the bridge's encoder; `datagram(step, mutate)` is step k's datagram, parsed."""

    def __init__(self, sysid: int = SYSID, compid: int = dialect.COMPID_BRIDGE) -> None:
        self.plant = Plant(VehicleConfig.load(), PlantParams.load(), load_scenario("hover"), np.random.default_rng(3))
        self.cmd = self.plant.trim_command()
        self.enc = codec.Encoder(codec.seam_codec(), sysid, compid)
        self.step = 0

    def raw(self, mutate=None, truth_mutate=None) -> bytes:
        sw, tw = self.plant.sense_wire(), self.plant.truth_floats()
        if mutate:
            mutate(sw)
        if truth_mutate:
            truth_mutate(tw)
        return seam.encode_bundle(self.enc, self.step, sw, tw)

    def next(self, mutate=None, truth_mutate=None) -> bytes:
        """The next step's datagram (the plant advanced one 10 ms step)."""
        if self.step > 0 or getattr(self, "_started", False):
            self.plant.step_us(self.cmd, 10_000)
            self.step += 1
        self._started = True
        return self.raw(mutate, truth_mutate)

    def frame(self, record: seam.Record) -> bytes:
        return self.enc.frame(*record)

    def pair(self, guard: SimGuard) -> None:
        """Sign from now on with the session key the guard derived from the nonce this wire echoed."""
        assert guard.session_key is not None
        self.key = guard.session_key
        self.enc.signing = codec.FrameSigning(guard.session_key)

    def parse(self, data: bytes) -> list[codec.Message]:
        """data as the FC's sim link decodes it once paired (signatures verified with the session key)."""
        return codec.seam_codec().parse(data, codec.ParseCounters(), getattr(self, "key", None))


def parse(data: bytes) -> list[codec.Message]:
    return codec.seam_codec().parse(data, codec.ParseCounters())


def paired(now: float = 0.0) -> tuple[SimGuard, Wire]:
    nonces = iter(range(101, 200))
    g = SimGuard(SYSID, SensorLimits.from_vehicle(VehicleConfig.load()), lambda: next(nonces))
    w = Wire()
    inp, to = g.on_datagram(w.parse(w.frame(pairing_heartbeat(0))), BRIDGE, now)  # the bridge asks to pair
    assert to == BRIDGE and inp.kind == "none"
    assert g.announce_record()[1][3] == g.nonce == 101  # HEARTBEAT.custom_mode carries the nonce
    g.on_datagram(w.parse(w.frame(pairing_heartbeat(g.nonce))), BRIDGE, now)  # the echo opens the session
    assert g.peer == BRIDGE and g.counters.sessions == 1 and g.nonce != 101
    w.pair(g)
    return g, w


def test_pairing_needs_the_nonce_and_refuses_a_second_bridge_while_the_first_is_live() -> None:
    g = SimGuard(SYSID, SensorLimits.from_vehicle(VehicleConfig.load()), lambda: 0)
    assert g.nonce == 1  # never 0: 0 is the pair request
    w = Wire()
    assert g.on_datagram(w.parse(w.next()), BRIDGE, 0.0)[0].kind == "none"  # a bundle before pairing
    assert g.counters.unpaired_bundles == 1
    g.on_datagram(w.parse(w.frame(pairing_heartbeat(12345))), BRIDGE, 0.0)  # a guessed nonce
    assert g.peer is None and g.counters.wrong_sender == 1
    g.on_datagram(w.parse(w.frame(pairing_heartbeat(1))), BRIDGE, 0.0)
    assert g.peer == BRIDGE
    # a second "bridge" (right ids, other address) while ours talks: refused, no announcement (no nonce leaks)
    assert g.on_datagram(w.parse(w.frame(pairing_heartbeat(0))), OTHER, 1.0) == (g.on_datagram([], OTHER, 1.0)[0], None)
    assert g.counters.pair_refused == 1
    # other ids from the paired address: not the bridge
    stranger = Wire(sysid=SYSID, compid=dialect.COMPID_FC)
    assert g.on_datagram(parse(stranger.next()), BRIDGE, 1.0)[0].kind == "none"
    # silence for REPAIR_SILENCE_S: another may pair (a bridge restarted on another port)
    assert g.on_datagram(w.parse(w.frame(pairing_heartbeat(0))), OTHER, REPAIR_SILENCE_S)[1] == OTHER


def test_a_lost_echo_is_recovered_by_announcing_to_the_asker_and_a_repeated_echo_is_ignored() -> None:
    g, w = paired()
    assert not g.needs_announce(1.0)  # a live session: no announcements
    # the bridge restarts on its port and asks again: answered; until its echo comes, announced every wall second
    # to the asker (our answer or its echo may be lost: the bridge echoes what it hears again)
    assert g.on_datagram(w.parse(w.frame(pairing_heartbeat(0))), BRIDGE, 1.0)[1] == BRIDGE
    assert g.needs_announce(1.1) and g.pair_asked_by == BRIDGE
    nonce = g.nonce
    g.on_datagram(w.parse(w.frame(pairing_heartbeat(nonce))), BRIDGE, 1.2)
    assert g.counters.sessions == 2 and g.pair_asked_by is None and not g.needs_announce(1.3)
    # the bridge's echo again (it heard an announcement sent before ours arrived): not a wrong nonce, no session
    g.on_datagram(w.parse(w.frame(pairing_heartbeat(nonce))), BRIDGE, 1.4)
    assert (g.counters.repeated_echoes, g.counters.wrong_sender, g.counters.sessions) == (1, 0, 2)
    assert not g.has_reports or all("wrong nonce" not in t for _, t in g.reports(1.5))


def test_only_the_next_step_runs_the_controller() -> None:
    g, w = paired()
    steps = []
    for _ in range(3):
        inp, _ = g.on_datagram(w.parse(w.next()), BRIDGE, 0.1)
        steps.append((inp.kind, inp.bundle.step))
    assert steps == [("step", 0), ("step", 1), ("step", 2)]
    assert g.on_datagram(w.parse(w.raw()), BRIDGE, 0.1)[0].kind == "duplicate"  # the bridge's re-send
    old = w.raw()
    w.next()
    ahead = w.next()  # step 4: a step skipped
    assert g.on_datagram(w.parse(ahead), BRIDGE, 0.1)[0].kind == "none"
    replay = Wire()  # the bridge itself, sending an older stamp (signed: a spoofed one is refused earlier, below)
    replay.pair(g)
    assert g.on_datagram(replay.parse(replay.next()), BRIDGE, 0.1)[0].kind == "none"  # time went back: no restart
    assert g.on_datagram(w.parse(old), BRIDGE, 0.1)[0].kind == "duplicate"  # still at step 2
    assert g.counters.out_of_order == 2 and g.counters.duplicates == 2
    # forged for the next step by another socket: dropped
    nxt = Wire()
    for _ in range(4):
        data = nxt.next()
    assert parse(data)[0].fields["time_usec"] == 30_001
    assert g.on_datagram(parse(data), OTHER, 0.1)[0].kind == "none" and g.counters.wrong_sender == 1
    # the explicit reset: pair request + echo from the bridge, then time starts again
    g.on_datagram(w.parse(w.frame(pairing_heartbeat(0))), BRIDGE, 0.2)
    g.on_datagram(w.parse(w.frame(pairing_heartbeat(g.nonce))), BRIDGE, 0.2)
    assert g.counters.sessions == 2
    replay.pair(g)  # the new session's key
    assert g.on_datagram(replay.parse(replay.raw()), BRIDGE, 0.2)[0].bundle.step == 0
    # the paired address without the key (a spoofed source, or the old session's key): never a step
    assert g.on_datagram(parse(Wire().next()), BRIDGE, 0.3)[0].kind == "none"
    assert codec.seam_codec().parse(w.next(), codec.ParseCounters(), g.session_key) == []  # the old key: dropped
    assert g.counters.unauthenticated == 1


def test_fragments_and_mixed_datagrams_never_make_a_step() -> None:
    g, w = paired()
    data = w.next()
    frames, _, _ = codec.split_frames(data)
    assert len(frames) == 5
    kinds = [g.on_datagram(w.parse(b"".join(frames[:2])), BRIDGE, 0.0)[0].kind,
             g.on_datagram(w.parse(b"".join(frames[2:])), BRIDGE, 0.0)[0].kind,  # ends with HIL_SENSOR: no step
             g.on_datagram(w.parse(b"".join(frames[2:]) + b"".join(frames[:2])), BRIDGE, 0.0)[0].kind,  # wrong order
             g.on_datagram(w.parse(data + data), BRIDGE, 0.0)[0].kind,  # two bundles in one datagram
             g.on_datagram(w.parse(b"\xfd\x09garbage" + b"".join(frames[:-1])), BRIDGE, 0.0)[0].kind]
    assert kinds == ["none"] * 5 and g.counters.malformed == 5
    inp, _ = g.on_datagram(w.parse(b"\x00\x01junk" + data), BRIDGE, 0.0)  # bytes between frames, whole bundle: a step
    assert inp.kind == "step"


def set_field(name: str, i: int, value: float):
    """A bundle edit setting one sample's field[i] (test_fc_sim_guard.py uses it too)."""
    def f(sw):
        getattr(sw, name)[i] = value
    return f


@pytest.mark.parametrize(("name", "i", "value", "group"), [
    ("joint_pos_rad", 0, math.nan, "arm"),  # today: "empty box (or NaN bound)" in the estimator's projection
    ("joint_rate_rad_s", 2, math.inf, "arm"),
    ("gyro_frd_rad_s", 1, math.nan, "imu"),
    ("accel_frd_m_s2", 2, 1e6, "imu"),
    ("pos_ned_m", 0, 1e6, "mocap"),  # today: moves the vehicle 6.36 m
    ("vel_ned_m_s", 1, -math.inf, "mocap"),
    ("quat_wxyz", 0, 2.0, "mocap"),
    ("prop_speed_rad_s", 1, 1e6, "actuators"),
    ("duct_tilt_rad", 0, math.nan, "actuators"),
])
def test_a_bad_value_is_replaced_by_the_last_good_one(name: str, i: int, value: float, group: str) -> None:
    g, w = paired()
    good = g.on_datagram(w.parse(w.next()), BRIDGE, 0.0)[0].bundle
    inp, _ = g.on_datagram(w.parse(w.next(set_field(name, i, value))), BRIDGE, 0.0)
    assert inp.kind == "step" and inp.bad_groups == (group,) and inp.wire is None  # never logged decoded
    field = {"arm": "joint_pos_rad", "imu": "gyro_frd_rad_s", "mocap": "pos_ned_m",
             "actuators": "prop_speed_rad_s"}[group]
    assert getattr(inp.bundle, field) == getattr(good, field)
    flat = [x for v in inp.bundle[2:12] for x in (v if isinstance(v, tuple) else (v,))]
    assert all(math.isfinite(x) for x in flat) and max(abs(x) for x in flat) < 1e4
    assert getattr(g.counters, f"invalid_{group}") == 1 and g.counters.invalid == 1
    ok, _ = g.on_datagram(w.parse(w.next()), BRIDGE, 0.0)
    assert ok.bad_groups == () and ok.wire is not None and g.bad_data_s() == 0.0


def test_a_position_jump_faster_than_the_vehicle_can_fly_is_implausible() -> None:
    g, w = paired()
    g.on_datagram(w.parse(w.next()), BRIDGE, 0.0)
    inp, _ = g.on_datagram(w.parse(w.next(lambda sw: sw.pos_ned_m.__setitem__(0, sw.pos_ned_m[0] + 0.5))), BRIDGE, 0.0)
    assert inp.bad_groups == ("mocap",)  # 0.5 m in 10 ms: 50 m/s
    inp, _ = g.on_datagram(w.parse(w.next(lambda sw: sw.pos_ned_m.__setitem__(0, sw.pos_ned_m[0] + 0.2))), BRIDGE, 0.0)
    assert inp.bad_groups == ()  # 0.2 m over 20 ms since the last good sample: within 30 m/s + noise


def test_persistent_bad_data_reaches_the_failsafe_time_and_truth_is_checked() -> None:
    g, w = paired()
    assert not g.has_good
    first, _ = g.on_datagram(w.parse(w.next(set_field("gyro_frd_rad_s", 0, math.nan))), BRIDGE, 0.0)
    assert first.bad_groups == ("imu",) and not g.has_good  # nothing good to fly on yet
    g.on_datagram(w.parse(w.next()), BRIDGE, 0.0)
    n = 0
    while g.bad_data_s() < BAD_DATA_FAILSAFE_S:
        g.on_datagram(w.parse(w.next(set_field("accel_frd_m_s2", 0, math.nan))), BRIDGE, 0.0)
        n += 1
    assert n == round(BAD_DATA_FAILSAFE_S / 0.01) + 1
    inp, _ = g.on_datagram(w.parse(w.next(truth_mutate=lambda t: t.pos_ned_m.__setitem__(2, math.nan))), BRIDGE, 0.0)
    assert inp.bad_groups == () and inp.bundle.truth is None and "NAVIG8_TRUTH" not in inp.wire
    assert g.counters.invalid_truth == 1


def test_a_forged_done_from_another_socket_is_not_the_bridge_status() -> None:
    g, w = paired()
    done = w.frame(seam.encode_sim_status(seam.SimStatus(1, 0, seam.SIM_STATE_DONE, 0.0, 1.0, 0)))
    assert g.on_datagram(w.parse(done), OTHER, 0.0)[0].kind == "none"
    inp, _ = g.on_datagram(w.parse(done), BRIDGE, 0.0)
    assert inp.kind == "status" and inp.status.state == seam.SIM_STATE_DONE


def test_reports_once_per_kind_and_period_with_the_count() -> None:
    g, w = paired()
    assert [s for s, _ in g.reports(0.0)] == [6]  # the session
    for _ in range(1000):
        g.on_datagram(w.parse(w.next()), OTHER, 0.0)
    first = g.reports(0.0)
    assert len(first) == 1 and "(not paired)" in first[0][1] and "(x1000)" in first[0][1]
    g.on_datagram(w.parse(w.next()), OTHER, 1.0)
    assert g.reports(1.0) == []  # within the period: counted, not sent
    later = g.reports(REPORT_PERIOD_S)
    assert len(later) == 1 and first[0][0] == 4


def test_the_position_allowance_stops_growing_and_a_consistent_new_position_is_reacquired() -> None:
    g, w = paired()
    g.on_datagram(w.parse(w.next()), BRIDGE, 0.0)
    x0 = w.plant.sense_wire().pos_ned_m[0]
    for _ in range(1000):  # 10 s without a valid motion-capture sample
        g.on_datagram(w.parse(w.next(set_field("pos_ned_m", 0, math.nan))), BRIDGE, 0.0)
    far = w.next(set_field("pos_ned_m", 0, x0 + 100.0))  # 100 m off: 30 m/s x 10 s would allow 300 m
    assert g.on_datagram(w.parse(far), BRIDGE, 0.0)[0].bad_groups == ("mocap",)
    kinds = [g.on_datagram(w.parse(w.next(set_field("pos_ned_m", 0, x0 + 100.0))), BRIDGE, 0.0)[0].bad_groups
             for _ in range(MOCAP_REANCHOR_SAMPLES - 1)]  # the same place again and again: re-acquired there
    assert kinds[:-1] == [("mocap",)] * (MOCAP_REANCHOR_SAMPLES - 2) and kinds[-1] == ()
    assert g.counters.mocap_reanchors == 1


def test_one_far_future_stamp_does_not_make_later_bundles_older_in_real_time() -> None:
    g, w = paired()
    g.monotonic = True
    assert g.on_datagram(w.parse(w.next()), BRIDGE, 0.0)[0].kind == "step"
    future = seam.bundle_records(w.step + 1, _restamped(w, 1_000_000_000), None)
    assert g.on_datagram(w.parse(w.enc.frames(future)), BRIDGE, 0.0)[0].kind == "none"
    assert g.counters.stamp_leaps == 1
    assert [g.on_datagram(w.parse(w.next()), BRIDGE, 0.0)[0].kind for _ in range(3)] == ["step"] * 3
    # a simulator that really moved on: STAMP_LEAP_CONFIRM bundles in a row continue from the new time
    kinds = [g.on_datagram(w.parse(w.enc.frames(seam.bundle_records(w.step + 1 + i, _restamped(
        w, 1_000_000_000 + i * 10_000), None))), BRIDGE, 0.0)[0].kind for i in range(STAMP_LEAP_CONFIRM)]
    assert kinds == ["none"] * (STAMP_LEAP_CONFIRM - 1) + ["step"]


def _restamped(w: Wire, t_add_us: int):
    s = w.plant.sense_wire()
    s.time_us += t_add_us
    return s
