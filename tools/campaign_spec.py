"""The campaign file and its rows (navig8-campaign, tools/campaign.py): parsing and checking a campaign file
(docs/campaigns.md; params/campaigns/), expanding it into rows (variants x grid cells x samples x seeds, or the
draws of a generated campaign), each row's id (a hash of everything its run depends on) and the command that
replays it alone (`navig8-sim`, or `navig8-sitl` with `navig8-mission` as the ground station).
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import shlex
from collections.abc import Mapping
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
    sitl = shlex.join(sitl_argv(row, Path(f"out/replay_{row.run_id}")))
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


def sitl_argv(row: Row, out: Path) -> list[str]:
    """navig8-sitl's command line for a row, its log, state and summary in `out`."""
    from navig8_tools.sim import CONTROLLERS
    from sim_bridge.world import world_args

    sets, dur = _set_and_duration_args(row)
    return ["navig8-sitl", "--scenario", row.scenario, "--speed", f"{row.speed:g}", "--until-done", "--seed",
            str(row.seed), *dur, "--instance", str(row.instance), "--log-dir", str(out), "--state-dir", str(out),
            "--set", f"CKF_MODE={CONTROLLERS[row.controller]}", *sets,
            *world_args(row.world), "--summary", str(out / "summary.json")]


__all__ = ["Campaign", "Factor", "Variant", "Row", "GeneratedDraw", "generated_draws", "write_scenario_files",
           "expand", "replay_command", "sitl_argv", "default_out_dir"]
