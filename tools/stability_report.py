"""navig8-stability: the stability analysis of paper Sec. 3.1-3.2 (Eq. 9-20, Figs. 5-7) for the configuration flown.

    navig8-stability [--params FILE ...] [--set NAME=VALUE ...] [--wn W] [--zeta Z] [--ts T] [--tl L]
                     [--k-min K] [--k-max K] [--lambda-min L] [--lmi] [--json] [--plots DIR]

The configuration is the parameter defaults (params/fc_params.yaml), then `--params` files, then `--set` items, as
navig8-sim takes them (navig8_fc.params.store.read_overrides): ACT_WN, ACT_ZETA, tau_s = 1/INDI_RATE_HZ,
INDI_LPF_TAU, INDI_K_MIN, INDI_K_MAX, INDI_LAMBDA_MIN, INDI_LAM_MARGIN, INDI_U0_SRC, INDI_U0_TAU. `--wn` ...
`--lambda-min` override the analysis inputs directly (tau_s need not be 1/an integer rate). The report holds
the configured loop next to the paper's Section 3 constants (the reference), the stated margin the parameter
checks enforce (INDI_LAM_MARGIN) with the registry's verdict, the model-based U0 over an actuator-bandwidth
mismatch and the sampled loop as a check of the Pade analysis. `--lmi` adds the common-Lyapunov statement for the
loop flown while K varies (navig8_fc.core.varying_k; about 45 s with the defaults, 100 s with the paper's preset, so
off by default). The math lives in navig8_fc.core.stability; this
file only formats it. See docs/stability.md.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from navig8_fc.core import k_xi
from navig8_fc.core import stability as st
from navig8_fc.core import varying_k as vk
from navig8_fc.core.sampled_loop import CHANNELS, sampled_lambda_crit
from navig8_fc.core.vehicle import VehicleConfig
from navig8_tools.stability_plots import write_plots
from navig8_tools.stability_text import render_text

REPORT_LAMBDAS = (0.1, 0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0)


# The paper's Section 3 constants (Sec. 3.1: wn 120 rad/s, zeta 1, tau_s 0.01 s, tau_L 0.1 s): the reference column.
PAPER_LOOP = (120.0, 1.0, 0.01, 0.1)
# Plant actuator bandwidth / ACT_WN for the mismatch table (the plant's actuators +-40 % off the FC's model).
MISMATCH_FACTORS = (0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4)
CONFIG_PARAMS = ("ACT_WN", "ACT_ZETA", "INDI_RATE_HZ", "INDI_LPF_TAU", "INDI_K_MIN", "INDI_K_MAX", "INDI_LAMBDA_MIN",
                 "INDI_LAM_MARGIN", "INDI_U0_SRC", "INDI_U0_TAU", "INDI_ACC_REF", "INDI_LAM_REF", "INDI_KFL_MIN")


@dataclass(frozen=True)
class Inputs:
    wn_rad_s: float
    zeta: float
    ts_s: float
    tl_s: float
    k_min: float
    k_max: float
    lambda_min: float
    lam_margin: float = 1.0  # INDI_LAM_MARGIN: required guaranteed-min-eigenvalue / lambda_crit
    u0_src: int = 0  # INDI_U0_SRC
    u0_tau_s: float = 0.2  # INDI_U0_TAU


@dataclass(frozen=True)
class Configuration:
    """The parameter values the report analyses (defaults, then --params, then --set) and what the registry says."""

    values: dict[str, float | int]  # CONFIG_PARAMS as the registry stores them (shortest decimal for REAL32)
    overrides: dict[str, float]  # what --params / --set changed
    verdict: str | None  # the registry's refusal of this configuration (None: a PARAM_SET to it is accepted)


def _shortest(x: float | int) -> float | int:
    # The registry stores REAL32 values as float32 (what MAVLink carries): 0.1 -> 0.10000000149. Take the
    # shortest decimal that rounds to the same float32, i.e. the value in the YAML or .parm file.
    return x if isinstance(x, int) else float(str(np.float32(x)))


def configuration(files: Sequence[str] = (), set_items: Sequence[str] = ()) -> Configuration:
    """The defaults with `--params` files and `--set` items applied (store.read_overrides, the one parser), each
    checked by the registry's per-parameter rules (name, range, type). The stability rules are not applied while
    setting (the report analyses refused configurations too, to show why); `verdict` is the registry's answer to
    the configuration as a whole: its stability floor, the INDI_LAM_MARGIN margin and INDI_LAMBDA_MIN."""
    from navig8_fc.params.registry import ParamRegistry
    from navig8_fc.params.store import read_overrides

    overrides = read_overrides(files, set_items)
    plain = ParamRegistry.from_defaults(check_stability=False)
    for name, value in overrides.items():
        res = plain.set(name, value)
        if not res.accepted:
            raise ValueError(res.reason or f"{name}: refused")
    checked = ParamRegistry.from_defaults()
    checked.restore(plain.as_dict())
    verdict = checked.validate("INDI_LAM_MARGIN", checked["INDI_LAM_MARGIN"])
    if verdict is not None:
        verdict = verdict.removeprefix("INDI_LAM_MARGIN: ")
    values = {n: _shortest(plain[n]) for n in CONFIG_PARAMS}
    return Configuration(values, overrides, verdict)


def inputs_of(values: dict[str, float | int]) -> Inputs:
    """The analysis inputs of a configuration. K's range is the box of the K the INDI flies (registry.flown_k_bounds:
    INDI_LAM_REF and INDI_KFL_MIN move it off the estimate's Eq. 20 box), which the eigenvalue sweep, the margin and
    the LMI's corners analyse; at the defaults it is [INDI_K_MIN, INDI_K_MAX]."""
    from navig8_fc.params.registry import flown_k_bounds

    k_lo, k_hi = flown_k_bounds(values)
    return Inputs(float(values["ACT_WN"]), float(values["ACT_ZETA"]), 1.0 / float(values["INDI_RATE_HZ"]),
                  float(values["INDI_LPF_TAU"]), k_lo, k_hi,
                  float(values["INDI_LAMBDA_MIN"]), float(values["INDI_LAM_MARGIN"]), int(values["INDI_U0_SRC"]),
                  float(values["INDI_U0_TAU"]))


def _lam_key(lam: float) -> str:
    return str(float(lam))  # "0.1", "1.0", "2.0"


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _pairs(z: np.ndarray) -> list[list[float]]:
    return [[float(v.real), float(v.imag)] for v in np.asarray(z, dtype=complex)]


def _step_dict(m: st.StepMetrics) -> dict[str, Any]:
    return {
        "stable": m.stable,
        "overshoot_pct": _finite_or_none(m.overshoot_pct),
        "settling_s": _finite_or_none(m.settling_s),
        "peak_time_s": _finite_or_none(m.peak_time_s),
        "rise_time_s": _finite_or_none(m.rise_time_s),
    }


def loop_report(wn: float, zeta: float, ts: float, tl: float) -> dict[str, Any]:
    """lambda_crit, lambda_upper, zeros, poles and step metrics of H(s) (Eq. 13) at REPORT_LAMBDAS."""
    p = (wn, zeta, ts, tl)
    return {
        "wn_rad_s": wn, "zeta": zeta, "ts_s": ts, "tl_s": tl,
        "lambda_crit": st.lambda_crit(*p),
        "lambda_upper": _finite_or_none(st.lambda_upper(*p)),
        "zeros": [float(z) for z in st.zeros(*p)],
        "poles_at_lambda": {_lam_key(lam): _pairs(st.poles(lam, *p)) for lam in REPORT_LAMBDAS},
        "step": {_lam_key(lam): _step_dict(st.step_metrics(lam, *p)) for lam in REPORT_LAMBDAS},
    }


def mismatch_table(inp: Inputs, factors: Sequence[float] = MISMATCH_FACTORS) -> list[dict[str, Any]]:
    """lambda_crit with the plant's actuator bandwidth factor x ACT_WN (same zeta) for U0 measured (Eq. 9 with the
    true actuators), model-based with INDI_U0_TAU and model alone (core.stability.lambda_crit_model_u0), and the
    sampled loop's rotational and force modes with the model-based U0 (sampled_lambda_crit)."""
    wn, z, ts, tl = inp.wn_rad_s, inp.zeta, inp.ts_s, inp.tl_s
    rows = []
    for f in factors:
        wp = f * wn
        row: dict[str, Any] = {
            "plant_wn_factor": f,
            "plant_wn_rad_s": wp,
            "measured_u0": st.lambda_crit(wp, z, ts, tl),
            "model_u0": st.lambda_crit_model_u0(wn, z, ts, tl, wp, z, inp.u0_tau_s),
            "model_u0_alone": st.lambda_crit_model_u0(wn, z, ts, tl, wp, z),
        }
        for ch in CHANNELS:
            row[f"sampled_{ch}"] = sampled_lambda_crit(wn, z, 1.0 / ts, tl, ch, wp, z, "model", inp.u0_tau_s)
        rows.append(row)
    return rows


def analyse(inp: Inputs, cfg: VehicleConfig, verdict: str | None = None) -> dict[str, Any]:
    """Everything the report prints, as one JSON-ready dict."""
    p = (inp.wn_rad_s, inp.zeta, inp.ts_s, inp.tl_s)
    loop = loop_report(*p)
    lam_crit = loop["lambda_crit"]
    t0 = time.perf_counter()
    kb = k_xi.k_bounds_analysis(cfg, inp.k_min, inp.k_max)
    kb_s = time.perf_counter() - t0
    k_bounds = _k_bounds_report(kb, kb_s, inp, lam_crit)
    # The same worst case for the matrix the paper's loop flies (INDI feedback at O: K Xi T^-1)
    kb_o = k_xi.k_bounds_analysis(cfg, inp.k_min, inp.k_max, reference="o")
    k_bounds_flown_o = {
        "min_eigenvalue": kb_o.min_eigenvalue,
        "pose_deg": [math.degrees(v) for v in kb_o.pose_rad],
        "object_mass_kg": kb_o.object_mass_kg,
        "k": list(kb_o.k),
        "max_eigenvalue": kb_o.max_eigenvalue,
        "max_abs_imag": kb_o.max_abs_imag,
        "stable_margin_ok": kb_o.min_eigenvalue > lam_crit,
    }
    margin = _margin_report(inp, cfg, kb, lam_crit, verdict)
    model_u0 = {
        "u0_src": inp.u0_src,
        "u0_tau_s": inp.u0_tau_s,
        # the model right (plant = ACT_WN, ACT_ZETA): Eq. 9 again, whatever INDI_U0_TAU
        "lambda_crit_model_right": st.lambda_crit_model_u0(*p, inp.wn_rad_s, inp.zeta, inp.u0_tau_s),
        "mismatch": mismatch_table(inp),
    }
    rate = 1.0 / inp.ts_s
    sampled = {ch: sampled_lambda_crit(inp.wn_rad_s, inp.zeta, rate, inp.tl_s, ch) for ch in CHANNELS}
    reference = loop_report(*PAPER_LOOP)
    return {
        "k_bounds_flown_o": k_bounds_flown_o,
        "inputs": {
            "wn_rad_s": inp.wn_rad_s,
            "zeta": inp.zeta,
            "ts_s": inp.ts_s,
            "tl_s": inp.tl_s,
            "k_min": inp.k_min,
            "k_max": inp.k_max,
            "lambda_min": inp.lambda_min,
        },
        "lambda_crit": lam_crit,
        "lambda_upper": loop["lambda_upper"],
        "zeros": loop["zeros"],
        "poles_at_lambda": loop["poles_at_lambda"],
        "step": loop["step"],
        "step_band_pct": 100.0 * st.SETTLING_BAND,
        "k_bounds": k_bounds,
        "margin": margin,
        "model_u0": model_u0,
        "sampled_lambda_crit": sampled,
        "reference": reference,
        "reference_sampled_lambda_crit": {ch: sampled_lambda_crit(PAPER_LOOP[0], PAPER_LOOP[1], 1.0 / PAPER_LOOP[2],
                                                                     PAPER_LOOP[3], ch) for ch in CHANNELS},
    }


def _k_bounds_report(kb: k_xi.KBoundsResult, kb_s: float, inp: Inputs, lam_crit: float) -> dict[str, Any]:
    """The eigenvalues of K Xi over the workspace and the K box (k_xi.k_bounds_analysis, which took kb_s seconds),
    JSON-ready."""
    p = (inp.wn_rad_s, inp.zeta, inp.ts_s, inp.tl_s)
    worst_c = kb.max_imag_eigenvalue
    return {
        "min_eigenvalue": kb.min_eigenvalue,
        "pose_deg": [math.degrees(v) for v in kb.pose_rad],
        "object_mass_kg": kb.object_mass_kg,
        "k": list(kb.k),
        "eigenvalues_at_min": _pairs(np.array(kb.eigenvalues_at_min)),
        "max_eigenvalue": kb.max_eigenvalue,
        "max_abs_imag": kb.max_abs_imag,
        "max_imag_eigenvalue": [worst_c.real, worst_c.imag],
        "max_imag_pose_deg": [math.degrees(v) for v in kb.max_imag_pose_rad],
        "max_imag_object_mass_kg": kb.max_imag_object_mass_kg,
        "max_imag_k": list(kb.max_imag_k),
        # Eq. 9 with the complex eigenvalue itself: is H still stable there? (notes 6.1 item 4)
        "max_real_pole_at_max_imag_eigenvalue": st.max_real_pole(worst_c, *p),
        "complex_fraction": kb.complex_fraction,
        "max_xi_block_coupling": kb.max_xi_block_coupling,
        "n_poses": kb.n_poses,
        "n_masses": kb.n_masses,
        "n_k": kb.n_k,
        "n_cases": kb.n_cases,
        "runtime_s": kb_s,
        "stable_margin_ok": kb.min_eigenvalue > lam_crit,
        "above_lambda_min": kb.min_eigenvalue >= inp.lambda_min,
    }


def _margin_report(inp: Inputs, cfg: VehicleConfig, kb: k_xi.KBoundsResult, lam_crit: float,
                   verdict: str | None) -> dict[str, Any]:
    """The stated margin (INDI_LAM_MARGIN) against the guaranteed minimum eigenvalue, JSON-ready."""
    p = (inp.wn_rad_s, inp.zeta, inp.ts_s, inp.tl_s)
    # The stated margin: the registry's floor computation (the coarse workspace sweep) against lambda_crit.
    guaranteed = k_xi.min_eigenvalue_over_workspace(cfg, inp.k_min, inp.k_max)
    ratio = guaranteed / lam_crit if lam_crit > 0.0 else math.inf
    at_g = st.step_metrics(guaranteed, *p) if guaranteed > 0.0 else None
    return {
        "realtime_link": _realtime_link_report(inp, guaranteed),
        "lambda_crit": lam_crit,
        "lambda_min": inp.lambda_min,
        "guaranteed_min_eigenvalue": guaranteed,
        "margin": _finite_or_none(ratio),
        "required_margin": inp.lam_margin,
        "meets_margin": ratio >= inp.lam_margin,
        "full_sweep_margin": kb.min_eigenvalue / lam_crit if lam_crit > 0.0 else None,
        "step_at_guaranteed": _step_dict(at_g) if at_g is not None else None,
        "registry_verdict": verdict,
    }


def _realtime_link_report(inp: Inputs, guaranteed: float) -> dict[str, Any]:
    """The loop over a real-time link, whose answer to the sample at t_k flies from t_k+2 (docs/hil.md): the sampled
    loop's lambda_crit with one more tick of delay (sampled_loop_matrix's link_delay_ticks), the actuator model told
    which command flew (the bridge's echo) and blind, and the guaranteed eigenvalue's margin against it. The registry's
    floor in force follows a real-time FC's measured link (docs/stability.md, "Over a real-time link"); this is what the
    configuration has left over a link one tick late."""
    src = "model" if inp.u0_src == 1 else "measured"
    args = (inp.wn_rad_s, inp.zeta, 1.0 / inp.ts_s, inp.tl_s)
    told = {ch: sampled_lambda_crit(*args, ch, None, None, src, inp.u0_tau_s, link_delay_ticks=1) for ch in CHANNELS}
    # the measured U0 reads no actuator model: told or not, the same loop
    blind = told if src == "measured" else {
        ch: sampled_lambda_crit(*args, ch, None, None, src, inp.u0_tau_s, link_delay_ticks=1, model_told=False)
        for ch in CHANNELS}
    worst = max(told.values())
    ratio = guaranteed / worst
    return {"sampled_lambda_crit": told, "sampled_lambda_crit_blind": blind, "margin": _finite_or_none(ratio),
            "meets_margin": ratio >= inp.lam_margin}


def lmi_report(inp: Inputs, cfg: VehicleConfig, acc_ref: int, bisection_steps: int = 3) -> dict[str, Any]:
    """The common quadratic Lyapunov function of the coupled loop over the K corners x the pose/object grid
    (core.varying_k.varying_k_lmi) for the configured loop, JSON-ready. acc_ref: INDI_ACC_REF (0: Xi T^-1 at O)."""
    loop = vk.LoopConfig(inp.wn_rad_s, inp.zeta, 1.0 / inp.ts_s, inp.tl_s, inp.k_min, inp.k_max,
                         "model" if inp.u0_src == 1 else "measured", inp.u0_tau_s, "o" if acc_ref == 0 else "com")
    poses, masses, offsets = vk.default_grid(cfg, inp.k_min)
    t0 = time.perf_counter()
    r = vk.varying_k_lmi(cfg, loop, poses, masses, offsets, bisection_steps=bisection_steps)
    runtime = time.perf_counter() - t0

    def blk(b: vk.BlockResult) -> dict[str, Any]:
        ly = b.lyapunov
        return {"name": b.name, "n_vertices": b.n_vertices, "state_dim": ly.state_dim, "feasible": ly.feasible,
                "rate": ly.rate, "max_spectral_radius": ly.max_spectral_radius, "status": ly.status,
                "failing": [v.text() for v in b.failing],
                "certificate_residual": None if ly.certificate_residual is None else
                _finite_or_none(ly.certificate_residual)}

    return {
        "feasible": r.feasible,
        "n_vertices": r.n_vertices,
        "state_dim": r.state_dim,
        "rate": r.rate,
        "decay_time_s": r.decay_time_s,
        "max_spectral_radius": r.max_spectral_radius,
        "max_spectral_radius_vertex": r.max_spectral_radius_vertex.text(),
        "failing": [v.text() for v in r.failing],
        "failing_block": r.failing_block,
        "certificate_residual": None if r.certificate_residual is None else _finite_or_none(r.certificate_residual),
        "blocks": [blk(b) for b in r.blocks],
        "xi_block_coupling": r.xi_block_coupling,
        "grid": {"poses": int(poses.shape[0]), "object_masses_kg": [float(m) for m in masses],
                 "object_offsets_m": [float(o) for o in offsets], "k_corners": 16},
        "loop": {"rate_hz": loop.rate_hz, "tl_s": loop.tl_s, "u0_source": loop.u0_source,
                 "u0_tau_s": _finite_or_none(loop.u0_tau_s), "reference": loop.reference},
        "n_sdp": r.n_sdp,
        "sdp_time_s": r.sdp_time_s,
        "runtime_s": runtime,
    }


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="navig8-stability", description=__doc__.split("\n\n")[0])
    ap.add_argument("--params", action="append", default=[], metavar="FILE",
                    help="a parameter set (.parm), e.g. params/presets/paper.parm; applied before --set")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override a parameter")
    ap.add_argument("--wn", type=float, default=None, help="analysis input: actuator natural frequency, rad/s")
    ap.add_argument("--zeta", type=float, default=None, help="analysis input: actuator damping ratio")
    ap.add_argument("--ts", type=float, default=None, help="analysis input: sampling time tau_s, s")
    ap.add_argument("--tl", type=float, default=None, help="analysis input: LPF time constant tau_L, s")
    ap.add_argument("--k-min", type=float, default=None, help="analysis input: lower bound of K_i")
    ap.add_argument("--k-max", type=float, default=None, help="analysis input: upper bound of K_i")
    ap.add_argument("--lambda-min", type=float, default=None, help="analysis input: desired min eigenvalue")
    ap.add_argument("--lmi", action="store_true",
                    help="add the common Lyapunov function (LMI) of the loop flown while K varies (~45 s)")
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    ap.add_argument("--plots", type=Path, default=None, metavar="DIR", help="write fig5/6/7 PNGs to DIR")
    args = ap.parse_args(argv)
    try:
        conf = configuration(args.params, args.set)
    except (OSError, ValueError) as exc:
        ap.error(str(exc))
    inp = inputs_of(conf.values)
    direct = {"wn_rad_s": args.wn, "zeta": args.zeta, "ts_s": args.ts, "tl_s": args.tl, "k_min": args.k_min,
              "k_max": args.k_max, "lambda_min": args.lambda_min}
    direct = {k: v for k, v in direct.items() if v is not None}
    inp = replace(inp, **direct)
    cfg = VehicleConfig.load()
    try:
        # --wn ... override the analysis inputs, not the parameters: the registry's verdict does not apply then
        report = analyse(inp, cfg, None if direct else conf.verdict)
    except ValueError as e:
        print(f"navig8-stability: {e}", file=sys.stderr)
        return 2
    if not direct:
        report["configuration"] = {"values": conf.values, "overrides": conf.overrides, "verdict": conf.verdict}
    if args.lmi:
        report["lmi"] = lmi_report(inp, cfg, int(conf.values["INDI_ACC_REF"]))
    if args.plots is not None:
        paths = write_plots(inp, cfg, args.plots, report["lambda_crit"])
        report["plots"] = [str(p) for p in paths]
    if args.json:
        print(json.dumps(report, allow_nan=False))
    else:
        print(render_text(report))
        for path in report.get("plots", []):
            print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
