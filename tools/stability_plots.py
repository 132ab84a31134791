"""navig8-stability --plots (tools/stability_report.py): the paper's Figs. 5-7 for the configured loop, as PNGs:
the poles of H(s) as lambda varies, H(s)'s step responses, and lambda_4, lambda_5 of K Xi over (K1, K3).
docs/stability.md.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from navig8_fc.core import k_xi
from navig8_fc.core import stability as st
from navig8_fc.core.vehicle import VehicleConfig

if TYPE_CHECKING:
    from navig8_tools.stability_report import Inputs

FIG6_LAMBDAS = (0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0)


def write_plots(inp: Inputs, cfg: VehicleConfig, out_dir: Path, lam_crit: float) -> list[Path]:
    """Figs. 5, 6 and 7 of the configured loop as PNGs in out_dir; their paths."""
    import matplotlib

    matplotlib.use("Agg")
    out_dir.mkdir(parents=True, exist_ok=True)
    return [_fig5_poles(inp, lam_crit, out_dir / "fig5_poles.png"), _fig6_step(inp, out_dir / "fig6_step.png"),
            _fig7_k_bounds(inp, cfg, out_dir / "fig7_k_bounds.png")]


def _fig5_poles(inp: Inputs, lam_crit: float, path: Path) -> Path:
    """Fig. 5: poles of H(s) as lambda varies."""
    import matplotlib
    import matplotlib.pyplot as plt

    p = (inp.wn_rad_s, inp.zeta, inp.ts_s, inp.tl_s)
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
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _fig6_step(inp: Inputs, path: Path) -> Path:
    """Fig. 6: step responses of H(s)."""
    import matplotlib.pyplot as plt

    p = (inp.wn_rad_s, inp.zeta, inp.ts_s, inp.tl_s)
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
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _fig7_k_bounds(inp: Inputs, cfg: VehicleConfig, path: Path) -> Path:
    """Fig. 7: lam_4, lam_5 over (K1, K3) for the stretched and curled arm with a 2 kg object."""
    import matplotlib.pyplot as plt

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
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
