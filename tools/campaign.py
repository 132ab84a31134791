"""navig8-campaign: Monte-Carlo and test campaigns, the world varied, on a process pool or a Dask cluster.

    navig8-campaign CAMPAIGN.yaml [--out DIR] [--workers N] [--cluster local|ADDRESS] [--retry-failed]
                    [--limit N] [--no-progress] [--no-report]

A campaign file (docs/campaigns.md; params/campaigns/) names a base scenario, the controller variants and the
factors to vary (grids crossed, distributions drawn); every row is one run, fully determined by the row
(variant, factor values, seed) and reproducible alone with the `navig8-sim` / `navig8-sitl` command in its
`replay` column. Runs go to a local process pool (default, one worker per core) or, with --cluster, to Dask
distributed (`--cluster local` starts a LocalCluster for the campaign; `--cluster tcp://host:8786` uses a
running scheduler). Results stream to DIR/runs.jsonl as runs finish; a run that raises or times out is recorded
with its error and the campaign goes on; running again with the same DIR skips the rows already recorded.
At the end: DIR/results.parquet + results.csv (every factor and summary metric per run) and DIR/report.md
with PNG figures (tools/campaign_report.py).
"""

from __future__ import annotations

import argparse
import ctypes
import dataclasses
import gc
import hashlib
import io
import itertools
import json
import math
import os
import shlex
import signal
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from navig8_fc.params.store import read_parm_file

KINDS = ("inprocess", "sitl")
GENERATORS = ("envelope",)  # campaign `generator:` values: rows whose scenarios are drawn (tools/envelope.py)
SCENARIO_DIR = "scenarios"  # DIR/scenarios/: the generated scenarios, one file per draw (the replays read them)
DISTRIBUTIONS = ("grid", "value", "uniform", "normal", "loguniform", "choice")
TABLE_FILE = "results.parquet"
STREAM_FILE = "runs.jsonl"
# Scalar summary keys of navig8_tools.summary.summarize kept per run (settle is folded to two counts).
METRICS = ("sim_time_s", "wall_time_s", "real_time_factor", "lost_control", "lost_control_t_s", "min_eigenvalue",
           "max_eigenvalue", "bound_violations", "max_pos_error_m", "pos_rms_error_m", "max_att_error_deg",
           "att_rms_error_deg", "peak_reaction_force_n", "peak_reaction_torque_nm", "max_joint_rate_rad_s",
           "max_joint_accel_rad_s2", "steps_settled", "steps_total")
# Columns of a sitl run that flies a plan (from navig8-mission's fly(): items, items reached, complete, path length)
MISSION_METRICS = ("mission_items", "mission_reached", "mission_complete", "mission_path_m")
# Columns that depend on where and when a run ran, not on its row (left out when comparing two tables).
RUN_ENV_COLUMNS = ("wall_time_s", "real_time_factor", "run_wall_s", "run_cpu_s", "worker")
# Thread counts of a worker process: the ones Dask's nanny gives its workers (distributed.nanny.pre-spawn-environ).
# A run's linear algebra is on matrices of 3x3 to 12x12, where OpenBLAS's second thread only spins: in one process
# it burns the idle core (+30 % CPU per run, docs/results.md), in a pool of one process per core it takes the
# other worker's core.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
# Dask configuration of the LocalCluster's workers (docs/campaigns.md: the same for a cluster's workers).
DASK_WORKER_CONFIG = {"distributed.worker.profile.enabled": False,
                      "distributed.admin.system-monitor.gil.enabled": False}


# ---------------------------------------------------------------------------------------------
# The campaign file and its rows
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Factor:
    name: str  # the table's column
    target: str  # "world" (sim_bridge.world name) or "set" (flight-controller parameter)
    key: str  # the world override name (NAME or NAME*) or the parameter name
    dist: str  # one of DISTRIBUTIONS
    args: tuple[float, ...]

    @property
    def random(self) -> bool:
        return self.dist in ("uniform", "normal", "loguniform", "choice")

    def draw(self, rng: np.random.Generator) -> float:
        if self.dist == "uniform":
            return float(rng.uniform(self.args[0], self.args[1]))
        if self.dist == "normal":
            return float(rng.normal(self.args[0], self.args[1]))
        if self.dist == "loguniform":
            return float(np.exp(rng.uniform(np.log(self.args[0]), np.log(self.args[1]))))
        return float(self.args[int(rng.integers(len(self.args)))])  # choice


@dataclass(frozen=True)
class Variant:
    name: str
    controller: str  # navig8_tools.sim.CONTROLLERS
    params: tuple[tuple[str, float], ...] = ()  # FC parameters (params/fc_params.yaml), e.g. an allocation option
    world: tuple[tuple[str, float], ...] = ()  # world overrides of this variant's runs (over the campaign's world:)


@dataclass(frozen=True)
class Campaign:
    name: str
    description: str
    kind: str
    scenario: str  # name (params/scenarios) or path
    duration_s: float | None
    timeout_s: float
    variants: tuple[Variant, ...]
    factors: tuple[Factor, ...]
    seeds: tuple[int, ...]
    samples: int  # draws of the random factors, each crossed with every grid cell, variant and seed
    sample_seed: int
    heatmap: tuple[str, str] | None  # two factor names for the report's heat maps
    world: tuple[tuple[str, float], ...] = ()  # fixed world overrides of every run
    plan: tuple[Any, ...] = ()  # sitl: mission items (navig8_fc.mission.plan.MissionItem) every run uploads and flies
    plan_source: str = ""  # where the plan came from: a file path, or "from-scenario:NAME"
    speed: float = 0.0  # sitl: navig8-sitl --speed (0: as fast as possible)
    # `generator: envelope`: each sample is a generated scenario (tools/envelope.py, its ranges in `envelope:`)
    generator: str = ""
    envelope: Any = None  # navig8_tools.envelope.EnvelopeSpec with generator: envelope
    authority: bool = False  # per run, navig8_tools.authority.bound_from_log on its log (inprocess kind)

    @staticmethod
    def from_dict(d: Mapping[str, Any], base_dir: Path | None = None) -> Campaign:
        kind = str(d.get("kind", "inprocess"))
        if kind not in KINDS:
            raise ValueError(f"campaign kind must be one of {KINDS}, got {kind!r}")
        from navig8_tools.sim import CONTROLLERS

        variants = []
        for vname, v in (d.get("variants") or {}).items():
            ctrl = str((v or {}).get("controller", vname))
            if ctrl not in CONTROLLERS:
                raise ValueError(f"variant {vname!r}: controller must be one of {sorted(CONTROLLERS)}, got {ctrl!r}")
            unknown = set(v or {}) - {"controller", "params", "set", "world"}
            if unknown:
                raise ValueError(f"variant {vname!r}: unknown keys {sorted(unknown)} (controller, params, set, world)")
            preset: dict[str, float] = {}
            if (v or {}).get("params"):  # a parameter set file (.parm), relative to the campaign file; set: wins
                pf = Path(str(v["params"]))
                preset = read_parm_file(pf if pf.is_absolute() or base_dir is None else base_dir / pf)
            params = tuple((str(k), float(x)) for k, x in (preset | dict((v or {}).get("set") or {})).items())
            vworld = tuple((str(k), float(x)) for k, x in ((v or {}).get("world") or {}).items())
            variants.append(Variant(str(vname), ctrl, params, vworld))
        if not variants:
            raise ValueError("a campaign needs at least one variant")
        factors = []
        for fname, f in (d.get("factors") or {}).items():
            targets = [t for t in ("world", "set") if t in f]
            dists = [k for k in DISTRIBUTIONS if k in f]
            if len(targets) != 1 or len(dists) != 1:
                raise ValueError(f"factor {fname!r} needs exactly one of world:/set: and one of {DISTRIBUTIONS}")
            raw = f[dists[0]]
            args = tuple(float(x) for x in (raw if isinstance(raw, list) else [raw]))
            if dists[0] in ("uniform", "normal", "loguniform") and len(args) != 2:
                raise ValueError(f"factor {fname!r}: {dists[0]} takes [a, b]")
            if not args:
                raise ValueError(f"factor {fname!r}: empty {dists[0]}")
            factors.append(Factor(str(fname), targets[0], str(f[targets[0]]), dists[0], args))
        names = [f.name for f in factors]
        hm = d.get("report", {}).get("heatmap")
        if hm is not None and (len(hm) != 2 or any(h not in names for h in hm)):
            raise ValueError(f"report.heatmap must name two factors of {names}")
        scenario = str(d.get("scenario", "paper"))
        if base_dir is not None and (scenario.endswith((".yaml", ".yml"))) and not Path(scenario).is_absolute():
            scenario = str((base_dir / scenario).resolve())
        seeds = d.get("seeds", [1])
        seeds = list(range(1, int(seeds) + 1)) if isinstance(seeds, int) else [int(s) for s in seeds]
        plan, plan_source = _load_plan(d.get("plan"), base_dir)
        if plan and kind != "sitl":
            raise ValueError("a plan is flown over MAVLink: it needs kind: sitl")
        generator, envelope = str(d.get("generator") or ""), None
        if generator:
            if generator not in GENERATORS:
                raise ValueError(f"generator must be one of {GENERATORS}, got {generator!r}")
            clash = sorted({"factors", "seeds", "scenario", "plan"} & {k for k, v in d.items() if v})
            if kind != "inprocess" or clash:
                raise ValueError(f"generator: {generator} makes each row's scenario, factors and seed; it needs kind: "
                                 f"inprocess and no {clash or 'other kind'}")
            from navig8_tools.envelope import EnvelopeSpec

            envelope = EnvelopeSpec.from_dict(d.get(generator) or {})
            scenario, seeds = f"generated:{generator}", [0]
        elif d.get("envelope") is not None:
            raise ValueError("envelope: ranges need generator: envelope")
        authority = bool(d.get("authority", False))
        if authority and kind != "inprocess":
            raise ValueError("authority: true reads the run's log in the worker: it needs kind: inprocess")
        return Campaign(
            name=str(d.get("name", "campaign")), description=str(d.get("description", "")), kind=kind,
            scenario=scenario, duration_s=None if d.get("duration_s") is None else float(d["duration_s"]),
            timeout_s=float(d.get("timeout_s", 300.0)), variants=tuple(variants), factors=tuple(factors),
            seeds=tuple(seeds), samples=int(d.get("samples", 1)), sample_seed=int(d.get("sample_seed", 0)),
            heatmap=tuple(hm) if hm else None,
            world=tuple((str(k), float(v)) for k, v in (d.get("world") or {}).items()), plan=plan,
            plan_source=plan_source, speed=float(d.get("speed", 0.0)), generator=generator, envelope=envelope,
            authority=authority)

    @staticmethod
    def load(path: str | Path) -> Campaign:
        p = Path(path)
        return Campaign.from_dict(yaml.safe_load(p.read_text()), p.parent)


def _load_plan(spec: Any, base_dir: Path | None) -> tuple[tuple[Any, ...], str]:
    """The campaign's `plan:`: a plan file (QGroundControl .plan or waypoint text; relative to the campaign file)
    or {from_scenario: NAME} (navig8-mission from-scenario: a scenario's script and arm schedule as a plan)."""
    if spec is None:
        return (), ""
    from navig8_tools.mission import plan_from_scenario, read_plan

    if isinstance(spec, Mapping):
        if set(spec) != {"from_scenario"}:
            raise ValueError(f"plan: a file name or {{from_scenario: NAME}}, got {dict(spec)!r}")
        name = str(spec["from_scenario"])
        return plan_from_scenario(name), f"from-scenario:{name}"
    path = Path(str(spec))
    if base_dir is not None and not path.is_absolute():
        path = (base_dir / path).resolve()
    items = read_plan(path).mission
    if not items:
        raise ValueError(f"plan {path}: no mission items")
    return items, str(path)


@dataclass(frozen=True)
class Row:
    """One run, everything it depends on; `run_id` is a hash of exactly that, so resuming is by content."""

    index: int
    run_id: str
    kind: str
    scenario: str
    duration_s: float | None
    variant: str
    controller: str
    seed: int
    sample: int
    factors: dict[str, float]
    world: dict[str, float]
    params: dict[str, float]
    timeout_s: float
    instance: int = field(default=0)  # SITL only: ports 4560 + 2N... (navig8-sitl --instance)
    plan: tuple[Any, ...] = ()  # SITL only: the mission items uploaded and flown (Campaign.plan)
    plan_source: str = ""
    speed: float = 0.0  # SITL only: navig8-sitl --speed
    # a generated scenario's document: the worker flies it (no shared file system needed); `scenario` is the file
    # run_campaign writes it to, which the replay command reads
    scenario_doc: Mapping[str, Any] | None = None
    authority: bool = False  # also compute navig8_tools.authority.bound_from_log on the run's log


def _run_id(variant: str, content: Mapping[str, Any]) -> str:
    h = hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()[:12]
    return f"{variant}-{h}"


def _scenario_digest(scenario: str) -> str | None:
    """A digest of the scenario's content (its parsed YAML, so comments do not count): a run id names the
    scenario's content, not just its name, and resuming after the file changed flies the changed rows again.
    None when the file cannot be read (its rows then fail with the reason when they run)."""
    from navig8_fc.flight.script import read_scenario_file

    try:
        doc = read_scenario_file(scenario)
    except (OSError, ValueError, yaml.YAMLError):
        return None
    return _doc_digest(doc)


def _doc_digest(doc: Any) -> str:
    """The digest of a parsed scenario document (the same for a generated document and the file written from it:
    YAML keeps every float's bits)."""
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:16]


def default_out_dir(c: Campaign) -> Path:
    return Path("out/campaigns") / c.name


def expand(c: Campaign, out_dir: str | Path | None = None) -> list[Row]:
    """The campaign's rows in a fixed order: variant x grid cells x samples x seeds. The random factors are
    drawn once per sample (Generator(sample_seed)), so every variant meets the same worlds. A generated campaign:
    variant x samples, each sample's scenario drawn once (_expand_generated); `out_dir` (default
    out/campaigns/<name>) is where its scenario files go, which the rows' replay commands name."""
    if c.generator:
        return _expand_generated(c, Path(out_dir) if out_dir is not None else default_out_dir(c))
    grid = [f for f in c.factors if not f.random]
    rand = [f for f in c.factors if f.random]
    scen_sha = _scenario_digest(c.scenario)
    rng = np.random.default_rng(c.sample_seed)
    draws = [{f.name: f.draw(rng) for f in rand} for _ in range(c.samples if rand else 1)]
    rows: list[Row] = []
    cells = list(itertools.product(*[f.args for f in grid]))
    for v in c.variants:
        for cell in cells:
            for s, draw in enumerate(draws):
                for seed in c.seeds:
                    values = {f.name: float(x) for f, x in zip(grid, cell, strict=True)} | draw
                    world = dict(c.world) | dict(v.world)
                    params = dict(v.params)
                    for f in c.factors:
                        (world if f.target == "world" else params)[f.key] = values[f.name]
                    content = {"kind": c.kind, "scenario": c.scenario, "duration_s": c.duration_s,
                               "controller": v.controller, "seed": seed, "world": world, "params": params,
                               "scenario_sha": scen_sha}
                    if c.plan:  # only then: the ids of campaigns without a plan stay what they were
                        content |= {"plan": [dataclasses.astuple(it) for it in c.plan], "speed": c.speed}
                    elif c.speed:
                        content["speed"] = c.speed
                    rows.append(Row(len(rows), _run_id(v.name, content), c.kind, c.scenario, c.duration_s, v.name,
                                    v.controller, seed, s, values, world, params, c.timeout_s,
                                    instance=1 + len(rows) % 500, plan=c.plan, plan_source=c.plan_source,
                                    speed=c.speed))
    return rows


@dataclass(frozen=True)
class GeneratedDraw:
    """One sample of a generated campaign: its scenario document and file name, world, FC parameters, factors."""

    sample: int
    file_name: str
    scenario: dict[str, Any]
    world: dict[str, float]
    params: dict[str, float]
    factors: dict[str, Any]


def generated_draws(c: Campaign) -> list[GeneratedDraw]:
    """The campaign's draws (tools/envelope.py draw(sample, sample_seed, spec)); each draw's file is named by its
    sample and a digest of its content, so an edited spec never overwrites a file an older row's replay names."""
    from navig8_tools.envelope import draw

    out = []
    for s in range(c.samples):
        scen, world, params, factors = draw(s, c.sample_seed, c.envelope)
        name = f"{c.name}_{s:04d}_{_doc_digest(scen)[:8]}.yaml"
        out.append(GeneratedDraw(s, name, scen, world, params, factors))
    return out


def _expand_generated(c: Campaign, out_dir: Path) -> list[Row]:
    """Rows of a generated campaign: variant x samples, every variant on the same draws (common random numbers:
    the same scenario, world, FC parameters and seed); campaign and variant world/params apply under the draw's."""
    draws = generated_draws(c)
    rows: list[Row] = []
    for v in c.variants:
        # the authority bound depends on the draw only (the arm's motion is the plant's servo on the drawn plan, the
        # object and the commanded pitch are the draw's), so it is computed on the first variant's runs and shared
        # by every variant's row of the same sample (build_table): a third of the cost for three controllers
        authority = c.authority and v is c.variants[0]
        for g in draws:
            world = dict(c.world) | dict(v.world) | g.world
            params = dict(v.params) | g.params
            seed = int(g.factors["seed"])
            content = {"kind": c.kind, "generator": c.generator, "duration_s": c.duration_s,
                       "controller": v.controller, "seed": seed, "world": world, "params": params,
                       "scenario_sha": _doc_digest(g.scenario)}
            if authority:
                content["authority"] = True
            rows.append(Row(len(rows), _run_id(v.name, content), c.kind, str(out_dir / SCENARIO_DIR / g.file_name),
                            c.duration_s, v.name, v.controller, seed, g.sample, dict(g.factors), world, params,
                            c.timeout_s, scenario_doc=g.scenario, authority=authority))
    return rows


def write_scenario_files(rows: list[Row]) -> list[Path]:
    """Each generated row's scenario document to its file (once per draw; the same content for every variant)."""
    written: dict[str, Path] = {}
    for r in rows:
        if r.scenario_doc is None or r.scenario in written:
            continue
        p = Path(r.scenario)
        p.parent.mkdir(parents=True, exist_ok=True)
        head = (f"# A generated scenario (navig8-campaign, tools/envelope.py), sample {r.sample}: fly it with the "
                f"row's replay command.\n")
        p.write_text(head + yaml.safe_dump(dict(r.scenario_doc), sort_keys=False, default_flow_style=None,
                                           width=120))
        written[r.scenario] = p
    return list(written.values())


def _set_and_duration_args(row: Row) -> tuple[list[str], list[str]]:
    sets = [a for k, v in row.params.items() for a in ("--set", f"{k}={v!r}")]
    return sets, (["--duration", f"{row.duration_s!r}"] if row.duration_s is not None else [])


def replay_command(row: Row) -> str:
    """The command that flies this row alone (sitl with a plan: navig8-sitl, and navig8-mission as the GCS)."""
    from sim_bridge.world import world_args

    if row.kind == "inprocess":
        sets, dur = _set_and_duration_args(row)
        return shlex.join(["navig8-sim", "--scenario", row.scenario, "--controller", row.controller, "--seed",
                           str(row.seed), *dur, *sets, *world_args(row.world), "--log",
                           f"out/replay_{row.run_id}.mcap"])
    sitl = shlex.join(_sitl_argv(row, Path(f"out/replay_{row.run_id}")))
    if not row.plan:
        return sitl
    # navig8-fc sends to udp 14550 until a GCS talks: navig8-mission listens there, as QGroundControl would
    plan, prep = row.plan_source, ""
    if plan.startswith("from-scenario:"):
        plan = f"out/replay_{row.run_id}.waypoints"
        prep = shlex.join(["navig8-mission", "from-scenario", "--scenario", row.plan_source.split(":", 1)[1],
                           plan]) + " && "
    fly = shlex.join(["navig8-mission", "fly", plan, "--connect", "udpin:127.0.0.1:14550", "--timeout",
                      f"{row.timeout_s:g}"])
    return f"{prep}{{ {sitl} & {fly}; wait; }}"


def _sitl_argv(row: Row, out: Path) -> list[str]:
    """navig8-sitl's command line for a row, its log, state and summary in `out`."""
    from navig8_tools.sim import CONTROLLERS
    from sim_bridge.world import world_args

    sets, dur = _set_and_duration_args(row)
    return ["navig8-sitl", "--scenario", row.scenario, "--speed", f"{row.speed:g}", "--until-done", "--seed",
            str(row.seed), *dur, "--instance", str(row.instance), "--log-dir", str(out), "--state-dir", str(out),
            "--set", f"CKF_MODE={CONTROLLERS[row.controller]}", *sets,
            *world_args(row.world), "--summary", str(out / "summary.json")]


# ---------------------------------------------------------------------------------------------
# One run (executes in a worker: a pool process or a Dask worker)
# ---------------------------------------------------------------------------------------------


class RunTimeout(Exception):
    pass


def call_with_timeout(fn: Callable[[], Any], timeout_s: float) -> Any:
    """fn() in this thread, interrupted with RunTimeout after timeout_s of wall time. The exception is raised
    asynchronously in this thread (PyThreadState_SetAsyncExc) at its next Python bytecode, so it works in a pool
    process's main thread and in a Dask worker's thread alike; a run spends its time in a Python loop calling
    short numba kernels, so it is interrupted within a tick."""
    tid = threading.get_ident()
    lock = threading.Lock()
    state = {"done": False, "fired": False}

    def _fire() -> None:
        with lock:
            if not state["done"]:
                state["fired"] = True
                ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(tid), ctypes.py_object(RunTimeout))

    timer = threading.Timer(timeout_s, _fire)
    timer.daemon = True
    timer.start()
    try:
        out = fn()
        with lock:
            state["done"] = True
        return out
    finally:
        timer.cancel()
        with lock:
            state["done"] = True


def _flatten_summary(s: Mapping[str, Any]) -> dict[str, Any]:
    out = {k: s.get(k) for k in (*METRICS, *MISSION_METRICS, *AUTHORITY_COLUMNS, "authority_error") if k in s}
    settle = s.get("settle") or []
    out["steps_settled"] = sum(1 for x in settle if x.get("settle_s") is not None)
    out["steps_total"] = len(settle)
    return out


AUTHORITY_COLUMNS = ("authority_bound_deg", "authority_trim_feasible", "authority_worst_t_s")


def _inprocess(row: Row, tmp: Path) -> dict[str, Any]:
    from navig8_tools.sim import run

    scenario = row.scenario
    if row.scenario_doc is not None:  # the worker's own copy: a Dask worker elsewhere need not see DIR
        scenario = str(tmp / "scenario.yaml")
        Path(scenario).write_text(yaml.safe_dump(dict(row.scenario_doc), sort_keys=False))
    res = run(scenario, row.controller, row.seed, row.duration_s, tmp / "run.mcap", dict(row.params),
              world=dict(row.world))
    summary = dict(res.summary)
    if row.authority:
        summary |= _authority_columns(res.run_log, scenario, row.world)
    return summary


def _authority_columns(run_log: Any, scenario: str, world: Mapping[str, float]) -> dict[str, Any]:
    """navig8_tools.authority.bound_from_log(run_log, vehicle) on this run's log and true vehicle, as columns:
    the smallest peak pitch excursion any controller could reach on the logged arm motion (deg), whether the
    trim is feasible, when the bound's worst moment falls. NaN (and `authority_error` saying why) while that
    function is not there, or when it fails: the run's own metrics are kept either way."""
    nan = {k: math.nan for k in AUTHORITY_COLUMNS}
    try:
        from navig8_tools.authority import bound_from_log
    except ImportError as exc:
        return nan | {"authority_error": f"navig8_tools.authority.bound_from_log is not available ({exc})"}
    from sim_bridge.world import load_world

    try:
        b = bound_from_log(run_log, load_world(scenario, dict(world)).vehicle)
        return {"authority_bound_deg": float(b["bound_deg"]), "authority_trim_feasible": bool(b["trim_feasible"]),
                "authority_worst_t_s": float(b["worst_t_s"]), "authority_error": None}
    except Exception as exc:  # noqa: BLE001 - a failed bound is a missing column, not a failed run
        return nan | {"authority_error": f"{type(exc).__name__}: {exc}"}


class _RunEnded(Exception):
    pass


class _GcsUntil:
    """The GCS connection as navig8-mission's fly() uses it, whose recv_match raises _RunEnded once `stop` is set:
    fly() waits for the plan's end, and the run may end first (the scenario's duration)."""

    def __init__(self, conn: Any, stop: threading.Event) -> None:
        self._conn, self._stop = conn, stop

    def __getattr__(self, name: str) -> Any:
        return getattr(self._conn, name)

    def recv_match(self, *args: Any, **kwargs: Any) -> Any:
        if self._stop.is_set():
            raise _RunEnded
        return self._conn.recv_match(*args, **kwargs)


def _fly_plan(gcs: Any, row: Row, proc: subprocess.Popen, deadline: float) -> dict[str, Any]:
    """Be this run's ground station: wait for navig8-fc's HEARTBEAT, then navig8-mission's fly() (upload the plan,
    Mission, arm, follow the progress) until the plan completes or navig8-sitl ends. The mission's columns."""
    from navig8_tools.mission import fly

    hb = None
    while hb is None:
        if proc.poll() is not None:
            raise RuntimeError(f"navig8-sitl exited ({proc.returncode}) before navig8-fc's first HEARTBEAT")
        if time.monotonic() > deadline:
            raise RunTimeout(f"no HEARTBEAT from navig8-fc within {row.timeout_s:.0f} s")
        m = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
        hb = m if m is not None and m.get_srcComponent() == 1 else None
    gcs.target_system, gcs.target_component = hb.get_srcSystem(), 1
    stop = threading.Event()
    out: dict[str, Any] = {}
    log = io.StringIO()

    def _fly() -> None:
        try:
            out["summary"] = fly(_GcsUntil(gcs, stop), row.plan, timeout_s=max(0.0, deadline - time.monotonic()),
                                 out=log)
        except _RunEnded:
            pass
        except Exception as exc:  # noqa: BLE001 - re-raised in the worker's thread below
            out["error"] = exc

    th = threading.Thread(target=_fly, name="navig8-campaign-gcs", daemon=True)
    th.start()
    while th.is_alive() and proc.poll() is None:
        th.join(0.1)
    stop.set()  # navig8-sitl has ended: fly() stops at its next receive (within 0.5 s)
    th.join()
    if "error" in out:
        raise RuntimeError(f"flying the plan: {out['error']} | {' | '.join(log.getvalue().splitlines()[-2:])}")
    s = out.get("summary")
    if s is None:  # the run ended before the plan did
        return {"mission_items": len(row.plan), "mission_reached": None, "mission_complete": False,
                "mission_path_m": None}
    return {"mission_items": s["items"], "mission_reached": len(s["reached"]), "mission_complete": s["complete"],
            "mission_path_m": s["path_m"]}


def _sitl(row: Row, tmp: Path) -> dict[str, Any]:
    """navig8-sitl on the row's own --instance (two processes over MAVLink/UDP: the command of replay_command,
    with this run's directories). With a plan, this worker is the run's ground station (_fly_plan), on a UDP port
    of its own that navig8-fc is told to send to."""
    # navig8-fc reads params/vehicle.yaml and the scenario's setpoint script itself; only the plant's side of the
    # world travels (--bridge-arg=--world)
    # navig8-sitl --world gives the FC the world's vehicle (vehicle.*, fc_vehicle.*, tail_max_thrust_n); the FC's
    # flight script it reads from the scenario file itself, so overrides of the script cannot reach it
    fc_only = [k for k in row.world if k.startswith(("scenario.setpoints", "scenario.duration_s", "scenario.armed"))]
    if fc_only:
        raise ValueError(f"the sitl kind cannot apply {fc_only} (navig8-fc's side of the world); use inprocess")
    argv = _sitl_argv(row, tmp)
    gcs = None
    if row.plan:
        from pymavlink import mavutil

        gcs = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255, source_component=190,
                                         dialect="common")
        argv.append(f"--fc-arg=--gcs-port={gcs.port.getsockname()[1]}")
    deadline = time.monotonic() + row.timeout_s
    mission: dict[str, Any] = {}
    # stderr to a file, not a pipe: nobody reads a pipe while the plan is flown, and a full one would block the FC
    with open(tmp / "navig8-sitl.stderr", "wb") as err:
        proc = subprocess.Popen([sys.executable, "-m", "navig8_fc.shell.sitl", *argv[1:]], stdin=subprocess.DEVNULL,
                                stdout=subprocess.DEVNULL, stderr=err, start_new_session=True)
        try:
            if gcs is not None:
                mission = _fly_plan(gcs, row, proc, deadline)
            proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            _stop_group(proc)
            raise RunTimeout(f"navig8-sitl did not finish within {row.timeout_s:.0f} s") from None
        except BaseException:
            _stop_group(proc)
            raise
        finally:
            if gcs is not None:
                gcs.close()
    if not (tmp / "summary.json").exists():  # exit 1 with a summary: it lost control, which is a result
        tail = (tmp / "navig8-sitl.stderr").read_text(errors="replace").strip().splitlines()[-3:]
        raise RuntimeError(f"navig8-sitl exited with {proc.returncode}: {' | '.join(tail)}")
    return json.loads((tmp / "summary.json").read_text()) | mission


def _stop_group(proc: subprocess.Popen) -> None:
    """Stop navig8-sitl's process group: SIGINT (it stops both children), then SIGKILL."""
    if proc.poll() is not None:
        return
    os.killpg(proc.pid, signal.SIGINT)
    try:
        proc.wait(timeout=15.0)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


RUNNERS: dict[str, Callable[[Row, Path], dict[str, Any]]] = {"inprocess": _inprocess, "sitl": _sitl}


def execute_row(row: Row) -> dict[str, Any]:
    """Fly one row; never raises: the record says ok / error / timeout (with the error) and the metrics, and the
    run's wall and CPU time in its worker (`run_cpu_s`: the whole worker process, its other threads included)."""
    rec: dict[str, Any] = {"run_id": row.run_id, "status": "ok", "error": None,
                           "worker": f"{os.uname().nodename}:{os.getpid()}"}
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    try:
        with tempfile.TemporaryDirectory(prefix="navig8_campaign_") as tmp:
            if row.kind == "sitl":  # the subprocess has its own timeout and is killed by it
                summary = RUNNERS[row.kind](row, Path(tmp))
            else:
                summary = call_with_timeout(lambda: RUNNERS[row.kind](row, Path(tmp)), row.timeout_s)
        rec.update(_flatten_summary(summary))
    except RunTimeout as exc:
        rec.update(status="timeout", error=str(exc) or f"no result within {row.timeout_s:.0f} s")
    except Exception as exc:  # noqa: BLE001 - a run's failure is data, recorded with its traceback's last line
        tb = traceback.extract_tb(exc.__traceback__)
        where = f" ({Path(tb[-1].filename).name}:{tb[-1].lineno})" if tb else ""
        rec.update(status="error", error=f"{type(exc).__name__}: {exc}{where}")
    rec["run_wall_s"] = time.perf_counter() - t0
    rec["run_cpu_s"] = time.process_time() - cpu0
    return rec


def warm_worker(kind: str) -> None:
    """Load once per worker process what every in-process run needs (the imports, numba's on-disk cache of the
    plant's and the controller's kernels, the MCAP writer/reader and the summary) by flying 0.1 s of the hover
    scenario with a log: the first row's run then costs what every other row costs, and its timeout_s counts
    the run, not the worker's start. Then gc.freeze(): the ~150,000 objects alive now (modules, functions,
    numba's dispatchers; ~185,000 in a Dask worker) live as long as the worker, and without the freeze the
    cyclic garbage collector walks them all at each full collection a run's allocations trigger: ~20 % of a
    run's CPU, and more the bigger the worker's heap (docs/campaigns.md, "Throughput"). Never raises: a broken
    installation shows as each row's error instead."""
    if kind != "inprocess":  # a sitl run is two new processes: nothing to keep warm here
        return
    try:
        from navig8_tools.sim import run

        with tempfile.TemporaryDirectory(prefix="navig8_warm_") as tmp:
            run("hover", "proposed", 1, 0.1, Path(tmp) / "warm.mcap")
    except Exception:  # noqa: BLE001, S110 - see the docstring
        pass
    gc.collect()
    gc.freeze()


@contextmanager
def worker_pool(workers: int, kind: str) -> Iterator[Any]:
    """A concurrent.futures process pool of `workers` spawned processes (spawn: they start clean, without the
    parent's threads), each started with WORKER_ENV and warmed once (warm_worker). WORKER_ENV is in os.environ
    while the pool lives (its processes are spawned on demand and load numpy with it; the parent's own thread
    pools, loaded already, are unaffected) and restored after."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    old = {k: os.environ.get(k) for k in WORKER_ENV}
    os.environ.update(WORKER_ENV)
    try:
        with ProcessPoolExecutor(workers, multiprocessing.get_context("spawn"), warm_worker, (kind,)) as pool:
            yield pool
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


# ---------------------------------------------------------------------------------------------
# Backends: a local process pool, or Dask distributed
# ---------------------------------------------------------------------------------------------


def _pool_results(rows: list[Row], workers: int) -> Iterator[tuple[Row, dict[str, Any]]]:
    """A local process pool (worker_pool). At most 2 x workers runs are in flight, so a worker that dies
    (BrokenProcessPool) costs only the runs in flight: they are recorded as crashed and a new pool takes the rest."""
    from concurrent.futures import FIRST_COMPLETED, wait
    from concurrent.futures.process import BrokenProcessPool

    todo = list(rows)
    todo.reverse()
    kind = rows[0].kind if rows else "inprocess"
    while todo:
        with worker_pool(workers, kind) as pool:
            inflight: dict[Any, Row] = {}
            broken = False
            while (todo or inflight) and not broken:
                while todo and len(inflight) < 2 * workers:
                    r = todo.pop()
                    inflight[pool.submit(execute_row, r)] = r
                done, _ = wait(inflight, return_when=FIRST_COMPLETED)
                for fut in done:
                    r = inflight.pop(fut)
                    try:
                        yield r, fut.result()
                    except BrokenProcessPool as exc:
                        broken = True
                        yield r, {"run_id": r.run_id, "status": "crashed", "worker": "",
                                  "error": f"worker process died while this run was in flight ({exc})"}
            if broken:
                for r in inflight.values():
                    yield r, {"run_id": r.run_id, "status": "crashed", "worker": "",
                              "error": "worker process died while this run was in flight"}


def _dask_results(rows: list[Row], cluster: str, workers: int) -> Iterator[tuple[Row, dict[str, Any]]]:
    """Dask distributed as its users drive it: a Client on the scheduler's address (or on a LocalCluster this
    campaign starts and stops), submit, as_completed. A worker that dies is the engine's business (the nanny
    restarts it, the scheduler reschedules; after allowed-failures the task raises KilledWorker, recorded here).
    Every worker, also one that joins or restarts later, is warmed once by a worker plugin (warm_worker); its
    thread counts are WORKER_ENV already (the nanny's pre-spawn-environ)."""
    import dask
    from distributed import Client, LocalCluster, as_completed
    from distributed.diagnostics.plugin import WorkerPlugin

    class WarmWorker(WorkerPlugin):
        name = "navig8-warm-worker"

        def __init__(self, kind: str) -> None:
            self.kind = kind

        def setup(self, worker: Any) -> None:
            warm_worker(self.kind)

    local = None
    if cluster == "local":
        # the workers' own sampling profiler walks the running task's stack every 10 ms (and a GIL monitor, when
        # gilknocker is installed, every 1 ms): CPU and GIL taken from the runs, for a dashboard nobody reads here.
        with dask.config.set(DASK_WORKER_CONFIG):
            local = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                 dashboard_address="127.0.0.1:0")  # a private cluster: loopback, free ports
        client = Client(local)
    else:
        client = Client(cluster)
    try:
        client.register_plugin(WarmWorker(rows[0].kind if rows else "inprocess"))
        futs = {client.submit(execute_row, r, key=f"navig8-run-{r.run_id}", pure=False): r for r in rows}
        for fut in as_completed(futs):
            r = futs[fut]
            try:
                yield r, fut.result()
            except Exception as exc:  # noqa: BLE001 - KilledWorker, a lost scheduler: recorded per run
                yield r, {"run_id": r.run_id, "status": "crashed", "worker": "",
                          "error": f"{type(exc).__name__}: {exc}"}
    finally:
        client.close()
        if local is not None:
            local.close()


# ---------------------------------------------------------------------------------------------
# The campaign: stream, resume, table
# ---------------------------------------------------------------------------------------------


def read_stream(out_dir: Path) -> dict[str, dict[str, Any]]:
    """Records of DIR/runs.jsonl by run_id (the last one wins); a torn last line (a killed campaign) is skipped."""
    recs: dict[str, dict[str, Any]] = {}
    p = out_dir / STREAM_FILE
    if not p.exists():
        return recs
    for line in p.read_text().splitlines():
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue
        recs[rec["run_id"]] = rec
    return recs


def row_record(row: Row, rec: Mapping[str, Any], authority: bool | None = None) -> dict[str, Any]:
    """One table row: the row's identity and factors, then the run's record (with the authority columns when the
    row computed them or `authority` says the table has them)."""
    out: dict[str, Any] = {"index": row.index, "run_id": row.run_id, "variant": row.variant,
                           "controller": row.controller, "seed": row.seed, "sample": row.sample, **row.factors}
    for k in ("status", "error", "run_wall_s", "run_cpu_s", "worker"):
        out[k] = rec.get(k)
    for k in (*METRICS, *(MISSION_METRICS if row.plan else ()),
              *((*AUTHORITY_COLUMNS, "authority_error") if (row.authority if authority is None else authority)
                else ())):
        out[k] = rec.get(k, math.nan if k in AUTHORITY_COLUMNS else None)
    out["success"] = bool(rec.get("status") == "ok" and rec.get("lost_control") is False
                          and (not row.plan or rec.get("mission_complete") is True))
    out["replay"] = replay_command(row)
    return out


def build_table(rows: list[Row], recs: Mapping[str, Mapping[str, Any]]) -> Any:
    """The campaign's table (pandas DataFrame, campaign order) of the rows that have a record."""
    import pandas as pd

    have = [r for r in rows if r.run_id in recs]
    authority = any(r.authority for r in rows)
    # a generated campaign computes the bound on one variant's runs per draw; the others' rows share it
    shared = {r.sample: recs[r.run_id] for r in have if r.authority}
    data = []
    for r in have:
        rec = recs[r.run_id]
        if authority and not r.authority and r.sample in shared:
            rec = dict(rec) | {k: shared[r.sample].get(k) for k in (*AUTHORITY_COLUMNS, "authority_error")}
        data.append(row_record(r, rec, authority))
    return pd.DataFrame(data)


def write_table(df: Any, out_dir: Path) -> tuple[Path, Path]:
    pq, csv = out_dir / TABLE_FILE, out_dir / "results.csv"
    df.to_parquet(pq, index=False)
    df.to_csv(csv, index=False)
    return pq, csv


@dataclass(frozen=True)
class CampaignResult:
    out_dir: Path
    table: Any  # pandas DataFrame
    ran: int  # runs executed now (the others were recorded by an earlier, resumed campaign)
    failed: int  # of those, status != ok
    wall_s: float


def run_campaign(campaign: Campaign, out_dir: str | Path, workers: int | None = None, cluster: str | None = None,
                 retry_failed: bool = False, limit: int | None = None, progress: bool = True) -> CampaignResult:
    """Run the rows not yet in out_dir/runs.jsonl (also the failed ones with retry_failed), stream each record as
    it arrives, then write the table. `limit`: run at most that many of the missing rows."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = expand(campaign, out)
    write_scenario_files(rows)  # every generated row's file, also of rows recorded before: the replays read them
    recs = read_stream(out)
    todo = [r for r in rows if r.run_id not in recs or (retry_failed and recs[r.run_id]["status"] != "ok")]
    if limit is not None:
        todo = todo[:limit]
    workers = workers or os.cpu_count() or 1
    source = _pool_results(todo, workers) if cluster is None else _dask_results(todo, cluster, workers)
    bar = None
    if progress and todo:
        from tqdm import tqdm

        bar = tqdm(total=len(todo), unit="run", file=sys.stderr, dynamic_ncols=True, smoothing=0.1)
    failed = 0
    t0 = time.perf_counter()
    with open(out / STREAM_FILE, "a") as stream:
        for i, (row, rec) in enumerate(source, start=1):
            stream.write(json.dumps(rec, allow_nan=True) + "\n")
            stream.flush()
            recs[row.run_id] = rec
            failed += rec["status"] != "ok"
            if bar is not None:
                rate = 60.0 * i / max(time.perf_counter() - t0, 1e-9)
                bar.set_postfix_str(f"failed {failed}, {rate:.1f} runs/min", refresh=False)
                bar.update(1)
    if bar is not None:
        bar.close()
    wall = time.perf_counter() - t0
    df = build_table(rows, recs)
    write_table(df, out)
    return CampaignResult(out, df, len(todo), failed, wall)


def comparable(df: Any) -> Any:
    """The table without the columns that depend on where and when runs ran (for comparing backends)."""
    return df.drop(columns=[c for c in RUN_ENV_COLUMNS if c in df.columns]).reset_index(drop=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="navig8-campaign", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("campaign", help="campaign YAML (params/campaigns/)")
    ap.add_argument("--out", default=None, help="output directory (default out/campaigns/<name>)")
    ap.add_argument("--workers", type=int, default=None, help="pool size / LocalCluster workers (default: cores)")
    ap.add_argument("--cluster", default=None, help="'local' (a Dask LocalCluster) or a scheduler address")
    ap.add_argument("--retry-failed", action="store_true", help="also rerun recorded rows that failed")
    ap.add_argument("--limit", type=int, default=None, help="run at most N of the missing rows")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--no-report", action="store_true")
    a = ap.parse_args(argv)
    c = Campaign.load(a.campaign)
    out = Path(a.out) if a.out else default_out_dir(c)
    res = run_campaign(c, out, a.workers, a.cluster, a.retry_failed, a.limit, progress=not a.no_progress)
    backend = "dask " + a.cluster if a.cluster else f"local pool of {a.workers or os.cpu_count()}"
    print(f"{res.ran} runs now ({res.failed} failed) in {res.wall_s:.1f} s on {backend}; "
          f"table: {len(res.table)} rows -> {out / TABLE_FILE}, {out / 'results.csv'}", file=sys.stderr)
    if not a.no_report:
        from navig8_tools.campaign_report import write_report

        cmd = "navig8-campaign " + " ".join(argv if argv is not None else sys.argv[1:])
        print(f"report: {write_report(c, res.table, out, cmd)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["Campaign", "Factor", "Variant", "Row", "GeneratedDraw", "generated_draws", "write_scenario_files",
           "expand", "execute_row", "run_campaign", "build_table", "read_stream", "replay_command", "comparable",
           "call_with_timeout", "worker_pool", "warm_worker", "default_out_dir", "main"]
