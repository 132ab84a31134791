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

REPORT_LAMBDAS = (0.1, 0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0)
FIG6_LAMBDAS = (0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0)


# The paper's Section 3 constants (Sec. 3.1: wn 120 rad/s, zeta 1, tau_s 0.01 s, tau_L 0.1 s): the reference column.
PAPER_LOOP = (120.0, 1.0, 0.01, 0.1)
# Plant actuator bandwidth / ACT_WN for the mismatch table (the plant's actuators +-40 % off the FC's model).
MISMATCH_FACTORS = (0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4)
CONFIG_PARAMS = ("ACT_WN", "ACT_ZETA", "INDI_RATE_HZ", "INDI_LPF_TAU", "INDI_K_MIN", "INDI_K_MAX", "INDI_LAMBDA_MIN",
                 "INDI_LAM_MARGIN", "INDI_U0_SRC", "INDI_U0_TAU", "INDI_ACC_REF")


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
    return Inputs(float(values["ACT_WN"]), float(values["ACT_ZETA"]), 1.0 / float(values["INDI_RATE_HZ"]),
                  float(values["INDI_LPF_TAU"]), float(values["INDI_K_MIN"]), float(values["INDI_K_MAX"]),
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
    worst_c = kb.max_imag_eigenvalue
    k_bounds = {
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
    # The stated margin: the registry's floor computation (the coarse workspace sweep) against lambda_crit.
    guaranteed = k_xi.min_eigenvalue_over_workspace(cfg, inp.k_min, inp.k_max)
    ratio = guaranteed / lam_crit if lam_crit > 0.0 else math.inf
    at_g = st.step_metrics(guaranteed, *p) if guaranteed > 0.0 else None
    margin = {
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


def _fmt_c(re: float, im: float) -> str:
    if abs(im) < 1e-9:
        return f"{re:.3f}"
    return f"{re:.3f}{im:+.3f}j"


def _fmt_poles(pls: list[list[float]]) -> list[str]:
    """Poles as text, a conjugate pair written once as "re +- im j"."""
    out: list[str] = []
    i = 0
    while i < len(pls):
        re, im = pls[i]
        if abs(im) > 1e-9 and i + 1 < len(pls) and abs(pls[i + 1][1] + im) <= 1e-9 * max(1.0, abs(im)):
            out.append(f"{re:.3f} +- {abs(im):.3f}j")
            i += 2
        else:
            out.append(_fmt_c(re, im))
            i += 1
    return out


def _fmt_opt(x: float | None, fmt: str) -> str:
    return "     -" if x is None else format(x, fmt)


def render_text(r: dict[str, Any]) -> str:
    i = r["inputs"]
    lam_up = "inf (stable to the scan end, 100)" if r["lambda_upper"] is None else f"{r['lambda_upper']:.4f}"
    lines = [
        "Navig8 INDI stability analysis (paper Sec. 3.1-3.2, Eq. 9-20)",
        f"  actuator wn = {i['wn_rad_s']:g} rad/s, zeta = {i['zeta']:g}; tau_s = {i['ts_s']:g} s; "
        f"tau_L = {i['tl_s']:g} s; K in [{i['k_min']:g}, {i['k_max']:g}]; lambda_min = {i['lambda_min']:g}",
    ]
    conf = r.get("configuration")
    if conf is not None:
        v = conf["values"]
        lines += [
            "  configured values (defaults, then --params, then --set): "
            + ", ".join(f"{n} {v[n]:g}" for n in v),
            "  changed from the defaults: "
            + (", ".join(f"{n}={x:g}" for n, x in conf["overrides"].items()) or "nothing"),
        ]
    if "reference" in r:
        lines += ["", *_side_by_side(r)]
    lines += [
        "",
        "H_i(s) (Eq. 13), configured",
        f"  lambda_crit  = {r['lambda_crit']:.4f}   (H stable for lambda in (lambda_crit, 1])",
        f"  lambda_upper = {lam_up}",
        "  zeros        = " + ", ".join(f"{z:g}" for z in r["zeros"]) + "  (independent of lambda)",
        "",
        f"  {'lambda':>6}  {'overshoot %':>11}  {'settle 2% s':>11}  {'dominant':>20}  other poles",
    ]
    for key, pls in r["poles_at_lambda"].items():
        txt = _fmt_poles(pls)
        s = r["step"][key]
        os_txt = _fmt_opt(s["overshoot_pct"], "11.1f") if s["stable"] else "   unstable"
        st_txt = _fmt_opt(s["settling_s"], "11.3f") if s["stable"] else "   unstable"
        lines.append(f"  {key:>6}  {os_txt:>11}  {st_txt:>11}  {txt[0]:>20}  {', '.join(txt[1:])}")
    kb = r["k_bounds"]
    pose = "/".join(f"{v:.0f}" for v in kb["pose_deg"])
    pose_c = "/".join(f"{v:.0f}" for v in kb["max_imag_pose_deg"])
    lines += [
        "",
        f"Eigenvalues of G_hat G^-1 = K Xi (Eq. 14-20): {kb['n_poses']} poses x {kb['n_masses']} "
        f"object masses x {kb['n_k']} K = {kb['n_cases']} 5x5 cases in {kb['runtime_s']:.2f} s",
        f"  min Re(eig)   = {kb['min_eigenvalue']:.4f} at q = {pose} deg, m_o = {kb['object_mass_kg']:g} kg, "
        f"K = ({', '.join(f'{k:g}' for k in kb['k'])})",
        f"  max Re(eig)   = {kb['max_eigenvalue']:.4f}",
        f"  max |Im(eig)| = {kb['max_abs_imag']:.4f} (eigenvalue {_fmt_c(*kb['max_imag_eigenvalue'])} at "
        f"q = {pose_c} deg, m_o = {kb['max_imag_object_mass_kg']:g} kg, K = "
        f"({', '.join(f'{k:g}' for k in kb['max_imag_k'])})); "
        f"complex in {100 * kb['complex_fraction']:.1f} % of cases",
        "  H(s) at that complex eigenvalue (Eq. 9 with complex lambda): max Re(pole) = "
        f"{kb['max_real_pole_at_max_imag_eigenvalue']:.3f} 1/s",
        f"  Xi block coupling (longitudinal rows, lateral columns) = {kb['max_xi_block_coupling']:.1e}",
        f"  min eigenvalue > lambda_crit: {'yes' if kb['stable_margin_ok'] else 'NO'};  "
        f">= lambda_min: {'yes' if kb['above_lambda_min'] else 'no'}",
    ]
    ko = r.get("k_bounds_flown_o")
    if ko is not None:
        pose_o = "/".join(f"{v:.0f}" for v in ko["pose_deg"])
        lines += [
            "The matrix the paper's loop flies (INDI force feedback at O, INDI_ACC_REF = 0): K Xi T^-1",
            f"  min Re(eig)   = {ko['min_eigenvalue']:.4f} at q = {pose_o} deg, m_o = {ko['object_mass_kg']:g} kg;"
            f"  max Re(eig) = {ko['max_eigenvalue']:.4f};  > lambda_crit: {'yes' if ko['stable_margin_ok'] else 'NO'}",
        ]
    if "margin" in r:
        lines += ["", *_margin_lines(r), "", *_model_u0_lines(r)]
    if "lmi" in r:
        lines += ["", *_lmi_lines(r["lmi"])]
    return "\n".join(lines)


def _os(step: dict[str, Any] | None) -> str:
    if step is None or not step["stable"]:
        return "unstable"
    return f"{step['overshoot_pct']:.1f} % / {step['settling_s']:.3f} s"


def _side_by_side(r: dict[str, Any]) -> list[str]:
    ref, i = r["reference"], r["inputs"]
    sr, sc = r["reference_sampled_lambda_crit"], r["sampled_lambda_crit"]
    rows = [
        ("wn, zeta, tau_s, tau_L", f"{ref['wn_rad_s']:g}, {ref['zeta']:g}, {ref['ts_s']:g}, {ref['tl_s']:g}",
         f"{i['wn_rad_s']:g}, {i['zeta']:g}, {i['ts_s']:g}, {i['tl_s']:g}"),
        ("lambda_crit (Eq. 13, Pade)", f"{ref['lambda_crit']:.4f}", f"{r['lambda_crit']:.4f}"),
        ("sampled loop lambda_crit, rot.", f"{sr['rotational']:.4f}", f"{sc['rotational']:.4f}"),
        ("sampled loop lambda_crit, force", f"{sr['force']:.4f}", f"{sc['force']:.4f}"),
        ("zeros", ", ".join(f"{z:g}" for z in ref["zeros"]), ", ".join(f"{z:g}" for z in r["zeros"])),
        ("lambda_min / lambda_crit", f"{i['lambda_min'] / ref['lambda_crit']:.2f}",
         f"{i['lambda_min'] / r['lambda_crit']:.2f}"),
    ]
    for key in ("0.3", "0.5", "1.0"):
        rows.append((f"step at lambda {key}: OS / 2 % settle", _os(ref["step"][key]), _os(r["step"][key])))
    rows.append(("dominant pole(s) at lambda 0.5", _fmt_poles(ref["poles_at_lambda"]["0.5"])[0],
                 _fmt_poles(r["poles_at_lambda"]["0.5"])[0]))
    out = [f"  {'':34}  {'paper Sec. 3 (reference)':>26}  {'configured':>26}"]
    out += [f"  {a:34}  {b:>26}  {c:>26}" for a, b, c in rows]
    return ["The configured loop next to the paper's Section 3 constants", *out]


def _margin_lines(r: dict[str, Any]) -> list[str]:
    m = r["margin"]
    ratio = "inf" if m["margin"] is None else f"{m['margin']:.3f}"
    full = "-" if m["full_sweep_margin"] is None else f"{m['full_sweep_margin']:.3f}"
    verdict = m["registry_verdict"]
    out = [
        "Stated margin (INDI_LAM_MARGIN; the registry's stability floor)",
        f"  lambda_crit = {m['lambda_crit']:.4f};  lambda_min (INDI_LAMBDA_MIN) = {m['lambda_min']:g}",
        f"  guaranteed min Re eig(G_hat G^-1) over the K box and the workspace (the registry's sweep) = "
        f"{m['guaranteed_min_eigenvalue']:.4f}",
        f"  margin = guaranteed / lambda_crit = {ratio} (the full sweep's minimum gives {full}); "
        f"required >= {m['required_margin']:g}: {'yes' if m['meets_margin'] else 'NO'}",
        f"  step at the guaranteed min eigenvalue: overshoot / 2 % settling {_os(m['step_at_guaranteed'])}",
    ]
    if "configuration" in r:
        out.append("  registry: a PARAM_SET to this configuration is "
                   + ("accepted" if verdict is None else f"refused: {verdict}"))
    return out


def _model_u0_lines(r: dict[str, Any]) -> list[str]:
    mu = r["model_u0"]
    state = "in force" if mu["u0_src"] == 1 else "not in force"
    tau = mu["u0_tau_s"]
    out = [
        f"Model-based U0 (INDI_U0_SRC = 1, {state}; INDI_U0_TAU = {tau:g} s)",
        f"  with the actuator model right: lambda_crit = {mu['lambda_crit_model_right']:.4f} (Eq. 9: the loop "
        "is unchanged)",
        "  lambda_crit with the plant's actuators off ACT_WN (same zeta):",
        f"  {'plant wn':>14}  {'U0 measured':>11}  {'model, tau ' + format(tau, 'g'):>14}  {'model alone':>11}  "
        f"{'sampled rot.':>12}  {'sampled force':>13}",
    ]
    for row in mu["mismatch"]:
        f = row["plant_wn_factor"]
        label = f"{f:.1f} x = {row['plant_wn_rad_s']:g}"
        out.append(f"  {label:>14}  {row['measured_u0']:11.4f}  "
                   f"{row['model_u0']:14.4f}  {row['model_u0_alone']:11.4f}  {row['sampled_rotational']:12.4f}  "
                   f"{row['sampled_force']:13.4f}")
    return out


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


def _lmi_lines(m: dict[str, Any]) -> list[str]:
    g = m["grid"]
    verdict = {True: "FEASIBLE: one P for every vertex", False: "INFEASIBLE: no common P on the grid",
               None: "UNDECIDED (the solver could not tell)"}[m["feasible"]]
    ref = "the estimated CoM" if m["loop"]["reference"] == "com" else "O (K Xi T^-1)"
    out = [
        "The loop flown while K varies: a common quadratic Lyapunov function (LMI A_i' P A_i <= rho^2 P)",
        f"  coupled loop, {m['state_dim']} states (5 rows of Eq. 7 x 7), U0 {m['loop']['u0_source']}, "
        f"feedback at {ref}",
        f"  vertices: 16 K corners x {g['poses']} poses x object masses "
        + "/".join(f"{v:g}" for v in g["object_masses_kg"]) + " kg x offsets "
        + "/".join(f"{v:g}" for v in g["object_offsets_m"]) + f" m = {m['n_vertices']} distinct",
        "    (lifted in K^-1, so the K corners are exact vertices; the pose/object cases are a grid)",
        f"  frozen-time: max spectral radius {m['max_spectral_radius']:.4f} per tick "
        f"({m['max_spectral_radius_vertex']})",
        f"  result: {verdict}",
    ]
    if m["rate"] is not None:
        out.append(f"  decay rate: V^(1/2) shrinks by {m['rate']:.5f} per tick at least (e-folding time "
                   f"{m['decay_time_s']:.3f} s) for any K(t) in the box, switching among the grid's cases")
    if m["failing"]:
        out.append(f"  vertices that share no P ({m['failing_block']} block; infeasibility certificate residual "
                   f"{m['certificate_residual']:.1e}):")
        out += [f"    {v}" for v in m["failing"]]
    for b in m["blocks"]:
        state = {True: "common P", False: "no common P", None: "undecided"}[b["feasible"]]
        rate = "" if b["rate"] is None else f", rate {b['rate']:.5f} per tick"
        out.append(f"  {b['name']} block ({b['state_dim']} states, {b['n_vertices']} distinct vertices): {state}"
                   f"{rate} (max spectral radius {b['max_spectral_radius']:.4f})")
    out.append(f"  {m['n_sdp']} SDPs (clarabel {m['sdp_time_s']:.1f} s), {m['runtime_s']:.1f} s in all")
    return out


def write_plots(inp: Inputs, cfg: VehicleConfig, out_dir: Path, lam_crit: float) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    p = (inp.wn_rad_s, inp.zeta, inp.ts_s, inp.tl_s)
    written: list[Path] = []

    # Fig. 5: poles of H(s) as lambda varies.
    lams = np.geomspace(max(0.5 * lam_crit, 0.02), 2.0, 400)
    pl = np.array([st.poles(lam, *p) for lam in lams])
    z = st.zeros(*p)
    fig, axes = plt.subplots(1, 2, figsize=(12, 5))
    for ax, xlim in zip(axes, (None, (-60.0, 10.0)), strict=True):
        sc = None
        for k in range(pl.shape[1]):
            sc = ax.scatter(
                pl[:, k].real, pl[:, k].imag, c=lams, s=4, cmap="viridis", norm=matplotlib.colors.LogNorm()
            )
        ax.plot(z, np.zeros_like(z), "o", mfc="none", mec="r", ms=9, label="zeros")
        for lam in (lam_crit, 0.5, 1.0):
            pk = st.poles(lam, *p)
            ax.plot(pk.real, pk.imag, "kx", ms=7)
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_xlabel("Re(s) [1/s]")
        ax.set_ylabel("Im(s) [rad/s]")
        ax.grid(True, alpha=0.3)
        if xlim is not None:
            ax.set_xlim(*xlim)
            ax.set_title(f"zoom: dominant pair crosses at lambda_crit = {lam_crit:.4f}")
        else:
            ax.set_title("Poles of H(s) vs lambda (x: lambda_crit, 0.5, 1)")
        ax.legend(loc="upper left")
        fig.colorbar(sc, ax=ax, label="lambda")
    fig.suptitle(f"Fig. 5: wn={inp.wn_rad_s:g}, zeta={inp.zeta:g}, tau_s={inp.ts_s:g}, tau_L={inp.tl_s:g}")
    fig.tight_layout()
    written.append(out_dir / "fig5_poles.png")
    fig.savefig(written[-1], dpi=110)
    plt.close(fig)

    # Fig. 6: step responses of H(s).
    fig, ax = plt.subplots(figsize=(9, 5.5))
    for lam in FIG6_LAMBDAS:
        if st.max_real_pole(lam, *p) >= 0.0:
            continue
        t, y = st.step_response(lam, *p, t_end_s=1.0, n_samples=4001)
        m = st.step_metrics(lam, *p)
        ax.plot(t, y, label=f"lambda={lam:g}: OS {m.overshoot_pct:.0f} %, t_s {m.settling_s:.2f} s")
    band = st.SETTLING_BAND
    ax.axhspan(1 - band, 1 + band, color="grey", alpha=0.2, label="+-2 % band")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("s chi / upsilon (acceleration / command)")
    ax.set_title("Fig. 6: step response of H(s) at different lambda")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    written.append(out_dir / "fig6_step.png")
    fig.savefig(written[-1], dpi=110)
    plt.close(fig)

    # Fig. 7: lam_4, lam_5 over (K1, K3) for the stretched and curled arm with a 2 kg object.
    kg = np.linspace(inp.k_min, inp.k_max, 41)
    fig = plt.figure(figsize=(12, 10))
    cases = (("stretched", k_xi.POSE_STRETCHED_DEG), ("curled", k_xi.POSE_CURLED_DEG))
    panel = iter("abcd")
    for row, (name, q_deg) in enumerate(cases):
        s = k_xi.lateral_eigenvalue_surfaces(cfg, np.radians(q_deg), k_xi.FIG7_OBJECT_MASS_KG, kg, kg)
        for col, (lab, val) in enumerate((("lambda_4", s.lam4), ("lambda_5", s.lam5))):
            ax = fig.add_subplot(2, 2, 2 * row + col + 1, projection="3d")
            re = val.real
            ax.plot_surface(s.k1, s.k3, re, cmap="viridis", edgecolor="none", alpha=0.9)
            ax.plot_surface(s.k1, s.k3, np.full_like(re, inp.lambda_min), color="r", alpha=0.15)
            i = np.unravel_index(int(np.argmin(re)), re.shape)
            ax.scatter([s.k1[i]], [s.k3[i]], [re[i]], color="r", s=20)
            ax.set_xlabel("K1")
            ax.set_ylabel("K3")
            ax.set_zlabel(f"Re {lab}")
            q_txt = "/".join(f"{v:g}" for v in q_deg)
            ax.set_title(
                f"({next(panel)}) {lab}, {name} {q_txt} deg, 2 kg\nmin {re[i]:.4f} at K1={s.k1[i]:.2f}, "
                f"K3={s.k3[i]:.2f}; max|Im| {np.abs(val.imag).max():.3f}",
                fontsize=9,
            )
    fig.suptitle("Fig. 7: eigenvalues lambda_4, lambda_5 of K Xi over (K1, K3); red plane: lambda_min")
    fig.tight_layout()
    written.append(out_dir / "fig7_k_bounds.png")
    fig.savefig(written[-1], dpi=110)
    plt.close(fig)
    return written


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
