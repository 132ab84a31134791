"""The arm's `steps` kind with per-step ramps (navig8_fc.flight.script.arm_segments): targets against closed forms,
the plant's kernel against the same lookup, and the kinds that existed before ramps give the same bits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.flight.script import ArmSegment, arm_segments, read_scenario_file, vec3
from sim_bridge.joint_servo import schedule_target
from sim_bridge.scenario import Scenario, load_scenario


def _scenario(arm: dict, q0_deg: tuple[float, float, float] = (0.0, 0.0, 0.0), duration_s: float = 12.0) -> Scenario:
    return Scenario.from_dict({"name": "ramps", "duration_s": duration_s, "initial": {"joint_pos_deg": list(q0_deg)},
                               "arm": arm})


def test_a_ramped_step_moves_the_target_linearly_then_holds() -> None:
    # a slow sweep: 0 -> (60, -30, 10) deg over 4 s from t = 1 s, then a plain step to -20 deg at 8 s
    scn = _scenario({"kind": "steps", "steps": [{"t_s": 1.0, "q_deg": [60.0, -30.0, 10.0], "ramp_s": 4.0},
                                                {"t_s": 8.0, "q_deg": [-20.0, -20.0, -20.0]}]})
    end = np.radians([60.0, -30.0, 10.0])
    for t in (0.0, 0.5, 1.0):
        np.testing.assert_allclose(scn.arm_targets(t), 0.0, atol=0.0)
    for t in (1.5, 2.0, 3.0, 4.9):
        np.testing.assert_allclose(scn.arm_targets(t), end * (t - 1.0) / 4.0, rtol=1e-12, atol=1e-15)
    for t in (5.0, 6.0, 7.999):
        np.testing.assert_allclose(scn.arm_targets(t), end, rtol=1e-12)
    np.testing.assert_allclose(scn.arm_targets(8.0), np.radians([-20.0] * 3), rtol=1e-12)
    np.testing.assert_allclose(scn.arm_targets(11.0), np.radians([-20.0] * 3), rtol=1e-12)


def test_a_ramp_cut_short_by_the_next_one_starts_where_the_target_is() -> None:
    # 0 -> 40 deg over 4 s from 0 s, cut at 2 s (target 20 deg) by a ramp to -40 deg over 3 s: no jump at 2 s
    scn = _scenario({"kind": "steps", "steps": [{"t_s": 0.0, "q_deg": [40.0] * 3, "ramp_s": 4.0},
                                                {"t_s": 2.0, "q_deg": [-40.0] * 3, "ramp_s": 3.0}]})
    at_cut = math.radians(20.0)
    assert scn.arm_targets(2.0 - 1e-9)[0] == pytest.approx(at_cut, abs=1e-8)
    assert scn.arm_targets(2.0)[0] == pytest.approx(at_cut, rel=1e-12)
    for t in (2.5, 3.5, 4.9):
        expect = at_cut + (math.radians(-40.0) - at_cut) * (t - 2.0) / 3.0
        assert scn.arm_targets(t)[0] == pytest.approx(expect, rel=1e-12)
    assert scn.arm_targets(6.0)[0] == pytest.approx(math.radians(-40.0), rel=1e-12)


def test_the_plants_kernel_reads_the_same_targets() -> None:
    scn = _scenario({"kind": "steps", "steps": [{"t_s": 0.5, "q_deg": [80.0, 10.0, 10.0], "ramp_s": 2.5},
                                                {"t_s": 2.0, "q_deg": [-30.0, 45.0, 0.0], "ramp_s": 1.0},
                                                {"t_s": 6.0, "q_deg": [0.0, 0.0, 0.0]}]})
    sched = scn.arm_schedule()
    for t in np.linspace(0.0, 8.0, 161):
        got = [schedule_target.py_func(sched, float(round(t * 1e6)), j) for j in range(3)]
        np.testing.assert_allclose(got, scn.arm_targets(float(round(t * 1e6)) * 1e-6), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("bad", [{"t_s": 1.0, "q_deg": [0, 0, 0], "ramp_s": -1.0},
                                 {"t_s": 1.0, "q_deg": [0, 0, 0], "ramp": 1.0}])
def test_bad_steps_refuse(bad: dict) -> None:
    with pytest.raises(ValueError):
        _scenario({"kind": "steps", "steps": [bad]})
    with pytest.raises(ValueError, match="sorted"):
        _scenario({"kind": "steps", "steps": [{"t_s": 3.0, "q_deg": [0, 0, 0]}, {"t_s": 1.0, "q_deg": [1, 1, 1]}]})


def _segments_before_ramps(kind: str, arm: dict, q0: tuple[float, float, float], duration_s: float
                           ) -> tuple[ArmSegment, ...]:
    """arm_segments as it was before `steps` took ramps (hold and steps; eq26 is the same code)."""
    if kind == "hold":
        q = vec3(arm["q_deg"], deg=True) if "q_deg" in arm else q0
        return (ArmSegment(0.0, 0.0, q, q),)
    if kind == "steps":
        segs = [ArmSegment(0.0, 0.0, q0, q0)]
        for st in arm["steps"]:
            q = vec3(st["q_deg"], deg=True)
            t = float(st["t_s"])
            segs.append(ArmSegment(t, t, segs[-1].q_end_rad, q))
        return tuple(segs)
    return arm_segments(kind, arm, q0, duration_s)


@pytest.mark.parametrize("name", ["paper", "hover", "ident", "hover_arm_forward", "ground", "paper_wrong_model"])
def test_the_shipped_scenarios_schedules_are_unchanged(name: str) -> None:
    d = read_scenario_file(name)
    arm = d.get("arm", {"kind": "hold"})
    q0 = vec3(d.get("initial", {}).get("joint_pos_deg", [0.0, 0.0, 0.0]), deg=True)
    assert load_scenario(name).arm_segments == _segments_before_ramps(str(arm["kind"]), arm, q0,
                                                                      float(d["duration_s"]))


def test_step_only_lists_give_the_same_bits_as_before() -> None:
    arm = {"kind": "steps", "steps": [{"t_s": 0.1, "q_deg": [-20.0, -20.0, -20.0]},
                                      {"t_s": 1.3, "q_deg": [35.0, 5.0, -7.5]}, {"t_s": 1.3, "q_deg": [1.0, 2.0, 3.0]}]}
    q0 = (0.1, -0.2, 0.3)
    assert arm_segments("steps", arm, q0, 5.0) == _segments_before_ramps("steps", arm, q0, 5.0)
