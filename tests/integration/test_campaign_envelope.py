"""A generated campaign (`generator: envelope`): rows are controllers x draws on the same draws, ids by content,
the scenario files written, the authority columns guarded, the report's envelope sections, and a printed replay
that reproduces its row through navig8_tools.sim.run."""

from __future__ import annotations

import argparse
import math
import re
import shlex
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from navig8_fc.flight.script import read_scenario_file
from navig8_tools import campaign_run
from navig8_tools.campaign import run_campaign
from navig8_tools.campaign_report import beyond_authority, envelope_table, paired_table, write_report
from navig8_tools.campaign_spec import Campaign, expand
from navig8_tools.sim import run
from sim_bridge.world import parse_world_items

ENV = {"name": "env_small", "kind": "inprocess", "generator": "envelope", "envelope": {}, "samples": 4,
       "sample_seed": 3, "timeout_s": 120,
       "variants": {"proposed": {"controller": "proposed"}, "fixed": {"controller": "fixed"},
                    "unconstrained": {"controller": "unconstrained"}}}


def test_every_controller_flies_the_same_draws(tmp_path: Path) -> None:
    rows = expand(Campaign.from_dict(ENV), tmp_path)
    assert len(rows) == 3 * 4 and len({r.run_id for r in rows}) == len(rows)
    by_sample: dict[int, list] = {}
    for r in rows:
        by_sample.setdefault(r.sample, []).append(r)
    assert sorted(by_sample) == [0, 1, 2, 3]
    for same in by_sample.values():
        assert [r.controller for r in same] == ["proposed", "fixed", "unconstrained"]
        first = same[0]
        for r in same[1:]:  # common random numbers: scenario, world, parameters, seed and factors all equal
            assert r.scenario == first.scenario and r.scenario_doc == first.scenario_doc
            assert r.world == first.world and r.params == first.params and r.seed == first.seed
            assert str(r.factors) == str(first.factors)
        assert Path(first.scenario).parent == tmp_path / "scenarios"
        assert first.seed == first.factors["seed"] and first.duration_s is None
    # ids are content: the same in another output directory, stable across expansions, and a changed range changes
    # the draws it reaches
    again = expand(Campaign.from_dict(ENV), tmp_path / "elsewhere")
    assert [r.run_id for r in again] == [r.run_id for r in rows]
    other = expand(Campaign.from_dict(dict(ENV, envelope={"tail_max_thrust_n": [60.0, 61.0]})), tmp_path)
    assert not {r.run_id for r in other} & {r.run_id for r in rows}
    more = expand(Campaign.from_dict(dict(ENV, samples=6)), tmp_path)  # more samples: the first four unchanged
    assert {r.run_id for r in rows} < {r.run_id for r in more}


def test_a_generated_campaign_refuses_what_the_draw_decides() -> None:
    for extra in ({"factors": {"m": {"world": "scenario.object.mass_kg", "grid": [1.0]}}}, {"seeds": [1, 2]},
                  {"scenario": "paper"}, {"kind": "sitl"}):
        with pytest.raises(ValueError, match="generator"):
            Campaign.from_dict(ENV | extra)
    with pytest.raises(ValueError, match="generator must be one of"):
        Campaign.from_dict(ENV | {"generator": "other"})
    with pytest.raises(ValueError, match="unknown keys"):
        Campaign.from_dict(ENV | {"envelope": {"mass": [0, 1]}})
    with pytest.raises(ValueError, match="need generator"):
        Campaign.from_dict({"name": "x", "envelope": {}, "variants": {"proposed": {}}})
    for name in ("square_half_period_s", "sweep_leg_s", "hold_s"):  # a zero step would never end the arm's motion
        with pytest.raises(ValueError, match=f"{name}: the range must be > 0"):
            Campaign.from_dict(ENV | {"envelope": {name: [0.0, 0.0]}})


def test_the_authority_columns_come_from_bound_from_log_and_are_nan_without_it(monkeypatch) -> None:
    import navig8_tools.authority as authority

    seen = {}

    def fake_bound(run_log, vehicle_cfg):  # the helper's contract: at least these three keys
        seen["cfg"] = vehicle_cfg
        return {"bound_deg": 71.5, "trim_feasible": True, "worst_t_s": 3.25, "other": 1}

    monkeypatch.setattr(authority, "bound_from_log", fake_bound, raising=False)
    cols = campaign_run.authority_columns(object(), "hover", {"tail_max_thrust_n": 80.0})
    assert cols == {"authority_bound_deg": 71.5, "authority_trim_feasible": True, "authority_worst_t_s": 3.25,
                    "authority_error": None}
    assert seen["cfg"].k_thrust_tail * seen["cfg"].tail_speed_max**2 == pytest.approx(80.0)  # the run's true vehicle
    monkeypatch.delattr(authority, "bound_from_log")
    cols = campaign_run.authority_columns(object(), "hover", {})
    assert all(math.isnan(cols[k]) for k in campaign_run.AUTHORITY_COLUMNS)
    assert "not available" in cols["authority_error"]

    def broken(run_log, vehicle_cfg):
        raise RuntimeError("no arm motion")

    monkeypatch.setattr(authority, "bound_from_log", broken, raising=False)
    cols = campaign_run.authority_columns(object(), "hover", {})
    assert math.isnan(cols["authority_bound_deg"]) and "no arm motion" in cols["authority_error"]


def test_the_report_pairs_the_draws_and_marks_losses_beyond_authority() -> None:
    # 4 draws x 2 controllers, by hand: fixed loses draws 0 and 1, proposed draw 1; draw 1's bound is beyond 60 deg
    df = pd.DataFrame({
        "variant": ["proposed"] * 4 + ["fixed"] * 4, "sample": [0, 1, 2, 3] * 2, "status": ["ok"] * 8,
        "lost_control": [False, True, False, False, True, True, False, False],
        "max_att_error_deg": [20.0, 75.0, 10.0, 30.0, 80.0, 90.0, 10.2, 25.0],
        "att_rms_error_deg": [2.0] * 8, "bound_violations": [0] * 8, "min_eigenvalue": [0.5] * 8,
        "run_wall_s": [1.0] * 8, "authority_bound_deg": [30.0, 65.0, 5.0, 12.0] * 2,
        "authority_trim_feasible": [True] * 8})
    assert beyond_authority(df).tolist() == [False, True, False, False, False, True, False, False]
    t = envelope_table(df)
    assert "| proposed | 4 | 0 | 1 (25 %) | 1 |" in t and "| fixed | 4 | 0 | 2 (50 %) | 1 |" in t
    # proposed better on draw 0 (fixed lost), fixed better on draw 3, draw 1 both lost (75 < 90: proposed), draw 2 tie
    p = paired_table(df)
    assert "| proposed vs fixed | 4 | 2 | 1 | 1 | 1 (25 %) | 2 (50 %) | 1 |" in p
    assert "unconstrained" not in p  # a pair whose controller is not in the table is left out


def _replay_run(replay: str, log: Path) -> dict:
    """The replay command's navig8-sim arguments, flown with navig8_tools.sim.run."""
    argv = shlex.split(replay)
    assert argv[0] == "navig8-sim"
    ap = argparse.ArgumentParser()
    for opt in ("--scenario", "--controller", "--log"):
        ap.add_argument(opt)
    ap.add_argument("--seed", type=int)
    ap.add_argument("--duration", type=float)
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--world", action="append", default=[])
    a = ap.parse_args(argv[1:])
    sets = {k: float(v) for k, v in (s.split("=", 1) for s in a.set)}
    return run(a.scenario, a.controller, a.seed, a.duration, log, sets, world=parse_world_items(a.world)).summary


def test_a_tiny_envelope_campaign_writes_its_table_scenarios_and_report_and_its_replay_reproduces_a_row(
        tmp_path: Path) -> None:
    d = dict(ENV, samples=2, duration_s=1.5, authority=True, variants={"proposed": {"controller": "proposed"}})
    c = Campaign.from_dict(d)
    res = run_campaign(c, tmp_path, workers=1, progress=False)
    df = res.table
    assert res.failed == 0 and len(df) == 2 and df["status"].tolist() == ["ok", "ok"]
    for col in ("object_mass_kg", "arm_speed_rad_s", "arm_shape", "pitch_deg", "yaw_step_deg", "tail_max_thrust_n",
                "actuator_bandwidth_scale", "sensor_noise_scale", "servo_model_error", "grasp_t_s", "release_t_s",
                "authority_bound_deg", "authority_trim_feasible", "authority_worst_t_s"):
        assert col in df, col
    files = sorted((tmp_path / "scenarios").glob("*.yaml"))
    assert len(files) == 2
    for (_, r), row in zip(df.iterrows(), expand(c, tmp_path), strict=True):
        assert read_scenario_file(Path(row.scenario)) == row.scenario_doc  # the file is the document flown
        assert f"--scenario {row.scenario} " in r["replay"] and f"--seed {row.seed} " in r["replay"]
        assert "--world tail_max_thrust_n=" in r["replay"] and "--set ARM_SERVO_VMAX=" in r["replay"]
    # the authority bound: its columns are the function's when it exists, NaN (with the reason) until then
    from navig8_tools import authority

    if hasattr(authority, "bound_from_log"):
        assert np.all(np.isfinite(df["authority_bound_deg"].astype(float)))
    else:
        assert df["authority_bound_deg"].isna().all() and df["authority_error"].str.contains("not available").all()
    md = write_report(c, df, tmp_path, "navig8-campaign env_small.yaml").read_text()
    for section in ("## The envelope per controller", "## Paired on the same draws",
                    "## Max attitude error against the authority bound", "## Worst 10 runs per controller",
                    "navig8-sim --scenario "):
        assert section in md, section
    for name in re.findall(r"\(figures/([^)]+\.png)\)", md):
        assert (tmp_path / "figures" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the printed replay flies the row again: its summary, bit for bit
    row = df.iloc[1]
    s = _replay_run(row["replay"], tmp_path / "replay.mcap")
    for k in ("max_att_error_deg", "att_rms_error_deg", "max_pos_error_m", "min_eigenvalue", "peak_reaction_force_n",
              "max_joint_rate_rad_s"):
        assert s[k] == row[k], k
    # resume: nothing to run, the files rewritten identically
    before = {p.name: p.read_text() for p in files}
    again = run_campaign(c, tmp_path, workers=1, progress=False)
    assert again.ran == 0 and {p.name: p.read_text() for p in files} == before
    assert yaml.safe_load(files[0].read_text())["arm"]["kind"] == "steps"
