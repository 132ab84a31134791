"""Command shaping on the paper scenario (in-process, seed 1, the first 12.5 s: the east and north position
steps at 5 s and 10 s, each at an arm reversal, with the defaults, which shape). Without shaping the north step makes
the commanded roll jump by atan(OL_ACC_MAX / g) = 22 deg in one tick; with it the attitude error stays within
20 deg, and both steps still settle (against the raw setpoint)."""

from __future__ import annotations

import pytest

from navig8_tools.sim import run

ATT_TARGET_DEG = 20.0
UNSHAPED = {"OL_JERK_MAX": 0.0, "OL_ATT_ACC_REF": 0.0}


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, dict]:
    d = tmp_path_factory.mktemp("shape")
    return {name: run("paper", "proposed", seed=1, duration_s=12.5, log_path=d / f"{name}.mcap",
                      overrides=extra).summary for name, extra in (("unshaped", UNSHAPED), ("shaped", {}))}


def test_shaped_commands_hold_the_attitude_bound(runs) -> None:
    s = runs["shaped"]
    assert s["lost_control"] is False
    assert s["bound_violations"] == 0
    assert s["max_att_error_deg"] <= ATT_TARGET_DEG, s["max_att_error_deg"]
    settle = {st["axis"]: st["settle_s"] for st in s["settle"]}
    assert settle["east"] is not None and settle["east"] < 4.5, settle  # 4.02 s (3.9 s flying K_hat, INDI_LAM_REF 1)
    assert settle["north"] is not None and settle["north"] < 2.5, settle  # window to the run's end


def test_the_unshaped_loop_does_not(runs) -> None:
    assert runs["unshaped"]["max_att_error_deg"] > ATT_TARGET_DEG + 2.0, runs["unshaped"]["max_att_error_deg"]
