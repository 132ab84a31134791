"""Adapting beats not adapting on the wrong-model paper scenario, in-process, seed 1, with the defaults.

paper_wrong_model: the paper's scenario flown by a controller that believes the UAV body 20 % lighter and its inertia
40 % smaller (params/scenarios/paper_wrong_model.yaml), besides the object it is never told about. With the defaults,
`proposed` (the constrained adaptive law) flies with >= 20 % less attitude RMS than `fixed` (K = 1, the controller's
own model); with the paper's group-scaling allocation the same comparison stays below 20 %: the test can fail, and
it tells the two apart (10 seeds: docs/results.md, "Estimator"). The first 12.5 s hold the 1 kg and 2 kg arm
reversals, the object's arrival and the east/north position steps.
"""

from __future__ import annotations

import pytest

from navig8_tools.sim import run

GAIN_MIN = 0.20  # proposed improves on fixed by >= 20 % in attitude RMS
DURATION_S = 12.5


@pytest.fixture(scope="module")
def summaries(tmp_path_factory) -> dict[tuple[str, str], dict]:
    d = tmp_path_factory.mktemp("adapt")
    return {(cfg, ctl): run("paper_wrong_model", ctl, seed=1, duration_s=DURATION_S,
                            log_path=d / f"{cfg}_{ctl}.mcap", overrides=ov).summary
            for cfg, ov in (("best", {}), ("paper_alloc", {"INDI_ALLOC": 0})) for ctl in ("proposed", "fixed")}


def _gain(summaries: dict, cfg: str) -> float:
    return 1.0 - summaries[(cfg, "proposed")]["att_rms_error_deg"] / summaries[(cfg, "fixed")]["att_rms_error_deg"]


def test_adapting_beats_fixed_by_20_percent_with_the_prioritised_allocation(summaries) -> None:
    p = summaries[("best", "proposed")]
    assert p["lost_control"] is False and summaries[("best", "fixed")]["lost_control"] is False
    assert p["bound_violations"] == 0
    assert p["min_eigenvalue"] >= 0.45
    assert _gain(summaries, "best") >= GAIN_MIN, _gain(summaries, "best")


def test_with_group_scaling_adapting_gains_less(summaries) -> None:
    # measured 12 % on this seed and window; the allocation is what lets the adapted model's larger moments through
    assert _gain(summaries, "paper_alloc") < GAIN_MIN, _gain(summaries, "paper_alloc")
    assert _gain(summaries, "best") > _gain(summaries, "paper_alloc") + 0.1
