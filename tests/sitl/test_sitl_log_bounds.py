"""The log under a datagram flood and a crash, over real processes (docs/logs.md, "Floods" and "A cut log"): a
hovering FC with a small size cap (0.3 MB parts, 2 kept after the first) takes ~1,000 garbage datagrams of 1,500
bytes a second for 5 s on its GCS port and is then killed (SIGKILL). The flood stays out of the log beyond the
budget (counted in /fc/sim_guard's `log_gcs_over_budget`), the first part with the flight's start is still there
after the rotations, and the cut last part reads with the stock mcap reader's defaults
(`make_reader(f).iter_messages()`).
"""

from __future__ import annotations

import os
import signal
import socket
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from sitl_helpers import sitl

from navig8_fc.shell.mcap_log import part_path, read_mcap, read_metadata

FLOOD_S = 5.0
FLOOD_HZ = 1000.0
DATAGRAM = bytes(range(256)) * 5 + bytes(220)  # 1,500 bytes of garbage


def _parts(log: Path) -> list[Path]:
    return [part_path(log, k) for k in range(64) if part_path(log, k).exists()]


def _last_guard(path: Path) -> dict | None:
    last = None
    for _t, _ns, rec in read_mcap(path, ["/fc/sim_guard"]):
        last = rec
    return last


@pytest.mark.local_only("reads the FC's log parts and kills the FC")
def test_a_flood_stays_out_of_the_log_the_start_is_kept_and_a_killed_fcs_log_reads(tmp_path: Path) -> None:
    with sitl(tmp_path, scenario="hover", speed=1.0, bridge_args=["--duration", "40"],
              fc_args=["--log-max-mb", "0.3", "--log-keep", "2"]) as run:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            deadline = time.monotonic() + 20.0  # the FC is flying: its log has a /fc/sim_guard record
            while time.monotonic() < deadline and not (run.log.exists() and _last_guard(run.log)):
                time.sleep(0.1)
            start, sent = time.monotonic(), 0
            while (now := time.monotonic()) < start + FLOOD_S:
                while sent < (now - start) * FLOOD_HZ:
                    sock.sendto(DATAGRAM, ("127.0.0.1", run.gcs_bind_port))
                    sent += 1
                time.sleep(0.002)
            deadline = time.monotonic() + 10.0  # until the newest part's guard record has counted the flood
            guard = None
            while time.monotonic() < deadline:
                guard = _last_guard(_parts(run.log)[-1])
                if guard is not None and guard.get("log_gcs_over_budget", 0) >= 0.5 * sent:
                    break
                time.sleep(0.2)
            assert run.fc.poll() is None, "navig8-fc died"
            os.kill(run.fc.pid, signal.SIGKILL)
            run.fc.wait(timeout=10)
        finally:
            sock.close()
    parts = _parts(run.log)
    print(f"\nflood: {sent} datagrams ({sent * len(DATAGRAM) / 1e6:.1f} MB); log parts kept "
          f"{[p.name for p in parts]}; left out of the log: {guard and guard.get('log_gcs_over_budget')}")
    assert guard is not None and guard["log_gcs_over_budget"] >= 0.5 * sent, guard
    # The first part (the flight's start) survived the rotations, whole.
    assert parts[0] == run.log and len(parts) == 3 and part_path(run.log, 1) not in parts  # rotated >= 3 times
    assert read_metadata(run.log)["run"]["scenario"] == "hover"
    first = next(t for _topic, t, _d in read_mcap(run.log, ["/truth"]))
    assert first <= 2e9  # the first control steps
    # The cut last part: the stock reader with its defaults reads it up to its last complete chunk.
    with open(parts[-1], "rb") as fh:
        n = sum(1 for _ in make_reader(fh).iter_messages())
    assert n > 100, n
