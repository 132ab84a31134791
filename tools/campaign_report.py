"""The campaign report: Markdown + PNG figures from the campaign's table (navig8-campaign writes it at the end).

Sections: summary per variant (the robustness table), success rate by factor (table + figure), heat maps of the
loss-of-control rate and the median max attitude error over the campaign's `report.heatmap` factors per variant,
distributions of the metrics per variant, the worst runs with their replay commands, and the failed runs.

A generated campaign (`generator: envelope`) gets the envelope's sections instead of the generic worst runs:
per controller the loss-of-control rate, max attitude error quantiles, attitude RMS, bound violations and the
smallest eigenvalue; the controllers paired on the same draws; the worst 10 runs per controller with their
replays; and max attitude error against the run's authority bound (`authority: true`), where a loss whose
bound exceeds the loss threshold, or whose trim is infeasible, is "beyond authority": no controller flying this
actuator set could have held it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from navig8_tools.summary import LOST_ATT_DEG, LOST_POS_M  # what counts as a loss of control

# the drawn factors the success-by-factor section of a generated campaign shows (the others are in the table)
ENVELOPE_REPORT_FACTORS = ("pattern", "arm_shape", "object_mass_kg", "arm_speed_rad_s", "pitch_deg", "yaw_step_deg",
                           "tail_max_thrust_n", "actuator_bandwidth_scale", "sensor_noise_scale", "servo_model_error",
                           "grasp_pose", "release_pose")
# the factors shown beside each of the worst runs
WORST_FACTORS = ("pattern", "arm_shape", "object_mass_kg", "arm_speed_rad_s", "pitch_deg", "yaw_step_deg",
                 "tail_max_thrust_n", "actuator_bandwidth_scale")
PAIRS = (("proposed", "fixed"), ("proposed", "pinned"), ("proposed", "unconstrained"), ("proposed", "lms"))
TIE_DEG = 0.5  # paired max attitude errors closer than this are a tie
DIST_METRICS = (("max_att_error_deg", "max attitude error (deg)"), ("max_pos_error_m", "max position error (m)"),
                ("pos_rms_error_m", "position RMS error (m)"), ("min_eigenvalue", "min eig(G_hat G^-1)"))
MAX_LEVELS = 8  # a factor with more distinct values is binned into quartiles for the by-factor tables


def _levels(df: Any, col: str) -> Any:
    """The factor's values, or its quartile bins when it is continuous (a drawn factor)."""
    import pandas as pd

    if df[col].nunique() <= MAX_LEVELS:
        return df[col]
    return pd.qcut(df[col], 4, duplicates="drop").astype(str)


def _fmt(x: Any, nd: int = 2) -> str:
    return "–" if x is None or (isinstance(x, float) and not np.isfinite(x)) else f"{x:.{nd}f}"


def _fmt_value(x: Any) -> str:
    """A factor's value in a table cell: numbers with %g, text as it is, NaN as a dash."""
    if isinstance(x, (bool, np.bool_)):
        return str(bool(x))
    if isinstance(x, (int, float, np.integer, np.floating)):
        return "–" if not np.isfinite(x) else f"{x:g}"
    return str(x) if x not in (None, "") else "–"


def _col(df: Any, name: str) -> Any:
    """A numeric column, all-NaN when the table has no such column (rows written before it existed)."""
    return df[name].astype(float) if name in df else df.index.to_series().astype(float) * np.nan


def robustness_table(df: Any, by: str | None = None) -> str:
    """Per variant (and per value of `by`): runs, failed runs, lost control, success rate, median and worst max
    attitude error, median attitude and position RMS, the worst (smallest) eigenvalue and the bound violations."""
    keys = ["variant"] + ([by] if by else [])
    head = "| " + " | ".join(keys) + " | runs | failed | lost control | success | max att err ° (median / worst) " \
        "| att RMS ° (median) | pos RMS m (median) | min λ (worst) | bound violations |"
    lines = [head, "|" + "---|" * len(keys) + "---:|" * 9]
    for key, g in df.groupby(keys, sort=False):
        key = key if isinstance(key, tuple) else (key,)
        ok = g[g["status"] == "ok"]
        att = ok["max_att_error_deg"].astype(float)
        lines.append("| " + " | ".join(str(k) for k in key) + f" | {len(g)} | {int((g['status'] != 'ok').sum())} "
                     f"| {int(ok['lost_control'].astype(bool).sum())} | {100 * g['success'].mean():.0f} % "
                     f"| {_fmt(att.median(), 1)} / {_fmt(att.max(), 1)} "
                     f"| {_fmt(_col(ok, 'att_rms_error_deg').median(), 2)} "
                     f"| {_fmt(ok['pos_rms_error_m'].astype(float).median(), 3)} "
                     f"| {_fmt(_col(ok, 'min_eigenvalue').min(), 3)} "
                     f"| {int(_col(ok, 'bound_violations').fillna(0).sum())} |")
    return "\n".join(lines)


def _success_by_factor(df: Any, factors: list[str], fig_dir: Path) -> tuple[list[str], list[str]]:
    import matplotlib.pyplot as plt

    md, figs = [], []
    for f in factors:
        lev = _levels(df, f)
        tab = df.assign(level=lev).pivot_table(index="level", columns="variant", values="success", aggfunc="mean",
                                               sort=True)
        md.append(f"\n**{f}** (success rate, %)\n")
        md.append("| " + f + " | " + " | ".join(tab.columns) + " |")
        md.append("|---|" + "---:|" * len(tab.columns))
        for idx, r in tab.iterrows():
            md.append(f"| {idx} | " + " | ".join(_fmt(100 * v, 0) for v in r.to_numpy()) + " |")
        fig, ax = plt.subplots(figsize=(5.5, 3.4))
        x = np.arange(len(tab.index))
        for v in tab.columns:
            ax.plot(x, 100 * tab[v].to_numpy(), marker="o", label=v)
        ax.set_xticks(x, [str(i) for i in tab.index], rotation=30 if isinstance(tab.index[0], str) else 0)
        ax.set_xlabel(f)
        ax.set_ylabel("success (%)")
        ax.set_ylim(-5, 105)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        p = fig_dir / f"success_by_{f}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        figs.append(p.name)
    return md, figs


def _heatmaps(df: Any, xy: tuple[str, str], fig_dir: Path) -> list[str]:
    import matplotlib.pyplot as plt

    fx, fy = xy
    variants = list(dict.fromkeys(df["variant"]))
    out = []
    ok = df[df["status"] == "ok"].assign(lost=lambda d: d["lost_control"].astype(float),
                                         att=lambda d: d["max_att_error_deg"].astype(float))
    for col, title, cmap in (("lost", "loss of control (fraction of runs)", "Reds"),
                             ("att", "max attitude error, median (deg)", "viridis")):
        fig, axes = plt.subplots(1, len(variants), figsize=(4.2 * len(variants), 3.8), squeeze=False,
                                 layout="constrained")
        piv = {v: ok[ok["variant"] == v].pivot_table(index=fy, columns=fx, values=col, aggfunc="median" if
                                                     col == "att" else "mean") for v in variants}
        vals = np.concatenate([p.to_numpy().ravel() for p in piv.values()]) if piv else np.zeros(1)
        vmax = float(np.nanmax(vals)) if np.any(np.isfinite(vals)) else 1.0
        vmax = 1.0 if col == "lost" else vmax
        for ax, v in zip(axes[0], variants, strict=True):
            p = piv[v]
            im = ax.imshow(p.to_numpy(), origin="lower", aspect="auto", cmap=cmap, vmin=0.0, vmax=vmax)
            ax.set_xticks(range(len(p.columns)), [f"{c:g}" for c in p.columns])
            ax.set_yticks(range(len(p.index)), [f"{c:g}" for c in p.index])
            ax.set_xlabel(fx)
            ax.set_ylabel(fy)
            ax.set_title(v)
            for (i, j), z in np.ndenumerate(p.to_numpy()):
                if np.isfinite(z):
                    ax.text(j, i, f"{z:.2f}" if col == "lost" else f"{z:.0f}", ha="center", va="center", fontsize=7,
                            color="k" if z < 0.6 * vmax else "w")
        fig.colorbar(im, ax=axes[0].tolist(), shrink=0.9)
        fig.suptitle(title)
        p = fig_dir / f"heatmap_{col}_{fx}_x_{fy}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        out.append(p.name)
    return out


def _distributions(df: Any, fig_dir: Path) -> str:
    import matplotlib.pyplot as plt

    variants = list(dict.fromkeys(df["variant"]))
    ok = df[df["status"] == "ok"]
    fig, axes = plt.subplots(1, len(DIST_METRICS), figsize=(3.6 * len(DIST_METRICS), 3.4), layout="constrained")
    for ax, (col, label) in zip(axes, DIST_METRICS, strict=True):
        data = [ok[ok["variant"] == v][col].astype(float).dropna().to_numpy() for v in variants]
        ax.boxplot([d if len(d) else np.array([np.nan]) for d in data], tick_labels=variants)
        ax.set_title(label, fontsize=9)
        if col == "min_eigenvalue":  # a diverged estimate sends it to -1e6: symlog keeps 0..1 readable
            ax.set_yscale("symlog", linthresh=1.0)
        ax.tick_params(axis="x", rotation=30)
        ax.grid(alpha=0.3)
    p = fig_dir / "distributions.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    return p.name


def beyond_authority(df: Any) -> Any:
    """Per run: lost control with an authority bound above the loss threshold or an infeasible trim (a boolean
    Series; False where the bound is unknown)."""
    lost = df["lost_control"].fillna(False).astype(bool) if "lost_control" in df else df.index.to_series() < 0
    bound = _col(df, "authority_bound_deg")
    trim = df["authority_trim_feasible"] if "authority_trim_feasible" in df else None
    infeasible = (trim.map(lambda v: v is False or v == 0.0) if trim is not None
                  else df.index.to_series() < 0)
    return lost & ((bound > LOST_ATT_DEG) | infeasible.astype(bool))


def envelope_table(df: Any) -> str:
    """Per controller (variant): loss-of-control rate (and how many of the losses are beyond authority), max
    attitude error median / p95 / worst, attitude RMS median, bound violations (samples, runs with any), the
    smallest eigenvalue of G_hat G^-1 (the minimum over runs and its 5th percentile), time per run."""
    head = ("| controller | runs | failed | lost control | of them beyond authority | max att err ° median / p95 / "
            "worst | att RMS ° median | bound violations (samples / runs) | min λ (min / p5) | s per run, wall / CPU "
            "(median) |")
    lines = [head, "|---|" + "---:|" * 9]
    beyond = beyond_authority(df)
    for v, g in df.groupby("variant", sort=False):
        ok = g[g["status"] == "ok"]
        lost = ok["lost_control"].astype(bool)
        att = ok["max_att_error_deg"].astype(float)
        eig = _col(ok, "min_eigenvalue")
        viol = _col(ok, "bound_violations").fillna(0)
        rate = f"{int(lost.sum())} ({100 * lost.mean():.0f} %)" if len(ok) else "–"
        rms, wall, cpu = (_col(ok, "att_rms_error_deg").median(), _col(g, "run_wall_s").median(),
                          _col(g, "run_cpu_s").median())
        lines.append(f"| {v} | {len(g)} | {int((g['status'] != 'ok').sum())} | {rate} | {int(beyond[ok.index].sum())} "
                     f"| {_fmt(att.median(), 1)} / {_fmt(att.quantile(0.95), 1)} / {_fmt(att.max(), 1)} "
                     f"| {_fmt(rms, 2)} | {int(viol.sum())} / {int((viol > 0).sum())} "
                     f"| {_fmt(eig.min(), 3)} / {_fmt(eig.quantile(0.05), 3)} | {_fmt(wall, 2)} / {_fmt(cpu, 2)} |")
    return "\n".join(lines)


def paired_table(df: Any, pairs: tuple[tuple[str, str], ...] = PAIRS) -> str:
    """Controller a against b on the same draws (rows with the same `sample`, both ok): per draw the better one (a
    loss is worse than no loss; else the smaller max attitude error, within TIE_DEG a tie), the losses of each and
    together, the median paired difference of the max attitude error, and the sign test's two-sided p-value over
    the draws that were not ties."""
    from scipy.stats import binomtest

    head = ("| a vs b | draws | a better | b better | ties | a lost | b lost | both lost | median Δ max att ° (a − b) "
            "| sign test p |")
    lines = [head, "|---|" + "---:|" * 9]
    for a, b in pairs:
        if not {a, b} <= set(df["variant"]):
            continue
        cols = ["sample", "lost_control", "max_att_error_deg"]
        pa = df[(df["variant"] == a) & (df["status"] == "ok")][cols]
        pb = df[(df["variant"] == b) & (df["status"] == "ok")][cols]
        m = pa.merge(pb, on="sample", suffixes=("_a", "_b"))
        if not len(m):
            continue
        la, lb = m["lost_control_a"].astype(bool), m["lost_control_b"].astype(bool)
        d = m["max_att_error_deg_a"].astype(float) - m["max_att_error_deg_b"].astype(float)
        a_better = (lb & ~la) | ((la == lb) & (d < -TIE_DEG))
        b_better = (la & ~lb) | ((la == lb) & (d > TIE_DEG))
        n_a, n_b = int(a_better.sum()), int(b_better.sum())
        p = binomtest(n_a, n_a + n_b).pvalue if n_a + n_b else float("nan")
        lines.append(f"| {a} vs {b} | {len(m)} | {n_a} | {n_b} | {len(m) - n_a - n_b} | {int(la.sum())} "
                     f"({100 * la.mean():.0f} %) | {int(lb.sum())} ({100 * lb.mean():.0f} %) | {int((la & lb).sum())} "
                     f"| {_fmt(d.median(), 1)} | {'–' if not np.isfinite(p) else f'{p:.2g}'} |")
    return "\n".join(lines)


def worst_runs_table(df: Any, n: int = 10) -> list[str]:
    """The n worst runs per controller (lost control first, then by max attitude error), each with its replay."""
    ok = df[df["status"] == "ok"].assign(_lost=lambda d: d["lost_control"].astype(bool),
                                         _beyond=beyond_authority(df[df["status"] == "ok"]))
    facs = [f for f in WORST_FACTORS if f in df]
    md: list[str] = []
    for v, g in ok.groupby("variant", sort=False):
        w = g.sort_values(["_lost", "max_att_error_deg"], ascending=[False, False]).head(n)
        md += ["", f"**{v}**", "",
               "| run | sample | lost | beyond authority | max att err ° | bound ° | " + " | ".join(facs)
               + " | replay |",
               "|---|---:|---|---|---:|---:|" + "---|" * len(facs) + "---|"]
        for _, r in w.iterrows():
            md.append(f"| {r['run_id']} | {r['sample']} | {bool(r['_lost'])} | {bool(r['_beyond'])} "
                      f"| {_fmt(r['max_att_error_deg'], 1)} | {_fmt(_col(w, 'authority_bound_deg')[r.name], 1)} | "
                      + " | ".join(_fmt_value(r[f]) for f in facs) + f" | `{r['replay']}` |")
    return md


def _authority_scatter(df: Any, fig_dir: Path) -> tuple[str, int]:
    """Max attitude error against the run's authority bound, every ok run, per controller; losses ringed, those
    beyond authority in red. Returns the figure's name and how many runs have a bound."""
    import matplotlib.pyplot as plt

    ok = df[df["status"] == "ok"]
    x, y = _col(ok, "authority_bound_deg"), ok["max_att_error_deg"].astype(float)
    lost, beyond = ok["lost_control"].astype(bool), beyond_authority(ok)
    n_bound = int(np.isfinite(x).sum())
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    for v, marker in zip(dict.fromkeys(ok["variant"]), "os^Dvx", strict=False):
        sel = ok["variant"] == v
        ax.scatter(x[sel], y[sel], s=18, marker=marker, alpha=0.7, label=v)
    ax.scatter(x[lost & ~beyond], y[lost & ~beyond], s=70, facecolors="none", edgecolors="k", label="lost control")
    ax.scatter(x[beyond], y[beyond], s=70, facecolors="none", edgecolors="r", linewidths=1.5,
               label="lost, beyond authority")
    ax.axhline(LOST_ATT_DEG, color="r", ls="--", lw=0.8)
    ax.axvline(LOST_ATT_DEG, color="r", ls=":", lw=0.8)
    if n_bound:
        hi = float(np.nanmax(np.concatenate([x[np.isfinite(x)], y[np.isfinite(y)]])))
        line = np.linspace(0.0, hi, 200)
        ax.plot(line, line, color="0.5", lw=0.8, label="error = bound")
    else:
        ax.text(0.5, 0.5, "no authority bound in this table\n(authority: true, navig8_tools.authority.bound_from_log)",
                transform=ax.transAxes, ha="center", va="center", fontsize=9)
    # symmetric-log axes: most bounds and errors are a few degrees, losses reach 180
    ax.set_xscale("symlog", linthresh=1.0)
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_xlabel("authority bound: smallest reachable peak pitch excursion (deg, symlog)")
    ax.set_ylabel("max attitude error (deg, symlog)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    p = fig_dir / "att_error_vs_authority_bound.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    return p.name, n_bound


def envelope_sections(df: Any, fig_dir: Path, n_worst: int = 10) -> list[str]:
    """The generated campaign's sections (module docstring)."""
    md = ["", "## The envelope per controller", "",
          f"Loss of control: attitude error > {LOST_ATT_DEG:g} °, position error > {LOST_POS_M:g} m or a non-finite "
          "state. Beyond "
          f"authority: a loss whose authority bound (the smallest peak pitch excursion any controller reaches on the "
          f"run's logged arm motion) exceeds {LOST_ATT_DEG:g} °, or whose trim is infeasible.", "", envelope_table(df),
          "", "## Paired on the same draws", "",
          "Every controller flies the same draws (scenario, world, parameters, seed): per draw, which one did better.",
          "", paired_table(df)]
    fig, n_bound = _authority_scatter(df, fig_dir)
    md += ["", "## Max attitude error against the authority bound", "",
           f"{n_bound} of {int((df['status'] == 'ok').sum())} runs have a bound." if n_bound else
           "No run has an authority bound (the campaign ran without `authority: true`, or "
           "`navig8_tools.authority.bound_from_log` was not available: the table's `authority_error` says which).",
           "", f"![max attitude error against the authority bound](figures/{fig})"]
    md += ["", f"## Worst {n_worst} runs per controller (lost control first, then by max attitude error)",
           *worst_runs_table(df, n_worst)]
    return md


def _worst_runs(df: Any, factors: list[str], n_worst: int) -> list[str]:
    ok = df[df["status"] == "ok"]
    worst = ok.assign(_lost=ok["lost_control"].astype(bool)).sort_values(
        ["_lost", "max_att_error_deg"], ascending=[False, False]).groupby("variant", sort=False).head(n_worst)
    md = ["", f"## Worst {n_worst} runs per variant (lost control first, then by max attitude error)", "",
          "| run | variant | " + " | ".join(factors) + " | seed | lost | max att err ° | replay |",
          "|---|---|" + "---:|" * len(factors) + "---:|---|---:|---|"]
    for _, r in worst.iterrows():
        md.append(f"| {r['run_id']} | {r['variant']} | " + " | ".join(_fmt_value(r[f]) for f in factors)
                  + f" | {r['seed']} | {bool(r['lost_control'])} | {_fmt(r['max_att_error_deg'], 1)} "
                  f"| `{r['replay']}` |")
    return md


def write_report(campaign: Any, df: Any, out_dir: str | Path, command: str, n_worst: int = 4) -> Path:
    """DIR/report.md and DIR/figures/*.png; returns the report's path."""
    import matplotlib

    matplotlib.use("Agg")
    out = Path(out_dir)
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    generated = bool(getattr(campaign, "generator", ""))
    factors = ([f for f in ENVELOPE_REPORT_FACTORS if f in df] if generated else [f.name for f in campaign.factors])
    where = (f"Scenarios generated by `{campaign.generator}` ({getattr(campaign, 'samples', '?')} draws, sample_seed "
             f"{getattr(campaign, 'sample_seed', '?')}; each draw's file in `scenarios/`)" if generated
             else f"Scenario `{campaign.scenario}`")
    md = [f"# Campaign `{campaign.name}`", "", campaign.description.strip(), "",
          f"{where}, kind `{campaign.kind}`, {len(df)} runs "
          f"({int((df['status'] == 'ok').sum())} ok, {int((df['status'] != 'ok').sum())} failed). "
          f"Success: the run completed and did not lose control (summary.py: attitude error > 60 °, position error "
          f"> 5 m or a non-finite state).", "", f"Command: `{command}`", "", "## Robustness per variant", "",
          robustness_table(df)]
    if campaign.heatmap:
        md += ["", f"### Per variant and {campaign.heatmap[0]}", "", robustness_table(df, campaign.heatmap[0])]
    if len(df) and generated:  # its own worst runs (10 per controller, with the authority bound), first
        md += envelope_sections(df, fig_dir)
    if len(df):
        sbf, figs = _success_by_factor(df, factors, fig_dir)
        md += ["", "## Success rate by factor", *sbf, ""] + [f"![success by factor](figures/{f})" for f in figs]
        if campaign.heatmap:
            md += ["", f"## Heat maps over {campaign.heatmap[0]} x {campaign.heatmap[1]}", ""]
            md += [f"![heat map](figures/{f})" for f in _heatmaps(df, campaign.heatmap, fig_dir)]
        dist = _distributions(df, fig_dir)
        md += ["", "## Metric distributions per variant", "", f"![distributions](figures/{dist})"]
        if not generated:
            md += _worst_runs(df, factors, n_worst)
        bad = df[df["status"] != "ok"]
        if len(bad):
            md += ["", f"## Failed runs ({len(bad)})", "", "| run | status | error | replay |", "|---|---|---|---|"]
            for _, r in bad.head(50).iterrows():
                md.append(f"| {r['run_id']} | {r['status']} | {str(r['error']).replace('|', '/')} | `{r['replay']}` |")
    p = out / "report.md"
    p.write_text("\n".join(md) + "\n")
    return p


__all__ = ["write_report", "robustness_table", "envelope_table", "paired_table", "worst_runs_table",
           "beyond_authority", "envelope_sections"]
