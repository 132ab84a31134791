"""I_yy's prior at a grasp (CKF_IYY_GRIP_W; docs/model.md, "Estimator" item 23), flown where its pull shows alone.

The prior's mean is the estimate before the grasp (the UAM's I_yy, K2 = 1), so its weight pulls the held estimate
back toward it, a bias that the windows' information only dilutes: after the grasp of 0.25 kg hanging at q1 0 the
plant's I_yy moves from 0.599 to 0.783 kg m^2 (K2 0.765, inside the box, off its bounds). Flown with no sensor noise, so
that the flight is the same in every seed and the bias is not the sensors' errors-in-variables one: with half a box
width (the default) K2 held reads 0.0106 high on average over 12-16 s, with one width 0.003, with two 0.001 (with the
preset's half-tick synchronisation, CKF_SYNC; 0.0125 / 0.005 / 0.003 without); it is high (toward the prior's K = 1)
in each, while every other K's mean error is within 0.001 (test_estimator_sync.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from shared_trace import k_trace

from navig8_fc.params.store import read_overrides

PRESETS = Path(__file__).resolve().parents[2] / "params" / "presets"
IDENT = read_overrides([str(PRESETS / "identification.parm")], [])
WORLD = {"scenario.events.0.mass_kg": 0.25, "scenario.initial.joint_pos_deg.0": 0.0, "sensor_noise_scale": 0.0}
K2 = 1


def _held_k2_bias(widths: float) -> float:
    """The mean of K2 - K2_true over the held window (12-16 s)."""
    t, k, kt = k_trace({**IDENT, "CKF_IYY_GRIP_W": widths}, 16.0, 1, "grasp_release_ident", WORLD,
                       truth_box=(0.0, np.inf))
    sel = (t >= 12.0) & (t < 16.0)
    assert np.all(np.abs(kt[sel, K2] - 0.765) < 0.01)  # inside the box, off its bounds
    return float(np.mean(k[sel, K2] - kt[sel, K2]))


def test_the_grasp_prior_pulls_the_held_estimate_toward_the_estimate_before_the_grasp() -> None:
    assert IDENT["CKF_CZ_SIG"] > 0.0 and "CKF_IYY_GRIP_W" not in IDENT  # the preset flies the default half width
    half, one, two = (_held_k2_bias(w) for w in (0.5, 1.0, 2.0))
    assert 0.008 < half < 0.016, half  # measured 0.0106
    assert 0.0 < one < 0.006, one  # 0.0029
    assert 0.0 < two < one, (two, one)  # 0.0009
