"""The text of navig8-stability's report (tools/stability_report.py): the configured loop next to the paper's
Section 3 constants, H(s)'s poles and step responses, the eigenvalues of K Xi, the stated margin, the model-based
U0 over an actuator-bandwidth mismatch and, with --lmi, the common Lyapunov function. docs/stability.md.
"""

from __future__ import annotations

from typing import Any


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
        if v.get("INDI_LAM_REF", 1.0) != 1.0 or v.get("INDI_KFL_MIN", 0.0) > 0.0:
            lines.append(f"  K is the flown K: max(INDI_LAM_REF {v['INDI_LAM_REF']:g} x K_hat, INDI_KFL_MIN "
                         f"{v['INDI_KFL_MIN']:g}) on the rotational axes, K_hat in [{v['INDI_K_MIN']:g}, "
                         f"{v['INDI_K_MAX']:g}] (the estimate's Eq. 20 box)")
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
        *_realtime_link_lines(m),
    ]
    if "configuration" in r:
        out.append("  registry: a PARAM_SET to this configuration is "
                   + ("accepted" if verdict is None else f"refused: {verdict}"))
    return out


def _realtime_link_lines(m: dict[str, Any]) -> list[str]:
    rt = m["realtime_link"]
    told, blind = rt["sampled_lambda_crit"], rt["sampled_lambda_crit_blind"]
    ratio = "inf" if rt["margin"] is None else f"{rt['margin']:.3f}"
    return [
        "  over a real-time link (the answer flown one tick later, docs/hil.md): sampled loop lambda_crit "
        f"rot. {told['rotational']:.4f}, force {told['force']:.4f}",
        f"    (the actuator model not told which command flew: rot. {blind['rotational']:.4f}, "
        f"force {blind['force']:.4f})",
        f"    margin = guaranteed / {max(told.values()):.4f} = {ratio}; required >= {m['required_margin']:g}: "
        f"{'yes' if rt['meets_margin'] else 'NO'} (a real-time FC measures its link's delay and judges that loop;",
        "    with INDI_KFL_LINK 1 it raises the flown K's floor to the least that meets the margin: docs/stability.md)",
    ]


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
