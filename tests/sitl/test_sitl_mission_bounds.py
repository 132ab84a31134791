"""Mission uploads and offboard targets held to their bounds, over real UDP (docs/security.md, "Missions and
offboard targets"):

- an impostor with an allowed id (250), from its own address, sends MISSION_COUNT twice a second and never an item:
  the operator's upload is DENIED while that upload is fresh, and goes through once it has made no progress for
  1 s (the impostor's repeated MISSION_COUNT does not extend it); the operator's download and clear then work
  while the impostor keeps going;
- waypoints 1e9 m up, 214 km away and underground are refused with the MAV_MISSION_RESULT naming the coordinate
  and the reason, the plan in force unchanged; offboard targets of 1e9 m, 1e6 m/s and INT32_MAX lat/lon are
  ignored with a STATUSTEXT at most once a second.

The volume test is MAVLink only (any FC by connection string, `make test-hil`, docs/hil.md, with the default
VOL_*); the impostor needs the local pair (raw UDP to its GCS socket).
"""

from __future__ import annotations

import math
import socket
import threading
import time
from io import BytesIO

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import FcTarget, wait_for

from navig8_fc.mission.plan import Cmd, Frame, MissionItem
from navig8_tools.mission import download, upload

M = mavlink2
FC_LOCAL = {"speed": 1.0}  # the local pair (conftest.py `fc`): ground, nothing flies
INT32_MAX = 2**31 - 1
TWO = (MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_TAKEOFF, 1, 0, 0, 0, math.nan, 0, 0, 2.0),
       MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 0, 0.25, 0, math.nan, 10000, 0, -2.0))


class Impostor:
    """Another ground station with an allowed id (250/190) on its own address, confirmed by a HEARTBEAT, sending
    MISSION_COUNT every `period_s` until stopped."""

    def __init__(self, fc_port: int, period_s: float) -> None:
        self.mav = M.MAVLink(BytesIO(), srcSystem=250, srcComponent=190)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.fc = ("127.0.0.1", fc_port)
        self.period_s = period_s
        self.sent = 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _send(self, msg: object) -> None:
        self.sock.sendto(msg.pack(self.mav), self.fc)  # type: ignore[attr-defined]

    def _run(self) -> None:
        self._send(self.mav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0))
        while not self.stop.is_set():
            self._send(self.mav.mission_count_encode(1, 1, 5, 0))
            self.sent += 1
            self.stop.wait(self.period_s)

    def __enter__(self) -> Impostor:
        self.thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self.stop.set()
        self.thread.join(timeout=5.0)
        self.sock.close()


def _until_accepted(op: object, items: tuple[MissionItem, ...], timeout_s: float) -> list[int]:
    """Upload until ACCEPTED (bounded); every answer in order."""
    results: list[int] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and (not results or results[-1] != M.MAV_MISSION_ACCEPTED):
        retry_at = time.monotonic() + 0.2  # paced as a person retrying, reading what comes meanwhile
        while results and (left := retry_at - time.monotonic()) > 0:
            op.recv_match(blocking=True, timeout=left)
        results.append(upload(op, items, timeout_s=3.0))
    return results


def test_targets_outside_the_operating_volume_are_refused_with_the_reason(fc: FcTarget) -> None:
    with fc.session() as op:
        assert upload(op, TWO) == M.MAV_MISSION_ACCEPTED
        cases = [
            ("1e9 m up", MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 0, 0.25, 0, math.nan, 0, 0, -1e9),
             M.MAV_MISSION_INVALID_PARAM7, "VOL_ALT_MAX"),
            ("214 km away", MissionItem(Frame.LOCAL_NED, Cmd.NAV_WAYPOINT, 1, 0, 0.25, 0, math.nan, 2_140_000_000,
                                        0, -5.0), M.MAV_MISSION_INVALID_PARAM5_X, "VOL_DIST_MAX"),
            ("underground", MissionItem(Frame.GLOBAL_RELATIVE_ALT_INT, Cmd.NAV_WAYPOINT, 1, 0, 0.25, 0, math.nan, 0,
                                        0, -30.0), M.MAV_MISSION_INVALID_PARAM7, "VOL_ALT_MIN"),
        ]
        for name, item, result, words in cases:
            op.recv_match(type="STATUSTEXT", blocking=False)
            got = upload(op, (TWO[0], item))
            texts = ""
            while (m := wait_for(op, "STATUSTEXT", 1.0)) is not None and words not in texts:
                texts += m.text
            assert got == result and words in texts, (name, got, texts)
        items, _current = download(op)
        assert len(items) == 2  # the plan in force is the one before
        # Offboard targets outside the volume: ignored, said at most once a second.
        bad = [
            lambda: op.mav.set_position_target_local_ned_send(0, op.target_system, 1, M.MAV_FRAME_LOCAL_NED,
                                                              0b110111111000, 1e9, 0, -2, 0, 0, 0, 0, 0, 0, 0, 0),
            lambda: op.mav.set_position_target_local_ned_send(0, op.target_system, 1, M.MAV_FRAME_LOCAL_NED,
                                                              0b110111000111, 0, 0, 0, 1e6, 0, 0, 0, 0, 0, 0, 0),
            lambda: op.mav.set_position_target_global_int_send(0, op.target_system, 1,
                                                               M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0b110111111000,
                                                               INT32_MAX, INT32_MAX, 2.0, 0, 0, 0, 0, 0, 0, 0, 0),
        ]
        texts: list[str] = []
        t0 = time.monotonic()
        for k in range(20):  # 2 s at 10 Hz
            while time.monotonic() < t0 + 0.1 * k:
                if (m := wait_for(op, "STATUSTEXT", max(0.0, t0 + 0.1 * k - time.monotonic()))) is not None:
                    texts.append(m.text)
            bad[k % 3]()
        while (m := wait_for(op, "STATUSTEXT", 1.0)) is not None:
            texts.append(m.text)
        firsts = [t for t in texts if t.startswith("Offboard target ignored")]
        assert 2 <= len(firsts) <= 3, texts
        # A DO_REPOSITION (MAVSDK's goto_location) to 49.33 N, far beyond VOL_DIST_MAX: DENIED with the reason
        op.mav.command_int_send(op.target_system, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_DO_REPOSITION, 0,
                                0, -1.0, 1, 0, math.nan, 493_300_000, 85_455_940, 10.0)
        ack = wait_for(op, "COMMAND_ACK", 5.0, lambda m: m.command == M.MAV_CMD_DO_REPOSITION)
        assert ack is not None and ack.result == M.MAV_RESULT_DENIED, ack
        text = wait_for(op, "STATUSTEXT", 5.0, lambda m: m.text.startswith("Reposition refused:"))
        assert text is not None


def test_an_impostor_repeating_mission_count_does_not_hold_the_upload_lock(fc: FcTarget) -> None:
    fc_port = fc.require_local("the impostor sends raw UDP to the FC's GCS socket").gcs_bind_port
    with fc.session() as op:
        # a ground station that says it is one: the impostor's HEARTBEAT makes it a telemetry peer, and the FC then
        # streams to confirmed peers only (docs/security.md)
        op.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        assert upload(op, ()) == M.MAV_MISSION_ACCEPTED  # an empty plan to start from
        with Impostor(fc_port, 0.5) as imp:
            deadline = time.monotonic() + 5.0
            while imp.sent < 1 and time.monotonic() < deadline:  # its upload has started
                time.sleep(0.01)
            results = _until_accepted(op, TWO, 10.0)
            assert results[0] == M.MAV_MISSION_DENIED and results[-1] == M.MAV_MISSION_ACCEPTED, results
            # while the impostor goes on: the operator's download (retried over a fresh impostor upload) and clear
            items: tuple = ()
            deadline = time.monotonic() + 10.0
            while len(items) != 2 and time.monotonic() < deadline:
                items, _current = download(op, timeout_s=3.0)
            assert len(items) == 2
            cleared = None
            deadline = time.monotonic() + 10.0
            while cleared != M.MAV_MISSION_ACCEPTED and time.monotonic() < deadline:
                op.mav.mission_clear_all_send(op.target_system, 1, 0)
                ack = wait_for(op, "MISSION_ACK", 3.0)
                cleared = None if ack is None else ack.type
            assert cleared == M.MAV_MISSION_ACCEPTED
        print(f"\nimpostor: {imp.sent} MISSION_COUNT; the operator's upload denied {len(results) - 1} times, accepted "
              f"{0.2 * (len(results) - 1):.1f} s after the impostor began")
