"""The defaults' short INDI filter (INDI_LPF_TAU = 0.02 s) with the model-based U0 (INDI_U0_SRC = 1) against the
same loop with the measured U0 (the paper's Eq. 5), on the paper scenario (in-process, full 30 s, ±60 N tail).

Over 10 seeds (params/campaigns/paper_attitude.yaml, docs/results.md "Controller") the model's U0 keeps every seed
under 20 deg and flies less attitude RMS on every seed: with the defaults' flown gain (INDI_LAM_REF 0.5, INDI_KFL_MIN
0.4) 17.3-17.6 deg against 17.4-17.9 with the measured U0, RMS 2-13 % lower (seed 3: 3.67 against 3.85 deg). Flying
the estimate K_hat (INDI_LAM_REF 1, the previous defaults) the measured U0 feeds the 20 rad/s speed-sensor noise
through the short filter into the increment and exceeds 20 deg on 3 of 10 (worst 23.6, seed 3). Seed 3 is that worst
case: the tests fail if the model's U0 stops mattering there, at either flown gain."""

from __future__ import annotations

import pytest

from navig8_tools.sim import run

# the flown eigenvalue's floor: the registry's guaranteed minimum of G_hat G^-1 over the flown K box (the defaults'
# INDI_LAM_REF 0.4, INDI_KFL_MIN 0.4: [0.4, 1]) and the workspace, 0.386 on navig8-stability's full sweep, rounded down
# (the paper scenario flies 0.396-0.399)
EIG_FLOOR = 0.38
ATT_BOUND_DEG = 20.0
SEED = 3
K_HAT = {"INDI_LAM_REF": 1.0, "INDI_KFL_MIN": 0.0}  # the INDI flies K_hat (in this order: the registry checks each)


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[tuple[str, int], dict]:
    d = tmp_path_factory.mktemp("u0")
    return {(gain, src): run("paper", "proposed", seed=SEED, log_path=d / f"{gain}_u{src}.mcap",
                             overrides={**extra, "INDI_U0_SRC": src}).summary
            for gain, extra in (("defaults", {}), ("k_hat", K_HAT)) for src in (0, 1)}


def test_model_u0_makes_the_short_filter_hold(runs) -> None:
    for gain, floor in (("defaults", EIG_FLOOR), ("k_hat", 0.45)):
        s = runs[(gain, 1)]
        assert s["lost_control"] is False, gain
        assert s["bound_violations"] == 0, gain
        assert s["min_eigenvalue"] >= floor, (gain, s["min_eigenvalue"])
        assert s["max_att_error_deg"] <= ATT_BOUND_DEG, (gain, s["max_att_error_deg"])


def test_measured_u0_does_not(runs) -> None:
    m, u = runs[("k_hat", 0)], runs[("k_hat", 1)]
    assert m["max_att_error_deg"] > ATT_BOUND_DEG, m["max_att_error_deg"]
    assert m["att_rms_error_deg"] > 1.08 * u["att_rms_error_deg"], (m["att_rms_error_deg"], u["att_rms_error_deg"])
    # the defaults' flown gain holds the bound with the measured U0 too (17.4 deg), and flies 4.9 % more RMS with it
    m, u = runs[("defaults", 0)], runs[("defaults", 1)]
    assert m["att_rms_error_deg"] > 1.03 * u["att_rms_error_deg"], (m["att_rms_error_deg"], u["att_rms_error_deg"])
