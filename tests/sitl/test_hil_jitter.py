"""The FC in real-time mode against a free-running bridge whose bundles cross a proxy adding
±2 ms jitter, 5 % drops and 5 % reordering (sitl_helpers.LossyUdpProxy) holds a 2 m hover (sitl_helpers' hover
band), never steps on a stale bundle (the stamps its answers echo only ever increase) and reports the drops
(STATUSTEXT); whatever delay it measures over the proxy, it arms only with the margin met (the automatic link floor
in force) and never lowers that floor in flight (docs/stability.md, "The automatic link floor")."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sitl_helpers import LossyUdpProxy, fly_from_gcs, mcap_metadata, sitl

from navig8_fc.shell.mcap_log import read_mcap

pytestmark = pytest.mark.realtime  # on the wall clock: run alone, after the parallel SITL lane (make test)


def test_realtime_fc_rides_out_jitter_drops_and_reordering(tmp_path: Path) -> None:
    proxy = LossyUdpProxy(jitter_s=0.002, drop=0.05, reorder=0.05, seed=3)
    try:
        with sitl(tmp_path, scenario="ground", speed=1.0, fc_args=["--timing", "realtime"],
                  bridge_args=["--free-run"],
                  fc_link_args=["--sim-port", "0", "--bridge-port", str(proxy.fc_side_port)]) as run:
            proxy.bridge_addr = ("127.0.0.1", run.ports["bridge"])
            fly_from_gcs(run)
            run.stop()
    finally:
        proxy.close()
    assert proxy.counts["dropped"] > 50 and proxy.counts["reordered"] > 50, proxy.counts
    rt = mcap_metadata(run.log, "realtime_stats")
    # a reordered bundle older than the newest step taken is refused by the sim guard (sequencing) or, if it came
    # before a tick used the newer one, by the real-time clock: both count it
    guard = json.loads(mcap_metadata(run.log, "fc_stats")["sim_guard"])
    assert int(rt["out_of_order"]) + guard["out_of_order"] > 0 and int(rt["missing"]) > 0, (rt, guard)
    echoed = [m["time_usec"] for _, _, m in read_mcap(run.log, ["/mavlink/sim/out/HIL_ACTUATOR_CONTROLS"])]
    assert len(echoed) > 1000 and all(b > a for a, b in zip(echoed, echoed[1:], strict=False))
    texts = [m["text"] for _, _, m in read_mcap(run.log, ["/fc/statustext"])]
    assert any(t.startswith("Sim link:") and "missing" in t for t in texts), texts[-10:]
    # the margin over the link measured: the FC's own floor (the defaults one tick late: 0.482, margin 1.50), only
    # raised in flight (the proxy's link can read no delay at arming and one tick later); armed only once the link was
    # measured and the margin met; nothing left for an operator to answer
    floors = [r for _, _, r in read_mcap(run.log, ["/fc/link_floor"])]
    assert all(r["k_floor"] >= r["k_floor_before"] for r in floors if r["armed"]), floors
    assert all(r["k_floor"] == pytest.approx(0.482) and r["meets_margin"] for r in floors
               if r.get("link_delay_ticks") == 1 and r.get("link_model_told")), floors
    assert not any("over this link < INDI_LAM_MARGIN" in t for t in texts), texts
    stab = [r for _, _, r in read_mcap(run.log, ["/fc/stability"])]
    assert all(r["meets_margin"] or r["link_k_floor"] == pytest.approx(0.5) for r in stab), stab
    at_arm = None
    for topic, _, r in read_mcap(run.log, ["/fc/stability", "/fc/statustext"]):  # file order
        if topic == "/fc/statustext" and r["text"].startswith("Armed"):
            break
        if topic == "/fc/stability":
            at_arm = r
    assert at_arm is not None and at_arm["meets_margin"], at_arm
    print(f"\nlink floors over the proxy: {[(r.get('link_delay_ticks'), r['k_floor']) for r in floors]}; stability "
          f"{[(r['link_delay_ticks'], round(r['margin'], 3), r['link_k_floor']) for r in stab]}")
