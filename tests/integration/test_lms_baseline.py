"""The LMS baseline (CKF_MODE 4, navig8_fc/core/lms.py) flies: 20 s of the identification scenario in one process
(navig8_tools.sim.run, as navig8-sim), controller 'lms' with its default rates.

The truth is the plant's, not the estimator's: ident carries an unknown 2 kg object at q = 0, so the clipped truth is
K ~ 0.5 / 0.5 / 0.99 / 0.77 (tests/integration/test_estimator_convergence.py derives it from the plant per tick);
the LMS starts at K = 1.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from navig8_tools.logdata import load_run
from navig8_tools.sim import run

K_TRUE_CLIPPED = (0.5, 0.5, 0.99, 0.77)  # ident: params/scenarios/ident.yaml, docs/model.md "Identification scenario"


def test_lms_keeps_control_on_ident_and_moves_k_toward_the_truth(tmp_path: Path) -> None:
    res = run("ident", "lms", seed=1, duration_s=20.0, log_path=tmp_path / "lms.mcap")
    s = res.summary
    assert not s["lost_control"] and s["bound_violations"] == 0
    assert s["max_att_error_deg"] < 3.0, s["max_att_error_deg"]  # against the commanded attitude (both ~0.8° here)
    r = load_run(tmp_path / "lms.mcap")
    assert r.metadata["run"]["controller"] == "lms" and r.metadata["params"]["CKF_MODE"] == 4
    adapt = [m["adapt"] for m in r["/fc/status"].msgs]
    running = [a for a in adapt if a["running"]]
    assert len(running) > 1000 and all(a["p_diag"] == [0.0] * 4 for a in running)
    k = np.array([a["k"] for a in running])
    assert np.all(k >= 0.5 - 1e-9) and np.all(k <= 1.0 + 1e-9)  # the Eq. 20 box, by the clip
    err_start = np.abs(np.ones(4) - K_TRUE_CLIPPED)
    err_end = np.abs(k[-1] - K_TRUE_CLIPPED)
    # K1 (roll inertia) and K4 (mass) start > 0.2 from the truth and end within 0.1 of it; K2 moves toward it.
    assert np.all(err_start[[0, 3]] > 0.2) and np.all(err_end[[0, 3]] < 0.1), k[-1]
    assert err_end[1] < err_start[1], k[-1]
    assert err_end[2] < 0.1, k[-1]
