"""MCAP logger: JSON channels with schemas, metadata, recovery of a truncated log."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from navig8_fc.shell.mcap_log import McapLogger, decode_json, json_schema_for, read_mcap, read_metadata, to_jsonable


@dataclass(frozen=True)
class _Rec:
    t: float
    v: tuple[float, float]
    ok: bool
    arr: np.ndarray


def test_round_trip_and_metadata(tmp_path: Path) -> None:
    p = tmp_path / "a.mcap"
    with McapLogger(p) as lg:
        lg.metadata("params", {"INDI_K_MIN": 0.5})
        for i in range(100):
            lg.log("/x", i * 10_000_000, _Rec(i * 0.01, (1.0, math.nan), True, np.arange(3.0)))
        lg.log_raw("/raw", 5, b"\xfd\x01")
    msgs = list(read_mcap(p))
    assert len(msgs) == 101
    topic, t_ns, d = msgs[1]
    assert topic == "/x" and t_ns == 10_000_000 and d == {"t": 0.01, "v": [1.0, None], "ok": True, "arr": [0, 1, 2]}
    assert any(m[2] == b"\xfd\x01" for m in msgs)
    assert read_metadata(p) == {"params": {"INDI_K_MIN": 0.5}}


def test_truncated_log_recovers_complete_chunks(tmp_path: Path) -> None:
    p = tmp_path / "b.mcap"
    with McapLogger(p) as lg:
        for i in range(30000):
            lg.log("/x", i, {"i": i, "pad": [float(i)] * 8})
    data = p.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    got = [d["i"] for _, _, d in read_mcap(cut)]
    assert 0 < len(got) < 30000
    assert got == list(range(len(got)))  # an unbroken prefix


def test_schema_describes_fields() -> None:
    s = json_schema_for(to_jsonable({"a": 1.0, "b": [1.0, 2.0], "c": {"d": True}}))
    assert s["properties"]["a"]["type"] == ["number", "null"]
    assert s["properties"]["b"]["type"] == "array"
    assert s["properties"]["c"]["properties"]["d"]["type"] == "boolean"
    json.dumps(s)


def test_mavlink_schema_from_the_message_definition() -> None:
    from pymavlink.dialects.v20 import common as m

    from navig8_fc.logrecords import mavlink_json_schema

    s = mavlink_json_schema(m.MAVLink_attitude_quaternion_message)
    props = s["properties"]
    assert props["q1"]["type"] == ["number", "null"] and "rad" not in props["q1"].get("description", "")
    assert props["rollspeed"]["description"].startswith("[rad/s]")
    assert props["repr_offset_q"]["type"] == "array" and props["repr_offset_q"]["maxItems"] == 4
    hb = mavlink_json_schema(m.MAVLink_heartbeat_message)["properties"]
    assert hb["custom_mode"]["type"] == "integer" and "MAV_TYPE" in hb["type"]["description"]
    # array lengths belong to the right fields when the wire order differs from the declaration order
    odom = mavlink_json_schema(m.MAVLink_odometry_message)["properties"]
    assert odom["y"]["type"] == ["number", "null"] and odom["frame_id"]["type"] == "integer"
    assert (odom["q"]["maxItems"], odom["pose_covariance"]["maxItems"]) == (4, 21)


def test_raw_channels_carry_the_peer_in_channel_metadata(tmp_path) -> None:
    from mcap.reader import make_reader

    from navig8_fc.shell.mcap_log import McapLogger, read_mcap

    path = tmp_path / "peers.mcap"
    with McapLogger(path) as log:
        log.log_raw("/mavlink/gcs/in", 1, b"\xfd\x01", peer="127.0.0.1:14550")
        log.log_raw("/mavlink/gcs/in", 2, b"\xfd\x02", peer="127.0.0.1:14551")
        log.log_raw("/mavlink/gcs/in", 3, b"\xfd\x03", peer="127.0.0.1:14550")
        log.log_raw("/mavlink/gcs/out", 4, b"\xfd\x04", peer="127.0.0.1:14550,127.0.0.1:14551")
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        peers = [(ch.topic, ch.metadata["peer"], ch.metadata["link"], ch.metadata["direction"])
                 for _, ch, _ in reader.iter_messages(log_time_order=True)]
    assert peers == [("/mavlink/gcs/in", "127.0.0.1:14550", "gcs", "in"),
                     ("/mavlink/gcs/in", "127.0.0.1:14551", "gcs", "in"),
                     ("/mavlink/gcs/in", "127.0.0.1:14550", "gcs", "in"),
                     ("/mavlink/gcs/out", "127.0.0.1:14550,127.0.0.1:14551", "gcs", "out")]
    # One topic for readers that go by topic.
    assert [d for _, _, d in read_mcap(path, ["/mavlink/gcs/in"])] == [b"\xfd\x01", b"\xfd\x02", b"\xfd\x03"]


def _expected_from_truth(tr: Any) -> dict[str, Any]:
    """What each /truth key must hold, read off the plant's Truth (numpy) by its own names."""
    import numpy as np

    by_name = {k: getattr(tr, k) for k in tr._fields}
    by_name.update(duct_tilt_rad=tr.actuator_pos[:2], prop_speed_rad_s=tr.actuator_pos[2:],
                   inertia_diag_kgm2=np.diag(tr.inertia_com_kgm2))
    return by_name


def test_truth_records_in_process_and_over_the_wire_agree() -> None:
    """/truth in navig8-sim (Plant.truth_floats) and in navig8-fc (a decoded NAVIG8_TRUTH): one record function, the
    plant's Truth vocabulary; every key equals the Truth field of its name (the in-process record exactly, the
    wire's to float32 rounding), and the wire lacks only the four quantities NAVIG8_TRUTH does not carry."""
    import numpy as np

    from navig8_fc.core.vehicle import VehicleConfig
    from navig8_fc.logrecords import log_truth_record
    from navig8_fc.mavlink import codec, seam
    from sim_bridge import Plant, PlantParams, load_scenario

    plant = Plant(VehicleConfig.load(), PlantParams.load(), load_scenario("paper"), np.random.default_rng(2))
    plant.step(plant.trim_command(), 0.5)
    tr = plant.truth()
    expected = _expected_from_truth(tr)
    local = log_truth_record(plant.truth_floats())
    c = codec.seam_codec()
    msgs = c.parse(seam.encode_bundle(codec.Encoder(c, 1, 25), 50, plant.sense(), tr), codec.ParseCounters())
    wire = log_truth_record(seam.decode_bundle(msgs).truth)
    extra = {"ang_accel_frd_rad_s2", "reaction_moment_o_frd_nm", "reaction_force_nog_frd_n",
             "reaction_moment_mount_nog_frd_nm"}
    assert set(local) - set(wire) == extra and set(wire) <= set(local)
    assert [k for k in local if k not in extra] == list(wire)  # the same order too
    assert set(local) <= set(expected), set(local) - set(expected)  # no key outside the Truth vocabulary
    for k, v in local.items():
        np.testing.assert_array_equal(np.asarray(v, dtype=float), np.asarray(expected[k], dtype=float), err_msg=k)
    for k, v in wire.items():
        np.testing.assert_allclose(np.asarray(v, dtype=float), np.asarray(expected[k], dtype=float), rtol=1e-6,
                                   atol=1e-6, err_msg=k)


def test_the_in_process_truth_record_follows_the_plant_step_by_step() -> None:
    """Plant.truth_floats is truth() as plain floats at every step (the same numbers, not a stale copy)."""
    import numpy as np

    from navig8_fc.core.vehicle import VehicleConfig
    from navig8_fc.logrecords import log_truth_record
    from sim_bridge import Plant, PlantParams, load_scenario

    plant = Plant(VehicleConfig.load(), PlantParams.load(), load_scenario("paper"), np.random.default_rng(2))
    for _ in range(3):
        plant.step(plant.trim_command(), 0.25)
        expected = _expected_from_truth(plant.truth())
        for k, v in log_truth_record(plant.truth_floats()).items():
            np.testing.assert_array_equal(np.asarray(v, dtype=float), np.asarray(expected[k], dtype=float),
                                          err_msg=k)


def test_rotation_keeps_complete_parts_with_the_same_channels(tmp_path: Path) -> None:
    """A size cap: each part is a whole MCAP (the library's CRC-checking reader reads it), holds the run's start
    metadata and every channel again (the cached ids stay valid), and the first part and the newest `keep_files`
    parts remain."""
    from mcap.reader import make_reader

    from navig8_fc.shell.mcap_log import part_path

    p = tmp_path / "run.mcap"
    lg = McapLogger(p, chunk_size=4096, max_bytes=50_000, keep_files=3)
    lg.metadata("run", {"scenario": "hover"})
    cid = lg.json_channel("/fast", {"type": "object"})
    for i in range(20_000):
        lg.log_json_bytes(cid, i, json.dumps({"i": i, "pad": [i] * 8}).encode(), i)
        lg.log_raw("/mavlink/sim/in", i, bytes(16), i, peer="127.0.0.1:1")
        if i % 100 == 0:
            lg.maybe_rotate()
    lg.close()
    assert lg.rotations >= 5 and lg.error is None and lg.dropped == 0
    parts = sorted(tmp_path.glob("run*.mcap"), key=lambda q: q.stat().st_mtime_ns)
    # the first part (the flight's start) is never deleted; after it the newest keep_files parts
    assert parts == [p] + [part_path(p, k) for k in range(lg.rotations - 2, lg.rotations + 1)]
    last = None
    for q in parts:
        assert q.stat().st_size < 50_000 + 20_000  # the cap plus at most one check interval of records
        with open(q, "rb") as fh:
            r = make_reader(fh, validate_crcs=True)
            got = [json.loads(m.data)["i"] for _s, ch, m in r.iter_messages(topics=["/fast"], log_time_order=False)]
        assert got == list(range(got[0], got[0] + len(got)))  # no record lost or doubled
        assert last is None or got[0] == last + 1 or q == parts[1]  # (the parts between the first and these: gone)
        last = got[-1]
        assert read_metadata(q)["run"] == {"scenario": "hover"}
    assert last == 19_999


def test_a_failing_disk_stops_the_log_without_raising() -> None:
    """/dev/full: every write fails with ENOSPC from the kernel. The logger keeps the reason, counts what it drops,
    and never raises into the caller."""
    lg = McapLogger("/dev/full", chunk_size=4096)
    for i in range(2000):
        lg.log("/x", i, {"i": i, "pad": [float(i)] * 8})
    lg.metadata("end", {"ok": True})
    lg.maybe_rotate()
    lg.close()
    assert lg.error == "No space left on device" and lg.dropped > 1000


def test_navig8_log_repair_rewrites_a_log_cut_in_the_middle_of_a_chunk(tmp_path: Path) -> None:
    """A log cut inside a write (no provisional footer at its end): the stock reader's defaults raise on it;
    `navig8-log repair` rewrites it, and the result reads with them, every message of the complete chunks kept with
    its channel's metadata (the peer)."""
    from mcap.reader import make_reader

    from navig8_tools.log_repair import main as log_main

    p = tmp_path / "run.mcap"
    lg = McapLogger(p, chunk_size=4096)
    lg.metadata("run", {"scenario": "hover"})
    cid = lg.json_channel("/fast", {"type": "object"})
    for i in range(3000):
        lg.log_json_bytes(cid, i, json.dumps({"i": i}).encode(), i)
        lg.log_raw("/mavlink/gcs/in", i, bytes(8), i, peer="127.0.0.1:9")
    lg.close()
    whole = p.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole[: len(whole) // 2])  # the middle of a chunk, no footer
    with open(cut, "rb") as fh, pytest.raises(Exception):  # noqa: B017 - whatever the stock reader raises
        list(make_reader(fh).iter_messages())
    assert log_main(["repair", str(cut), "-o", str(tmp_path / "fixed.mcap")]) == 0
    with open(tmp_path / "fixed.mcap", "rb") as fh:
        r = make_reader(fh, validate_crcs=True)
        got = [(ch.topic, ch.metadata.get("peer"), m.log_time) for _s, ch, m in r.iter_messages(log_time_order=False)]
    fast = [t for topic, _p, t in got if topic == "/fast"]
    assert 1000 < len(fast) < 3000 and fast == list(range(len(fast)))
    assert {p for topic, p, _t in got if topic == "/mavlink/gcs/in"} == {"127.0.0.1:9"}
    assert read_metadata(tmp_path / "fixed.mcap")["run"] == {"scenario": "hover"}
    assert log_main(["repair", str(tmp_path / "nope.mcap")]) == 1


def test_a_setpoint_logged_under_the_old_key_loads_under_pos_ned_m(tmp_path: Path) -> None:
    """/fc/setpoint's position was "pos_ned" before it had its unit: navig8_tools.logdata reads both."""
    from navig8_tools.logdata import load_run

    for i, key in enumerate(("pos_ned", "pos_ned_m")):
        p = tmp_path / f"sp{i}.mcap"
        with McapLogger(p) as lg:
            lg.log("/fc/setpoint", 0, {key: [1.0, 2.0, -3.0], "pitch_rad": 0.0, "yaw_rad": 0.5})
        sp = load_run(p)["/fc/setpoint"]
        np.testing.assert_array_equal(sp.field("pos_ned_m", 3), [[1.0, 2.0, -3.0]])


@pytest.mark.parametrize("text", [
    b'{"a":0.1,"b":[1e-320,5e-324,1.7976931348623157e308,-0.0],"c":0.00004855950094528755,"d":null,"e":"\\u00e9"}',
    b'{"t":9223372036854775807,"u":-9223372036854775808}', b'{"big":18446744073709551616}',
    b'[1, -123456789012345678901]',
    b'{"a": NaN, "b": -Infinity}', b'[1e999]', b'{"a":1,"a":2}', b'"\\ud800"', b'12345678901234567890'])
def test_the_readers_json_is_json_loads(text: bytes) -> None:
    """The log reader decodes through orjson where it gives json.loads's objects; integers beyond 64 bits, NaN and
    Infinity go to json.loads: the same types, the same float bits, the keys in the same order."""
    got, want = decode_json(text), json.loads(text)
    assert repr(got) == repr(want) and type(got) is type(want)
