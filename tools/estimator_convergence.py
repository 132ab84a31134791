"""Does the adaptive law's implied K converge to the truth? ("the estimate moves where the truth moves")

    python -m navig8_tools.estimator_convergence [--scenario ident] [--seeds 1-10] [--from-s 12] [--tol 0.1]
                                                 [--params FILE] [--set NAME=VALUE ...] [--world NAME=VALUE ...]
                                                 [--window A-B ...]

Plant and FlightStack in one process (as navig8-sim, no log), proposed controller. Per tick the implied
K = (J_xx / I_xx, J_yy / I_yy, J_zz / I_zz, m_UAM / m) of the estimate is compared with the truth from the plant's
composite inertia about its true CoM and the controller's UAM model, clipped to the Eq. 20 box [INDI_K_MIN,
INDI_K_MAX]. Prints one JSON line per seed (from when each |K - K_true| stays within --tol, the largest error from
--from-s on and in each --window A-B (s), K and K_true at the end) and the medians and worst seeds. --world changes
the flight's world as navig8-sim's does (e.g. `scenario.events.0.mass_kg=0.5`, `scenario.initial.joint_pos_deg.0=60`).
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

import numpy as np

from navig8_fc.core.controller import FcSensors, warm_up_kernels
from navig8_fc.flight import FlightStack, StepResult
from navig8_fc.params.registry import ParamRegistry
from navig8_fc.params.store import read_overrides
from navig8_tools.sim import fly
from sim_bridge.plant import Plant
from sim_bridge.world import load_world, parse_world_items

K_NAMES = ("K1", "K2", "K3", "K4")


def registry_with(overrides: dict[str, float]) -> ParamRegistry:
    """The defaults with `overrides` set in their order (each checked by the registry; a refused one raises)."""
    reg = ParamRegistry.from_defaults()
    for name, value in overrides.items():
        res = reg.set(name, value)
        if not res.accepted:
            raise ValueError(res.reason)
    return reg


def k_trace(overrides: dict[str, float], duration_s: float, seed: int = 1,
            scenario: str | Path = "ident", world: dict[str, float] | None = None,
            truth_box: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t (n,), implied K (n, 4), clip(K_true, k_min, k_max) (n, 4)) of a run with the parameters `overrides` (the
    controller is CKF_MODE's, the proposed one by default) in the world `world` (sim_bridge.world overrides).
    truth_box: the (k_min, k_max) the truth is clipped to (None: the run's own INDI_K_MIN, INDI_K_MAX; a test of a
    narrowed box passes the default box, so that a pinned estimate is not compared with a truth pinned alike)."""
    reg = registry_with(overrides)
    box = truth_box if truth_box is not None else (reg["INDI_K_MIN"], reg["INDI_K_MAX"])
    t, k, k_true, _ = k_trace_unclipped(reg, duration_s, seed, scenario, world)
    return t, k, np.clip(k_true, *box)


def k_trace_unclipped(reg: ParamRegistry, duration_s: float, seed: int = 1, scenario: str | Path = "ident",
                      world: dict[str, float] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """k_trace's flight with the registry `reg`: (t, implied K, K_true unclipped, the controller's dt_s). The flight
    does not depend on its length: a shorter one is a longer one's first int(round(duration_s / dt_s)) + 1 ticks."""
    w = load_world(scenario, world)
    plant = Plant(w.vehicle, w.plant, w.scenario, np.random.default_rng(seed))
    stack = FlightStack(w.fc_vehicle, reg, w.scenario.script)
    cfg = stack.core.config
    warm_up_kernels(w.fc_vehicle, cfg)
    ts, ks, kts = [], [], []

    def trace(_t_ns: int, s: FcSensors, res: StepResult) -> None:
        st, tr = res.status, plant.truth()
        j, i_true = st.inertia_uam_diag, np.asarray(tr.inertia_com_kgm2)
        ts.append(s.t_s)
        ks.append(np.array(st.adapt.k))
        kts.append(np.array([j[0] / i_true[0, 0], j[1] / i_true[1, 1], j[2] / i_true[2, 2],
                             st.mass_uam_kg / tr.mass_kg]))

    fly(plant, stack, int(round(duration_s / cfg.dt_s)), trace)
    return np.array(ts), np.array(ks), np.array(kts), cfg.dt_s


def within_for_good_from_s(t: np.ndarray, err: np.ndarray, tol: float) -> float:
    """The time from which |err| <= tol holds to the end (nan if it does not hold at the end)."""
    bad = np.nonzero(err > tol)[0]
    if len(bad) == 0:
        return float(t[0])
    return float(t[bad[-1] + 1]) if bad[-1] + 1 < len(t) else float("nan")


def window_max_error(t: np.ndarray, err: np.ndarray, t0_s: float, t1_s: float) -> list[float]:
    """The largest |K - K_true| per K over t0_s <= t < t1_s (nan where the window holds no sample)."""
    sel = (t >= t0_s - 1e-9) & (t < t1_s - 1e-9)
    return [float(x) for x in err[sel].max(axis=0)] if sel.any() else [float("nan")] * err.shape[1]


def window_mean_error(t: np.ndarray, err: np.ndarray, t0_s: float, t1_s: float) -> list[float]:
    """The mean signed error per column of err over t0_s <= t < t1_s (nan if the window holds no sample): the bias
    part of window_max_error's figure."""
    sel = (t >= t0_s - 1e-9) & (t < t1_s - 1e-9)
    return [float(x) for x in err[sel].mean(axis=0)] if sel.any() else [float("nan")] * err.shape[1]


def _window(text: str) -> tuple[float, float]:
    lo, sep, hi = text.partition("-")
    if not sep:
        raise argparse.ArgumentTypeError(f"--window expects A-B (s), got {text!r}")
    return float(lo), float(hi)


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out.extend(range(int(lo), int(hi or lo) + 1))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="ident")
    ap.add_argument("--seeds", default="1-10", help="e.g. 1-10 or 1,3,5")
    ap.add_argument("--duration", type=float, default=None, help="s (default: the scenario's)")
    ap.add_argument("--from-s", type=float, default=12.0, help="largest error reported from this time on")
    ap.add_argument("--tol", type=float, default=0.1)
    ap.add_argument("--params", action="append", default=[], metavar="FILE",
                    help="a parameter set (params/presets/*.parm), applied before --set")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--world", action="append", default=[], metavar="NAME=VALUE",
                    help="a world override (sim_bridge/world.py), as navig8-sim's --world")
    ap.add_argument("--window", action="append", default=[], type=_window, metavar="A-B",
                    help="also report the largest |K - K_true| over A <= t < B (s), and the mean K - K_true there")
    a = ap.parse_args(argv)
    try:
        overrides = read_overrides(a.params, a.set)
        world = parse_world_items(a.world)
        duration = a.duration if a.duration is not None else load_world(a.scenario, world).scenario.duration_s
    except (OSError, ValueError) as exc:
        ap.error(str(exc))
    rows = []
    for seed in _seeds(a.seeds):
        t, k, kt = k_trace(overrides, duration, seed, a.scenario, world)
        signed = k - kt
        err = np.abs(signed)
        row = {"seed": seed,
               "within_from_s": [within_for_good_from_s(t, err[:, i], a.tol) for i in range(4)],
               "max_err_late": [float(x) for x in err[t >= a.from_s - 1e-9].max(axis=0)],
               "windows": {f"{w0:g}-{w1:g}": window_max_error(t, err, w0, w1) for w0, w1 in a.window},
               "window_means": {f"{w0:g}-{w1:g}": window_mean_error(t, signed, w0, w1) for w0, w1 in a.window},
               "k_end": [round(float(x), 3) for x in k[-1]], "k_true_end": [round(float(x), 3) for x in kt[-1]]}
        rows.append(row)
        print(json.dumps(row), flush=True)
    for i, name in enumerate(K_NAMES):
        wf = [r["within_from_s"][i] for r in rows]
        me = [r["max_err_late"][i] for r in rows]
        print(f"{name}: within {a.tol} for good from (s) median {statistics.median(wf):.2f}, worst {max(wf):.2f}; "
              f"max |K - K_true| from {a.from_s:g} s median {statistics.median(me):.3f}, worst {max(me):.3f}; "
              f"seeds beyond {a.tol}: {sum(m > a.tol for m in me)}/{len(me)}")
        for w0, w1 in a.window:
            we = [r["windows"][f"{w0:g}-{w1:g}"][i] for r in rows]
            wm = [r["window_means"][f"{w0:g}-{w1:g}"][i] for r in rows]
            print(f"{name}: max |K - K_true| over {w0:g}-{w1:g} s median {statistics.median(we):.3f}, "
                  f"worst {max(we):.3f}; mean K - K_true there {statistics.fmean(wm):+.4f} over the seeds "
                  f"(spread {statistics.pstdev(wm):.4f}); seeds beyond 0.05: {sum(x > 0.05 for x in we)}/{len(we)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
