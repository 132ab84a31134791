"""MAVLink parameter protocol: paced list, read by name/index, set (accepted/refused), encoding, storage."""

from __future__ import annotations

import math
import struct
from io import BytesIO
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.gcs.params import (
    PARAM_ENCODING_CAPABILITY,
    ParamProtocol,
    decode_param_value,
    encode_param_value,
    param_name,
)
from navig8_fc.params.registry import ParamRegistry, StabilityFloor
from navig8_fc.params.store import ParamStore

REAL32 = mavlink2.MAV_PARAM_TYPE_REAL32
INT32 = mavlink2.MAV_PARAM_TYPE_INT32


def _floor(values):
    return StabilityFloor(lambda_crit=0.2, min_eigenvalue=float(values["INDI_K_MIN"]))


@pytest.fixture
def mavs() -> tuple[Any, Any]:
    return (mavlink2.MAVLink(BytesIO(), srcSystem=1, srcComponent=1),
            mavlink2.MAVLink(BytesIO(), srcSystem=255, srcComponent=190))


def wire(msg: Any, sender: Any, receiver: Any) -> Any:
    """What the other side decodes: packs with the sender (checks the message is valid) and parses."""
    return receiver.decode(bytearray(msg.pack(sender)))


def make(mavs, store: ParamStore | None = None) -> tuple[ParamProtocol, ParamRegistry]:
    reg = ParamRegistry.from_defaults(stability_check=_floor)
    return ParamProtocol(reg, mavs[0], store), reg


def send(proto: ParamProtocol, mavs, msg: Any, now_s: float = 0.0) -> list[Any]:
    veh, gcs = mavs
    return [wire(m, veh, gcs) for m in proto.handle(wire(msg, gcs, veh), now_s)]


def by_type(msgs: list[Any], kind: str) -> list[Any]:
    return [m for m in msgs if m.get_type() == kind]


def value_of(pv: Any) -> float | int:
    return decode_param_value(pv.param_value, pv.param_type)


# --- list ----------------------------------------------------------------------------------------------
def test_list_sends_every_index_exactly_once_paced(mavs) -> None:
    proto, reg = make(mavs)
    veh, gcs = mavs
    assert send(proto, mavs, gcs.param_request_list_encode(1, 0)) == []
    got: list[Any] = []
    t = 0.0
    polls = 0
    while proto.list_remaining:
        batch = [wire(m, veh, gcs) for m in proto.poll(t)]
        assert len(batch) <= 20
        got += batch
        t += 0.01
        polls += 1
        assert polls < 1000
    assert [m.param_index for m in got] == list(range(len(reg)))
    assert all(m.param_count == len(reg) for m in got)
    assert {m.param_id for m in got} == {d.name for d in reg.definitions}
    for m in got:
        d = reg.at_index(m.param_index)
        assert m.param_type == (INT32 if d.type == "INT32" else REAL32)
        assert value_of(m) == pytest.approx(reg.get(d.name))
    assert proto.poll(t + 1.0) == []


def test_list_pacing_rate(mavs) -> None:
    reg = ParamRegistry.from_defaults(stability_check=_floor)
    proto = ParamProtocol(reg, mavs[0], rate_per_s=100.0, burst=5)
    proto.handle(wire(mavs[1].param_request_list_encode(1, 1), mavs[1], mavs[0]), 0.0)
    assert len(proto.poll(0.0)) == 5  # a first burst at once
    assert len(proto.poll(0.0)) == 0
    assert len(proto.poll(0.02)) == 2  # then 100/s
    assert len(proto.poll(10.0)) == 5  # never more than the burst per call


def test_list_restarts_on_new_request_and_ignores_other_targets(mavs) -> None:
    proto, reg = make(mavs)
    gcs = mavs[1]
    assert send(proto, mavs, gcs.param_request_list_encode(2, 1)) == []  # another system
    assert proto.list_remaining == 0
    assert send(proto, mavs, gcs.param_request_list_encode(1, 5)) == []  # another component
    assert proto.list_remaining == 0
    send(proto, mavs, gcs.param_request_list_encode(0, 0))  # broadcast
    proto.poll(0.0)
    assert proto.list_remaining == len(reg) - 20
    send(proto, mavs, gcs.param_request_list_encode(1, 1))
    assert proto.list_remaining == len(reg)


def test_list_downloads_are_routed_to_their_requester(mavs) -> None:
    """Each PARAM_REQUEST_LIST's PARAM_VALUEs are tagged with that request's source (the shell sends them
    only there); two requesters each get every index once, and a restart only restarts its own list."""
    reg = ParamRegistry.from_defaults(stability_check=_floor)
    proto = ParamProtocol(reg, mavs[0], rate_per_s=1000.0, burst=7)
    req = wire(mavs[1].param_request_list_encode(1, 1), mavs[1], mavs[0])
    proto.handle(req, 0.0, source="api")
    proto.handle(req, 0.0, source="gcs")
    got: dict[str, list[int]] = {"api": [], "gcs": []}
    first = proto.poll_routed(0.0)
    assert {s for s, _ in first} == {"api"} and len(first) == 7
    got["api"] += [m.param_index for _, m in first]
    proto.handle(req, 0.0, source="gcs")  # the GCS retries: its list restarts, the API's carries on
    t = 0.0
    while proto.list_remaining:
        t += 0.01
        for source, m in proto.poll_routed(t):
            got[source].append(m.param_index)
        assert t < 10.0
    assert got["api"] == list(range(len(reg))) and got["gcs"] == list(range(len(reg)))
    # Without a source (an in-process caller) the download is untagged.
    proto.handle(req, 0.0)
    assert {s for s, _ in proto.poll_routed(20.0)} == {None}


# --- read ----------------------------------------------------------------------------------------------
def test_read_by_name_and_by_index(mavs) -> None:
    proto, reg = make(mavs)
    gcs = mavs[1]
    (pv,) = send(proto, mavs, gcs.param_request_read_encode(1, 1, b"ACT_WN", -1))
    assert pv.get_type() == "PARAM_VALUE" and pv.param_id == "ACT_WN" and pv.param_index == reg.index_of("ACT_WN")
    assert pv.param_value == pytest.approx(120.0)
    (pv,) = send(proto, mavs, gcs.param_request_read_encode(1, 1, b"IGNORED_NAME", 3))
    assert pv.param_index == 3 and pv.param_id == reg.at_index(3).name


def test_read_unknown_gives_statustext_only(mavs) -> None:
    proto, reg = make(mavs)
    gcs = mavs[1]
    out = send(proto, mavs, gcs.param_request_read_encode(1, 1, b"NOPE_X", -1))
    assert by_type(out, "PARAM_VALUE") == [] and "NOPE_X" in by_type(out, "STATUSTEXT")[0].text
    out = send(proto, mavs, gcs.param_request_read_encode(1, 1, b"", len(reg)))
    assert by_type(out, "PARAM_VALUE") == [] and by_type(out, "STATUSTEXT")


def test_int32_values_are_bytewise(mavs) -> None:
    proto, reg = make(mavs)
    (pv,) = send(proto, mavs, mavs[1].param_request_read_encode(1, 1, b"INDI_RATE_HZ", -1))
    assert pv.param_type == INT32
    assert struct.unpack("<i", struct.pack("<f", pv.param_value))[0] == 100
    assert PARAM_ENCODING_CAPABILITY == mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE


@pytest.mark.parametrize("ptype", [1, 2, 3, 4, 5, 6])
def test_bytewise_round_trip(ptype: int) -> None:
    for v in (0, 1, 7, 100, 127):
        assert decode_param_value(encode_param_value(v, ptype), ptype) == v
    assert decode_param_value(1.5, REAL32) == 1.5
    assert decode_param_value(1.0, mavlink2.MAV_PARAM_TYPE_REAL64) is None


# --- set -----------------------------------------------------------------------------------------------
def test_accepted_set_echoes_new_value_and_persists(mavs, tmp_path: Path) -> None:
    store = ParamStore(tmp_path / "p.json")
    proto, reg = make(mavs, store)
    out = send(proto, mavs, mavs[1].param_set_encode(1, 1, b"OL_POS_K", 2.5, REAL32))
    (pv,) = by_type(out, "PARAM_VALUE")
    assert pv.param_id == "OL_POS_K" and pv.param_value == pytest.approx(2.5) and pv.param_count == len(reg)
    assert by_type(out, "STATUSTEXT") == []
    assert reg.get("OL_POS_K") == pytest.approx(2.5)
    assert store.load().values == {"OL_POS_K": pytest.approx(2.5)}  # only non-default values are stored
    (change,) = proto.drain_changes()
    assert change.accepted and change.name == "OL_POS_K"
    # A fresh registry on the same file comes back with the value.
    proto2, reg2 = make(mavs, store)
    loaded = proto2.load_stored()
    assert loaded.ok and loaded.applied == 1 and reg2.get("OL_POS_K") == pytest.approx(2.5)


def test_refused_set_echoes_old_value_and_statustext(mavs, tmp_path: Path) -> None:
    store = ParamStore(tmp_path / "p.json")
    proto, reg = make(mavs, store)
    out = send(proto, mavs, mavs[1].param_set_encode(1, 1, b"INDI_K_MIN", 0.15, REAL32))  # stability floor
    (pv,) = by_type(out, "PARAM_VALUE")
    assert pv.param_value == pytest.approx(0.5)
    texts = by_type(out, "STATUSTEXT")
    assert texts and all(t.severity == mavlink2.MAV_SEVERITY_WARNING for t in texts)
    assert "stability floor" in "".join(t.text for t in texts)
    assert not store.exists()
    out = send(proto, mavs, mavs[1].param_set_encode(1, 1, b"ACT_WN", math.nan, REAL32))
    assert by_type(out, "PARAM_VALUE")[0].param_value == pytest.approx(120.0) and by_type(out, "STATUSTEXT")
    out = send(proto, mavs, mavs[1].param_set_encode(1, 1, b"ACT_WN", 1e9, REAL32))
    assert by_type(out, "PARAM_VALUE")[0].param_value == pytest.approx(120.0) and by_type(out, "STATUSTEXT")


def test_set_unknown_name_statustext_only(mavs) -> None:
    proto, _ = make(mavs)
    out = send(proto, mavs, mavs[1].param_set_encode(1, 1, b"NOPE_X", 1.0, REAL32))
    assert by_type(out, "PARAM_VALUE") == [] and "NOPE_X" in by_type(out, "STATUSTEXT")[0].text


def test_set_int32_bytewise_and_plain_float(mavs) -> None:
    proto, reg = make(mavs)
    gcs = mavs[1]
    # QGC / MAVSDK: bytewise with param_type INT32.
    (pv,) = send(proto, mavs, gcs.param_set_encode(1, 1, b"INDI_RATE_HZ", encode_param_value(200, INT32), INT32))
    assert reg.get("INDI_RATE_HZ") == 200 and value_of(pv) == 200 and pv.param_type == INT32
    # MAVProxy / pymavlink default: the plain float with param_type REAL32.
    (pv,) = send(proto, mavs, gcs.param_set_encode(1, 1, b"INDI_RATE_HZ", 250.0, REAL32))
    assert reg.get("INDI_RATE_HZ") == 250 and value_of(pv) == 250
    # A non-integral value for an INT32 parameter is refused.
    out = send(proto, mavs, gcs.param_set_encode(1, 1, b"INDI_RATE_HZ", 250.5, REAL32))
    assert value_of(by_type(out, "PARAM_VALUE")[0]) == 250 and by_type(out, "STATUSTEXT")


def test_sixteen_char_names_and_nul_padding(mavs) -> None:
    text = ("params:\n"
            "  - {name: ABCDEFGH_JKLMNOP, type: REAL32, default: 1, min: 0, max: 5, description: sixteen}\n"
            "  - {name: AB_C, type: REAL32, default: 2, min: 0, max: 5, description: short}\n")
    from navig8_fc.params.registry import load_definitions

    reg = ParamRegistry(load_definitions(text), check_stability=False)
    proto = ParamProtocol(reg, mavs[0])
    veh, gcs = mavs
    # Outbound: exactly 16 bytes, no terminator; short names NUL-padded on the wire.
    # (payload order: value, count, index, param_id[16], param_type)
    assert b"ABCDEFGH_JKLMNOP\x09" in proto.param_value("ABCDEFGH_JKLMNOP").pack(veh)
    assert b"AB_C" + b"\x00" * 12 + b"\x09" in proto.param_value("AB_C").pack(veh)
    (pv,) = send(proto, mavs, gcs.param_set_encode(1, 1, b"ABCDEFGH_JKLMNOP", 3.0, REAL32))
    assert pv.param_id == "ABCDEFGH_JKLMNOP" and reg.get("ABCDEFGH_JKLMNOP") == 3.0
    (pv,) = send(proto, mavs, gcs.param_request_read_encode(1, 1, b"AB_C\x00\x00\x00", -1))
    assert pv.param_id == "AB_C"
    # Inbound names: NUL-terminated, garbage after the NUL ignored; bytes or str.
    assert param_name(b"AB_C\x00XYZ") == "AB_C"
    assert param_name("ABCDEFGH_JKLMNOP") == "ABCDEFGH_JKLMNOP"
    assert param_name(b"ABCDEFGH_JKLMNOPQRS") == "ABCDEFGH_JKLMNOP"


# --- storage -------------------------------------------------------------------------------------------
def test_storage_write_read_reset(mavs, tmp_path: Path) -> None:
    veh, gcs = mavs
    store = ParamStore(tmp_path / "p.json")
    proto, reg = make(mavs, store)
    reg.set("OL_POS_K", 3.0)  # changed without the protocol: not yet saved
    result, msgs = proto.storage_command(1)
    assert result == mavlink2.MAV_RESULT_ACCEPTED and store.load().values == {"OL_POS_K": 3.0}
    reg.set("OL_POS_K", 1.5)
    result, msgs = proto.storage_command(0)
    assert result == mavlink2.MAV_RESULT_ACCEPTED and reg.get("OL_POS_K") == 3.0
    assert [m.param_id for m in by_type([wire(m, veh, gcs) for m in msgs], "PARAM_VALUE")] == ["OL_POS_K"]
    result, msgs = proto.storage_command(2)
    default = reg.definition("OL_POS_K").coerce(reg.definition("OL_POS_K").default)
    assert result == mavlink2.MAV_RESULT_ACCEPTED and reg.get("OL_POS_K") == default
    assert store.load().values == {}  # the reset is persisted
    assert proto.storage_command(7)[0] == mavlink2.MAV_RESULT_DENIED
    assert proto.storage_command(0, armed=True)[0] == mavlink2.MAV_RESULT_DENIED
    assert proto.storage_command(2, armed=True)[0] == mavlink2.MAV_RESULT_DENIED
    assert reg.get("OL_POS_K") == default


def test_storage_without_store_or_file_fails_cleanly(mavs, tmp_path: Path) -> None:
    proto, reg = make(mavs)
    assert proto.storage_command(1)[0] == mavlink2.MAV_RESULT_FAILED
    assert proto.storage_command(0)[0] == mavlink2.MAV_RESULT_FAILED
    proto2, reg2 = make(mavs, ParamStore(tmp_path / "missing.json"))
    reg2.set("OL_POS_K", 3.0)
    result, msgs = proto2.storage_command(0)
    assert result == mavlink2.MAV_RESULT_FAILED and reg2.get("OL_POS_K") == 3.0  # nothing changed
    assert msgs and msgs[0].get_type() == "STATUSTEXT"


def test_a_stored_file_with_a_refused_value_is_not_applied_and_set_aside(mavs, tmp_path: Path) -> None:
    store = ParamStore(tmp_path / "p.json")
    store.save({"INDI_K_MIN": 0.1, "OL_POS_K": 2.0, "GONE_PARAM": 1.0})
    proto, reg = make(mavs, store)
    reg.set("OL_VEL_K", 2.5)
    loaded = proto.load_stored()
    assert not loaded.ok and loaded.applied == 0
    assert {r.name for r in loaded.refused} == {"INDI_K_MIN"}
    assert reg.get("INDI_K_MIN") == 0.5 and reg.get("OL_POS_K") == 1.0 and reg.get("OL_VEL_K") == 2.5  # unchanged
    assert loaded.set_aside == str(tmp_path / "p.json.rejected-1") and not store.path.exists()
    report = "\n".join(loaded.report())
    assert "INDI_K_MIN" in report and "GONE_PARAM" in report and "p.json.rejected-1" in report


@pytest.mark.parametrize("content", ["garbage\x00", '{"format": "navig8-fc-params", "version": 1, "params": {"OL',
                                     '{"format": "navig8-fc-params", "version": 1, "params": {"OL_ATT_K": NaN}}',
                                     "[" * 200_000,
                                     '{"format": "navig8-fc-params", "version": 1, "params": {"OL_ATT_K": 0.0}}'])
def test_every_unusable_file_is_reported_and_kept_aside(mavs, tmp_path: Path, content: str) -> None:
    path = tmp_path / "p.json"
    path.write_text(content, encoding="latin-1")
    proto, reg = make(mavs, ParamStore(path))
    before = reg.as_dict()
    loaded = proto.load_stored()
    assert not loaded.ok and reg.as_dict() == before
    assert loaded.report() and loaded.set_aside is not None
    assert Path(loaded.set_aside).read_text(encoding="latin-1") == content and not path.exists()
    result, msgs = proto.storage_command(0)  # nothing left to load: a clear failure, nothing changed
    assert result == mavlink2.MAV_RESULT_FAILED and by_type(msgs, "STATUSTEXT")


def test_set_is_decoded_only_by_the_declared_type(mavs) -> None:
    proto, reg = make(mavs)
    veh, gcs = mavs
    nan_as_int8 = struct.unpack("<f", struct.pack("<f", math.nan))[0]  # bytewise INT8 would read this as 0
    for ptype in (mavlink2.MAV_PARAM_TYPE_INT8, mavlink2.MAV_PARAM_TYPE_UINT8, INT32):
        out = send(proto, mavs, gcs.param_set_encode(1, 1, b"OL_ATT_K", nan_as_int8, ptype))
        assert value_of(by_type(out, "PARAM_VALUE")[0]) == pytest.approx(4.0) and by_type(out, "STATUSTEXT")
    assert reg.get("OL_ATT_K") == pytest.approx(4.0)
    out = send(proto, mavs, gcs.param_set_encode(1, 1, b"OL_ATT_K", math.nan, REAL32))
    assert reg.get("OL_ATT_K") == pytest.approx(4.0) and by_type(out, "STATUSTEXT")


@pytest.mark.parametrize("name", ["OL_POS_K", "OL_VEL_K", "OL_ATT_K", "OL_RATE_K"])
def test_zero_gains_are_refused(mavs, name: str) -> None:
    proto, reg = make(mavs)
    _, gcs = mavs
    before = reg.get(name)
    out = send(proto, mavs, gcs.param_set_encode(1, 1, name.encode(), 0.0, REAL32))
    assert reg.get(name) == before and value_of(by_type(out, "PARAM_VALUE")[0]) == pytest.approx(before)
    assert "outside" in by_type(out, "STATUSTEXT")[0].text


def test_loop_parameters_are_refused_while_armed(mavs) -> None:
    reg = ParamRegistry.from_defaults(stability_check=_floor)
    armed = [True]
    proto = ParamProtocol(reg, mavs[0], armed=lambda: armed[0])
    _, gcs = mavs
    out = send(proto, mavs, gcs.param_set_encode(1, 1, b"INDI_RATE_HZ", struct.unpack("<f", struct.pack("<i", 200))[0],
                                                 INT32))
    assert reg.get("INDI_RATE_HZ") == 100 and "armed" in by_type(out, "STATUSTEXT")[0].text
    send(proto, mavs, gcs.param_set_encode(1, 1, b"OL_POS_K", 1.5, REAL32))  # a gain may be tuned in flight
    assert reg.get("OL_POS_K") == pytest.approx(1.5)
    armed[0] = False
    send(proto, mavs, gcs.param_set_encode(1, 1, b"INDI_RATE_HZ", struct.unpack("<f", struct.pack("<i", 200))[0],
                                           INT32))
    assert reg.get("INDI_RATE_HZ") == 200


def test_long_refusal_reason_is_chunked(mavs) -> None:
    proto, _ = make(mavs)
    veh, gcs = mavs
    out = send(proto, mavs, gcs.param_set_encode(1, 1, b"INDI_K_MIN", 0.15, REAL32))
    texts = by_type(out, "STATUSTEXT")
    reason = proto.drain_changes()[0].reason
    assert len(reason) > 50 and len(texts) >= 2
    assert len({t.id for t in texts}) == 1 and texts[0].id != 0
    assert [t.chunk_seq for t in texts] == list(range(len(texts)))
    assert "".join(t.text for t in texts) == reason
