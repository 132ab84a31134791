"""Adapting beats not adapting (issue 10's must-show) on the wrong-model paper scenario, in-process, seed 1.

paper_wrong_model: the paper's scenario flown by a controller that believes the UAV body 20 % lighter and its inertia
40 % smaller (params/scenarios/paper_wrong_model.yaml), besides the object it is never told about. With the
prioritised allocation, the short INDI filter and the arm feed-forward (the best flight configuration,
docs/results.md "Prioritised allocation"), `proposed` (the constrained adaptive law) flies with >= 20 % less
attitude RMS than `fixed` (K = 1, the controller's own model): 10 seeds of the full run -37.7 % median, -32.0 to
-42.8 % per seed (docs/results.md, "Adapting against not adapting"). With the paper's group-scaling allocation the
same comparison stays below 20 % (-17.2 % median over 10 seeds): the test can fail, and it tells the two apart.
The first 12.5 s hold the 1 kg and 2 kg arm reversals, the object's arrival and the east/north position steps.
"""

from __future__ import annotations

import pytest

from navig8_tools.sim import run

BEST = {"INDI_ALLOC": 1, "INDI_LPF_TAU": 0.03, "INDI_ARM_FF": 1}
GAIN_MIN = 0.20  # issue 10: proposed improves on fixed by >= 20 % in attitude RMS or position RMS
DURATION_S = 12.5


@pytest.fixture(scope="module")
def summaries(tmp_path_factory) -> dict[tuple[str, str], dict]:
    d = tmp_path_factory.mktemp("adapt")
    return {(cfg, ctl): run("paper_wrong_model", ctl, seed=1, duration_s=DURATION_S,
                            log_path=d / f"{cfg}_{ctl}.mcap", overrides=ov).summary
            for cfg, ov in (("best", BEST), ("paper_alloc", {})) for ctl in ("proposed", "fixed")}


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
