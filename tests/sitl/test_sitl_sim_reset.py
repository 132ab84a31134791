"""The explicit reset of the sim link with real processes: the bridge is stopped mid-flight and a new one started on
the same port; it asks to pair, the FC answers with a fresh nonce, and stepping starts again from t = 0 (a new
session, the only way time may go back). A bridge on another port asking to pair while the first is live is
refused."""

from __future__ import annotations

import signal
from pathlib import Path

from sitl_helpers import Proc, gcs_client, sitl, start_process, wait_for, wait_heartbeat

from navig8_fc.shell.mcap_log import read_mcap, read_metadata


def _bridge(tmp: Path, *args: str) -> Proc:
    return start_process("sim_bridge.bridge", ["--scenario", "hover", "--speed", "2", *args], tmp, text=True)


def test_a_restarted_bridge_pairs_again_and_a_second_one_is_refused(tmp_path: Path) -> None:
    with sitl(tmp_path, scenario="hover", speed=2.0) as run:
        gcs = gcs_client(run.gcs_port)
        new = intruder = None
        try:
            wait_heartbeat(gcs, 60.0)
            assert wait_for(gcs, "LOCAL_POSITION_NED", 20.0, lambda m: abs(m.z + 2.0) < 0.2) is not None
            # another bridge (its own port) asking the FC to pair while the first one steps it: refused
            intruder = _bridge(tmp_path, "--bridge-port", "0", "--fc-port", str(run.ports["sim"]),
                               "--startup-timeout", "3")
            assert intruder.wait(timeout=60) == 3  # never paired: it gives up at its startup timeout
            assert run.bridge is not None
            run.bridge.send_signal(signal.SIGTERM)
            assert run.bridge.wait(timeout=30) == 0
            new = _bridge(tmp_path, "--bridge-port", str(run.ports["bridge"]), "--fc-port", str(run.ports["sim"]))
            # stepping again, from the new session's t = 0 (the plant starts at the hover point)
            assert wait_for(gcs, "STATUSTEXT", 60.0, lambda m: "Sim link paired" in m.text and "(2)" in m.text)
            assert wait_for(gcs, "LOCAL_POSITION_NED", 20.0, lambda m: abs(m.z + 2.0) < 0.2) is not None
            assert new.poll() is None and run.fc.poll() is None
        finally:
            gcs.close()
            for p in (new, intruder):
                if p is not None and p.poll() is None:
                    p.send_signal(signal.SIGINT)
                    p.wait(timeout=30)
    guard = read_metadata(run.log)["fc_stats"]["sim_guard"]
    assert guard["sessions"] == 2 and guard["pair_refused"] >= 1 and guard["out_of_order"] == 0, guard
    times = [t for _topic, t, _d in read_mcap(run.log, topics=["/fc/command"])]
    backs = [i for i in range(1, len(times)) if times[i] < times[i - 1]]
    assert len(backs) == 1 and times[backs[0]] == 0, backs  # time went back exactly once: at the new session
