"""Who speaks for the operator, over real processes on loopback (docs/security.md): an impostor is a second UDP socket
claiming an allowed system id (no raw sockets: it sends from its own address, as a spoofer's victim would be).

- SETUP_SIGNING from an impostor (one HEARTBEAT, then an unsigned key) is refused, on the ground and in flight, and
  the operator's own re-keying is refused while armed; the operator's signed flight goes on and the impostor gets
  no command through;
- a captured signed PARAM_SET replays neither onto the other link nor after the FC restarts;
- one spoofed HEARTBEAT (id 250 as MAVLink 1 and 2, id 255) neither lands the vehicle nor takes its telemetry from
  the configured ground station, and reflects at most twice the bytes it cost.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import PARAM_SET_WAIT_S, RawPeer, gcs_client, sitl, wait_for, wait_heartbeat

from navig8_fc.links.signing import signing_timestamp
from navig8_fc.modes import FlightMode
from navig8_fc.params.store import default_state_path

M = mavlink2
KEY = bytes((i * 53 + 7) % 256 for i in range(32))
IMPOSTOR_KEY = bytes((i * 11 + 200) % 256 for i in range(32))
REAL32 = M.MAV_PARAM_TYPE_REAL32
HOLD = FlightMode.HOLD.custom_mode
LAND = FlightMode.LAND.custom_mode


class Impostor(RawPeer):
    """A UDP socket of its own speaking MAVLink as `sysid` (signed with `key` when given), counting bytes each way;
    told the FC's port at every send."""

    def __init__(self, sysid: int, key: bytes | None = None, mavlink1: bool = False) -> None:
        super().__init__(sysid, key=key, mavlink1=mavlink1)


def _fc_hb(pred: Any) -> Any:
    return lambda m: m.get_srcComponent() == 1 and pred(m)


def _command(gcs: Any, command: int, *p: float) -> int | None:
    gcs.mav.command_long_send(gcs.target_system, 1, command, 0, *(list(p) + [0.0] * (7 - len(p))))
    ack = wait_for(gcs, "COMMAND_ACK", 5.0, lambda m: m.command == command)
    return None if ack is None else ack.result


def _take_off(gcs: Any, alt_m: float) -> None:
    """Arm (pre-arm may wait for the first sensor data), take off, and wait for Hold at the height."""
    deadline = time.monotonic() + 20.0
    while _command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) != M.MAV_RESULT_ACCEPTED:
        assert time.monotonic() < deadline, "never armed"
        wait_for(gcs, "HEARTBEAT", 0.3)
    assert _command(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, alt_m) in (
        M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_IN_PROGRESS)
    assert wait_for(gcs, "HEARTBEAT", 20.0, _fc_hb(lambda m: m.custom_mode == HOLD)) is not None, "no Hold"


def _texts(gcs: Any, timeout_s: float, until: Any) -> list[str]:
    """STATUSTEXTs until one satisfies `until` (bounded)."""
    seen: list[str] = []
    wait_for(gcs, "STATUSTEXT", timeout_s, lambda m: seen.append(m.text) or until(m.text))
    return seen


def _keeps_flying(gcs: Any, duration_s: float, alt_m: float) -> tuple[int, list[str]]:
    """For `duration_s`: the positions the operator received (each within 0.5 m of the height, asserted), the
    STATUSTEXTs; the mode stays Hold and the vehicle armed (asserted)."""
    n_pos, texts = 0, []
    deadline = time.monotonic() + duration_s
    while time.monotonic() < deadline:
        m = gcs.recv_match(type=["LOCAL_POSITION_NED", "HEARTBEAT", "STATUSTEXT"], blocking=True, timeout=0.2)
        if m is None:
            continue
        kind = m.get_type()
        if kind == "STATUSTEXT":
            texts.append(m.text)
        elif kind == "LOCAL_POSITION_NED":
            n_pos += 1
            assert abs(-m.z - alt_m) < 0.5, f"the vehicle left its height: z = {m.z:.2f} m ({texts})"
        elif m.get_srcComponent() == 1:
            assert m.custom_mode == HOLD and m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, (m, texts)
    return n_pos, texts


def test_setup_signing_from_an_impostor_is_refused_and_nothing_of_its_gets_through(tmp_path: Path) -> None:
    with sitl(tmp_path, scenario="ground", speed=2.0) as run:
        gcs = gcs_client(run.gcs_port)
        impostor = Impostor(250, key=IMPOSTOR_KEY)
        fc = run.gcs_bind_port
        try:
            wait_heartbeat(gcs, 20.0)
            # On the ground: one HEARTBEAT and an unsigned SETUP_SIGNING from an address nobody configured.
            impostor.heartbeat(fc)
            impostor.send(impostor.mav.setup_signing_encode(1, 1, list(IMPOSTOR_KEY), signing_timestamp(time.time())),
                          fc)
            texts = _texts(gcs, 5.0, lambda t: t.startswith("SETUP_SIGNING refused"))
            assert texts[-1:] == ["SETUP_SIGNING refused: configured GCS link only"], texts
            assert not default_state_path(run.state_dir, 0, "fc_signing").exists()

            # The operator provisions from the configured peer, flies on signed commands.
            gcs.mav.setup_signing_send(1, 1, list(KEY), signing_timestamp(time.time()))
            assert wait_for(gcs, "STATUSTEXT", 5.0, lambda m: m.text == "Signing key set") is not None
            gcs.setup_signing(KEY, sign_outgoing=True)
            _take_off(gcs, 1.5)

            # In flight: the impostor again (unsigned and self-signed key, then self-signed commands).
            impostor.heartbeat(fc)
            impostor.send(impostor.mav.setup_signing_encode(1, 1, list(IMPOSTOR_KEY), 0), fc)
            commands = [(M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 21196), (M.MAV_CMD_NAV_LAND, 0, 0),
                        (M.MAV_CMD_DO_SET_MODE, 1, LAND)]
            for cmd, p1, p2 in commands * 3:
                impostor.send(impostor.mav.command_long_encode(1, 1, cmd, 0, p1, p2, 0, 0, 0, 0, 0), fc)
            # ... and the operator's own re-keying while armed
            gcs.mav.setup_signing_send(1, 1, list(IMPOSTOR_KEY), signing_timestamp(time.time()))
            texts = _texts(gcs, 5.0, lambda t: t.startswith("SETUP_SIGNING refused"))
            assert texts[-1:] == ["SETUP_SIGNING refused: not while armed"], texts
            n_pos, texts = _keeps_flying(gcs, 3.0, 1.5)
            impostor.drain(0.5)
            acks = [m for m in impostor.got if m.get_type() == "COMMAND_ACK"]
            print(f"\nimpostor: {len(commands) * 3} commands and 2 SETUP_SIGNINGs sent, {len(acks)} answered; "
                  f"operator: {n_pos} positions in 3 s, signatures good {gcs.mav.signing.goodsig_count} "
                  f"bad {gcs.mav.signing.badsig_count}")
            assert acks == [] and n_pos >= 20, (acks, n_pos)
            assert gcs.mav.signing.badsig_count == 0  # the FC still signs with the operator's key
            assert not [t for t in texts if "lost" in t], texts
            assert run.fc.poll() is None
        finally:
            impostor.close()
            gcs.close()


def _read_param(conn: Impostor, port: int, name: bytes) -> float | None:
    """A signed HEARTBEAT (requests are answered only to a confirmed source) and PARAM_REQUEST_READ from `conn`
    to `port`, in order after whatever `conn` sent there before; the value it is answered (None: none in 5 s)."""
    conn.got.clear()
    conn.heartbeat(port)
    conn.send(conn.mav.param_request_read_encode(1, 1, name, -1), port)
    conn.drain(5.0, lambda c: any(m.get_type() == "PARAM_VALUE" for m in c.got))
    pv = [m for m in conn.got if m.get_type() == "PARAM_VALUE"]
    return pv[0].param_value if pv else None


def _wait_value(gcs: Any, value: float) -> None:
    pv = wait_for(gcs, "PARAM_VALUE", PARAM_SET_WAIT_S,
                  lambda m: m.param_id == "OL_POS_K" and abs(m.param_value - value) < 1e-6)
    assert pv is not None, f"OL_POS_K = {value} not set"


def test_a_captured_signed_param_set_replays_neither_on_the_other_link_nor_after_a_restart(tmp_path: Path) -> None:
    state = tmp_path / "state"
    tool = Impostor(254, key=KEY)  # a second holder of the key (a script at an address nobody configured)
    try:
        with sitl(tmp_path, start_bridge=False, state_dir=state, log_name="a.mcap") as run:
            gcs = gcs_client(run.gcs_port)
            try:
                wait_heartbeat(gcs, 20.0)
                gcs.mav.setup_signing_send(1, 1, list(KEY), signing_timestamp(time.time()))
                assert wait_for(gcs, "STATUSTEXT", 5.0, lambda m: m.text == "Signing key set") is not None
                gcs.setup_signing(KEY, sign_outgoing=True)
                # what an eavesdropper captures on the wire: a HEARTBEAT (to be confirmed as a source when
                # replayed) and a PARAM_SET; then the operator sets the value back
                captured = [gcs.mav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(gcs.mav),
                            gcs.mav.param_set_encode(1, 1, b"OL_POS_K", 1.1, REAL32).pack(gcs.mav)]
                for frame in captured:
                    gcs.write(frame)
                _wait_value(gcs, 1.1)
                gcs.mav.param_set_send(1, 1, b"OL_POS_K", 1.0, REAL32)
                _wait_value(gcs, 1.0)
                api = run.ports["api"]
                for frame in captured:  # replayed onto the API link; then read there, in order
                    tool.send_raw(frame, api)
                on_other_link = _read_param(tool, api, b"OL_POS_K")
                gcs.mav.param_set_send(1, 1, b"OL_POS_K", 1.0, REAL32)  # stored as 1.0 whatever the replay did
                _wait_value(gcs, 1.0)
                stamp_after = gcs.mav.signing.timestamp
            finally:
                gcs.close()
        with sitl(tmp_path, start_bridge=False, state_dir=state, log_name="b.mcap") as run:
            gcs = gcs_client(run.gcs_port)
            try:
                gcs.setup_signing(KEY, sign_outgoing=True, initial_timestamp=stamp_after)  # the same station
                wait_heartbeat(gcs, 20.0)
                for frame in captured:  # replayed after the restart
                    tool.send_raw(frame, run.gcs_bind_port)
                after_restart = _read_param(tool, run.gcs_bind_port, b"OL_POS_K")
                gcs.mav.param_request_read_send(1, 1, b"OL_POS_K", -1)  # the operator's stream goes on
                own = wait_for(gcs, "PARAM_VALUE", 5.0, lambda m: m.param_id == "OL_POS_K")
            finally:
                gcs.close()
    finally:
        tool.close()
    print(f"\nreplayed PARAM_SET OL_POS_K = 1.1: on the other link the value stays {on_other_link}, after a "
          f"restart {after_restart}")
    assert on_other_link is not None and abs(on_other_link - 1.0) < 1e-6, on_other_link
    assert after_restart is not None and abs(after_restart - 1.0) < 1e-6, after_restart
    assert own is not None and abs(own.param_value - 1.0) < 1e-6


def test_one_spoofed_heartbeat_neither_lands_the_vehicle_nor_starves_the_operator_nor_reflects(tmp_path: Path
                                                                                            ) -> None:
    with sitl(tmp_path, scenario="ground", speed=2.0) as run:
        gcs = gcs_client(run.gcs_port)  # the configured ground station: it sends no HEARTBEAT at all
        spoofers = [Impostor(250), Impostor(250, mavlink1=True), Impostor(255)]
        fc = run.gcs_bind_port
        try:
            wait_heartbeat(gcs, 20.0)
            gcs.mav.param_set_send(1, 1, b"FS_GCS_TOUT", 1.0, REAL32)
            assert wait_for(gcs, "PARAM_VALUE", PARAM_SET_WAIT_S, lambda m: m.param_id == "FS_GCS_TOUT"
                            and m.param_value == 1.0) is not None
            _take_off(gcs, 1.5)
            for s in spoofers:  # one HEARTBEAT each, then silence (on main: "GCS link lost" a second later)
                s.heartbeat(fc)
            n_pos, texts = _keeps_flying(gcs, 4.0, 1.5)
            for s in spoofers:
                s.drain(0.3)
            ratios = [s.bytes_in / s.bytes_out for s in spoofers]
            print(f"\nafter one spoofed HEARTBEAT each (250 v2, 250 v1, 255): reflection "
                  f"{[round(r, 2) for r in ratios]} (bytes in/out {[(s.bytes_in, s.bytes_out) for s in spoofers]}); "
                  f"operator: {n_pos} positions in 4 s, texts {texts}")
            assert n_pos >= 20, n_pos
            assert not [t for t in texts if "lost" in t], texts
            assert max(ratios) <= 2.0, ratios
        finally:
            for s in spoofers:
                s.close()
            gcs.close()
