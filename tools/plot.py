"""navig8-plot: the paper's Figures 10-16 from one or more run logs (MCAP), baselines overlaid.

    navig8-plot run.mcap [other.mcap ...] --out DIR [--only fig15 ...] [--labels A B ...] [--suffix _x]

--only draws the named figures only (fig10 ... fig16); --labels names the runs in the legends (default: each run's
controller); --suffix goes into the file names (fig15_estimates_ident.png).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from navig8_tools.logdata import RunLog, load_run  # noqa: E402

STYLES = ["-", ":", "--", "-."]
COLORS = ["tab:blue", "tab:green", "tab:orange", "tab:purple"]


def _style(i: int) -> dict:
    return {"ls": STYLES[i % len(STYLES)], "color": COLORS[i % len(COLORS)], "lw": 1.2}


def _save(fig, out: Path, name: str) -> Path:
    fig.tight_layout()
    p = out / name
    fig.savefig(p, dpi=110)
    plt.close(fig)
    return p


def fig10_reaction(runs: list[RunLog], out: Path) -> Path:
    fig, ax = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    r = runs[0]["/truth"]
    f = r.field("reaction_force_frd_n")
    m = r.field("reaction_moment_mount_frd_nm")
    for i, lab in enumerate("xyz"):
        ax[0].plot(r.t, f[:, i], label=f"F{lab}")
        ax[1].plot(r.t, m[:, i], label=f"M{lab}")
    ax[0].plot(r.t, np.linalg.norm(f, axis=1), "k", lw=0.8, label="|F|")
    ax[1].plot(r.t, np.linalg.norm(m, axis=1), "k", lw=0.8, label="|M|")
    ax[0].set_ylabel("reaction force [N]")
    ax[1].set_ylabel("reaction torque [N m]")
    ax[1].set_xlabel("time [s]")
    ax[0].set_title("Fig. 10: arm reaction on the UAV (about the mount, incl. gravity)")
    for a in ax:
        a.legend(fontsize=7, ncol=4)
        a.grid(alpha=0.3)
    return _save(fig, out, "fig10_reaction.png")


def fig11_joints(runs: list[RunLog], out: Path) -> Path:
    fig, ax = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    r = runs[0]["/truth"]
    qd, qdd = r.field("joint_rate_rad_s"), r.field("joint_accel_rad_s2")
    for i in range(3):
        ax[0].plot(r.t, qd[:, i], label=f"q{i + 1}")
        ax[1].plot(r.t, qdd[:, i], label=f"q{i + 1}")
    ax[0].set_ylabel("joint rate [rad/s]")
    ax[1].set_ylabel("joint accel [rad/s²]")
    ax[1].set_xlabel("time [s]")
    ax[0].set_title("Fig. 11: joint angular velocities and accelerations")
    for a in ax:
        a.legend(fontsize=7)
        a.grid(alpha=0.3)
    return _save(fig, out, "fig11_joints.png")


def fig12_states(runs: list[RunLog], out: Path) -> Path:
    fig, ax = plt.subplots(3, 2, figsize=(10, 7), sharex=True)
    names_p = ["p_E [m]", "p_N [m]", "p_U [m]"]
    names_a = ["roll φ [deg]", "pitch θ [deg]", "yaw ψ [deg]"]
    for k, run in enumerate(runs):
        tr = run["/truth"]
        p = tr.field("pos_ned_m")
        enu = np.column_stack([p[:, 1], p[:, 0], -p[:, 2]])
        eul = np.degrees(tr.field("euler_rad"))
        for i in range(3):
            ax[i, 0].plot(tr.t, enu[:, i], label=run.label, **_style(k))
            ax[i, 1].plot(tr.t, eul[:, i], label=run.label, **_style(k))
    sp = runs[0]["/fc/setpoint"]
    spp = sp.field("pos_ned_m")
    spe = np.column_stack([spp[:, 1], spp[:, 0], -spp[:, 2]])
    for i in range(3):
        ax[i, 0].plot(sp.t, spe[:, i], "r--", lw=1, label="command")
        ax[i, 0].set_ylabel(names_p[i])
        ax[i, 1].set_ylabel(names_a[i])
    ax[1, 1].plot(sp.t, np.degrees(sp.field("pitch_rad")), "r--", lw=1, label="command")
    ax[2, 1].plot(sp.t, np.degrees(sp.field("yaw_rad")), "r--", lw=1, label="command")
    for a in ax.ravel():
        a.grid(alpha=0.3)
    ax[0, 0].legend(fontsize=7)
    ax[2, 0].set_xlabel("time [s]")
    ax[2, 1].set_xlabel("time [s]")
    fig.suptitle("Fig. 12: UAV position (ENU) and attitude")
    return _save(fig, out, "fig12_states.png")


def fig13_accels(runs: list[RunLog], out: Path) -> Path:
    fig, ax = plt.subplots(5, 1, figsize=(8, 9), sharex=True)
    st = runs[0]["/fc/status"]
    meas = st.field("indi.acc_filtered", 5)
    cmd = st.field("outer.accel_cmd", 5)
    names = ["Ṗ [rad/s²]", "Q̇ [rad/s²]", "Ṙ [rad/s²]", "a_x [m/s²]", "a_z [m/s²]"]
    for i in range(5):
        ax[i].plot(st.t, meas[:, i], label="filtered measurement")
        ax[i].plot(st.t, cmd[:, i], "r--", lw=0.8, label="command")
        ax[i].set_ylabel(names[i])
        ax[i].grid(alpha=0.3)
    ax[0].legend(fontsize=7)
    ax[-1].set_xlabel("time [s]")
    fig.suptitle("Fig. 13: INDI-controlled accelerations against commands (body FRD, specific force)")
    return _save(fig, out, "fig13_accels.png")


def fig14_actuators(runs: list[RunLog], out: Path) -> Path:
    fig, ax = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    tr = runs[0]["/truth"]
    tilt, speed = tr.field("duct_tilt_rad"), tr.field("prop_speed_rad_s")
    ax[0].plot(tr.t, np.degrees(tilt[:, 0]), label="α1")
    ax[0].plot(tr.t, np.degrees(tilt[:, 1]), label="α3")
    for i, lab in enumerate(["ω1", "ω2 (tail)", "ω3"]):
        ax[1].plot(tr.t, speed[:, i], label=lab)
    ax[0].set_ylabel("duct tilt [deg]")
    ax[1].set_ylabel("prop speed [rad/s]")
    ax[1].set_xlabel("time [s]")
    ax[0].set_title("Fig. 14: actuator states")
    for a in ax:
        a.legend(fontsize=7)
        a.grid(alpha=0.3)
    return _save(fig, out, "fig14_actuators.png")


def fig15_estimates(runs: list[RunLog], out: Path) -> Path:
    fig, ax = plt.subplots(4, 1, figsize=(8, 9), sharex=True)
    names = ["Î_xx [kg m²]", "Î_yy [kg m²]", "Î_zz [kg m²]", "m̂ [kg]"]
    for k, run in enumerate(runs):
        st = run["/fc/status"]
        x = st.field("adapt.x_hat", 4)
        for i in range(4):
            ax[i].plot(st.t, x[:, i], label=f"estimate ({run.label})", **_style(k))
    st = runs[0]["/fc/status"]
    lo, hi = st.field("adapt.lower", 4), st.field("adapt.upper", 4)
    eig = runs[0]["/analysis/eig"]
    true = eig.field("true_inertia_mass", 4)
    for i in range(4):
        ax[i].plot(eig.t, true[:, i], "r--", lw=1, label="true (UAM + object)")
        ax[i].plot(st.t, lo[:, i], "g-.", lw=0.8, label="bounds (Eq. 21)")
        ax[i].plot(st.t, hi[:, i], "g-.", lw=0.8)
        ax[i].set_ylabel(names[i])
        ax[i].grid(alpha=0.3)
    ax[0].legend(fontsize=7)
    ax[-1].set_xlabel("time [s]")
    fig.suptitle("Fig. 15: Ĝ_I estimates, truth and bounds")
    return _save(fig, out, "fig15_estimates.png")


def fig16_eigenvalues(runs: list[RunLog], out: Path) -> Path:
    fig, ax = plt.subplots(1, 1, figsize=(8, 4))
    for k, run in enumerate(runs):
        e = run["/analysis/eig"]
        lam = e.field("eig_real", 5)
        for i in range(5):
            ax.plot(e.t, lam[:, i], lw=1, ls=STYLES[k % 4], color=f"C{i}",
                    label=f"λ{i + 1} ({run.label})" if k == 0 or i == 0 else None)
    e0 = runs[0]["/analysis/eig"]
    lam_min = float(np.nanmedian(e0.field("lambda_min")))
    lam_crit = float(np.nanmedian(e0.field("lambda_crit")))
    ax.axhline(lam_min, color="k", ls="--", lw=0.8, label=f"λ_min = {lam_min:.2f}")
    ax.axhline(lam_crit, color="r", ls="--", lw=0.8, label=f"λ_crit = {lam_crit:.3f}")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("Re λ(Ĝ G⁻¹)")
    # An unconstrained estimate can send eigenvalues to +-1000s; keep the stability band readable.
    ax.set_ylim(-1.0, 3.5)
    ax.set_title("Fig. 16: eigenvalues of Ĝ·G⁻¹ (G from the plant's truth)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=3)
    return _save(fig, out, "fig16_eigenvalues.png")


FIGURES = [fig10_reaction, fig11_joints, fig12_states, fig13_accels, fig14_actuators, fig15_estimates,
           fig16_eigenvalues]


def plot_runs(paths: list[str | Path], out: str | Path, only: list[str] | None = None,
              labels: list[str] | None = None, suffix: str = "") -> list[Path]:
    """The figures (all, or those whose name starts with one of `only`) of the runs at `paths` into `out`."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    runs = [load_run(p) for p in paths]
    if labels:
        if len(labels) != len(runs):
            raise ValueError(f"{len(labels)} labels for {len(runs)} runs")
        for run, label in zip(runs, labels, strict=True):
            run.metadata.setdefault("run", {})["controller"] = label  # what RunLog.label shows
    figures = [f for f in FIGURES if not only or any(f.__name__.startswith(o) for o in only)]
    if not figures:
        raise ValueError(f"no figure matches {only}; figures: {[f.__name__ for f in FIGURES]}")
    if not suffix:
        return [f(runs, out) for f in figures]
    # drawn aside first, so that the unsuffixed files already in `out` are left alone
    with tempfile.TemporaryDirectory(dir=out) as tmp:
        return [p.replace(out / f"{p.stem}{suffix}{p.suffix}") for p in (f(runs, Path(tmp)) for f in figures)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("logs", nargs="+", help="MCAP logs; the first is the main run, others are overlaid")
    ap.add_argument("--out", required=True, help="output directory for the PNGs")
    ap.add_argument("--only", nargs="+", default=None, help="figure names to draw (e.g. fig15)")
    ap.add_argument("--labels", nargs="+", default=None, help="legend names of the runs, in order")
    ap.add_argument("--suffix", default="", help="appended to the file names")
    args = ap.parse_args(argv)
    for p in plot_runs(args.logs, args.out, args.only, args.labels, args.suffix):
        print(p)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["plot_runs", "main"]
