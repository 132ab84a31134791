"""navig8-stability: the stability analysis of paper Sec. 3.1-3.2 (Eq. 9-20, Figs. 5-7) for given constants.

    navig8-stability [--wn W] [--zeta Z] [--ts T] [--tl L] [--k-min K] [--k-max K] [--json] [--plots DIR]

Defaults come from the parameter registry (params/fc_params.yaml): ACT_WN, ACT_ZETA, 1/INDI_RATE_HZ,
INDI_LPF_TAU, INDI_K_MIN, INDI_K_MAX, INDI_LAMBDA_MIN. The math lives in navig8_fc.core.stability;
this file only formats it. See docs/stability.md.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from navig8_fc.core import stability as st
from navig8_fc.core.vehicle import VehicleConfig

REPORT_LAMBDAS = (0.1, 0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0)
FIG6_LAMBDAS = (0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0)


@dataclass(frozen=True)
class Inputs:
    wn_rad_s: float
    zeta: float
    ts_s: float
    tl_s: float
    k_min: float
    k_max: float
    lambda_min: float


def _registry_defaults() -> dict[str, float]:
    from navig8_fc.params.registry import ParamRegistry

    # The stability floor is not needed to read defaults; skip building its checker.
    reg = ParamRegistry.from_defaults(check_stability=False)

    def real(name: str) -> float:
        # The registry stores REAL32 values as float32 (what MAVLink carries): 0.1 -> 0.10000000149.
        # Take the shortest decimal that rounds to the same float32, i.e. the value in the YAML file.
        return float(str(np.float32(reg.get(name))))

    return {
        "wn": real("ACT_WN"),
        "zeta": real("ACT_ZETA"),
        "ts": 1.0 / float(reg.get("INDI_RATE_HZ")),
        "tl": real("INDI_LPF_TAU"),
        "k_min": real("INDI_K_MIN"),
        "k_max": real("INDI_K_MAX"),
        "lambda_min": real("INDI_LAMBDA_MIN"),
    }


def _lam_key(lam: float) -> str:
    return str(float(lam))  # "0.1", "1.0", "2.0"


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _pairs(z: np.ndarray) -> list[list[float]]:
    return [[float(v.real), float(v.imag)] for v in np.asarray(z, dtype=complex)]


def analyse(inp: Inputs, cfg: VehicleConfig) -> dict[str, Any]:
    """Everything the report prints, as one JSON-ready dict."""
    p = (inp.wn_rad_s, inp.zeta, inp.ts_s, inp.tl_s)
    lam_crit = st.lambda_crit(*p)
    lam_up = st.lambda_upper(*p)
    poles_at = {_lam_key(lam): _pairs(st.poles(lam, *p)) for lam in REPORT_LAMBDAS}
    step = {}
    for lam in REPORT_LAMBDAS:
        m = st.step_metrics(lam, *p)
        step[_lam_key(lam)] = {
            "stable": m.stable,
            "overshoot_pct": _finite_or_none(m.overshoot_pct),
            "settling_s": _finite_or_none(m.settling_s),
            "peak_time_s": _finite_or_none(m.peak_time_s),
            "rise_time_s": _finite_or_none(m.rise_time_s),
        }
    t0 = time.perf_counter()
    kb = st.k_bounds_analysis(cfg, inp.k_min, inp.k_max)
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
    # issue 10: the same worst case for the matrix the paper's loop flies (INDI feedback at O: K Xi T^-1)
    kb_o = st.k_bounds_analysis(cfg, inp.k_min, inp.k_max, reference="o")
    k_bounds_flown_o = {
        "min_eigenvalue": kb_o.min_eigenvalue,
        "pose_deg": [math.degrees(v) for v in kb_o.pose_rad],
        "object_mass_kg": kb_o.object_mass_kg,
        "k": list(kb_o.k),
        "max_eigenvalue": kb_o.max_eigenvalue,
        "max_abs_imag": kb_o.max_abs_imag,
        "stable_margin_ok": kb_o.min_eigenvalue > lam_crit,
    }
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
        "lambda_upper": _finite_or_none(lam_up),
        "zeros": [float(z) for z in st.zeros(*p)],
        "poles_at_lambda": poles_at,
        "step": step,
        "step_band_pct": 100.0 * st.SETTLING_BAND,
        "k_bounds": k_bounds,
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
        "",
        "H_i(s) (Eq. 13)",
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
            "The matrix the paper's loop flies (INDI force feedback at O, INDI_ACC_REF = 0): K Xi T^-1 (issue 10)",
            f"  min Re(eig)   = {ko['min_eigenvalue']:.4f} at q = {pose_o} deg, m_o = {ko['object_mass_kg']:g} kg;"
            f"  max Re(eig) = {ko['max_eigenvalue']:.4f};  > lambda_crit: {'yes' if ko['stable_margin_ok'] else 'NO'}",
        ]
    return "\n".join(lines)


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
    cases = (("stretched", st.POSE_STRETCHED_DEG), ("curled", st.POSE_CURLED_DEG))
    panel = iter("abcd")
    for row, (name, q_deg) in enumerate(cases):
        s = st.lateral_eigenvalue_surfaces(cfg, np.radians(q_deg), st.FIG7_OBJECT_MASS_KG, kg, kg)
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
    d = _registry_defaults()
    ap = argparse.ArgumentParser(prog="navig8-stability", description=__doc__.split("\n\n")[0])
    ap.add_argument("--wn", type=float, default=d["wn"], help="actuator natural frequency, rad/s (ACT_WN)")
    ap.add_argument("--zeta", type=float, default=d["zeta"], help="actuator damping ratio (ACT_ZETA)")
    ap.add_argument("--ts", type=float, default=d["ts"], help="sampling time tau_s, s (1/INDI_RATE_HZ)")
    ap.add_argument("--tl", type=float, default=d["tl"], help="LPF time constant tau_L, s (INDI_LPF_TAU)")
    ap.add_argument("--k-min", type=float, default=d["k_min"], help="lower bound of K_i (INDI_K_MIN)")
    ap.add_argument("--k-max", type=float, default=d["k_max"], help="upper bound of K_i (INDI_K_MAX)")
    ap.add_argument("--lambda-min", type=float, default=d["lambda_min"], help="desired min eigenvalue")
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    ap.add_argument("--plots", type=Path, default=None, metavar="DIR", help="write fig5/6/7 PNGs to DIR")
    args = ap.parse_args(argv)
    inp = Inputs(args.wn, args.zeta, args.ts, args.tl, args.k_min, args.k_max, args.lambda_min)
    cfg = VehicleConfig.load()
    try:
        report = analyse(inp, cfg)
    except ValueError as e:
        print(f"navig8-stability: {e}", file=sys.stderr)
        return 2
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
