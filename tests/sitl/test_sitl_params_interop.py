"""Parameters persist across a restart; MAVProxy (a real client) downloads and sets them; logs export to .tlog.

MAVProxy's session is MAVLink only: it runs against any FC by connection string (`make test-hil`, docs/hil.md;
MAVProxy's --master is the GCS string, the read-back goes over the API link) and restores the value it set. The
restart (process control) and the .tlog export (the local log) start their own pairs and skip when pointed
elsewhere."""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2
from sitl_helpers import PARAM_SET_WAIT_S, FcTarget, gcs_client, sitl, wait_for, wait_heartbeat

from navig8_fc.params.registry import ParamRegistry
from navig8_tools.mcap_to_tlog import export

M = mavlink2
FC_LOCAL = {"scenario": "ground"}  # the local pair for MAVProxy's session (conftest.py `fc`)


def _set(gcs, name: str, value: float):
    gcs.mav.param_set_send(gcs.target_system, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32)
    return wait_for(gcs, "PARAM_VALUE", PARAM_SET_WAIT_S, lambda m: m.param_id == name)


def _read(gcs, name: str):
    gcs.mav.param_request_read_send(gcs.target_system, 1, name.encode(), -1)
    return wait_for(gcs, "PARAM_VALUE", 5.0, lambda m: m.param_id == name)


@pytest.mark.local_only("restarts the FC process on its state dir")
def test_parameters_persist_across_restart_and_defaults_flag(tmp_path: Path) -> None:
    state = tmp_path / "state"
    with sitl(tmp_path, state_dir=state, log_name="a.mcap") as run:
        gcs = gcs_client(run.gcs_port)
        try:
            wait_heartbeat(gcs, 15.0)
            assert abs(_set(gcs, "OL_VEL_K", 2.5).param_value - 2.5) < 1e-6
            assert abs(_set(gcs, "INDI_K_MAX", 0.9).param_value - 0.9) < 1e-6
        finally:
            gcs.close()
    with sitl(tmp_path, state_dir=state, log_name="b.mcap") as run:
        gcs = gcs_client(run.gcs_port)
        try:
            wait_heartbeat(gcs, 15.0)
            assert abs(_read(gcs, "OL_VEL_K").param_value - 2.5) < 1e-6
            assert abs(_read(gcs, "INDI_K_MAX").param_value - 0.9) < 1e-6
        finally:
            gcs.close()
    with sitl(tmp_path, state_dir=state, log_name="c.mcap", fc_args=["--defaults"]) as run:
        gcs = gcs_client(run.gcs_port)
        try:
            wait_heartbeat(gcs, 15.0)
            assert abs(_read(gcs, "OL_VEL_K").param_value - 3.0) < 1e-6
        finally:
            gcs.close()


@pytest.mark.local_only("exports the local log")
def test_tlog_export_opens_in_pymavlink(tmp_path: Path) -> None:
    with sitl(tmp_path, scenario="hover", speed=4.0) as run:
        gcs = gcs_client(run.gcs_port)
        try:
            wait_heartbeat(gcs, 15.0)
            assert _read(gcs, "OL_POS_K") is not None
            # A second heartbeat after the read: the exchange is behind us and in the FC's log queue.
            assert wait_for(gcs, "HEARTBEAT", 5.0, lambda m: m.get_srcComponent() == 1) is not None
        finally:
            gcs.close()
    # Every datagram is logged raw once, on a channel per peer (the peer in the channel's metadata).
    from mcap.reader import make_reader

    with open(run.log, "rb") as fh:
        peers = {(ch.topic, ch.metadata.get("peer")) for ch in make_reader(fh).get_summary().channels.values()
                 if ch.topic.startswith("/mavlink/") and ch.topic.count("/") == 3}
    assert ("/mavlink/gcs/in", f"127.0.0.1:{run.gcs_port}") in peers, peers
    assert any(t == "/mavlink/sim/in" and p for t, p in peers), peers
    tlog = tmp_path / "run.tlog"
    n = export(run.log, tlog, link="gcs")
    assert n > 10
    conn = mavutil.mavlink_connection(str(tlog), dialect="common")
    types = set()
    while (m := conn.recv_match(blocking=False)) is not None:
        types.add(m.get_type())
    assert {"HEARTBEAT", "PARAM_VALUE", "PARAM_REQUEST_READ"} <= types


def test_mavproxy_downloads_all_parameters_and_sets_one(fc: FcTarget, tmp_path: Path) -> None:
    # Not skipped when missing: MAVProxy is part of what `make install` / `make test` set up (pinned, lean).
    assert shutil.which("mavproxy.py", path=str(Path(sys.executable).parent)), (
        "MAVProxy is missing from this venv: run `make install` (pip install --no-deps MAVProxy==1.8.75)")
    n_params = len(ParamRegistry.from_defaults(check_stability=False))
    mavproxy = str(Path(sys.executable).parent / "mavproxy.py")
    with fc.session("api", source_system=245) as api:  # a second client on the same vehicle reads the value back
        old = _read(api, "OL_ATT_K")
        assert old is not None
        cmd = [sys.executable, mavproxy, f"--master={fc.gcs}", "--nowait", "--default-modules=param",
               f"--target-system={fc.sysid}", f"--state-basedir={tmp_path}"]
        p = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                             cwd=tmp_path, text=True)
        out = _Reader(p)
        try:
            assert out.wait_for(f"Received {n_params} parameters", 60.0), out.text[-3000:]
            p.stdin.write("param set OL_ATT_K 4.5\n")
            p.stdin.flush()
            deadline = time.monotonic() + 30.0
            value = None
            while time.monotonic() < deadline:
                # No answer within _read's 5 s on a loaded machine (the set still on its stability check): ask again.
                msg = _read(api, "OL_ATT_K")
                value = None if msg is None else msg.param_value
                if value is not None and abs(value - 4.5) < 1e-6:
                    break
                time.sleep(0.2)
            assert value is not None and abs(value - 4.5) < 1e-6, out.text[-3000:]
        finally:
            p.kill()
            p.wait(timeout=10)
            _set(api, "OL_ATT_K", old.param_value)  # leave it as found


class _Reader:
    """Collects a child's stdout without blocking (a thread), so every wait is bounded."""

    def __init__(self, p: subprocess.Popen) -> None:
        import threading

        self.text = ""
        self._lock = threading.Lock()
        self._t = threading.Thread(target=self._run, args=(p,), daemon=True)
        self._t.start()

    def _run(self, p: subprocess.Popen) -> None:
        for line in p.stdout:
            with self._lock:
                self.text += line

    def wait_for(self, needle: str, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self._lock:
                if needle in self.text:
                    return True
            time.sleep(0.1)
        return False


def test_a_param_set_inside_the_stability_margin_is_refused_and_the_margin_streams(fc: FcTarget) -> None:
    """Over MAVLink: LAM_CRIT and LAM_MARGIN stream (the floor of the values in force, computed on the FC's worker),
    and a PARAM_SET that asks for more margin than the configuration has is refused: the value in force echoed, the
    reason in a STATUSTEXT. Nothing changes on the vehicle, so any FC target can take it."""
    with fc.session("api", source_system=246) as api:
        named: dict[str, float] = {}
        deadline = time.monotonic() + 60.0
        while len(named) < 2 and time.monotonic() < deadline:
            m = wait_for(api, "NAMED_VALUE_FLOAT", 5.0,
                         lambda m: m.name in ("LAM_CRIT", "LAM_MARGIN") and m.value == m.value)  # not NaN
            if m is not None:
                named[m.name] = m.value
        assert set(named) == {"LAM_CRIT", "LAM_MARGIN"}, named
        assert 0.0 < named["LAM_CRIT"] < 1.0 and named["LAM_MARGIN"] > 1.0
        asked = math.ceil(named["LAM_MARGIN"]) + 1.0  # more than the vehicle has
        old = _read(api, "INDI_LAM_MARGIN").param_value
        pv = _set(api, "INDI_LAM_MARGIN", asked)
        assert pv is not None and abs(pv.param_value - old) < 1e-6
        text = wait_for(api, "STATUSTEXT", 5.0, lambda m: m.text.startswith("INDI_LAM_MARGIN: refused"))
        assert text is not None and "stability margin" in text.text
