"""navig8-falsify: a search for a controller's worst case (falsification), by CMA-ES over one flight's factors.

    navig8-falsify --controller proposed|pinned|fixed|lms|unconstrained [--evals 80] [--popsize 10] [--seed 0]
                   [--workers 2] [--flight-seeds 1001 1002] [--out DIR] [--no-write]

Sampling (navig8-campaign's envelope) says how a controller does on typical flights; a search says where it does
worst. One flight is a point x of the unit cube [0, 1]^n (DIMS: each coordinate a factor's range, linear or
log): the plant's arm servo speed and the FC's model of it, the plant's actuator bandwidth (the FC's ACT_WN stays),
the object's mass and its offset beyond the gripper (the FC believes the nominal offset), one duct's efficiency
(0.5-1: the plant's duct fault) and when it strikes, the grasp pose and when the arm moves there, a swing to a
second pose and back (when, how fast, how long held), the release, and a pitch step. `flight(x)` maps x to a
scenario document (with its own world overrides) and FC parameters, a pure function: the same x gives the same
flight, bit for bit.

The objective (to maximise) of a flight is its maximum attitude error (deg); a flight that loses control scores
LOSS_SCORE_DEG plus LOSS_BONUS_PER_S for every second it had left (so of two losses the search prefers the
sooner), averaged over the flight seeds (the plant's sensor noise; the same seeds for every candidate: common
random numbers, so the search compares flights, not noise). A flight whose level hover trim needs more than
`trim_limit` of a propeller's speed limit at any pose the arm passes while holding the object (the duct fault,
the object and its offset included) is out of authority for any controller: it is not flown and scores minus its
excess, which leads the search back to flights a controller could hold (a worst case no controller could fly
says nothing about this one).

CMA-ES (pycma, Hansen's implementation) in the unit cube with its bounds handling; each generation's candidates x
seeds are flown on a local process pool (navig8_tools.campaign_run's warmed workers, `execute_row`). Output in DIR
(default out/falsify/<controller>): `trace.json` (every evaluation: generation, x, the factors, per-seed metrics,
the score; the best), and, unless --no-write, the worst case as a regression scenario:
`params/scenarios/falsified_<controller>.yaml` (its world overrides inside) and
`params/campaigns/falsified_<controller>.yaml` (all four controllers over 100 seeds: docs/campaigns.md).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from navig8_tools.envelope import arrival_s, servo_track

LOSS_SCORE_DEG = 200.0  # a lost flight scores above any flight held (attitude errors top out at 180 deg)
LOSS_BONUS_PER_S = 10.0  # + this per second of the flight left at the loss: the sooner lost, the worse
JOINT_LIMIT_DEG = 100.0  # poses drawn within +-100 deg (the vehicle's limit is 1.75 rad = 100.3 deg)
# The controllers searched, as campaign variants (the pinned one is the paper scenario's best constant, docs/results.md)
CONTROLLER_VARIANTS: dict[str, dict[str, Any]] = {
    "proposed": {"controller": "proposed"},
    "pinned": {"controller": "pinned", "set": {"CKF_K_PIN1": 0.5, "CKF_K_PIN2": 0.5, "CKF_K_PIN3": 0.5,
                                               "CKF_K_PIN4": 1.0}},
    "fixed": {"controller": "fixed"},
    "lms": {"controller": "lms"},
    "unconstrained": {"controller": "unconstrained"},
}
REGRESSION_CONTROLLERS = ("proposed", "pinned", "fixed", "lms")  # every worst case is flown by these


@dataclass(frozen=True)
class Dim:
    """One coordinate of the search: x in [0, 1] is `lo + x (hi - lo)`, or log-linear between lo and hi."""

    name: str
    lo: float
    hi: float
    log: bool = False
    digits: int = 3  # the value is rounded to this many decimals (the files stay readable; the rows carry what runs)

    def value(self, x: float) -> float:
        x = min(max(float(x), 0.0), 1.0)
        v = math.exp(math.log(self.lo) + x * (math.log(self.hi) - math.log(self.lo))) if self.log \
            else self.lo + x * (self.hi - self.lo)
        return float(round(min(max(v, self.lo), self.hi), self.digits))


@dataclass(frozen=True)
class FalsifySpec:
    """The flight template the search varies, and its constants."""

    duration_s: float = 14.0
    hover_z_ned_m: float = -3.0  # 3 m up, as the envelope's flights
    grasp_margin_s: float = 0.3  # the grasp this long after the arm has arrived at its pose
    latest_grasp_s: float = 7.0  # a servo too slow to arrive by then grasps where the arm is
    release_before_end_s: float = 1.5  # a release later than duration - this is dropped (the object stays held)
    trim_limit: float = 0.9  # the level trim may use at most this share of a propeller's speed limit (authority)
    trim_check_every_s: float = 0.05
    nominal_servo_v_max_rad_s: float = 4.0  # plant.yaml joint_servo and ARM_SERVO_VMAX/AMAX's defaults
    nominal_servo_a_max_rad_s2: float = 42.0
    nominal_object_offset_m: float = 0.0  # vehicle.yaml object.offset_from_tip_m: what the FC believes

    @property
    def dims(self) -> tuple[Dim, ...]:
        d = self.duration_s
        pose = [Dim(f"{p}_q{j}_deg", -JOINT_LIMIT_DEG, JOINT_LIMIT_DEG, digits=2) for p in ("grasp", "swing")
                for j in (1, 2, 3)]
        return (
            Dim("arm_speed_scale", 0.075, 1.0, log=True, digits=5),  # the plant's servo 0.3-4 rad/s (v x s, a x s^2)
            Dim("servo_model_error", 0.8, 1.25, log=True, digits=4),  # ARM_SERVO_VMAX = 4 x e, AMAX = 42 x e^2
            Dim("actuator_bandwidth_scale", 0.6, 1.4, digits=4),
            Dim("object_mass_kg", 0.0, 2.5),
            Dim("object_offset_m", 0.0, 0.15),
            Dim("duct_fault", 0.0, 1.0, digits=4),  # < 0.5: duct 1 (right), > 0.5: duct 3; e = 1 - |x - 0.5|
            Dim("duct_fault_t_s", 0.0, d - 2.0),
            *pose[:3],
            Dim("grasp_move_t_s", 0.5, 2.0),
            *pose[3:],
            Dim("swing_delay_s", 0.2, 3.0),
            Dim("swing_ramp_s", 0.0, 1.5),
            Dim("swing_hold_s", 0.3, 3.0),
            Dim("release_delay_s", 0.2, 4.0),
            Dim("pitch_deg", 0.0, 30.0, digits=2),
            Dim("pitch_t_s", 1.0, d - 3.0),
        )


@dataclass(frozen=True)
class Flight:
    """One point of the search as a run: the scenario document (its `world:` the plant's and the FC model's
    overrides), the FC parameters, the factor values (table columns), and the authority check."""

    x: tuple[float, ...]
    scenario: dict[str, Any]
    fc_params: dict[str, float]
    factors: dict[str, Any]
    trim_utilisation: float  # the largest share of a propeller's speed limit the level trim needs while holding
    feasible: bool


def factors_of(x: Sequence[float], spec: FalsifySpec) -> dict[str, float]:
    """The factor values of a point of the unit cube (clipped into it)."""
    dims = spec.dims
    if len(x) != len(dims):
        raise ValueError(f"a point of the search has {len(dims)} coordinates, got {len(x)}")
    return {d.name: d.value(v) for d, v in zip(dims, x, strict=True)}


def duct_fault(x_fault: float) -> tuple[int, float]:
    """The faulty duct (1 or 3) and its efficiency from the fault coordinate: continuous through 0.5 (no fault),
    0.5 at either end."""
    e = float(round(1.0 - abs(float(x_fault) - 0.5), 4))
    return (1 if x_fault < 0.5 else 3), e


@lru_cache(maxsize=8)
def _vehicle(offset_m: float) -> tuple[Any, Any, np.ndarray]:
    """The true vehicle with the object offset, its G_C model, and the propeller speed limits (w1, w2, w3)."""
    from navig8_fc.core.vehicle import UamModel, VehicleConfig
    from sim_bridge.plant import actuator_limits

    cfg = replace(VehicleConfig.load(), object_offset_m=offset_m)
    lo, hi = actuator_limits(cfg)
    return cfg, UamModel(cfg), np.maximum(np.abs(lo[2:]), np.abs(hi[2:]))


def _trim_utilisation(spec: FalsifySpec, track: np.ndarray, mass_at: Callable[[float], float], offset_m: float,
                      efficiency: tuple[float, float], fault_t_s: float) -> float:
    """The largest |speed| / limit of the plant's level hover trim (sim_bridge.plant.trim_actuators, written out
    with G_C built once per CoM) over the track's poses (every trim_check_every_s), with the object held then, the
    true offset and the duct fault once struck."""
    from navig8_fc.core.vehicle import mass_properties, u_to_actuators
    from sim_bridge.plant import duct_input_scale

    cfg, model, limit = _vehicle(float(offset_m))
    every = max(1, int(round(spec.trim_check_every_s / float(track[1, 0] - track[0, 0]))))
    scale, nominal = duct_input_scale(efficiency), np.ones(5)
    worst = 0.0
    for row in track[::every]:
        t = float(row[0])
        mp = mass_properties(cfg, row[1:], mass_at(t))
        u = np.linalg.solve(model.gc_about(float(mp.com_frd_m[0]), float(mp.com_frd_m[2])),
                            [0.0, 0.0, 0.0, 0.0, -mp.mass_kg * cfg.gravity_m_s2])
        act = u_to_actuators(u / (scale if t >= fault_t_s else nominal))
        worst = max(worst, float(np.max(np.abs(act[2:]) / limit)))
    return worst


def _r3(v: float) -> float:
    return float(round(v, 3))


def _flight_world(f: Mapping[str, Any], spec: FalsifySpec, duct: int, eff: float, t_fault: float) -> dict[str, float]:
    """The world overrides of a flight with factors f: the servo's speed, the actuators' bandwidth, the object's
    offset (the truth's; the FC keeps the nominal one) and the duct fault, if any."""
    world: dict[str, float] = {
        "arm_servo_speed_scale": f["arm_speed_scale"],
        "actuator_bandwidth_scale": f["actuator_bandwidth_scale"],
        # the object's centre beyond the gripper: the truth's; the FC keeps believing the nominal offset
        "vehicle.object.offset_from_tip_m": f["object_offset_m"],
        "fc_vehicle.object.offset_from_tip_m": spec.nominal_object_offset_m,
    }
    if eff < 1.0:
        world[f"plant.actuators.duct_efficiency.{0 if duct == 1 else 1}"] = eff
        world["plant.actuators.duct_fault_t_s"] = t_fault
    return world


def flight(x: Sequence[float], spec: FalsifySpec | None = None, name: str = "falsified") -> Flight:
    """The flight at point x of the unit cube (module docstring). Pure: the same x gives the same flight."""
    spec = spec or FalsifySpec()
    f = factors_of(x, spec)
    dur = spec.duration_s
    s = f["arm_speed_scale"]
    v_max, a_max = spec.nominal_servo_v_max_rad_s * s, spec.nominal_servo_a_max_rad_s2 * s * s
    grasp = [f[f"grasp_q{j}_deg"] for j in (1, 2, 3)]
    swing = [f[f"swing_q{j}_deg"] for j in (1, 2, 3)]

    # the arm to the grasp pose, and the grasp once the plant's servo is there and rested (servo_track runs the
    # plant's own servo law over the schedule), or where the arm is at latest_grasp_s
    t_move = f["grasp_move_t_s"]
    steps: list[dict[str, Any]] = [{"t_s": t_move, "q_deg": grasp}]
    track = servo_track(steps, dur, v_max, a_max)
    arrived = arrival_s(track, np.radians(grasp), t_move)
    in_place = arrived + spec.grasp_margin_s > spec.latest_grasp_s
    t_grasp = _r3(spec.latest_grasp_s if in_place else arrived + spec.grasp_margin_s)
    # the swing to the second pose and back (each a ramp of swing_ramp_s; the servo's limits shape it further)
    t_swing = _r3(t_grasp + f["swing_delay_s"])
    ramp = f["swing_ramp_s"]
    t_back = _r3(t_swing + ramp + f["swing_hold_s"])
    for t, q in ((t_swing, swing), (t_back, grasp)):
        if t < dur:
            steps.append({"t_s": t, "q_deg": list(q), **({"ramp_s": ramp} if ramp > 0.0 else {})})
    t_release = _r3(t_back + ramp + f["release_delay_s"])
    releasing = t_release <= dur - spec.release_before_end_s
    track = servo_track(steps, dur, v_max, a_max)
    events: list[dict[str, Any]] = [{"t_s": t_grasp, "kind": "grasp", "mass_kg": f["object_mass_kg"]}]
    if releasing:
        events.append({"t_s": t_release, "kind": "release"})

    duct, eff = duct_fault(f["duct_fault"])
    efficiency = (eff, 1.0) if duct == 1 else (1.0, eff)
    t_fault = f["duct_fault_t_s"]
    t_end_hold = t_release if releasing else math.inf
    util = _trim_utilisation(spec, track, lambda t: f["object_mass_kg"] if t_grasp <= t < t_end_hold else 0.0,
                             f["object_offset_m"], efficiency, t_fault)

    def pose_at(t_s: float) -> list[float]:
        k = int(np.searchsorted(track[:, 0], t_s - 1e-9))
        return [float(round(math.degrees(v), 2)) for v in track[min(k, len(track) - 1), 1:]]

    z0 = spec.hover_z_ned_m
    world = _flight_world(f, spec, duct, eff, t_fault)
    err = f["servo_model_error"]
    fc_params = {"ARM_SERVO_VMAX": float(round(spec.nominal_servo_v_max_rad_s * err, 5)),
                 "ARM_SERVO_AMAX": float(round(spec.nominal_servo_a_max_rad_s2 * err * err, 5))}
    scenario: dict[str, Any] = {
        "name": name,
        "description": (f"Found by navig8-falsify (tools/falsify.py): a {f['object_mass_kg']:g} kg object "
                        f"{f['object_offset_m']:g} m beyond the gripper grasped at {t_grasp:g} s, a swing, "
                        + (f"released at {t_release:g} s, " if releasing else "held to the end, ")
                        + (f"duct {duct} at {eff:g} efficiency from {t_fault:g} s, " if eff < 1.0
                           else "no duct fault, ")
                        + f"servo {v_max:.3g} rad/s, pitch {f['pitch_deg']:g} deg at {f['pitch_t_s']:g} s."),
        "duration_s": dur,
        "armed": True,
        "initial": {"pos_ned_m": [0.0, 0.0, z0], "vel_ned_m_s": [0.0, 0.0, 0.0], "euler_deg": [0.0, 0.0, 0.0],
                    "rate_frd_rad_s": [0.0, 0.0, 0.0], "joint_pos_deg": [0.0, 0.0, 0.0], "actuators": "trim",
                    "on_ground": False},
        "object": {"gripper_closed": False, "mass_kg": 0.0},
        "events": events,
        "arm": {"kind": "steps", "steps": steps},
        "setpoints": {"initial": {"pos_ned_m": [0.0, 0.0, z0], "pitch_deg": 0.0, "yaw_deg": 0.0},
                      "steps": [{"t_s": f["pitch_t_s"], "pitch_deg": f["pitch_deg"]}]},
        "world": world,
    }
    factors: dict[str, Any] = {
        **f,
        "arm_speed_rad_s": float(round(v_max, 4)), "arm_accel_rad_s2": float(round(a_max, 4)),
        "servo_model_ratio": float(round(fc_params["ARM_SERVO_VMAX"] / v_max, 4)),
        "duct": duct if eff < 1.0 else 0, "duct_efficiency": eff,
        "grasp_t_s": t_grasp, "grasp_in_place": bool(in_place), "swing_t_s": t_swing, "back_t_s": t_back,
        "release_t_s": t_release if releasing else math.nan,
        **{f"grasp_at_q{j + 1}_deg": q for j, q in enumerate(pose_at(t_grasp))},
        "trim_utilisation": float(round(util, 4)),
    }
    return Flight(tuple(float(v) for v in x), scenario, fc_params, factors, util, util <= spec.trim_limit)


# ---------------------------------------------------------------------------------------------
# The score and the search
# ---------------------------------------------------------------------------------------------


def flight_score(summary: Mapping[str, Any], duration_s: float) -> float:
    """One flight's score (deg): its maximum attitude error, or LOSS_SCORE_DEG + LOSS_BONUS_PER_S x the time it had
    left when it lost control; a run that did not finish (error, timeout) scores nan."""
    if summary.get("status", "ok") != "ok":
        return math.nan
    if summary.get("lost_control"):
        t_loss = summary.get("lost_control_t_s")
        left = duration_s - float(t_loss) if t_loss is not None and math.isfinite(float(t_loss)) else 0.0
        return LOSS_SCORE_DEG + LOSS_BONUS_PER_S * max(left, 0.0)
    return float(summary["max_att_error_deg"])


@dataclass(frozen=True)
class Evaluation:
    generation: int
    x: tuple[float, ...]
    score: float


@dataclass
class SearchTrace:
    """Every evaluation in order, and the best (the largest score)."""

    evaluations: list[Evaluation] = field(default_factory=list)

    @property
    def best(self) -> Evaluation:
        finite = [e for e in self.evaluations if math.isfinite(e.score)]
        if not finite:
            raise ValueError("no evaluation with a finite score")
        return max(finite, key=lambda e: e.score)


def maximise(evaluate: Callable[[list[np.ndarray]], list[float]], n_dims: int, evals: int, popsize: int, seed: int,
             sigma0: float = 0.3, x0: Sequence[float] | None = None) -> SearchTrace:
    """Maximise a function of the unit cube [0, 1]^n_dims by CMA-ES (pycma, bounds [0, 1]) within `evals`
    evaluations. `evaluate` takes one generation's candidates and returns their scores (nan: failed, treated as
    the worst). x0 defaults to the centre; `seed` seeds pycma's sampler (reproducible; 0 is remapped, since pycma
    reads a seed of 0 as "random")."""
    import cma

    opts = {"bounds": [0.0, 1.0], "popsize": int(popsize), "seed": int(seed) + 1, "verbose": -9,
            "maxfevals": int(evals), "tolfun": 0.0, "tolx": 1e-9, "CMA_stds": None}
    es = cma.CMAEvolutionStrategy(list(x0) if x0 is not None else [0.5] * n_dims, float(sigma0), opts)
    trace = SearchTrace()
    gen = 0
    while len(trace.evaluations) < evals and not es.stop():
        cands = es.ask()
        cands = cands[: evals - len(trace.evaluations)]
        scores = evaluate([np.clip(np.asarray(c, dtype=float), 0.0, 1.0) for c in cands])
        for c, s in zip(cands, scores, strict=True):
            trace.evaluations.append(Evaluation(gen, tuple(float(v) for v in np.clip(c, 0.0, 1.0)), float(s)))
        if len(cands) < es.popsize:
            break
        # pycma minimises; a failed run (nan) counts as the worst, a +inf would break its ranking
        es.tell(cands, [-s if math.isfinite(s) else 1e9 for s in scores])
        gen += 1
    return trace


# ---------------------------------------------------------------------------------------------
# Flying candidates (the campaign's warmed process pool)
# ---------------------------------------------------------------------------------------------


def _rows(fl: Flight, variant: Mapping[str, Any], seeds: Sequence[int], timeout_s: float) -> list[Any]:
    from navig8_tools.campaign_spec import Row

    params = {**fl.fc_params, **dict(variant.get("set") or {})}
    return [Row(index=i, run_id=f"x{i}", kind="inprocess", scenario=fl.scenario["name"], duration_s=None,
                variant=str(variant["controller"]), controller=str(variant["controller"]), seed=int(sd), sample=0,
                factors={}, world={}, params=params, timeout_s=timeout_s, scenario_doc=fl.scenario)
            for i, sd in enumerate(seeds)]


class PoolEvaluator:
    """Scores candidates by flying them (every flight seed) on a process pool of warmed workers; keeps a record of
    each evaluation (factors, per-seed metrics) for the trace."""

    def __init__(self, pool: Any, controller: str, seeds: Sequence[int], spec: FalsifySpec,
                 timeout_s: float = 300.0) -> None:
        self.pool, self.variant, self.seeds, self.spec = pool, CONTROLLER_VARIANTS[controller], list(seeds), spec
        self.timeout_s = timeout_s
        self.records: list[dict[str, Any]] = []
        self.flown = 0

    def __call__(self, xs: list[np.ndarray]) -> list[float]:
        from navig8_tools.campaign_run import execute_row

        flights = [flight(x, self.spec) for x in xs]
        futures = {}
        for k, fl in enumerate(flights):
            if fl.feasible:
                for row in _rows(fl, self.variant, self.seeds, self.timeout_s):
                    futures[(k, row.seed)] = self.pool.submit(execute_row, row)
        scores = []
        for k, fl in enumerate(flights):
            rec: dict[str, Any] = {"x": [float(v) for v in fl.x], "factors": fl.factors,
                                   "fc_params": fl.fc_params, "feasible": fl.feasible, "runs": []}
            if not fl.feasible:
                score = -100.0 * (fl.trim_utilisation - self.spec.trim_limit)  # back towards authority
            else:
                per_seed = []
                for sd in self.seeds:
                    r = futures[(k, sd)].result()
                    self.flown += 1
                    sc = flight_score(r, self.spec.duration_s)
                    per_seed.append(sc)
                    rec["runs"].append({"seed": sd, "score": sc, **{m: r.get(m) for m in (
                        "status", "error", "lost_control", "lost_control_t_s", "max_att_error_deg",
                        "att_rms_error_deg", "min_eigenvalue", "max_pos_error_m", "run_wall_s")}})
                score = float(np.mean(per_seed)) if all(math.isfinite(v) for v in per_seed) else math.nan
            rec["score"] = score
            self.records.append(rec)
            scores.append(score)
        return scores


# ---------------------------------------------------------------------------------------------
# The regression scenario and campaign
# ---------------------------------------------------------------------------------------------


def campaign_document(controller: str, fc_params: Mapping[str, float], seeds: int = 100) -> dict[str, Any]:
    """The regression campaign of controller's worst case: its scenario flown by REGRESSION_CONTROLLERS with the
    case's FC servo model, over `seeds` seeds."""
    variants = {}
    for name in REGRESSION_CONTROLLERS:
        v = CONTROLLER_VARIANTS[name]
        variants[name] = {"controller": v["controller"], "set": {**dict(fc_params), **dict(v.get("set") or {})}}
    return {"name": f"falsified_{controller}",
            "description": f"the worst case navig8-falsify found for {controller}, every controller, {seeds} seeds",
            "kind": "inprocess", "scenario": f"falsified_{controller}", "seeds": int(seeds), "timeout_s": 300,
            "variants": variants}


class _FlowListDumper(yaml.SafeDumper):
    """Lists of numbers in flow style ([0.0, 0.0, -3.0]), as the hand-written scenario files have them."""


_FlowListDumper.add_representer(
    list, lambda d, v: d.represent_sequence("tag:yaml.org,2002:seq", v,
                                            flow_style=all(isinstance(x, (int, float)) for x in v)))


def dump_yaml(doc: Mapping[str, Any]) -> str:
    return yaml.dump(dict(doc), Dumper=_FlowListDumper, sort_keys=False, width=120)


def _run_line(run: Mapping[str, Any]) -> str:
    lost = f"lost control at {run['lost_control_t_s']:.2f} s, " if run.get("lost_control") else ""
    return (f"#   flight seed {run['seed']}: score {run['score']:.2f} ({lost}max attitude error "
            f"{run['max_att_error_deg']:.2f} deg, max position error {run['max_pos_error_m']:.2f} m)\n")


def write_regression(controller: str, fl: Flight, score: float, command: str, params_dir: Path,
                     runs: Sequence[Mapping[str, Any]] = ()) -> tuple[Path, Path]:
    """params/scenarios/falsified_<controller>.yaml and params/campaigns/falsified_<controller>.yaml; `runs`: the
    search's flights of this case (seed, score, metrics), noted in the scenario's header."""
    head = (f"# The worst case navig8-falsify found for the {controller} controller (score {score:.1f}: the mean over\n"
            f"# the search's flight seeds of the max attitude error in deg, or {LOSS_SCORE_DEG:g} + "
            f"{LOSS_BONUS_PER_S:g}/s left when control was lost).\n"
            f"#   {command}\n"
            + "".join(_run_line(r) for r in runs if r.get("status") == "ok") +
            f"# Level-trim use of the propellers' speed limits while holding: {fl.trim_utilisation:.3f}. Its\n"
            f"# `world:` is the plant's and the FC model's side; the FC's servo model (ARM_SERVO_VMAX/AMAX) is in\n"
            f"# the campaign params/campaigns/falsified_{controller}.yaml (docs/results.md, \"Worst cases found by\n"
            f"# search\").\n")
    scn = dict(fl.scenario)
    scn["name"] = f"falsified_{controller}"
    scn_path = params_dir / "scenarios" / f"falsified_{controller}.yaml"
    scn_path.write_text(head + dump_yaml(scn))
    camp_head = (f"# Regression scenario: the worst case navig8-falsify found for {controller}, flown by every "
                 f"controller over 100 seeds.\n"
                 f"#   navig8-campaign params/campaigns/falsified_{controller}.yaml "
                 f"--out out/campaigns/falsified_{controller} --workers 2\n")
    camp_path = params_dir / "campaigns" / f"falsified_{controller}.yaml"
    camp_path.write_text(camp_head + dump_yaml(campaign_document(controller, fl.fc_params)))
    return scn_path, camp_path


def _jsonable(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    return v


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--controller", choices=sorted(CONTROLLER_VARIANTS), default="proposed")
    ap.add_argument("--evals", type=int, default=80, help="candidate flights (each flown once per flight seed)")
    ap.add_argument("--popsize", type=int, default=10, help="CMA-ES population per generation")
    ap.add_argument("--seed", type=int, default=0, help="the search's seed (CMA-ES sampling)")
    ap.add_argument("--sigma0", type=float, default=0.3, help="CMA-ES initial step in the unit cube")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--flight-seeds", type=int, nargs="+", default=[1001, 1002],
                    help="plant sensor-noise seeds every candidate is flown with (the score is their mean)")
    ap.add_argument("--out", default=None, help="trace directory (default out/falsify/<controller>)")
    ap.add_argument("--params-dir", default=None, help="where params/scenarios and params/campaigns are "
                    "(default: the package's params/)")
    ap.add_argument("--no-write", action="store_true", help="write the trace only, no regression files")
    ap.add_argument("--write-from", default=None, metavar="TRACE",
                    help="no search: write the regression files of a trace.json's best (the worse of two searches)")
    args = ap.parse_args(argv)
    if args.evals < 1 or args.popsize < 2:
        ap.error("--evals >= 1 and --popsize >= 2")
    spec = FalsifySpec()
    if args.write_from:
        doc = json.loads(Path(args.write_from).read_text())
        best = doc["best"]
        fl = flight(best["x"], spec)
        for p in write_regression(doc["controller"], fl, best["score"], search_command(doc["command"].split()),
                                  _params_dir(args.params_dir), best["runs"]):
            print(f"wrote {p}", file=sys.stderr)
        return 0

    from navig8_tools.campaign_run import worker_pool

    out = Path(args.out or f"out/falsify/{args.controller}")
    out.mkdir(parents=True, exist_ok=True)
    command = search_command(["navig8-falsify", *(argv if argv is not None else sys.argv[1:])])
    t0 = time.perf_counter()
    with worker_pool(args.workers, "inprocess") as pool:
        ev = PoolEvaluator(pool, args.controller, args.flight_seeds, spec)

        def evaluate(xs: list[np.ndarray]) -> list[float]:
            scores = ev(xs)
            best = max((s for s in scores if math.isfinite(s)), default=math.nan)
            print(f"  {len(ev.records):4d} evaluations, {ev.flown:4d} flights, {time.perf_counter() - t0:6.0f} s: "
                  f"generation best {best:7.2f}", file=sys.stderr, flush=True)
            return scores

        trace = maximise(evaluate, len(spec.dims), args.evals, args.popsize, args.seed, args.sigma0)
    wall = time.perf_counter() - t0
    best = trace.best
    i_best = trace.evaluations.index(best)
    fl = flight(best.x, spec)
    doc = {"controller": args.controller, "command": command, "evals": len(trace.evaluations),
           "flights": ev.flown, "wall_s": wall, "popsize": args.popsize, "seed": args.seed, "sigma0": args.sigma0,
           "flight_seeds": args.flight_seeds, "dims": [d.__dict__ for d in spec.dims],
           "best": {"index": i_best, "generation": best.generation, **ev.records[i_best]},
           "evaluations": [{"index": i, "generation": e.generation, **r}
                           for i, (e, r) in enumerate(zip(trace.evaluations, ev.records, strict=True))]}
    (out / "trace.json").write_text(json.dumps(_jsonable(doc), indent=1))
    print(json.dumps(_jsonable({"controller": args.controller, "score": best.score, "factors": fl.factors,
                                "fc_params": fl.fc_params, "runs": ev.records[i_best]["runs"]}), indent=1))
    print(f"trace: {out / 'trace.json'} ({len(trace.evaluations)} evaluations, {ev.flown} flights, {wall:.0f} s)",
          file=sys.stderr)
    if not args.no_write:
        for p in write_regression(args.controller, fl, best.score, command, _params_dir(args.params_dir),
                                  ev.records[i_best]["runs"]):
            print(f"wrote {p}", file=sys.stderr)
    return 0


def search_command(tokens: Sequence[str]) -> str:
    """The command line that reproduces a search, without where it wrote (--out, --params-dir: the same search
    written elsewhere) and without --write-from: what a regression file's header names."""
    out, skip = [], False
    for tok in tokens:
        if skip:
            skip = False
            continue
        if tok in ("--out", "--params-dir", "--write-from"):
            skip = True
            continue
        if tok.startswith(("--out=", "--params-dir=", "--write-from=")):
            continue
        out.append(tok)
    return " ".join(out)


def _params_dir(given: str | None) -> Path:
    """Where params/scenarios and params/campaigns are: the given directory, else the package's params/."""
    if given:
        return Path(given)
    from importlib.resources import files

    return Path(str(files("navig8_params")))


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["Dim", "FalsifySpec", "Flight", "flight", "factors_of", "duct_fault", "flight_score", "maximise",
           "SearchTrace", "Evaluation", "PoolEvaluator", "campaign_document", "write_regression", "main",
           "LOSS_SCORE_DEG", "LOSS_BONUS_PER_S", "CONTROLLER_VARIANTS", "REGRESSION_CONTROLLERS"]
