"""The defaults' short INDI filter (INDI_LPF_TAU = 0.02 s) with the model-based U0 (INDI_U0_SRC = 1) against the
same loop with the measured U0 (the paper's Eq. 5), on the paper scenario (in-process, full 30 s, ±60 N tail).

Over 10 seeds (params/campaigns/paper_attitude.yaml, docs/results.md "Controller") the model's U0 keeps every seed
under 20 deg (17.96-18.50) and flies 5-18 % less attitude RMS on every seed; the measured U0 feeds the 20 rad/s
speed-sensor noise through the short filter into the increment and exceeds 20 deg on 3 of 10 (worst 23.6, seed 3).
Seed 3 is that worst case: the test fails if the model's U0 stops mattering there."""

from __future__ import annotations

import pytest

from navig8_tools.sim import run

ATT_BOUND_DEG = 20.0
SEED = 3


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[int, dict]:
    d = tmp_path_factory.mktemp("u0")
    return {src: run("paper", "proposed", seed=SEED, log_path=d / f"u{src}.mcap",
                     overrides={"INDI_U0_SRC": src}).summary for src in (0, 1)}


def test_model_u0_makes_the_short_filter_hold(runs) -> None:
    s = runs[1]
    assert s["lost_control"] is False
    assert s["bound_violations"] == 0
    assert s["min_eigenvalue"] >= 0.45
    assert s["max_att_error_deg"] <= ATT_BOUND_DEG, s["max_att_error_deg"]


def test_measured_u0_does_not(runs) -> None:
    m, u = runs[0], runs[1]
    assert m["max_att_error_deg"] > ATT_BOUND_DEG, m["max_att_error_deg"]
    assert m["att_rms_error_deg"] > 1.08 * u["att_rms_error_deg"], (m["att_rms_error_deg"], u["att_rms_error_deg"])
