"""Ground-station hardening over real processes (docs/security.md), one hover flight:

- a stored parameter file of 200,000 `[` neither stops the FC nor is replaced silently: reported on stderr and by
  STATUSTEXT at the first contact, kept aside;
- a stranger (system id 200) is refused: force disarm in flight -> COMMAND_ACK DENIED, PARAM_SET -> the value in
  force; its HEARTBEAT does not arm the GCS-loss failsafe;
- reflection: an unconfirmed source (no HEARTBEAT, even with an allowed id) gets at most 2 bytes per byte it sends;
- 1,000 PARAM_SETs, 100 in flight at a time (stability-floor parameters among them): every one answered, lockstep
  control steps stay 10 ms apart in sim time, the stored file parses; NaN sent as INT8 and a zero gain are refused.
"""

from __future__ import annotations

import math
import struct
import time
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import RawPeer, gcs_client, sitl, wait_for, wait_heartbeat

from navig8_fc.modes import FlightMode
from navig8_fc.params.store import ParamStore, default_state_path
from navig8_fc.shell.mcap_log import read_mcap, read_mcap_records

M = mavlink2
REAL32 = M.MAV_PARAM_TYPE_REAL32
N_SETS = 1000
IN_FLIGHT = 100  # PARAM_SETs sent and not yet answered, at most
HOLD = FlightMode.HOLD.custom_mode


def _int8(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


def _strangers_are_refused(stranger: RawPeer, spoof: RawPeer) -> None:
    """A stranger (id 200) is refused and its heartbeat arms no failsafe; an unconfirmed allowed id gets no stream;
    both get at most twice the bytes they sent."""
    # A stranger: refused, and its heartbeat arms no failsafe.
    stranger.send(stranger.mav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0))
    stranger.send(stranger.mav.command_long_encode(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196,
                                                   0, 0, 0, 0, 0))
    stranger.send(stranger.mav.param_set_encode(1, 1, b"OL_ATT_K", 9.0, REAL32))
    stranger.send(stranger.mav.command_long_encode(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                                   M.MAVLINK_MSG_ID_ATTITUDE, 2000, 0, 0, 0, 0, 0))
    for _ in range(5):  # an unconfirmed source asking for the expensive answers
        spoof.send(spoof.mav.param_request_list_encode(1, 1))
        spoof.send(spoof.mav.command_long_encode(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, 435, 0, 0, 0, 0, 0, 0))
        spoof.send(spoof.mav.command_long_encode(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, 30, 2000,
                                                 0, 0, 0, 0, 0))
    stranger.drain(8.0, lambda p: sum(m.get_type() == "COMMAND_ACK" for m in p.got) >= 2)
    stranger.drain(0.5)  # anything more it would get (a stream, a second answer)
    spoof.drain(8.0, lambda p: sum(m.get_type() == "COMMAND_ACK" for m in p.got) >= 10)
    acks = [m for m in stranger.got if m.get_type() == "COMMAND_ACK"]
    assert [a.result for a in acks] == [M.MAV_RESULT_DENIED] * 2, acks
    # (its PARAM_SET's echo, the value in force, went to the confirmed ground stations: checked below)
    print(f"\nreflection: stranger {stranger.bytes_in}/{stranger.bytes_out} B, unconfirmed id 255 "
          f"{spoof.bytes_in}/{spoof.bytes_out} B")
    assert stranger.bytes_in <= 2 * stranger.bytes_out, (stranger.bytes_in, stranger.bytes_out)
    assert spoof.bytes_in <= 2 * spoof.bytes_out, (spoof.bytes_in, spoof.bytes_out)
    assert not [m for m in spoof.got if m.get_type() in ("PARAM_VALUE", "AVAILABLE_MODES")]


def _thousand_param_sets(gcs: Any) -> None:
    """1,000 PARAM_SETs, IN_FLIGHT at a time unanswered, each answered."""
    # 1,000 PARAM_SETs: K bounds (a stability sweep each) and a gain, as fast as a script can. At most IN_FLIGHT
    # wait unanswered: Linux's default net.core.rmem_max (208 KiB) caps every socket's receive buffer at a few
    # hundred small datagrams, so a script with 1,000 outstanding loses some in the kernel, on either side, before
    # any process reads them (538 of 1,000 answered that way; a GCS re-sends, this script would not know which).
    t_start = time.monotonic()
    replies = sent = 0

    def answer(m) -> bool:
        return m.get_type() == "PARAM_VALUE" and m.param_id in ("INDI_K_MIN", "OL_POS_K")

    deadline = time.monotonic() + 120.0
    while replies < N_SETS and time.monotonic() < deadline:
        while sent < N_SETS and sent - replies < IN_FLIGHT:
            i, sent = sent, sent + 1
            if i % 2:
                gcs.mav.param_set_send(1, 1, b"INDI_K_MIN", 0.5 + 0.001 * (i % 50), REAL32)
            else:
                gcs.mav.param_set_send(1, 1, b"OL_POS_K", 1.0 + 0.001 * (i % 100), REAL32)
        replies += wait_for(gcs, "PARAM_VALUE", 1.0, answer) is not None
        while (m := gcs.recv_match(blocking=False)) is not None:  # read as a GCS does, everything waiting
            replies += answer(m)
    assert replies == N_SETS, f"{replies} of {N_SETS} PARAM_SETs answered"
    print(f"\n{N_SETS} PARAM_SETs answered in {time.monotonic() - t_start:.1f} s wall")


def test_strangers_reflection_corrupt_file_and_a_thousand_param_sets_in_flight(tmp_path: Path) -> None:
    state = tmp_path / "state"
    state.mkdir()
    stored = default_state_path(state, 0)
    stored.write_text("[" * 200_000)
    with sitl(tmp_path, scenario="hover", speed=1.0, state_dir=state,
              bridge_args=["--duration", "40", "--until-done"]) as run:
        gcs = gcs_client(run.gcs_port)
        stranger = RawPeer(200, run.gcs_bind_port)
        spoof = RawPeer(255, run.gcs_bind_port)  # an allowed id, but from an address that never sent a HEARTBEAT
        try:
            hb0 = wait_heartbeat(gcs, 20.0)
            assert hb0.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
            # First contact: the operator hears about the unusable parameter file.
            gcs.mav.param_request_read_send(1, 1, b"OL_ATT_K", -1)
            text = wait_for(gcs, "STATUSTEXT", 5.0, lambda m: "unusable" in m.text)
            assert text is not None and text.severity <= M.MAV_SEVERITY_CRITICAL
            assert stored.with_name(stored.name + ".rejected-1").read_text() == "[" * 200_000

            _strangers_are_refused(stranger, spoof)

            # Flight-unsafe values, live: NaN as INT8 and a zero gain.
            gcs.mav.param_set_send(1, 1, b"OL_ATT_K", _int8(math.nan), M.MAV_PARAM_TYPE_INT8)
            gcs.mav.param_set_send(1, 1, b"OL_ATT_K", 0.0, REAL32)
            for _ in range(2):
                pv = wait_for(gcs, "PARAM_VALUE", 5.0, lambda m: m.param_id == "OL_ATT_K")
                assert pv is not None and pv.param_value == 4.0

            _thousand_param_sets(gcs)
            t_sets = time.monotonic()  # control goes on after the burst: HEARTBEATs for 1.5 s more (speed 1)
            hb = wait_heartbeat(gcs, 5.0)
            while time.monotonic() - t_sets < 1.5:
                hb = wait_heartbeat(gcs, 5.0)
            # still flying its scenario, or holding once the 10 s script has ended (a slow machine's burst outlasts it)
            assert hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED and hb.custom_mode in (hb0.custom_mode, HOLD)
            assert run.fc.poll() is None, "navig8-fc died"
        finally:
            stranger.close()
            spoof.close()
            codes = run.stop()
    assert codes[0] == 0, codes
    events = [d["text"] for _, _, d in read_mcap(run.log, ["/fc/event"])]  # what stderr got, as the log has it
    assert any("unusable" in e and "rejected-1" in e for e in events), events
    # Control kept its pace: lockstep steps 10 ms apart in sim time; the wall gaps are reported.
    rec = [(d["time_usec"], pub) for _, _, pub, d in read_mcap_records(run.log, ["/mavlink/sim/in/HIL_SENSOR"])]
    sets_ns = [t for _, t, _ in read_mcap(run.log, ["/mavlink/gcs/in/PARAM_SET"])]
    assert len(sets_ns) >= N_SETS and len(rec) > 100
    # The sets arrived in flight (hover is armed in the air from the first step), over more than one step (their
    # log times are the sim time of the step in force; how many steps a burst spans depends on the sender's pace,
    # as every datagram waiting is read each step) and steps went on after the last one.
    print(f"{N_SETS} PARAM_SETs received over {len(set(sets_ns))} control steps")
    assert len(set(sets_ns)) >= 2 and rec[-1][0] >= max(sets_ns) / 1000 + 1e6
    sim_gaps = [(b[0] - a[0]) * 1e-6 for a, b in zip(rec, rec[1:], strict=False)]
    wall_gaps = sorted((b[1] - a[1]) * 1e-9 for a, b in zip(rec, rec[1:], strict=False))
    assert max(sim_gaps) <= 0.020, max(sim_gaps)
    print(f"control steps: {len(rec)}, sim gap max {max(sim_gaps) * 1e3:.1f} ms, wall gap median "
          f"{wall_gaps[len(wall_gaps) // 2] * 1e3:.1f} ms, p99 {wall_gaps[int(0.99 * len(wall_gaps))] * 1e3:.1f} ms, "
          f"max {wall_gaps[-1] * 1e3:.1f} ms")
    texts = [d["text"] for _, _, d in read_mcap(run.log, ["/fc/statustext"])]
    assert not [t for t in texts if "GCS" in t and "lost" in t.lower()], texts  # the spoofed heartbeat armed nothing
    values, reason = ParamStore(stored).load()
    assert reason is None and 0.5 <= values.get("INDI_K_MIN", 0.5) <= 0.55
