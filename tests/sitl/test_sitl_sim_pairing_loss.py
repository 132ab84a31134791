"""Pairing on a lossy sim link: a real navig8-fc (lockstep, and real time) behind a relay that drops 20 % of the
datagrams each way (seeded, sitl_helpers.LossyUdpProxy), paired 20 times in a row by the bridge's own link code
(sim_bridge.fc_link.FcLink: pair requests, the nonce echo, bundle 0 re-sent every 0.1 s as navig8-bridge does at
startup). Each pairing must end with the FC's answer to bundle 0 within PAIR_TIMEOUT_S: a lost nonce echo is echoed
again when the FC announces the same nonce again, and a real-time FC answers a re-sent bundle it already flew
(docs/bridge.md, "Pairing and sequencing")."""

from __future__ import annotations

import json
import statistics
import time
from pathlib import Path

import pytest
from sitl_helpers import LossyUdpProxy, bridge_answer, mcap_metadata, sensors_at_rest, sitl

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.mavlink import seam
from sim_bridge.bridge_options import BridgeOptions
from sim_bridge.fc_link import FcLink

TRIALS = 20
LOSS = 0.2  # each way
PAIR_TIMEOUT_S = 12.0  # a few of the FC's 1 s announcements, each lost with LOSS: generous on a loaded host
RESEND_S = 0.1  # navig8-bridge's STARTUP_RESEND_S
DT_US = 10_000


def _pair_once(proxy: LossyUdpProxy, trial: int, limits: seam.ControlsScale) -> float | None:
    """A fresh bridge link pairs through the proxy and sends bundle 0 of this trial (stamps move on from trial to
    trial, as a restarted bridge's may not: the real-time FC never steps back) until the FC answers it: the wall
    seconds that took, or None past PAIR_TIMEOUT_S."""
    link = FcLink(BridgeOptions(bridge_port=0, fc_port=proxy.bridge_side_port), DT_US, limits, lambda _now: None)
    try:
        proxy.bridge_addr = ("127.0.0.1", link.port)
        step = trial * 100
        bundle = seam.encode_bundle(link.mav, step, sensors_at_rest(step * DT_US), None)
        t0 = time.perf_counter()
        got = bridge_answer(link, bundle, seam.time_usec_from_sim_us(step * DT_US), PAIR_TIMEOUT_S, RESEND_S)
        return None if got is None else time.perf_counter() - t0
    finally:
        link.close()


@pytest.mark.parametrize("timing", ["lockstep", "realtime"])
def test_pairing_completes_every_time_at_20_percent_loss(tmp_path: Path, timing: str) -> None:
    limits = seam.ControlsScale.from_vehicle(VehicleConfig.load(None))
    proxy = LossyUdpProxy(jitter_s=0.0, drop=LOSS, reorder=0.0, seed=11, drop_back=LOSS)
    times: list[float | None] = []
    try:
        with sitl(tmp_path, scenario="ground", start_bridge=False, fc_args=["--timing", timing],
                  fc_link_args=["--sim-port", "0", "--bridge-port", str(proxy.fc_side_port)]) as run:
            for trial in range(TRIALS):
                times.append(_pair_once(proxy, trial, limits))
                if times[-1] is None:
                    break
            run.stop()
    finally:
        proxy.close()
    done = [t for t in times if t is not None]
    print(f"\npairing at {LOSS:.0%} loss each way ({timing}): {len(done)}/{TRIALS}, median "
          f"{statistics.median(done) if done else float('nan'):.2f} s, max {max(done, default=float('nan')):.2f} s; "
          f"relay {proxy.counts}")
    assert len(done) == TRIALS, (times, proxy.counts, run.output("fc")[-2000:])
    assert proxy.counts["dropped"] > 0 and proxy.counts["dropped_back"] > 0, proxy.counts
    # a real-time FC may fly the new bridge's bundles in the session before (the same address, newer stamps) until
    # the echo comes: fewer sessions than pairings
    guard = json.loads(mcap_metadata(run.log, "fc_stats")["sim_guard"])
    assert guard["sessions"] >= 1, guard
