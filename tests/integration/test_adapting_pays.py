"""Adapting beats not adapting on the wrong-model paper scenario, in-process, seed 1.

paper_wrong_model: the paper's scenario flown by a controller that believes the UAV body 20 % lighter and its inertia
40 % smaller (params/scenarios/paper_wrong_model.yaml), besides the object it is never told about. Flying the
estimate (INDI_LAM_REF 1, INDI_KFL_MIN 0: the paper's reading, the previous defaults), `proposed` (the constrained
adaptive law) flies with >= 20 % less attitude RMS than `fixed` (K = 1, the controller's own model); with the paper's
group-scaling allocation the same comparison stays below 20 %: the test can fail, and it tells the two apart (10
seeds: docs/results.md, "Estimator"). At the defaults' flown gain (INDI_LAM_REF 0.4, INDI_KFL_MIN 0.4) both
controllers fly 0.4 on the rotational axes (fixed: K = 1 flown as 0.4; the defaults whatever K_hat) and differ on the
mass axis only: there the two fly alike (within 0.001 % on this seed; docs/results.md "Adapting with a flown gain"),
and the defaults beat the controller's own model flown as K = 1 by far more than 20 %. The first 12.5 s hold the 1 kg
and 2 kg arm reversals, the object's arrival and the east/north position steps.
"""

from __future__ import annotations

import pytest

from navig8_tools.sim import run

GAIN_MIN = 0.20  # proposed improves on fixed by >= 20 % in attitude RMS
DURATION_S = 12.5
K_HAT = {"INDI_LAM_REF": 1.0, "INDI_KFL_MIN": 0.0}  # the INDI flies K_hat (in this order: the registry checks each)


@pytest.fixture(scope="module")
def summaries(tmp_path_factory) -> dict[tuple[str, str], dict]:
    d = tmp_path_factory.mktemp("adapt")
    cfgs = (("best", K_HAT), ("paper_alloc", {**K_HAT, "INDI_ALLOC": 0}), ("defaults", {}))
    return {(cfg, ctl): run("paper_wrong_model", ctl, seed=1, duration_s=DURATION_S,
                            log_path=d / f"{cfg}_{ctl}.mcap", overrides=ov).summary
            for cfg, ov in cfgs for ctl in ("proposed", "fixed")}


def _gain(summaries: dict, cfg: str, against: str | None = None) -> float:
    return 1.0 - (summaries[(cfg, "proposed")]["att_rms_error_deg"]
                  / summaries[(against or cfg, "fixed")]["att_rms_error_deg"])


def test_adapting_beats_fixed_by_20_percent_with_the_prioritised_allocation(summaries) -> None:
    p = summaries[("best", "proposed")]
    assert p["lost_control"] is False and summaries[("best", "fixed")]["lost_control"] is False
    assert p["bound_violations"] == 0
    assert p["min_eigenvalue"] >= 0.45
    assert _gain(summaries, "best") >= GAIN_MIN, _gain(summaries, "best")


def test_with_group_scaling_adapting_gains_less(summaries) -> None:
    # the allocation is what lets the adapted model's larger moments through: with group scaling the adaptive law loses
    # the vehicle on this seed and window (att RMS 41.1 against fixed's 12.0 deg; gain -2.4)
    assert _gain(summaries, "paper_alloc") < GAIN_MIN, _gain(summaries, "paper_alloc")
    assert _gain(summaries, "best") > _gain(summaries, "paper_alloc") + 0.1


def test_at_the_defaults_flown_gain_adapting_is_no_worse_than_fixed(summaries) -> None:
    p = summaries[("defaults", "proposed")]
    assert p["lost_control"] is False and p["bound_violations"] == 0
    # the same rotational gain (0.4), the mass axis adapted or not: no worse than 0.5 % (-0.0003 % on this seed)
    assert _gain(summaries, "defaults") > -0.005, _gain(summaries, "defaults")
    assert _gain(summaries, "defaults", against="best") >= GAIN_MIN, _gain(summaries, "defaults", against="best")
