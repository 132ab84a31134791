"""navig8-falsify's plumbing (tools/falsify.py) without flying: the optimiser on a synthetic bounded objective with a
known maximum, the unit cube <-> flight mapping (bounds, purity, the duct fault's coordinate), the score, and the
regression files it writes (read back by the loaders that fly them)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from navig8_tools.campaign_spec import Campaign
from navig8_tools.falsify import (
    LOSS_BONUS_PER_S,
    LOSS_SCORE_DEG,
    REGRESSION_CONTROLLERS,
    FalsifySpec,
    duct_fault,
    factors_of,
    flight,
    flight_score,
    maximise,
    search_command,
    write_regression,
)
from sim_bridge.world import load_world

SPEC = FalsifySpec()
N = len(SPEC.dims)


def _peak(xs: list[np.ndarray]) -> list[float]:
    """A bounded objective with its maximum 0 at c, one coordinate of c on the cube's boundary (the bounds
    handling must let the search sit there)."""
    c = np.array([0.3, 0.8, 1.0, 0.1])
    w = np.array([1.0, 4.0, 2.0, 0.5])
    return [float(-np.sum(w * (x - c) ** 2)) for x in xs]


def test_cma_finds_the_known_maximum_of_a_bounded_function_and_is_reproducible():
    trace = maximise(_peak, 4, evals=400, popsize=8, seed=3)
    assert len(trace.evaluations) == 400
    best = trace.best
    np.testing.assert_allclose(best.x, [0.3, 0.8, 1.0, 0.1], atol=0.03)
    assert best.score > -1e-3
    assert all(0.0 <= v <= 1.0 for e in trace.evaluations for v in e.x)
    again = maximise(_peak, 4, evals=400, popsize=8, seed=3)
    assert [e.x for e in again.evaluations] == [e.x for e in trace.evaluations]
    other = maximise(_peak, 4, evals=40, popsize=8, seed=4)
    assert [e.x for e in other.evaluations[:8]] != [e.x for e in trace.evaluations[:8]]


def test_a_failed_evaluation_is_the_worst_and_the_budget_is_kept():
    """nan (a run that failed) never becomes the best, and a budget that is not a whole number of generations is
    kept exactly."""
    calls: list[int] = []

    def f(xs: list[np.ndarray]) -> list[float]:
        calls.append(len(xs))
        return [math.nan if x[0] > 0.5 else float(x[0]) for x in xs]

    trace = maximise(f, 2, evals=25, popsize=6, seed=0)
    assert len(trace.evaluations) == 25 and sum(calls) == 25
    assert math.isfinite(trace.best.score) and trace.best.x[0] <= 0.5


def test_the_cube_maps_into_the_factor_ranges_and_the_flight_is_a_pure_function():
    rng = np.random.default_rng(7)
    for _ in range(20):
        x = rng.uniform(0.0, 1.0, N)
        f = factors_of(x, SPEC)
        for d in SPEC.dims:
            assert d.lo <= f[d.name] <= d.hi, d.name
        a, b = flight(x, SPEC), flight(x.copy(), SPEC)
        assert a.scenario == b.scenario and a.fc_params == b.fc_params
        assert yaml.safe_dump(a.scenario) == yaml.safe_dump(b.scenario)
        dur = a.scenario["duration_s"]
        assert all(0.0 <= ev["t_s"] < dur for ev in a.scenario["events"])
        assert all(abs(q) <= 100.0 for st in a.scenario["arm"]["steps"] for q in st["q_deg"])
    lo = factors_of(np.zeros(N), SPEC)
    hi = factors_of(np.ones(N), SPEC)
    assert lo["arm_speed_scale"] == 0.075 and hi["arm_speed_scale"] == 1.0  # log-linear ends
    assert factors_of(np.full(N, -3.0), SPEC) == lo and factors_of(np.full(N, 5.0), SPEC) == hi  # clipped
    with pytest.raises(ValueError, match="coordinates"):
        factors_of(np.zeros(N + 1), SPEC)


def test_the_duct_fault_coordinate_is_continuous_through_no_fault():
    assert duct_fault(0.0) == (1, 0.5)
    assert duct_fault(1.0) == (3, 0.5)
    assert duct_fault(0.5)[1] == 1.0
    assert duct_fault(0.25) == (1, 0.75) and duct_fault(0.75) == (3, 0.75)
    x = np.full(N, 0.5)
    names = [d.name for d in SPEC.dims]
    x[names.index("duct_fault")] = 0.9
    fl = flight(x, SPEC)
    assert fl.scenario["world"]["plant.actuators.duct_efficiency.1"] == 0.6
    x[names.index("duct_fault")] = 0.5
    assert not any("duct" in k for k in flight(x, SPEC).scenario["world"])


def test_the_flight_is_a_valid_world_and_grasps_at_the_pose(tmp_path):
    """The document loads as a world (its overrides: the truth's object offset, the FC's nominal one; the duct
    fault in the plant), and the grasp happens with the plant's servo at the grasp pose."""
    x = np.full(N, 0.5)
    names = [d.name for d in SPEC.dims]
    x[names.index("duct_fault")] = 0.1
    x[names.index("object_offset_m")] = 1.0
    fl = flight(x, SPEC)
    p = tmp_path / "f.yaml"
    p.write_text(yaml.safe_dump(fl.scenario, sort_keys=False))
    w = load_world(p)
    assert w.plant.duct_efficiency == (0.6, 1.0)
    assert w.vehicle.object_offset_m == 0.15 and w.fc_vehicle.object_offset_m == 0.0
    assert not fl.factors["grasp_in_place"]
    for j in (1, 2, 3):
        assert fl.factors[f"grasp_at_q{j}_deg"] == pytest.approx(fl.factors[f"grasp_q{j}_deg"], abs=0.06)
    assert 0.0 < fl.trim_utilisation < 1.0 and fl.feasible == (fl.trim_utilisation <= SPEC.trim_limit)


def test_the_score_prefers_a_sooner_loss():
    assert flight_score({"max_att_error_deg": 12.5, "lost_control": False}, 14.0) == 12.5
    late = flight_score({"max_att_error_deg": 90.0, "lost_control": True, "lost_control_t_s": 12.0}, 14.0)
    soon = flight_score({"max_att_error_deg": 90.0, "lost_control": True, "lost_control_t_s": 4.0}, 14.0)
    assert late == LOSS_SCORE_DEG + 2.0 * LOSS_BONUS_PER_S and soon > late > 180.0
    assert math.isnan(flight_score({"status": "error"}, 14.0))


def test_the_regression_files_load_as_a_scenario_and_a_campaign(tmp_path):
    (tmp_path / "scenarios").mkdir()
    (tmp_path / "campaigns").mkdir()
    fl = flight(np.full(N, 0.3), SPEC)
    scn, camp = write_regression("proposed", fl, 12.3, "navig8-falsify --controller proposed", tmp_path)
    w = load_world(scn)
    assert w.scenario.name == "falsified_proposed"
    doc = yaml.safe_load(camp.read_text())
    doc["scenario"] = str(scn)  # the packaged name in the file; here the temporary copy
    c = Campaign.from_dict(doc)
    assert [v.name for v in c.variants] == list(REGRESSION_CONTROLLERS) and c.seeds == tuple(range(1, 101))
    for v in c.variants:
        assert dict(v.params)["ARM_SERVO_VMAX"] == fl.fc_params["ARM_SERVO_VMAX"]
    assert dict(c.variants[1].params)["CKF_K_PIN4"] == 1.0


def test_the_recorded_command_leaves_out_where_the_search_wrote():
    cmd = ["navig8-falsify", "--controller", "pinned", "--evals", "120", "--out", "out/x", "--params-dir=/tmp/p",
           "--seed", "1"]
    assert search_command(cmd) == "navig8-falsify --controller pinned --evals 120 --seed 1"
