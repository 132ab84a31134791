"""A stability-checked PARAM_SET is answered at once, the first after boot included (docs/security.md, "PARAM_SET
answers"): the FC's stability-floor worker is started and warm before the FC's first heartbeat, and a new
configuration's floor takes ~20 ms on it. Ground stations wait ~3 s for the PARAM_VALUE (QGroundControl, MAVProxy);
PX4 answers in milliseconds. A real FC and bridge on loopback."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from pymavlink import mavutil
from sitl_helpers import gcs_client, sitl, wait_for, wait_heartbeat

pytestmark = pytest.mark.slow

N_SETS = 21  # the first after boot and twenty more, each a configuration whose floor is not computed yet
# every answer, the first included: 40-68 ms on a quiet host, 0.31-0.53 s beside the SITL lane's other workers on two
# loaded cores; what it guards, a floor worker not warm at boot, answered the first in 1.5 s quiet, 2.6-6 s loaded
ANSWER_BOUND_S = 1.0


def test_the_first_stability_checked_param_set_after_boot_is_answered_at_once(tmp_path: Path) -> None:
    with sitl(tmp_path, scenario="ground", speed=1.0) as run:
        gcs = gcs_client(run.gcs_port)
        assert wait_heartbeat(gcs, 60.0) is not None
        gcs.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        answers_s: list[float] = []
        for k in range(N_SETS):
            value = 1.01 + 0.01 * k  # INDI_K_MAX: each a new flown box (a new stability floor)
            t0 = time.perf_counter()
            gcs.mav.param_set_send(1, 1, b"INDI_K_MAX", value, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
            pv = wait_for(gcs, "PARAM_VALUE", 10.0, lambda m: m.param_id == "INDI_K_MAX")
            answers_s.append(time.perf_counter() - t0)
            assert pv is not None, f"no PARAM_VALUE for INDI_K_MAX {value:.2f}"
            assert abs(pv.param_value - value) < 1e-5, (value, pv.param_value)  # accepted: inside the margin
        first_s, ordered = answers_s[0], sorted(answers_s)
        print(f"PARAM_SET -> PARAM_VALUE, stability-checked: first {first_s * 1e3:.0f} ms after boot, median "
              f"{ordered[N_SETS // 2] * 1e3:.0f} ms, max {ordered[-1] * 1e3:.0f} ms over {N_SETS}")
        assert ordered[-1] < ANSWER_BOUND_S, answers_s
