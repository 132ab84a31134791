"""The robustness envelope's draws (tools/envelope.py): deterministic per (seed, sample), covering the spec's
ranges, every drawn scenario loading through both parsers with its joint targets inside the limits, and grasps
and releases happening with the arm at rest at the drawn pose (checked against the plant)."""

from __future__ import annotations

import json
import math
from functools import cache

import numpy as np
import pytest

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.flight.script import parse_flight_script
from navig8_fc.params.registry import ParamRegistry
from navig8_tools.envelope import PATTERNS, SHAPES, EnvelopeSpec, draw, servo_track
from sim_bridge import Plant
from sim_bridge.scenario import Scenario
from sim_bridge.world import load_world

N = 200


@cache
def _spec() -> EnvelopeSpec:
    return EnvelopeSpec.from_dict({})


@cache
def _draws() -> tuple:
    return tuple(draw(k, 7, _spec()) for k in range(N))


def _same(a: object, b: object) -> bool:
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)  # NaN-safe: "NaN" == "NaN"


def test_a_draw_is_a_function_of_its_seed_and_sample_alone() -> None:
    spec = _spec()
    assert _same(draw(5, 7, spec), _draws()[5])  # alone, or after 200 others: the same bits
    assert _same(draw(5, 7, EnvelopeSpec.from_dict({})), draw(5, 7, spec))
    assert not _same(draw(5, 8, spec), draw(5, 7, spec))
    assert len({json.dumps(d[0], sort_keys=True) for d in _draws()}) == N  # every draw its own flight
    assert len({d[3]["seed"] for d in _draws()}) == N


def _column(name: str) -> np.ndarray:
    return np.array([d[3][name] for d in _draws()], dtype=float)


@pytest.mark.parametrize(("name", "lo", "hi"), [
    ("duration_s", 20.0, 25.0), ("object_mass_kg", 0.0, 2.5), ("arm_speed_rad_s", 0.3, 4.0),
    ("servo_model_error", 0.8, 1.25), ("pitch_deg", 0.0, 45.0), ("yaw_step_deg", -90.0, 90.0),
    ("pos_step_m", 0.0, 2.0), ("actuator_bandwidth_scale", 0.6, 1.4), ("sensor_noise_scale", 0.5, 2.0),
    ("tail_max_thrust_n", 60.0, 200.0)])
def test_the_draws_cover_their_ranges(name: str, lo: float, hi: float) -> None:
    x = _column(name)
    assert np.all(np.isfinite(x))
    assert x.min() >= lo - 1e-3 and x.max() <= hi + 1e-3, (name, x.min(), x.max())
    # 200 draws reach both ends of the range: within 10 % of the span (5 % for the log-uniform ones' log span)
    assert x.min() <= lo + 0.1 * (hi - lo) and x.max() >= hi - 0.1 * (hi - lo), (name, x.min(), x.max())


def test_the_draws_cover_the_shapes_patterns_poses_and_a_release_while_pitched() -> None:
    f = [d[3] for d in _draws()]
    assert {x["arm_shape"] for x in f} == set(SHAPES)
    assert {x["pattern"] for x in f} == set(PATTERNS)
    stretched = [x for x in f if x["grasp_pose"] == "stretched"]
    assert len(stretched) > 20 and {x["grasp_pose"] for x in f} == {"stretched", "random", "none"}
    for x in stretched:  # the arm is at the stretched pose when the gripper closes
        assert [x[f"grasp_q{j}_deg"] for j in (1, 2, 3)] == pytest.approx([80.0, 10.0, 10.0], abs=0.06)
    assert sum(x["release_pose"] == "stretched" for x in f) > 20
    pitched = [x for x in f if x["pattern"] != "grasp" and x["release_pitch_deg"] > 20.0]
    assert len(pitched) > 10
    for x in f:
        if x["pattern"] == "grasp_release":
            assert x["grasp_t_s"] < x["release_t_s"] < x["duration_s"]
        if x["pattern"] != "grasp":
            assert x["release_t_s"] <= x["duration_s"] - 2.5 + 1e-9  # flown for a while after the release
    # the FC's servo model: the default times the drawn error (a by its square), so the error over the plant's
    # servo spans the drawn plant speeds
    reg, other = ParamRegistry.from_defaults(), ParamRegistry.from_defaults()
    for d in _draws()[:20]:
        e = d[3]["servo_model_error"]
        assert d[2]["ARM_SERVO_VMAX"] == pytest.approx(reg["ARM_SERVO_VMAX"] * e, rel=1e-4)
        assert d[2]["ARM_SERVO_AMAX"] == pytest.approx(reg["ARM_SERVO_AMAX"] * e * e, rel=1e-4)
        assert all(other.set(k, v).accepted for k, v in d[2].items())
    ratio = _column("servo_model_ratio")
    assert ratio.min() < 1.0 < ratio.max() and ratio.max() > 5.0


def test_every_draw_loads_through_both_parsers_within_the_joint_limits() -> None:
    lim = VehicleConfig.load().joint_limit_rad
    for scen, _world, _params, f in _draws():
        script = parse_flight_script(scen)
        s = Scenario.from_dict(scen)
        assert s.script == script and s.armed and s.initial.actuators == "trim"
        assert s.duration_s == f["duration_s"]
        for seg in s.arm_segments:
            assert max(abs(x) for x in (*seg.q_start_rad, *seg.q_end_rad)) <= lim
        for t in np.linspace(0.0, s.duration_s, 50):
            assert np.all(np.abs(s.arm_targets(float(t))) <= lim)
        assert abs(math.degrees(max(abs(sp.pitch_rad) for sp in (script.setpoint_at(t) for t in
                                                                    np.linspace(0, s.duration_s, 200))))) <= 45.0
        if f["pattern"] == "release":
            assert s.object_mass(0.0) == f["object_mass_kg"] and s.object_mass(s.duration_s) == 0.0
        elif f["pattern"] == "grasp":
            assert s.object_mass(0.0) == 0.0 and s.object_mass(s.duration_s) == f["object_mass_kg"]


def test_the_draws_worlds_load_and_set_what_they_name() -> None:
    for _scen, world, _params, f in _draws()[:12]:
        w = load_world("hover", world)  # any scenario: the world is the plant's and the vehicle's side
        assert w.plant.joint_v_max_rad_s == pytest.approx(f["arm_speed_rad_s"], rel=1e-3)
        assert w.plant.joint_a_max_rad_s2 == pytest.approx(f["arm_accel_rad_s2"], rel=1e-3)
        assert w.vehicle.k_thrust_tail * w.vehicle.tail_speed_max**2 == pytest.approx(f["tail_max_thrust_n"])
        assert w.fc_vehicle == w.vehicle


def test_a_grasp_and_a_release_find_the_plants_arm_at_the_drawn_pose() -> None:
    """The generator's servo track is the plant's: the truth's joints at the event time are the drawn pose."""
    cfg = VehicleConfig.load()
    picks = [d for d in _draws() if d[3]["pattern"] == "grasp_release" and d[3]["release_pose"] != "in_place"]
    slow = min(picks, key=lambda d: d[3]["arm_speed_rad_s"])
    for scen, world, _params, f in (slow, picks[0]):
        w = load_world("hover", world)
        plant = Plant(cfg, w.plant, Scenario.from_dict(scen), np.random.default_rng(0), base_mode="fixed")
        cmd = plant.trim_command()
        for name in ("grasp", "release"):
            t_us = round(f[f"{name}_t_s"] * 1e6)
            plant.step_us(cmd, t_us - plant.truth().time_us)
            tr = plant.truth()
            np.testing.assert_allclose(np.degrees(tr.joint_pos_rad), [f[f"{name}_q{j}_deg"] for j in (1, 2, 3)],
                                       atol=0.011)  # the columns' 0.01 deg rounding
            assert np.all(np.abs(tr.joint_rate_rad_s) < 1e-6)  # at rest there
            assert tr.gripper_closed == (name == "grasp")


def test_servo_track_follows_a_ramp_and_the_rate_limit() -> None:
    tr = servo_track([{"t_s": 1.0, "q_deg": [60.0, 0.0, -30.0], "ramp_s": 0.001}], 8.0, 0.3, 0.3**2 / 16 * 42)
    q1 = tr[:, 1]
    rate = np.diff(q1) / np.diff(tr[:, 0])
    assert rate.max() <= 0.3 + 1e-9 and rate.max() > 0.29  # the servo's rate limit, reached
    assert q1[-1] == pytest.approx(math.radians(60.0), abs=1e-9) and tr[-1, 3] == pytest.approx(math.radians(-30.0))


def test_the_spec_refuses_unknown_keys_and_bad_ranges_and_takes_overrides() -> None:
    with pytest.raises(ValueError, match="unknown keys"):
        EnvelopeSpec.from_dict({"object_mass": [0, 1]})
    with pytest.raises(ValueError, match="lo <= hi"):
        EnvelopeSpec.from_dict({"pitch_deg": [45, 0]})
    with pytest.raises(ValueError, match="subset"):
        EnvelopeSpec.from_dict({"shapes": ["zigzag"]})
    with pytest.raises(ValueError, match="joint limits"):
        EnvelopeSpec.from_dict({"stretched_pose_deg": [120, 10, 10]})
    spec = EnvelopeSpec.from_dict({"object_mass_kg": [1.0, 1.0], "shapes": ["sweep"], "patterns": ["release"]})
    f = draw(3, 0, spec)[3]
    assert f["object_mass_kg"] == 1.0 and f["arm_shape"] == "sweep" and f["pattern"] == "release"
