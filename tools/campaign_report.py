"""The campaign report: Markdown + PNG figures from the campaign's table (navig8-campaign writes it at the end).

Sections: summary per variant (the robustness table), success rate by factor (table + figure), heat maps of the
loss-of-control rate and the median max attitude error over the campaign's `report.heatmap` factors per variant,
distributions of the metrics per variant, the worst runs with their replay commands, and the failed runs.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

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


def write_report(campaign: Any, df: Any, out_dir: str | Path, command: str, n_worst: int = 4) -> Path:
    """DIR/report.md and DIR/figures/*.png; returns the report's path."""
    import matplotlib

    matplotlib.use("Agg")
    out = Path(out_dir)
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    factors = [f.name for f in campaign.factors]
    md = [f"# Campaign `{campaign.name}`", "", campaign.description.strip(), "",
          f"Scenario `{campaign.scenario}`, kind `{campaign.kind}`, {len(df)} runs "
          f"({int((df['status'] == 'ok').sum())} ok, {int((df['status'] != 'ok').sum())} failed). "
          f"Success: the run completed and did not lose control (summary.py: attitude error > 60 °, position error "
          f"> 5 m or a non-finite state).", "", f"Command: `{command}`", "", "## Robustness per variant", "",
          robustness_table(df)]
    if campaign.heatmap:
        md += ["", f"### Per variant and {campaign.heatmap[0]}", "", robustness_table(df, campaign.heatmap[0])]
    if len(df):
        sbf, figs = _success_by_factor(df, factors, fig_dir)
        md += ["", "## Success rate by factor", *sbf, ""] + [f"![success by factor](figures/{f})" for f in figs]
        if campaign.heatmap:
            md += ["", f"## Heat maps over {campaign.heatmap[0]} x {campaign.heatmap[1]}", ""]
            md += [f"![heat map](figures/{f})" for f in _heatmaps(df, campaign.heatmap, fig_dir)]
        dist = _distributions(df, fig_dir)
        md += ["", "## Metric distributions per variant", "", f"![distributions](figures/{dist})"]
        ok = df[df["status"] == "ok"]
        worst = ok.assign(_lost=ok["lost_control"].astype(bool)).sort_values(
            ["_lost", "max_att_error_deg"], ascending=[False, False]).groupby("variant", sort=False).head(n_worst)
        md += ["", f"## Worst {n_worst} runs per variant (lost control first, then by max attitude error)", "",
               "| run | variant | " + " | ".join(factors) + " | seed | lost | max att err ° | replay |",
               "|---|---|" + "---:|" * len(factors) + "---:|---|---:|---|"]
        for _, r in worst.iterrows():
            md.append(f"| {r['run_id']} | {r['variant']} | " + " | ".join(f"{r[f]:g}" for f in factors)
                      + f" | {r['seed']} | {bool(r['lost_control'])} | {_fmt(r['max_att_error_deg'], 1)} "
                      f"| `{r['replay']}` |")
        bad = df[df["status"] != "ok"]
        if len(bad):
            md += ["", f"## Failed runs ({len(bad)})", "", "| run | status | error | replay |", "|---|---|---|---|"]
            for _, r in bad.head(50).iterrows():
                md.append(f"| {r['run_id']} | {r['status']} | {str(r['error']).replace('|', '/')} | `{r['replay']}` |")
    p = out / "report.md"
    p.write_text("\n".join(md) + "\n")
    return p


__all__ = ["write_report", "robustness_table"]
