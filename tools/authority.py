"""navig8-authority: the actuator set's moment authority at hover, and the physical limit it puts on pitch while
the arm moves: during the paper's arm reversal, or during every move of a flown run (its log).

    navig8-authority [--tail-max-thrust N] [--masses 0,1,2] [--pitch-deg 45] [--lag] [--json] [--no-reversal]
    navig8-authority --log RUN.mcap [--scenario S] [--world NAME=VALUE ...] [--preview] [--json]

1. **Static authority.** For an arm pose q and object mass m_o, the largest pure pitch (roll) moment about the
   composite CoM that the real actuator set (duct speeds 0..w_max, duct tilts within their limits, reversible
   tail speed) can hold at hover: maximise M (L) over U subject to G_C(c) U = [L, M, N, Fx, Fz] with the other
   moments 0, Fz = -m g and Fx = 0 ("Fx held") or Fx free (the tilt lever: common duct tilt x the duct height
   below the CoM). With the body pitched by theta (`--pitch-deg`, the paper's 45 deg phase) the hover force in
   body axes is m g (sin theta, 0, -cos theta): "Fx held" then holds Fx = m g sin theta.
   Each duct's (U_cos, U_sin) = w^2 (cos a, sin a) lies in a disk sector of radius w_max^2 and
   the tilt range; a range wider than 180 deg is not convex, but it is the union of two half disks, so the
   optimum is the best of the 4 linear programs over the pieces of the two ducts (exact up to the inscribed
   polygon of the disk, whose solutions are all flyable). The pose enters only through the composite CoM c and
   the total mass (G_C(c) is affine in c), so `authority_at_coms` solves it at CoM points, all of them and all
   pieces in one block-diagonal LP.
2. **Reversal bound.** During the arm's reversal the arm's angular momentum relative to the composite CoM,
   h(q, q'), changes; about the CoM gravity has no moment, so d/dt (I_yy(q) theta' + h) = M_act. With
   |M_act| inside the static authority of the current pose, the smallest peak |theta| any controller can
   reach is a linear program over the moment history (`min_pitch_excursion`: exact momentum under a held
   moment, trapezoid for theta, ending at rest; sparse, so a window of many seconds is cheap). It ignores the
   actuator lag, the noise and the hover-force coupling of a tilted body, so it is a lower bound: no controller
   flying this actuator set can do better. `reversal_bound` is `window_bound` on the plant's servo profile.
3. **With the actuators' lag** (`--lag`). The same LP with the delivered moment the commanded moment history
   through the actuators' second-order response (omega_n, zeta of params/plant.yaml: 120 rad/s, 1), the command
   inside the static authority (zeta = 1 does not overshoot, so the delivered moment stays inside it too), in two
   variants: *preview* (the command may start before the reaction: the controller knows the arm's plan) and
   *causal* (the command stays at trim until one control tick after the reaction starts: a controller that
   sees the reaction only when it happens). The moment is a nonlinear function of the actuator states (thrust
   ~ w|w|, the tail reversing through zero speed has none), so the linear lag of the moment is a model, not an
   exact bound; the numbers say how much of the flown error the lag alone explains.
4. **Authority bound of a flown run** (`bound_from_log`, `--log`). The run's log gives q(t), q'(t), m_o(t) and
   the commanded pitch; the run is split into the arm's moves (windows where h changes) and 2.-3. run on each,
   with the static authority along the window from `AuthorityMap` (the LP on a lattice of CoM points, bilinear
   in between: conservative, see there); the bound of the run is the worst window's. Docstring of
   `bound_from_log` for what each number means and where it is not a strict bound.

Everything is the model of navig8_fc.core.vehicle (the same G_C and mass properties the controller uses) and the
plant's joint servo (sim_bridge.joint_servo.servo_accel). See docs/model.md ("Pitch authority", "Authority bound of
a flown run").

The code: tools/authority_static.py (1.: the LP, AuthorityMap), tools/authority_excursion.py (2.-3.: the arm's
momentum, the excursion LP, the reversal), this file (4., the report and the command line).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import sys
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from navig8_fc.core.vehicle import N_LINKS, VehicleConfig
from navig8_tools.authority_excursion import (
    ArmMotion,
    authority_along,
    mass_terms,
    motion_terms,
    reversal_bound,
    window_bound,
)
from navig8_tools.authority_static import MAP_SPACING_M, TRIM_TOL_NM, hover_authority, map_lp_points


def with_tail_thrust(cfg: VehicleConfig, tail_max_thrust_n: float) -> VehicleConfig:
    """The vehicle with a tail propeller of the given maximum thrust (N) at its speed limit; K_Q2/K_T2 kept."""
    w = max(abs(cfg.tail_speed_min), abs(cfg.tail_speed_max))
    kt = float(tail_max_thrust_n) / (w * w)
    return dataclasses.replace(cfg, k_thrust_tail=kt, k_torque_tail=cfg.k_torque_tail * kt / cfg.k_thrust_tail)


def tail_max_thrust_n(cfg: VehicleConfig) -> float:
    w = max(abs(cfg.tail_speed_min), abs(cfg.tail_speed_max))
    return cfg.k_thrust_tail * w * w



_WINDOWS: dict[tuple[Any, ...], tuple[float, float | None]] = {}  # bound_from_log's windows: (peak, untrimmable)


# --------------------------------------------------------------------------------------
# The bound of a flown run
# --------------------------------------------------------------------------------------

LAG_PRE_S = 0.2  # how early a preview may start commanding before the reversal (longer than the actuators' lag)
CAUSAL_DELAY_S = 0.01  # one control tick at 100 Hz: the first tick that can see the reaction
RATE_EPS_RAD_S = 1e-6  # a joint faster than this is moving (the plant's servo holds exactly still)
SETTLE_S = 0.5  # a window ends at rest this long after the arm stops (the bound of the paper's reversal is the same
# with 1 s to 1e-3 deg)
MIN_SETTLE_S = 0.2  # a window may end this soon after the arm stops when the next move follows
CHUNK_S, CHUNK_OVERLAP_S = 1.5, 0.5  # a longer window is bounded in pieces this long, overlapping this much
LONG_DT_S = 0.01  # and on this grid (the log's): the paper reversal's bounds 0.1-0.3 deg lower than on 2 ms


def moment_lag(plant: Any) -> tuple[float, float]:
    """(omega_n, zeta) of the actuators' response that the moment lag models (PlantParams): the faster of the duct
    tilt and the propeller speed dynamics (the pitch moment has parts from both; the faster keeps the bound low)."""
    return max((plant.tilt_dynamics.omega_n_rad_s, plant.tilt_dynamics.zeta),
               (plant.speed_dynamics.omega_n_rad_s, plant.speed_dynamics.zeta))


def arm_windows(t_s: np.ndarray, qd_rad_s: np.ndarray, pre_s: float = LAG_PRE_S, settle_s: float = SETTLE_S,
                min_settle_s: float = MIN_SETTLE_S, rate_eps: float = RATE_EPS_RAD_S) -> list[dict[str, Any]]:
    """The arm's moves: runs of samples with a joint moving (h changes only then: it is linear in q'), each from the
    last sample at rest before it (its onset) to the first at rest after it (its stop). A window runs from pre_s
    before its onset to settle_s after its stop, cut short pre_s before the next onset when the arm rests at least
    min_settle_s between (the next window starts there, at rest); moves closer than that share one window, which
    keeps its first onset ("moves" counts them)."""
    t = np.asarray(t_s, dtype=float)
    moving = np.any(np.abs(np.nan_to_num(qd_rad_s)) > rate_eps, axis=1)
    idx = np.flatnonzero(moving)
    if idx.size == 0:
        return []
    cut = np.flatnonzero(np.diff(idx) > 1)
    first, last = idx[np.r_[0, cut + 1]], idx[np.r_[cut, idx.size - 1]]
    out: list[dict[str, Any]] = []
    for a, b in zip(first, last, strict=True):
        onset, stop = float(t[max(a - 1, 0)]), float(t[min(b + 1, len(t) - 1)])
        start = max(onset - pre_s, float(t[0]))
        if out and start < out[-1]["t_stop_s"] + min_settle_s:
            out[-1]["t_stop_s"] = stop
            out[-1]["moves"] += 1
            continue
        out.append({"t_start_s": start, "t_onset_s": onset, "t_stop_s": stop, "moves": 1})
    for i, w in enumerate(out):
        nxt = out[i + 1]["t_start_s"] if i + 1 < len(out) else math.inf
        w["t_end_s"] = min(w["t_stop_s"] + settle_s, nxt, float(t[-1]))
    return out


def _resample(t_log: np.ndarray, q: np.ndarray, qd: np.ndarray, t_grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """q, q' at t_grid: cubic Hermite through the logged (q, q') (the servo's rest stays exactly at rest)."""
    from scipy.interpolate import CubicHermiteSpline

    sp = CubicHermiteSpline(t_log, q, qd, axis=0)
    return sp(t_grid), sp(t_grid, 1)


def bound_from_log(run_log: Any, vehicle_cfg: VehicleConfig, plant: Any = None, *,
                   actuator: tuple[float, float] | None = None, dt_s: float = 0.005, pre_s: float = LAG_PRE_S,
                   settle_s: float = SETTLE_S, causal_delay_s: float = CAUSAL_DELAY_S, preview: bool = False,
                   spacing_m: float = MAP_SPACING_M) -> dict[str, Any]:
    """What physics allows on a flown run: the smallest peak pitch excursion any controller could reach on the
    arm's moves of this run, with this (true) vehicle's actuators.

    run_log: as `navig8_tools.logdata.load_run` returns it (anything with `topics` and `[topic]` giving Series with
    `t` and `field(name, width)`); read: /truth joint_pos_rad, joint_rate_rad_s, object_mass_kg and, when the log
    has no /fc/setpoint, euler_rad; /fc/setpoint pitch_rad (the commanded pitch). vehicle_cfg: the TRUE vehicle
    (`sim_bridge.world.load_world(...).vehicle`). plant: its PlantParams (`.plant`), for the actuators'
    omega_n/zeta (`moment_lag`: the faster of tilt and speed dynamics); actuator = (omega_n, zeta) overrides it;
    neither: params/plant.yaml.

    Method: the run is split into the arm's moves (`arm_windows`: where h changes, pre_s before and settle_s after);
    each window is resampled every dt_s (cubic Hermite through the logged q, q'; the object and the commanded
    pitch held from the last sample) and `window_bound` gives its smallest peak |theta - theta_start|, starting at
    rest at trim (theta = theta' = 0) and ending at rest, in these variants (degrees):

    - lag_free_fx_held / lag_free_fx_free: no actuator lag, the command free from the move's onset;
    - causal_fx_held / causal_fx_free: with the actuators' second-order lag, the command at trim until
      causal_delay_s (one control tick) after the onset;
    - preview_fx_held / preview_fx_free (preview=True): with the lag, the command free from pre_s before the onset.

    bound_deg = causal_fx_free, the worst window's: what a controller that sees the reaction when it happens (no
    plan of the arm's motion) could do at best with these actuators, giving up forward force (the tilt lever) for
    pitch, which is what it must do to hold attitude. It is the number to set against a flown attitude error: the
    lag-free numbers ignore the ~10 ms the actuators need, which any loop pays (docs/model.md: 7-10 deg on the
    paper's reversal), and F_x held throws away a lever any controller may use, so they would call avoidable
    losses unavoidable (lag-free) or unavoidable ones avoidable (held).

    Where it is not a strict bound: (1) the lag is linear in the moment while the thrust is ~ w|w| (a duct's
    thrust cut is faster, the tail's reversal through zero slower), and F_z is held at m g exactly while a real
    allocation may trade it for pitch for a few ticks; so the causal numbers are a model of the lag (the flown
    paper reversals have beaten the level causal F_x-free number by a few degrees); (2) the authority between
    lattice nodes relies on its convexity in the CoM, exact without the dihedral's side force (AuthorityMap);
    (3) each window starts at rest at the commanded attitude (a vehicle still swinging from an earlier move is
    not modelled: moves resting less than pre_s + MIN_SETTLE_S apart share one window instead, inside which the
    LP knows the later moves in advance, so its bound is lower, still a lower bound) and ends at rest settle_s
    after the arm stops (unless the log ends first, or the next window starts); a window longer than CHUNK_S
    (continuous motion) is bounded on the log's 10 ms grid in overlapping pieces, the first from rest, the later
    ones with their state free (a relaxation: each piece's number is at most the whole window's LP), because the
    LP's cost grows faster than its length; (4) a commanded pitch step during a move changes the
    authority but is not itself a demand on it; the excursion is the arm's, about the commanded attitude.

    Returns a dict: bound_deg (math.inf when trim_feasible is False), trim_feasible (False when at some pose,
    object and commanded pitch flown the actuator set cannot hold the hover wrench with F_x held: no moment
    range containing 0), untrimmable_t_s (the first such time, else None), worst_t_s (the onset of the worst
    window; the first untrimmable time when there is one; the log's start when the arm never moves), the
    variants' worst over windows (*_deg), windows (one dict per window: times, moves, object and pitch, peak
    reaction, the variants), actuator, tail_max_thrust_n, pitch_source, dt_s, lp_points (static LP points solved
    for it: the maps are kept per process), compute_s (wall) and cpu_s (this process's CPU time).
    """
    t0, c0 = time.perf_counter(), time.process_time()
    if actuator is None:
        if plant is None:
            from sim_bridge.params import PlantParams

            plant = PlantParams.load()
        actuator = moment_lag(plant)
    flown, pitch_source = _flown_motion(run_log)
    maps_before = map_lp_points()
    untrimmable = _first_untrimmable(vehicle_cfg, flown, spacing_m)
    variants = [("lag_free", None, "onset"), ("causal", actuator, "causal")]
    if preview:
        variants.append(("preview", actuator, "start"))
    windows = arm_windows(flown.t_s, flown.qd_rad_s, pre_s, settle_s)
    for w in windows:
        u_t = _bound_window(w, vehicle_cfg, flown, variants, dt_s, causal_delay_s, settle_s, spacing_m)
        if u_t is not None and (untrimmable is None or u_t < untrimmable):
            untrimmable = u_t
    out = _worst_of_windows(windows, [name for name, _, _ in variants], untrimmable, flown.t_s)
    lp_points = sum(n - maps_before.get(k, 0) for k, n in map_lp_points().items())
    out.update({"actuator": {"omega_n_rad_s": float(actuator[0]), "zeta": float(actuator[1])},
                "tail_max_thrust_n": tail_max_thrust_n(vehicle_cfg), "pitch_source": pitch_source, "dt_s": dt_s,
                "lp_points": lp_points, "compute_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0})
    return out


def _flown_motion(run_log: Any) -> tuple[ArmMotion, str]:
    """The run's arm motion, object and commanded pitch at each /truth sample with finite joint data, and where the
    commanded pitch came from (/fc/setpoint, rounded to 1e-3 deg: the AuthorityMap keys; else the flown pitch)."""
    tr = run_log["/truth"]
    t = np.asarray(tr.t, dtype=float)
    q = tr.field("joint_pos_rad", N_LINKS)
    qd = tr.field("joint_rate_rad_s", N_LINKS)
    mo = np.nan_to_num(tr.field("object_mass_kg"))
    if "/fc/setpoint" in run_log.topics and len(run_log["/fc/setpoint"].t):
        sp = run_log["/fc/setpoint"]
        idx = np.clip(np.searchsorted(sp.t, t, side="right") - 1, 0, len(sp.t) - 1)
        pitch = np.radians(np.round(np.degrees(np.nan_to_num(sp.field("pitch_rad"))[idx]), 3))  # map keys
        pitch_source = "/fc/setpoint"
    else:
        pitch = np.round(np.nan_to_num(tr.field("euler_rad", 3)[:, 1]) / math.radians(1.0)) * math.radians(1.0)
        pitch_source = "/truth euler (flown, to 1 deg)"
    ok = np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(qd), axis=1)
    return ArmMotion(t[ok], q[ok], qd[ok], mo[ok], pitch[ok]), pitch_source


def _first_untrimmable(cfg: VehicleConfig, flown: ArmMotion, spacing_m: float) -> float | None:
    """The first time at which the actuator set cannot hold the hover (F_x held) at the pose, object and commanded
    pitch flown; None when it can throughout."""
    mt = mass_terms(cfg, flown.q_rad, flown.object_mass_kg)
    terms = {"com_x": mt[:, 1], "com_z": mt[:, 2], "mass": mt[:, 3]}
    lo, hi = authority_along(cfg, flown, terms, False, spacing_m)
    bad = ~((lo <= TRIM_TOL_NM) & (hi >= -TRIM_TOL_NM))
    return float(flown.t_s[np.argmax(bad)]) if np.any(bad) else None


def _window_motion(w: dict[str, Any], flown: ArmMotion, dt_s: float) -> tuple[ArmMotion, float]:
    """The window's motion resampled on its grid (dt_s; a window of continuous motion longer than one piece on a
    coarser grid, as its LPs grow faster than its length), the object and the commanded pitch held from the last
    logged sample; and the grid's step."""
    t = flown.t_s
    dt_w = dt_s if w["t_end_s"] - w["t_start_s"] <= CHUNK_S else max(dt_s, LONG_DT_S)
    n = int(math.floor((w["t_end_s"] - w["t_start_s"]) / dt_w + 1e-9)) + 1
    tg = w["t_start_s"] + dt_w * np.arange(n)
    i0 = max(int(np.searchsorted(t, w["t_start_s"], side="right")) - 1, 0)
    i1 = min(int(np.searchsorted(t, w["t_end_s"], side="left")) + 1, len(t))
    qg, qdg = _resample(t[i0:i1], flown.q_rad[i0:i1], flown.qd_rad_s[i0:i1], tg)
    j = np.clip(np.searchsorted(t, tg + 1e-9, side="right") - 1, 0, len(t) - 1)
    return ArmMotion(tg, qg, qdg, flown.object_mass_kg[j], flown.body_pitch_rad[j]), dt_w


def _window_pieces(n: int, dt_w: float) -> list[tuple[int, int]]:
    """A window of n samples as pieces [k_a, k_b) of CHUNK_S overlapping by CHUNK_OVERLAP_S (one piece when it is
    no longer than that)."""
    step, span = int(round((CHUNK_S - CHUNK_OVERLAP_S) / dt_w)), int(round(CHUNK_S / dt_w))
    starts = [0]
    while starts[-1] + span < n - 1:
        starts.append(starts[-1] + step)
    return [(k, min(k + span + 1, n)) for k in starts]


def _bound_window(w: dict[str, Any], cfg: VehicleConfig, flown: ArmMotion, variants: list[tuple[str, Any, str]],
                  dt_s: float, causal_delay_s: float, settle_s: float, spacing_m: float) -> float | None:
    """One window's bounds: `w` gains its object and pitch ranges, peak reaction, pieces and each variant's worst
    piece (deg, F_x held and free). Returns the first untrimmable time found in it, or None."""
    motion, dt_w = _window_motion(w, flown, dt_s)
    tg, n = motion.t_s, len(motion.t_s)
    mo, pitch = motion.object_mass_kg, motion.body_pitch_rad
    onset = int(np.searchsorted(tg, w["t_onset_s"] - 1e-9))
    hold = {"onset": onset, "causal": onset + int(round(causal_delay_s / dt_w)), "start": 0}
    end_at_rest = w["t_end_s"] - w["t_stop_s"] >= min(settle_s, MIN_SETTLE_S) - 1e-9  # else the log ends first
    w.update({"object_kg": [float(np.min(mo)), float(np.max(mo))],
              "pitch_cmd_deg": [math.degrees(float(np.min(pitch))), math.degrees(float(np.max(pitch)))],
              "end_at_rest": bool(end_at_rest)})
    terms = motion_terms(cfg, motion)
    w["peak_reaction_nm"] = float(np.max(np.abs(np.gradient(terms["h"], tg))))
    # a long window (continuous motion) in overlapping pieces, each after the first with its state free
    pieces = _window_pieces(n, dt_w)
    w["pieces"], w["dt_s"] = len(pieces), dt_w
    untrimmable = None
    for name, act, when in variants:
        for fx_free in (False, True):
            worst = 0.0
            for k_a, k_b in pieces:
                flags = (hold[when] if k_a == 0 else 0, end_at_rest and k_b == n, k_a > 0)
                peak, u_t = _piece_bound(cfg, motion, terms, (k_a, k_b), act, flags, fx_free, spacing_m)
                worst = max(worst, peak)
                if u_t is not None and (untrimmable is None or u_t < untrimmable):
                    untrimmable = u_t
            w[f"{name}_fx_{'free' if fx_free else 'held'}_deg"] = math.degrees(worst)
    return untrimmable


def _piece_bound(cfg: VehicleConfig, motion: ArmMotion, terms: dict[str, np.ndarray], span: tuple[int, int],
                 actuator: tuple[float, float] | None, flags: tuple[int, bool, bool], fx_free: bool,
                 spacing_m: float) -> tuple[float, float | None]:
    """`window_bound` on the samples span = [k_a, k_b) of a window's motion, flags = (hold_until, end_at_rest,
    free_start): its peak (rad) and its first untrimmable time (s) or None. A repeated move (a square wave's) is
    solved once per process (_WINDOWS, keyed by the piece's content)."""
    k_a, k_b = span
    n = len(motion.t_s)
    sl = slice(k_a, k_b)
    piece = ArmMotion(motion.t_s[sl], motion.q_rad[sl], motion.qd_rad_s[sl], motion.object_mass_kg[sl],
                      motion.body_pitch_rad[sl])
    p_terms = {key: v[k_a:k_b] if len(v) == n else v[k_a:k_b - 1] for key, v in terms.items()}
    digest = hashlib.sha1(b"".join(np.ascontiguousarray(np.round(x, 9)).tobytes() for x in (
        piece.q_rad, piece.qd_rad_s, piece.object_mass_kg, piece.body_pitch_rad,
        piece.t_s - piece.t_s[0]))).hexdigest()
    key = (cfg, actuator, flags, spacing_m, fx_free, digest)
    if key not in _WINDOWS:
        if len(_WINDOWS) >= 4096:
            _WINDOWS.clear()
        b = window_bound(cfg, piece, fx_free, actuator, flags[0], flags[1], spacing_m, p_terms, flags[2])
        u_t = None if b.untrimmable_t_s is None else b.untrimmable_t_s - float(piece.t_s[0])
        _WINDOWS[key] = (b.min_peak_pitch_rad, u_t)
    peak, u_t = _WINDOWS[key]
    return peak, None if u_t is None else u_t + float(piece.t_s[0])


def _worst_of_windows(windows: list[dict[str, Any]], names: list[str], untrimmable: float | None,
                      t: np.ndarray) -> dict[str, Any]:
    """The run's figures from its windows': each variant's worst, the bound (inf when untrimmable), when."""
    keys = [f"{name}_fx_{fx}_deg" for name in names for fx in ("held", "free")]
    out: dict[str, Any] = {k: max((w[k] for w in windows), default=0.0) for k in keys}
    trim_ok = untrimmable is None
    if windows:
        worst = max(windows, key=lambda w: w["causal_fx_free_deg"])
        worst_t = worst["t_onset_s"]
    else:
        worst_t = float(t[0]) if len(t) else 0.0
    out.update({
        "bound_deg": out["causal_fx_free_deg"] if trim_ok else math.inf,
        "trim_feasible": trim_ok,
        "untrimmable_t_s": untrimmable,
        "worst_t_s": float(worst_t if trim_ok else untrimmable),
        "windows": windows,
    })
    return out


# --------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------

POSES_DEG = {"q=0": (0.0, 0.0, 0.0), "+20x3": (20.0, 20.0, 20.0), "-20x3": (-20.0, -20.0, -20.0),
             "80/10/10": (80.0, 10.0, 10.0), "60/60/60": (60.0, 60.0, 60.0)}


def analyse(cfg: VehicleConfig, masses: Sequence[float], reversal: bool, v_max: float,
            a_max: float, amplitude_deg: float, actuator: tuple[float, float] | None = None,
            pitch_deg: float = 0.0) -> dict[str, Any]:
    th = math.radians(pitch_deg)
    static = []
    for name, pose in POSES_DEG.items():
        q = [math.radians(v) for v in pose]
        for m in masses:
            row: dict[str, Any] = {"pose": name, "object_kg": m}
            for axis in ("pitch", "roll"):
                for fx_free in (False, True):
                    if axis == "roll" and fx_free:
                        continue
                    key = f"{axis}{'_fx_free' if fx_free else ''}"
                    try:
                        a = hover_authority(cfg, q, m, axis, fx_free, body_pitch_rad=th)
                    except ValueError:  # this actuator set cannot even trim there
                        row[key] = None
                        continue
                    row[key] = [a.min_nm, a.max_nm]
            static.append(row)
    rev = []
    if reversal:
        amp = math.radians(amplitude_deg)
        for m in masses:
            for q0, q1 in ((amp, -amp), (-amp, amp)):
                for fx_free in (False, True):
                    b = reversal_bound(cfg, q0, q1, m, v_max, a_max, fx_free, body_pitch_rad=th)
                    row = {"object_kg": m, "from_deg": math.degrees(q0), "to_deg": math.degrees(q1),
                           "fx_free": fx_free, "min_peak_pitch_deg": _finite(math.degrees(b.min_peak_pitch_rad)),
                           "peak_reaction_nm": float(np.max(np.abs(b.disturbance_nm))),
                           "authority_nm": [float(np.min(b.authority_min_nm)), float(np.max(b.authority_max_nm))]}
                    if actuator is not None:
                        for key, delay in (("lag_preview_deg", None), ("lag_causal_deg", CAUSAL_DELAY_S)):
                            bl = reversal_bound(cfg, q0, q1, m, v_max, a_max, fx_free, actuator=actuator,
                                                causal_delay_s=delay, pre_s=LAG_PRE_S, body_pitch_rad=th)
                            row[key] = _finite(math.degrees(bl.min_peak_pitch_rad))
                    rev.append(row)
    return {"tail_max_thrust_n": tail_max_thrust_n(cfg), "body_pitch_deg": pitch_deg, "static": static,
            "reversal": rev}


def _finite(v: float) -> float | None:
    return v if math.isfinite(v) else None


def _deg(v: float | None) -> str:
    return "  untrimmable" if v is None or not math.isfinite(v) else f"{v:6.2f}"


def render_text(rep: dict[str, Any]) -> str:
    lines = [f"tail: +-{rep['tail_max_thrust_n']:.0f} N; body pitch {rep['body_pitch_deg']:g} deg",
             "static pure-moment authority at hover about the composite CoM, N m [min, max] (inner LP)",
             f"{'pose':>9} {'m_o':>4} | {'pitch, Fx held':>17} | {'pitch, Fx free':>17} | {'roll':>17}"]
    for r in rep["static"]:
        p, pf, ro = r["pitch"], r["pitch_fx_free"], r["roll"]
        if p is None or pf is None or ro is None:
            lines.append(f"{r['pose']:>9} {r['object_kg']:4.1f} | cannot hover (no trim inside the limits)")
            continue
        lines.append(f"{r['pose']:>9} {r['object_kg']:4.1f} | {p[0]:7.1f} {p[1]:8.1f} | {pf[0]:7.1f} {pf[1]:8.1f}"
                     f" | {ro[0]:7.1f} {ro[1]:8.1f}")
    if rep["reversal"]:
        lines.append("arm reversal: smallest peak pitch excursion any controller reaches (lower bound)")
        for r in rep["reversal"]:
            lag = ""
            if "lag_preview_deg" in r:
                lag = (f"; with the actuators' lag {_deg(r['lag_preview_deg'])} (preview)"
                       f" {_deg(r['lag_causal_deg'])} (causal)")
            lines.append(f"  m_o {r['object_kg']:.1f} kg {r['from_deg']:+.0f} -> {r['to_deg']:+.0f} deg"
                         f" Fx {'free' if r['fx_free'] else 'held'}: {_deg(r['min_peak_pitch_deg'])} deg"
                         f" (peak reaction {r['peak_reaction_nm']:.1f} N m){lag}")
    return "\n".join(lines)


def render_log_text(rep: dict[str, Any]) -> str:
    act = rep["actuator"]
    lines = [f"{rep['log']}: scenario {rep['scenario']}, world {rep['world'] or '{}'}",
             f"tail +-{rep['tail_max_thrust_n']:.0f} N; moment lag omega_n {act['omega_n_rad_s']:g} rad/s, zeta"
             f" {act['zeta']:g}; commanded pitch from {rep['pitch_source']}"]
    if rep["trim_feasible"]:
        lines.append("trim: the actuator set holds the hover at every pose, object and commanded pitch flown")
    else:
        lines.append(f"trim: NOT feasible from {rep['untrimmable_t_s']:.2f} s (no controller can hold this hover)")
    lines.append(f"bound (causal with the actuators' lag, F_x free): {_deg(rep['bound_deg'])} deg,"
                 f" worst at {rep['worst_t_s']:.2f} s")
    pv = "preview_fx_free_deg" in rep
    head = (f"{'onset s':>8} {'stop s':>7} {'moves':>5} {'m_o kg':>9} {'pitch':>7} {'react Nm':>8} |"
            f" {'lag-free held':>13} {'free':>6} | {'causal held':>11} {'free':>6}")
    lines += ["windows (smallest peak |pitch excursion|, deg):", head + (" | preview held   free" if pv else "")]
    for w in rep["windows"]:
        mo = w["object_kg"]
        line = (f"{w['t_onset_s']:8.2f} {w['t_stop_s']:7.2f} {w['moves']:5d} {mo[0]:4.2f}-{mo[1]:<4.2f}"
                f" {w['pitch_cmd_deg'][1]:7.1f} {w['peak_reaction_nm']:8.1f} | {_deg(w['lag_free_fx_held_deg']):>13}"
                f" {_deg(w['lag_free_fx_free_deg'])} | {_deg(w['causal_fx_held_deg']):>11}"
                f" {_deg(w['causal_fx_free_deg'])}")
        if pv:
            line += f" | {_deg(w['preview_fx_held_deg']):>12} {_deg(w['preview_fx_free_deg'])}"
        lines.append(line)
    lines.append(f"({rep['lp_points']} static LP points, {rep['compute_s']:.2f} s wall, {rep['cpu_s']:.2f} s CPU)")
    return "\n".join(lines)


def _jsonable(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_jsonable(x) for x in v]
    return v


def log_main(args: argparse.Namespace) -> int:
    """--log: the bound of one flown run, in the world it flew (the log's metadata; --scenario/--world on top)."""
    from navig8_tools.logdata import load_run
    from sim_bridge.world import load_world, parse_world_items

    run = load_run(args.log, topics=["/truth", "/fc/setpoint"])
    meta = run.metadata.get("run", {})
    scenario = args.scenario or meta.get("scenario") or "paper"
    world = {str(k): float(v) for k, v in (meta.get("world") or {}).items()}
    world.update(parse_world_items(args.world))
    w = load_world(scenario, world)
    rep = bound_from_log(run, w.vehicle, w.plant, preview=args.preview)
    rep.update({"log": str(args.log), "scenario": scenario, "world": world})
    print(json.dumps(_jsonable(rep), allow_nan=False) if args.json else render_log_text(rep))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    from sim_bridge.params import PlantParams

    plant = PlantParams.load()
    ap = argparse.ArgumentParser(prog="navig8-authority", description=__doc__.split("\n\n")[0])
    ap.add_argument("--tail-max-thrust", type=float, default=None, metavar="N",
                    help="evaluate a tail of this maximum thrust (N) instead of params/vehicle.yaml's")
    ap.add_argument("--masses", default="0,1,2", help="object masses, kg, comma separated")
    ap.add_argument("--amplitude-deg", type=float, default=20.0, help="reversal amplitude (Eq. 26: 20 deg)")
    ap.add_argument("--pitch-deg", type=float, default=0.0,
                    help="hover with the body pitched (the paper's 45 deg phase); default level")
    ap.add_argument("--no-reversal", action="store_true", help="static authority only")
    ap.add_argument("--json", action="store_true", help="one JSON object instead of the table")
    ap.add_argument("--lag", action="store_true",
                    help="also the reversal bound with the actuators' second-order lag (preview and causal)")
    ap.add_argument("--log", default=None, metavar="RUN.mcap",
                    help="the authority bound of a flown run instead (bound_from_log), in the world of the log's"
                         " metadata (navig8-sim records it) with --scenario/--world on top")
    ap.add_argument("--scenario", default=None, help="with --log: the run's scenario (default: the log's, or paper)")
    ap.add_argument("--world", action="append", default=[], metavar="NAME=VALUE",
                    help="with --log: a world override the run flew with (sim_bridge/world.py names)")
    ap.add_argument("--preview", action="store_true", help="with --log: also the preview variants")
    args = ap.parse_args(argv)
    if args.log is not None:
        try:
            return log_main(args)
        except (ValueError, KeyError, OSError) as e:
            print(f"navig8-authority: {e}", file=sys.stderr)
            return 2
    cfg = VehicleConfig.load()
    if args.tail_max_thrust is not None:
        if not args.tail_max_thrust > 0.0:
            print("navig8-authority: --tail-max-thrust must be > 0", file=sys.stderr)
            return 2
        cfg = with_tail_thrust(cfg, args.tail_max_thrust)
    try:
        masses = [float(v) for v in args.masses.split(",")]
        act = moment_lag(plant) if args.lag else None
        rep = analyse(cfg, masses, not args.no_reversal, plant.joint_v_max_rad_s, plant.joint_a_max_rad_s2,
                      args.amplitude_deg, act, args.pitch_deg)
    except ValueError as e:
        print(f"navig8-authority: {e}", file=sys.stderr)
        return 2
    print(json.dumps(rep, allow_nan=False) if args.json else render_text(rep))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
