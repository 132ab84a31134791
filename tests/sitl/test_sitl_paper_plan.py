"""The paper run flown as an uploaded plan: `navig8-mission from-scenario --scenario paper` writes Eq. 25/26 as
mission items, `navig8-mission fly` uploads and flies it on the `paper_plan` world (the paper's world without a
flight script; the bridge keeps only the object's mass event), and the log's summary meets the paper criteria of
the scripted run (tests/sitl/test_sitl_paper.py) and is close to it (tolerances below, docs/gcs.md)."""

from __future__ import annotations

import io
import time
from pathlib import Path

import numpy as np
import pytest
from sitl_helpers import gcs_client, sitl, wait_heartbeat

from navig8_tools.logdata import load_run
from navig8_tools.mission import fly, plan_from_scenario, read_plan, write_wpl
from navig8_tools.summary import summarize

# the flown eigenvalue's floor: the registry's guaranteed minimum of G_hat G^-1 over the defaults' flown K box
# ([0.4, 1]: INDI_LAM_REF 0.4, INDI_KFL_MIN 0.4) and the workspace, 0.386 on the full sweep, rounded down (0.399 here)
EIG_FLOOR = 0.38

def test_paper_plan_flown_by_navig8_mission_meets_the_paper_criteria(tmp_path: Path,
                                                                    paper_reference: tuple[dict, Path]) -> None:
    plan_file = tmp_path / "paper.waypoints"
    plan_file.write_text(write_wpl(plan_from_scenario("paper")))
    items = read_plan(plan_file).mission
    with sitl(tmp_path, scenario="paper_plan", speed=1.0, fc_args=["--until-done"],
              bridge_args=["--until-done"]) as run:
        gcs = gcs_client(run.gcs_port)
        try:
            wait_heartbeat(gcs, 15.0)
            out = io.StringIO()
            summary = fly(gcs, items, timeout_s=60.0, out=out)
            assert summary["complete"], out.getvalue()[-2000:]
            assert summary["reached"] == list(range(len(items))), summary
        finally:
            gcs.close()
        deadline = time.monotonic() + 30.0
        while run.fc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
    s = summarize(load_run(run.log), 0.0)
    assert s["lost_control"] is False and s["bound_violations"] == 0 and s["min_eigenvalue"] >= EIG_FLOOR
    assert len(s["settle"]) == 5 and all(x["settle_s"] is not None for x in s["settle"]), s["settle"]

    # Close to the scripted run (the in-process reference; test_sitl_paper.py shows SITL == in-process to float32
    # rounding). Differences: the plan starts when its upload completes (~0.04 s of sim time after the start, so
    # every step and arm command comes that much later relative to the 6 s mass event), the arm's initial 2 s
    # ramp is 0.25 s joint-target steps, and the run lasts 32 s (holding after the plan ends) instead of 30 s.
    ref, ref_log = paper_reference  # run("paper", "proposed", seed=1) logged, flown once a run (tests/conftest.py)
    # The eigenvalues follow the estimate, which moves with the windowed estimator (CKF_INC_N = 25): a start 0.04 s
    # later shifts its windows against the arm's reversals (measured 0.504-0.545 against 0.507). The largest
    # position error is the altitude sag after the yaw step flown at 45 deg pitch with the arm reversing, which
    # spans 2.65-2.72 m over seeds of the scripted run itself and is sensitive to the commands' timing (docs/results.md,
    # "Controller", "SITL"): 3.7-4.3 m measured here against 2.77 m; not compared, only held below the loss-of-control
    # threshold above. For the same reason the position RMS is compared up to the yaw step (25 s), where the two
    # runs fly the same manoeuvres (0.85 against 0.85 m); over the whole run 1.35-1.61 m against 1.18 m. Attitude
    # error 18.9-19.4 against 18.4 deg.
    for key, rel in (("min_eigenvalue", 0.1), ("max_eigenvalue", 0.05), ("max_att_error_deg", 0.1),
                     ("peak_reaction_force_n", 0.05), ("peak_reaction_torque_nm", 0.1)):
        assert s[key] == pytest.approx(ref[key], rel=rel), key
    before, before_ref = pos_rms_until(run.log, YAW_STEP_S), pos_rms_until(ref_log, YAW_STEP_S)
    assert before == pytest.approx(before_ref, rel=0.1), (before, before_ref)
    # Settling: the first four steps within 0.3 s of the scripted run's. The yaw step's window runs to the end of
    # the log (32 s here, 30 s there): where the yaw error crosses 5 deg again after 30 s (with the arm resting in
    # Pose 2 it did at ~30.3 s before the estimator's moment rows referred to the estimated CoM), its settle time is
    # later here by construction; where it does not, it is the same step's, within the same 0.3 s (measured 2.82
    # against 2.98 s). It must settle all the same.
    # (0.3 s: with the windowed estimator the estimate, and with it the loop's gain, follows the commands' timing;
    # a 0.02-0.04 s later plan start moved the pitch step's settling by 0.21 s in one run.)
    for a, b in zip(s["settle"][:4], ref["settle"][:4], strict=True):
        assert a["axis"] == b["axis"] and a["settle_s"] == pytest.approx(b["settle_s"], abs=0.3), (a, b)
    assert s["settle"][4]["axis"] == "yaw" and s["settle"][4]["settle_s"] >= ref["settle"][4]["settle_s"] - 0.3


YAW_STEP_S = 25.0  # the paper scenario's last step (Eq. 25)


def pos_rms_until(log: Path, t_end_s: float) -> float:
    """RMS of the distance between the true position and the FC's position setpoint over the log's first t_end_s."""
    run = load_run(log)
    tr, sp = run["/truth"], run["/fc/setpoint"]
    t = tr.t - tr.t[0]
    keep = t < t_end_s
    pos, sp_pos = tr.field("pos_ned_m", 3)[keep], sp.field("pos_ned_m", 3)
    at = tr.t[keep]
    err = pos - np.column_stack([np.interp(at, sp.t, sp_pos[:, k]) for k in range(3)])
    return float(np.sqrt(np.mean(np.sum(err * err, axis=1))))

