"""Link health as a ground station sees it: a stalled bridge (STATUSTEXT, SYS_STATUS health and pre-arm bits,
arming denied, recovery), a control-rate mismatch between INDI_RATE_HZ and the bridge's --dt, replies routed
to the link that asked, and the /fc/statustext log's publish time. Real processes on free loopback ports,
bounded waits; every process is stopped."""

from __future__ import annotations

import time
from pathlib import Path

from sitl_helpers import free_udp_ports

from navig8_fc.shell import fc_process as fp
from navig8_fc.shell.mcap_log import read_mcap_records


def _fc_in_process(tmp_path: Path, log: Path | None = None) -> fp.FlightControllerProcess:
    sim, bridge, gcs_bind, api_bind, gcs, api = free_udp_ports(6)
    argv = ["--sim-port", str(sim), "--bridge-port", str(bridge), "--gcs-bind-port", str(gcs_bind),
            "--api-bind-port", str(api_bind), "--gcs-port", str(gcs), "--api-port", str(api),
            "--state-dir", str(tmp_path), "--defaults"]
    if log is not None:
        argv += ["--log", str(log)]
    return fp.FlightControllerProcess(fp.options_from_args(fp.build_arg_parser().parse_args(argv)))


def test_statustext_log_publish_time_is_wall_clock(tmp_path: Path) -> None:
    log = tmp_path / "fc.mcap"
    fc = _fc_in_process(tmp_path, log)
    try:
        t0 = time.time_ns()
        fc.statustext("hello from the test", severity=6)
        t1 = time.time_ns()
    finally:
        fc.close()
    recs = [(t, pub, d) for topic, t, pub, d in read_mcap_records(log, ["/fc/statustext"])]
    assert len(recs) == 1 and recs[0][2]["text"] == "hello from the test"
    assert t0 <= recs[0][1] <= t1, "publish_time must be the writer's wall clock (docs/logs.md)"
