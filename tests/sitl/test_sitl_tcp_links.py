"""TCP links reached by strangers (docs/security.md, "TCP links"): a tcpin: server serves several connections, each
its own sender, so an idle or hostile connection neither displaces the paired peer nor takes over its pairing.
Real processes on loopback: the bridge listening as PX4's simulator does (the FC connects), and the FC's GCS link
served on TCP."""

from __future__ import annotations

import contextlib
import socket
import time
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil
from sitl_helpers import gcs_client, sitl, wait_for, wait_heartbeat

from navig8_fc.links.sim_guard import pairing_heartbeat
from navig8_fc.mavlink import codec, dialect

pytestmark = pytest.mark.slow

N_CONNECTIONS = 100
SAMPLE_S = 2.0


def _stepping(gcs: Any, timeout_s: float = 20.0) -> bool:
    """The FC is still stepping: its attitude estimate (from the noisy motion-capture samples of each step) takes
    several values within SAMPLE_S of ATTITUDE (frozen when no sensor bundle arrives: lockstep)."""
    seen: set[tuple[float, float, float]] = set()
    t_end = time.monotonic() + SAMPLE_S
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and (time.monotonic() < t_end or len(seen) < 5):
        m = wait_for(gcs, "ATTITUDE", 1.0)
        if m is not None:
            seen.add((m.roll, m.pitch, m.yaw))
    return len(seen) >= 5


def _connect_many(port: int, n: int) -> list[socket.socket]:
    out = []
    for _ in range(n):
        with contextlib.suppress(OSError):  # a full backlog may refuse some: the point is the ones it takes
            out.append(socket.create_connection(("127.0.0.1", port), timeout=2.0))
    return out


def test_strangers_on_the_bridges_tcp_port_neither_blind_the_fc_nor_take_over_its_pairing(tmp_path: Path) -> None:
    """A stranger connects to the bridge's port and announces itself as the FC (its system and component id, a
    nonce of its own): the bridge neither echoes that nonce to it nor drops the paired FC. Then 100 connections: the
    FC keeps stepping and the bridge keeps running."""
    nonce = 0x5EC0DE
    enc = codec.Encoder(codec.seam_codec(), 1, dialect.COMPID_FC)
    with sitl(tmp_path, scenario="ground", speed=1.0, link="tcp") as run:
        gcs = gcs_client(run.gcs_port)
        assert wait_heartbeat(gcs, 60.0) is not None
        assert _stepping(gcs), "not stepping before any stranger connected"
        s = socket.create_connection(("127.0.0.1", run.ports["bridge"]), timeout=2.0)
        try:
            s.settimeout(0.2)
            c, counts = codec.seam_codec(), codec.ParseCounters()
            echoed, buf = [], b""
            deadline = time.monotonic() + 3.0
            while time.monotonic() < deadline:
                s.sendall(enc.frame(*pairing_heartbeat(nonce)))
                with contextlib.suppress(TimeoutError):
                    buf += s.recv(65536)
                frames, garbage, _ = codec.split_frames(buf)
                buf = buf[sum(map(len, frames)) + garbage:]
                echoed += [m for m in c.parse(b"".join(frames), counts)
                           if m.name == "HEARTBEAT" and m.fields["custom_mode"] == nonce]
            assert not echoed, "the bridge paired with the stranger"
            assert _stepping(gcs), "the paired FC lost its bundles"
        finally:
            s.close()
        strangers = _connect_many(run.ports["bridge"], N_CONNECTIONS)
        try:
            assert len(strangers) > 10
            assert _stepping(gcs), "the FC stopped stepping once strangers connected to the bridge's port"
            assert run.bridge is not None and run.bridge.poll() is None, "the bridge ended"
        finally:
            for st in strangers:
                st.close()


def test_connections_to_the_fcs_tcp_gcs_link_do_not_cut_the_ground_station_off(tmp_path: Path) -> None:
    """A ground station on the FC's TCP GCS link (a plain socket: MAVLink 2 packed and parsed with the dialect) keeps
    hearing the FC's HEARTBEATs while strangers connect to the same port."""
    mav = dialect.new_mav(255, 190)
    hb = mav.heartbeat_encode(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    with sitl(tmp_path, scenario="ground", speed=1.0, fc_args=["--gcs-link", "tcpin:127.0.0.1:0"]) as run:
        gcs = socket.create_connection(("127.0.0.1", run.gcs_bind_port), timeout=5.0)
        gcs.settimeout(0.2)

        def fc_heartbeats(window_s: float) -> int:
            n, t_end = 0, time.monotonic() + window_s
            while time.monotonic() < t_end:
                gcs.sendall(hb.pack(mav))
                with contextlib.suppress(TimeoutError):
                    got = mav.parse_buffer(gcs.recv(65536)) or []
                    n += sum(1 for m in got if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1)
            return n

        try:
            deadline = time.monotonic() + 60.0
            while fc_heartbeats(1.0) == 0 and time.monotonic() < deadline:
                pass
            strangers = _connect_many(run.gcs_bind_port, 20)
            try:
                beats = fc_heartbeats(4.0)
                assert beats >= 3, f"{beats} heartbeats from the FC in 4 s with strangers connected"
            finally:
                for s in strangers:
                    s.close()
        finally:
            gcs.close()
