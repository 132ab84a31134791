"""navig8-campaign: the same rows give the same table on the local pool and on a real Dask LocalCluster; a run
that raises or times out is recorded, not fatal; a resumed campaign runs only the missing rows; every row
replays alone through `navig8-sim` with the printed command."""

from __future__ import annotations

import copy
import json
import os
import re
import shlex
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from navig8_tools.campaign import STREAM_FILE, comparable, read_stream, run_campaign
from navig8_tools.campaign_run import RunTimeout, call_with_timeout, worker_pool
from navig8_tools.campaign_spec import Campaign, expand, replay_command
from navig8_tools.mission import plan_from_scenario
from navig8_tools.sim import main as sim_main

SMALL = {
    "name": "small", "scenario": "paper", "duration_s": 0.6, "timeout_s": 120, "seeds": [1, 2],
    "variants": {"proposed": {"controller": "proposed"}, "fixed": {"controller": "fixed"}},
    "factors": {
        "object_mass_kg": {"world": "scenario.object.mass_kg", "grid": [0.0, 3.0]},
        "noise": {"world": "sensor_noise_scale", "uniform": [0.5, 2.0]},
    },
    "report": {"heatmap": ["object_mass_kg", "noise"]},
}


def test_rows_are_the_crossed_grid_with_shared_draws_and_stable_ids() -> None:
    c = Campaign.from_dict(SMALL)
    rows = expand(c)
    assert len(rows) == 2 * 2 * 2  # variants x mass grid x seeds (one sample of the drawn factor)
    assert len({r.run_id for r in rows}) == len(rows)
    assert len({r.factors["noise"] for r in rows}) == 1  # common random numbers across variants and cells
    assert [r.run_id for r in expand(Campaign.from_dict(SMALL))] == [r.run_id for r in rows]
    assert rows[0].world == {"scenario.object.mass_kg": 0.0, "sensor_noise_scale": rows[0].factors["noise"]}


def test_a_variant_world_applies_to_its_rows_only_and_factors_win() -> None:
    d = dict(SMALL, world={"sensor_noise_scale": 1.0, "vehicle.propulsion.k_thrust_tail": 2e-4},
             variants={"weak_tail": {"controller": "proposed", "world": {"vehicle.propulsion.k_thrust_tail": 6e-5}},
                       "paper_tail": {"controller": "proposed"}})
    rows = expand(Campaign.from_dict(d))
    by = {v: [r for r in rows if r.variant == v] for v in ("weak_tail", "paper_tail")}
    assert {r.world["vehicle.propulsion.k_thrust_tail"] for r in by["weak_tail"]} == {6e-5}
    assert {r.world["vehicle.propulsion.k_thrust_tail"] for r in by["paper_tail"]} == {2e-4}
    # the drawn noise factor overrides the campaign's fixed value in both
    assert all(r.world["sensor_noise_scale"] == r.factors["noise"] != 1.0 for r in rows)
    # same world content, different variant: still different runs (the name is part of the id)
    assert len({r.run_id for r in rows}) == len(rows)
    assert "--world vehicle.propulsion.k_thrust_tail=6e-05" in replay_command(by["weak_tail"][0])
    with pytest.raises(ValueError, match="unknown keys"):
        Campaign.from_dict(dict(SMALL, variants={"v": {"controller": "proposed", "sets": {"INDI_ALLOC": 1}}}))


def test_a_variant_params_file_is_read_relative_to_the_campaign_and_set_wins(tmp_path: Path) -> None:
    (tmp_path / "p.parm").write_text("INDI_ALLOC 1\nINDI_LPF_TAU 0.03\n")
    d = dict(SMALL, variants={"v": {"controller": "proposed", "params": "p.parm", "set": {"INDI_LPF_TAU": 0.05}}})
    rows = expand(Campaign.from_dict(d, tmp_path))
    assert rows[0].params == {"INDI_ALLOC": 1.0, "INDI_LPF_TAU": 0.05}


def test_a_changed_scenario_file_changes_the_run_ids_but_a_comment_does_not(tmp_path: Path) -> None:
    # resume is by run id: a scenario edited between two runs of a campaign must fly again, not reuse old rows
    src = (Path(__file__).resolve().parents[2] / "params" / "scenarios" / "hover.yaml").read_text()
    f = tmp_path / "s.yaml"
    f.write_text(src)
    d = dict(SMALL, scenario=str(f))
    ids = [r.run_id for r in expand(Campaign.from_dict(d))]
    f.write_text("# a comment\n" + src)
    assert [r.run_id for r in expand(Campaign.from_dict(d))] == ids
    assert "duration_s: 10.0" in src
    f.write_text(src.replace("duration_s: 10.0", "duration_s: 7.0", 1))
    changed = [r.run_id for r in expand(Campaign.from_dict(d))]
    assert not set(changed) & set(ids)


def test_local_pool_and_dask_local_cluster_give_the_same_table(tmp_path: Path) -> None:
    distributed = pytest.importorskip("distributed")
    c = Campaign.from_dict(SMALL)
    pool = run_campaign(c, tmp_path / "pool", workers=2, progress=False)
    dask = run_campaign(c, tmp_path / "dask", workers=2, cluster="local", progress=False)
    assert pool.failed == dask.failed == 0 and len(pool.table) == 8
    pd.testing.assert_frame_equal(comparable(pool.table), comparable(dask.table))
    assert pool.table["worker"].nunique() >= 1 and dask.table["worker"].nunique() >= 1
    # the LocalCluster was stopped with the campaign: no client of it is left open in this process
    with pytest.raises(ValueError, match="No clients found"):
        distributed.default_client()
    # Parquet and CSV hold the same rows
    csv = pd.read_csv(tmp_path / "pool" / "results.csv")
    np.testing.assert_allclose(csv["max_att_error_deg"], pool.table["max_att_error_deg"], rtol=1e-12)
    # the report: its sections, and every figure it links exists as a PNG
    from navig8_tools.campaign_report import write_report

    md = write_report(c, pool.table, tmp_path / "pool", "navig8-campaign small.yaml").read_text()
    for section in ("## Robustness per variant", "## Success rate by factor", "## Heat maps over object_mass_kg",
                    "## Metric distributions per variant", "## Worst", "navig8-sim --scenario paper"):
        assert section in md, section
    links = re.findall(r"\(figures/([^)]+\.png)\)", md)
    assert len(links) >= 5
    for name in links:
        assert (tmp_path / "pool" / "figures" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_raising_and_a_timed_out_run_are_recorded_and_the_campaign_goes_on(tmp_path: Path) -> None:
    d = dict(SMALL, variants={"proposed": {"controller": "proposed"}}, seeds=[1])
    d["factors"] = {"arm_rate_rad_s": {"world": "plant.joint_servo.v_max_rad_s", "grid": [4.0, -1.0]}}
    d["report"] = {}
    res = run_campaign(Campaign.from_dict(d), tmp_path, workers=1, progress=False)
    t = res.table.set_index("arm_rate_rad_s")
    assert t.loc[4.0, "status"] == "ok" and bool(t.loc[4.0, "success"])
    assert t.loc[-1.0, "status"] == "error" and "joint servo limits must be > 0" in t.loc[-1.0, "error"]
    assert res.failed == 1
    # a timeout: the same row with a 0.3 s budget for a 30 s flight
    slow = dict(d, duration_s=30.0, timeout_s=0.3)
    slow["factors"] = {"arm_rate_rad_s": {"world": "plant.joint_servo.v_max_rad_s", "grid": [4.0]}}
    res = run_campaign(Campaign.from_dict(slow), tmp_path / "slow", workers=1, progress=False)
    assert res.table["status"].tolist() == ["timeout"] and "0 s" in res.table["error"][0]


def test_a_pool_worker_is_warmed_once_and_runs_one_thread() -> None:
    """worker_pool's processes start with WORKER_ENV and are warmed before their first row: the flight loop's modules
    are loaded, the objects alive then are frozen out of the garbage collector's walks, and the process runs one
    OS thread (OpenBLAS would otherwise start one per core, which spins in each worker on the core the other
    worker needs: docs/campaigns.md, "Throughput"). The parent's environment is as it was."""
    env = dict(os.environ)
    with worker_pool(1, "inprocess") as pool:
        warm = pool.submit(eval, "[m in __import__('sys').modules for m in ('navig8_tools.sim', 'mcap.reader')]")
        frozen = pool.submit(eval, "__import__('gc').get_freeze_count()")
        threads = pool.submit(eval, "len(__import__('os').listdir('/proc/self/task'))")
        assert warm.result() == [True, True]
        assert frozen.result() > 10_000
        assert threads.result() == 1
    assert dict(os.environ) == env


def test_call_with_timeout_interrupts_a_python_loop_and_leaves_a_fast_call_alone() -> None:
    t0 = time.perf_counter()
    with pytest.raises(RunTimeout):
        call_with_timeout(lambda: [i for i in iter(int, 1)], 0.2)  # an endless loop
    assert time.perf_counter() - t0 < 5.0
    assert call_with_timeout(lambda: 42, 0.2) == 42
    time.sleep(0.3)  # the cancelled timer must not fire into this thread later


def test_a_resumed_campaign_runs_only_the_missing_rows(tmp_path: Path) -> None:
    c = Campaign.from_dict(dict(SMALL, variants={"proposed": {"controller": "proposed"}}))
    first = run_campaign(c, tmp_path, workers=1, limit=2, progress=False)
    assert first.ran == 2 and len(first.table) == 2
    before = read_stream(tmp_path)
    second = run_campaign(c, tmp_path, workers=1, progress=False)
    assert second.ran == 2 and len(second.table) == 4
    lines = [json.loads(x) for x in (tmp_path / STREAM_FILE).read_text().splitlines()]
    ids = [x["run_id"] for x in lines]
    assert len(ids) == len(set(ids)) == 4  # nothing ran twice
    after = read_stream(tmp_path)
    assert all(after[k] == v for k, v in before.items())  # the first records were kept as they were
    third = run_campaign(c, tmp_path, workers=1, progress=False)
    assert third.ran == 0 and len(third.table) == 4


def test_the_printed_replay_command_reproduces_the_row(tmp_path: Path) -> None:
    c = Campaign.from_dict(dict(SMALL, variants={"fixed": {"controller": "fixed"}}, seeds=[2]))
    res = run_campaign(c, tmp_path, workers=1, limit=1, progress=False)
    row = res.table.iloc[0]
    argv = shlex.split(row["replay"])
    assert argv[0] == "navig8-sim"
    argv[argv.index("--log") + 1] = str(tmp_path / "replay.mcap")
    summary = tmp_path / "replay.json"
    assert sim_main([*argv[1:], "--summary", str(summary)]) == 0
    s = json.loads(summary.read_text())
    for k in ("max_att_error_deg", "max_pos_error_m", "min_eigenvalue", "peak_reaction_force_n"):
        assert s[k] == row[k], k  # bit for bit: the row determines the run


def test_a_sitl_campaign_with_a_plan_names_it_in_every_row_and_replay() -> None:
    d = {"name": "plan", "kind": "sitl", "scenario": "paper_plan", "speed": 1.0, "seeds": [1, 2],
         "plan": {"from_scenario": "paper"}, "variants": {"proposed": {"controller": "proposed"}}}
    rows = expand(Campaign.from_dict(d))
    assert all(r.plan == plan_from_scenario("paper") for r in rows) and len(rows) == 2
    # the replay: the plan written by navig8-mission, navig8-sitl on the row's instance, navig8-mission fly on the
    # port navig8-fc sends to before a GCS talks
    cmd = replay_command(rows[1])
    assert cmd.startswith("navig8-mission from-scenario --scenario paper out/replay_")
    assert f"--instance {rows[1].instance} " in cmd and "--speed 1 " in cmd
    assert "navig8-mission fly out/replay_" in cmd and "udpin:127.0.0.1:14550" in cmd
    # the plan is part of a row's identity; a campaign without one keeps the ids it had
    other = expand(Campaign.from_dict(dict(d, plan={"from_scenario": "hover"})))
    assert {r.run_id for r in other}.isdisjoint(r.run_id for r in rows)
    # (No id is pinned here: every id includes the scenario's content digest,
    # test_a_changed_scenario_file_changes_the_run_ids_but_a_comment_does_not, so outputs written under ids without
    # it fly again on resume instead of being reused.)
    with pytest.raises(ValueError, match="kind: sitl"):
        Campaign.from_dict(dict(d, kind="inprocess"))


_DRAWS: dict[tuple[int, int, str], tuple] = {}  # envelope.draw's results in this process (it is pure)


@pytest.fixture
def shared_draws(monkeypatch: pytest.MonkeyPatch) -> None:
    """envelope.draw drawn once a process for its arguments: ten of the shipped campaigns draw the same 100 samples
    of the same envelope (sample seed 0), each draw ~10 ms of servo simulation. draw is pure, bit for bit
    (test_envelope.py); every caller gets its own copy."""
    from navig8_tools import envelope

    real = envelope.draw

    def draw(sample_index: int, rng_seed: int, spec: envelope.EnvelopeSpec) -> tuple:
        key = (int(sample_index), int(rng_seed), repr(spec))
        if key not in _DRAWS:
            _DRAWS[key] = real(sample_index, rng_seed, spec)
        return copy.deepcopy(_DRAWS[key])

    monkeypatch.setattr(envelope, "draw", draw)


@pytest.mark.parametrize("path", sorted((Path(__file__).resolve().parents[2] / "params" / "campaigns").glob("*.yaml")),
                         ids=lambda p: p.stem)
def test_every_shipped_campaign_loads_and_expands(path: Path, shared_draws: None) -> None:
    # the shipped files name presets and world keys by path: a renamed parameter or preset breaks them here
    c = Campaign.load(path)
    rows = expand(c)
    assert rows and len({r.run_id for r in rows}) == len(rows)
    from navig8_fc.params.registry import ParamRegistry

    reg = ParamRegistry.from_defaults()
    for r in rows:
        for k, v in r.params.items():
            assert reg.set(k, v).accepted, (path.name, r.variant, k, v)
