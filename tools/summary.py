"""summary.json from a run's log, so the in-process and the SITL runs are judged by one function.

Keys: sim_time_s, wall_time_s, real_time_factor, lost_control, min_eigenvalue,
max_eigenvalue, bound_violations, max_pos_error_m, pos_rms_error_m, max_att_error_deg, att_rms_error_deg, settle,
peak_reaction_force_n, peak_reaction_torque_nm, max_joint_rate_rad_s, max_joint_accel_rad_s2.

Definitions:
- position error: |p - p_cmd| (3-D, UAV origin O, NED); attitude error: rotation angle between the
  true attitude and the outer loop's commanded attitude (commanded pitch/yaw with its chosen roll),
  not counted during the ATT_STEP_GRACE_S after a commanded pitch or yaw step (the 90 deg yaw step
  is itself a 90 deg "error" at the instant it is commanded); att_rms_error_deg is its RMS over the samples
  outside those grace windows (it separates adapting from not adapting);
- lost_control: any non-finite state, attitude error > 60 deg or position error > 5 m;
- eigenvalues: real parts of eig(G_hat G^-1) with G from the plant's truth, while the estimator runs;
- bound_violations: samples where the estimate leaves the Eq. 21 box by more than 1e-9 relative;
- settle: per commanded step, the time from the step until the stepped quantity enters and stays
  within 0.2 m (position axis) or 5 deg (pitch, yaw) up to the next command (or the end), else null.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from navig8_tools.logdata import RunLog

POS_TOL_M = 0.2
ATT_TOL_DEG = 5.0
LOST_ATT_DEG = 60.0
LOST_POS_M = 5.0
ATT_STEP_GRACE_S = 2.0


def _quat_angle_deg(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    dot = np.abs(np.sum(qa * qb, axis=1))
    return np.degrees(2.0 * np.arccos(np.clip(dot, -1.0, 1.0)))


def _wrap_deg(a: np.ndarray) -> np.ndarray:
    return (a + 180.0) % 360.0 - 180.0


def _interp_rows(t_src: np.ndarray, y: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Zero-order hold of y (rows at t_src) at times t."""
    idx = np.clip(np.searchsorted(t_src, t, side="right") - 1, 0, len(t_src) - 1)
    return y[idx]


def _steps(t: np.ndarray, values: np.ndarray, names: list[str]) -> list[tuple[float, int, str]]:
    out = []
    for j, name in enumerate(names):
        v = values[:, j]
        for i in np.nonzero(np.abs(np.diff(v)) > 1e-9)[0]:
            out.append((float(t[i + 1]), j, name))
    return sorted(out)


def settle_times(
    t: np.ndarray, err: np.ndarray, steps: list[tuple[float, int, str]], tol: np.ndarray, t_end: float
) -> list[dict[str, Any]]:
    """For each step (time, column, name): time until |err[:, column]| <= tol[column] holds to the next step."""
    times = sorted({s[0] for s in steps}) + [t_end + 1e-9]
    out = []
    for t_step, col, name in steps:
        t_next = min(x for x in times if x > t_step + 1e-12)
        win = (t >= t_step) & (t < t_next)
        tw, ew = t[win], np.abs(err[win, col])
        settle = None
        if len(tw) and ew[-1] <= tol[col]:
            bad = np.nonzero(ew > tol[col])[0]
            t_in = tw[0] if len(bad) == 0 else tw[min(bad[-1] + 1, len(tw) - 1)]
            settle = float(t_in - t_step)
        out.append({"t_cmd_s": t_step, "axis": name, "settle_s": settle,
                    "window_s": float(t_next - t_step) if t_next <= t_end else float(t_end - t_step)})
    return out


def fmax(a: np.ndarray) -> float | None:
    """The largest finite value of a, None when there is none."""
    return float(np.nanmax(a)) if a.size and np.any(np.isfinite(a)) else None


def fmin(a: np.ndarray) -> float | None:
    """The smallest finite value of a, None when there is none."""
    return float(np.nanmin(a)) if a.size and np.any(np.isfinite(a)) else None


def summarize(run: RunLog, wall_time_s: float) -> dict[str, Any]:
    tr = run["/truth"]
    st = run["/fc/status"]
    sp = run["/fc/setpoint"]
    eig = run["/analysis/eig"]
    t = tr.t
    sim_time = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    pos = tr.field("pos_ned_m", 3)
    quat = tr.field("quat_wxyz", 4)
    eul = tr.field("euler_rad", 3)
    sp_pos = _interp_rows(sp.t, sp.field("pos_ned_m", 3), t)
    sp_att = np.column_stack([sp.field("pitch_rad"), sp.field("yaw_rad")])
    sp_att_t = _interp_rows(sp.t, sp_att, t)
    att_cmd = st.field("outer.att_cmd_quat", 4)
    att_cmd_t = _interp_rows(st.t, att_cmd, t)
    pos_err = np.linalg.norm(pos - sp_pos, axis=1)
    have_cmd = np.all(np.isfinite(att_cmd_t), axis=1)
    att_err = np.where(have_cmd, _quat_angle_deg(quat, np.nan_to_num(att_cmd_t)), 0.0)
    graced = np.zeros(len(t), dtype=bool)
    for j in range(2):  # grace window after each commanded pitch/yaw step
        for i in np.nonzero(np.abs(np.diff(sp_att[:, j])) > 1e-9)[0]:
            t_step = sp.t[i + 1]
            graced |= (t >= t_step) & (t < t_step + ATT_STEP_GRACE_S)
    att_err[graced] = 0.0
    finite = bool(np.all(np.isfinite(pos)) and np.all(np.isfinite(quat)))
    bad = ~np.isfinite(pos).all(axis=1) | ~np.isfinite(quat).all(axis=1)
    bad |= (att_err > LOST_ATT_DEG) | (pos_err > LOST_POS_M)
    lost = (not finite) or bool(np.any(bad))
    lost_t = float(t[np.argmax(bad)]) if np.any(bad) else None

    running = st.field("adapt.running").astype(bool) if len(st.t) else np.zeros(0, bool)
    lam = eig.field("eig_real", 5)
    # Eigenvalues count from the estimator's start delay in every mode (fixed K = 1 never "runs").
    start_dly = float(run.metadata.get("params", {}).get("CKF_START_DLY", 0.0))
    eig_running = eig.t >= (eig.t[0] if len(eig.t) else 0.0) + start_dly - 1e-9
    lam_run = lam[eig_running] if len(lam) else lam
    x = st.field("adapt.x_hat", 4)
    lo, hi = st.field("adapt.lower", 4), st.field("adapt.upper", 4)
    tol = 1e-9 * np.maximum(np.abs(hi), 1.0)
    viol = running & np.any((x < lo - tol) | (x > hi + tol), axis=1)

    # Settling per commanded step: position axes (NED), pitch and yaw.
    err_cols = np.column_stack([pos - sp_pos, np.degrees(eul[:, 1]) - np.degrees(sp_att_t[:, 0]),
                                _wrap_deg(np.degrees(eul[:, 2]) - np.degrees(sp_att_t[:, 1]))])
    sp_vals = np.column_stack([sp.field("pos_ned_m", 3), sp_att])
    names = ["north", "east", "down", "pitch", "yaw"]
    t_last = float(t[-1]) if len(t) else 0.0
    steps = [st_ for st_ in _steps(sp.t, sp_vals, names) if st_[0] < t_last - 1e-9]  # a step at the end has no window
    tol_cols = np.array([POS_TOL_M] * 3 + [ATT_TOL_DEG] * 2)
    settle = settle_times(t, err_cols, steps, tol_cols, float(t[-1]) if len(t) else 0.0)

    f_mount = tr.field("reaction_force_frd_n", 3)
    m_mount = tr.field("reaction_moment_mount_frd_nm", 3)
    qd = tr.field("joint_rate_rad_s", 3)
    qdd = tr.field("joint_accel_rad_s2", 3)

    return {
        "sim_time_s": sim_time,
        "wall_time_s": float(wall_time_s),
        "real_time_factor": sim_time / wall_time_s if wall_time_s > 0 else math.inf,
        "lost_control": lost,
        "lost_control_t_s": lost_t,
        "min_eigenvalue": fmin(lam_run),
        "max_eigenvalue": fmax(lam_run),
        "bound_violations": int(np.sum(viol)),
        "max_pos_error_m": fmax(pos_err),
        "pos_rms_error_m": float(np.sqrt(np.nanmean(pos_err**2))) if len(pos_err) else None,
        "max_att_error_deg": fmax(att_err),
        "att_rms_error_deg": float(np.sqrt(np.nanmean(att_err[~graced] ** 2))) if np.any(~graced) else None,
        "settle": settle,
        "peak_reaction_force_n": fmax(np.linalg.norm(f_mount, axis=1)),
        "peak_reaction_torque_nm": fmax(np.linalg.norm(m_mount, axis=1)),
        "max_joint_rate_rad_s": fmax(np.abs(qd)),
        "max_joint_accel_rad_s2": fmax(np.abs(qdd)),
    }


SIDE_BY_SIDE = (("lost_control", "lost control", "{}"), ("max_att_error_deg", "max attitude error (deg)", "{:.1f}"),
                ("att_rms_error_deg", "attitude RMS (deg)", "{:.2f}"), ("max_pos_error_m", "max position error (m)",
                                                                        "{:.2f}"),
                ("pos_rms_error_m", "position RMS (m)", "{:.2f}"), ("min_eigenvalue", "min eigenvalue", "{:.3f}"),
                ("bound_violations", "bound violations", "{}"), ("real_time_factor", "real-time factor", "{:.1f}"))


def side_by_side(summaries: dict[str, dict[str, Any]]) -> str:
    """A text table of summary.json files (columns by label), the keys of SIDE_BY_SIDE plus the settled steps."""
    labels = list(summaries)
    rows = [["", *labels]]
    for key, name, fmt in SIDE_BY_SIDE:
        rows.append([name] + [fmt.format(s[key]) if s.get(key) is not None else "-" for s in summaries.values()])
    rows.append(["steps settled"] + [f"{sum(1 for x in s.get('settle', []) if x.get('settle_s') is not None)}"
                                     f" / {len(s.get('settle', []))}" for s in summaries.values()])
    widths = [max(len(r[i]) for r in rows) for i in range(len(labels) + 1)]
    def line(r: list[str]) -> str:
        return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths, strict=True)))

    return "\n".join(line(r) for r in rows)


def main(argv: list[str] | None = None) -> int:
    """navig8-compare LABEL=summary.json ...: the runs' summaries side by side (make demo prints the defaults and
    the paper's method this way)."""
    import argparse
    import json
    from pathlib import Path

    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("runs", nargs="+", metavar="LABEL=FILE")
    a = ap.parse_args(argv)
    sums: dict[str, dict[str, Any]] = {}
    for item in a.runs:
        label, sep, path = item.partition("=")
        if not sep:
            label, path = Path(item).stem, item
        sums[label] = json.loads(Path(path).read_text())
    print(side_by_side(sums))
    return 0
