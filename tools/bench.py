"""navig8-bench: speed (and accuracy) benchmarks, one section per piece of the system.

    navig8-bench                  # every section (~25 s on a quiet 2-core machine)
    navig8-bench --plant          # the plant alone: us per physics step (with sensors), real-time factor
    navig8-bench --plant-accuracy # the plant's integration error against a 10 kHz reference
    navig8-bench --fc             # the flight controller's tick inside the closed loop: median and p99 us
    navig8-bench --inprocess      # plant + FC in one process: real-time factor without and with the MCAP log
    navig8-bench --lockstep       # navig8-sitl at --speed 0 (two processes, MAVLink over UDP, MCAP on):
                                  # real-time factor, median of --repeat runs (5), and its ratio to in-process
    navig8-bench --stability      # the K-bounds analysis and the workspace floor the registry checks: s per call
    navig8-bench --startup        # the FC's and the bridge's imports in a fresh interpreter: CPU s (median of
                                  # --repeat), beside numpy's alone
    navig8-bench --campaign       # navig8-campaign runs/min: one process, the local pool, a Dask LocalCluster
                                  # (--campaign-runs N, --campaign-rounds R: R rounds in turn, medians)
    navig8-bench --lockstep --foxglove  # also with navig8-sitl --foxglove 0 (server up, nobody connected),
                                  # runs alternated with the plain ones: lockstep_foxglove_rtf and its ratio
    navig8-bench --fc --params params/presets/paper.parm  # the FC sections with a parameter set
    navig8-bench --json           # one JSON object with every metric (plant_rtf, fc_tick_us_median,
                                  # inprocess_rtf, lockstep_rtf, lockstep_over_inprocess, ...)

The machine's speed drifts by tens of percent over minutes on a shared VM: compare medians and ratios,
measured close in time. Adding a section: write `def _my_section(args) -> SectionResult` and append a
Section to SECTIONS (flag, help, function); its metrics are merged into the JSON object (prefix them with
the section's name) and its lines printed in the text report.
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class SectionResult:
    metrics: dict[str, Any]
    lines: list[str]


@dataclass(frozen=True)
class Section:
    flag: str  # command-line flag without the leading dashes
    help: str
    run: Callable[[argparse.Namespace], SectionResult]


# ---------------------------------------------------------------------------------------------
# --plant
# ---------------------------------------------------------------------------------------------


def _plant_section(args: argparse.Namespace) -> SectionResult:
    """The 30 s paper scenario, arm moving (Eq. 26), actuators held at the initial trim, sensors sampled
    once per control period (the closed loop's calling pattern: step(cmd, dt) + sense())."""
    from navig8_fc.core.vehicle import VehicleConfig
    from sim_bridge import Plant, PlantParams, integrator, load_scenario, sensors

    vehicle = VehicleConfig.load()
    params = PlantParams.load()
    scenario = load_scenario("paper")
    dt_s = args.plant_dt
    # first construction + call: numba compile, or the load of the on-disk cache
    t0 = time.perf_counter()
    warm = Plant(vehicle, params, scenario, np.random.default_rng(0))
    warm.step(warm.trim_command(), dt_s)
    warm.sense()
    warm.truth()
    first_call_s = time.perf_counter() - t0
    kernels = (integrator.advance, integrator.evaluate, sensors.sense)
    cache_misses = sum(sum(f.stats.cache_misses.values()) for f in kernels)
    gc.collect()  # a fresh compile leaves garbage whose collection would otherwise land in the timed loop

    plant = Plant(vehicle, params, scenario, np.random.default_rng(args.seed))
    cmd = plant.trim_command()
    n_calls = round(scenario.duration_s / dt_s)
    per_call = np.empty(n_calls)
    clock = time.perf_counter
    wall0 = clock()
    for k in range(n_calls):
        c0 = clock()
        plant.step(cmd, dt_s)
        plant.sense()
        per_call[k] = clock() - c0
    wall = clock() - wall0
    steps_per_call = round(dt_s * params.physics_rate_hz)
    call_us = float(np.median(per_call)) * 1e6
    metrics = {
        "plant_step_us_median": call_us / steps_per_call,
        "plant_rtf": scenario.duration_s / wall,
        "plant_call_us_median": call_us,
        "plant_physics_rate_hz": params.physics_rate_hz,
        "plant_control_dt_s": dt_s,
        "plant_sim_s": scenario.duration_s,
        "plant_wall_s": wall,
        "plant_first_call_s": first_call_s,
        "plant_numba_compiled": cache_misses > 0,
    }
    lines = [
        f"plant: paper scenario {scenario.duration_s:.0f} s, physics {params.physics_rate_hz:.0f} Hz, "
        f"step(cmd, {dt_s * 1e3:.0f} ms) + sense() per call, actuators at trim",
        f"  median per physics step (with sensors): {metrics['plant_step_us_median']:.2f} us "
        f"({call_us:.1f} us per {steps_per_call}-step call)",
        f"  real-time factor (plant only):          {metrics['plant_rtf']:.0f}x  ({wall:.3f} s wall)",
        f"  first call (numba {'compile' if cache_misses else 'cache load'}): {first_call_s:.2f} s",
    ]
    return SectionResult(metrics, lines)


# ---------------------------------------------------------------------------------------------
# --plant-accuracy
# ---------------------------------------------------------------------------------------------


def _quat_angle(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """Rotation angle between attitude rows (numerically accurate for tiny angles)."""
    w = np.abs(np.sum(qa * qb, axis=1))
    # |vector part of qa^-1 qb| via the cross-product identity; 2 atan2(|v|, |w|)
    va, vb = qa[:, 1:], qb[:, 1:]
    v = qa[:, :1] * vb - qb[:, :1] * va - np.cross(va, vb)
    return 2.0 * np.arctan2(np.linalg.norm(v, axis=1), w)


def _accuracy_case(vehicle, params, scenario, mode: str, rate_hz: float, duration_s: float) -> np.ndarray:
    from sim_bridge import Plant

    pp = dataclasses.replace(params, physics_rate_hz=rate_hz)
    plant = Plant(vehicle, pp, scenario, np.random.default_rng(0), base_mode=mode)
    cmd, mass = plant.trim_command(), plant.truth().object_mass_kg
    rows = []
    while plant.t_us < duration_s * 1e6:
        plant.step(cmd, 0.01)
        tr = plant.truth()
        if mode != "free" and tr.object_mass_kg != mass:  # gravity compensation for the locked base
            cmd, mass = plant.trim_command(), tr.object_mass_kg
        rows.append(np.concatenate([tr.pos_ned_m, tr.quat_wxyz, tr.rate_frd_rad_s, tr.reaction_force_frd_n,
                                    tr.reaction_moment_o_frd_nm, [tr.contact_points_active]]))
    return np.array(rows)


def _plant_accuracy_section(args: argparse.Namespace) -> SectionResult:
    """Integration error of the default physics rate against a 10x finer reference (same 1 kHz joint
    servo, so the joint trajectories are identical and only the RK4 step differs)."""
    from navig8_fc.core.vehicle import VehicleConfig
    from sim_bridge import PlantParams, load_scenario

    vehicle = VehicleConfig.load()
    params = PlantParams.load().without_noise()
    scenario = load_scenario("paper")
    ref_rate = 10.0 * params.physics_rate_hz
    cases = [
        # (label, key, vehicle, base mode, duration): the free base under constant trim tumbles and
        # hits the ground after ~1.5 s, so the smooth comparison is without gravity for the full 30 s.
        ("free base, no gravity, 30 s", "free_nog", dataclasses.replace(vehicle, gravity_m_s2=0.0), "free",
         30.0),
        ("attitude-locked base, gravity, 30 s", "locked", vehicle, "attitude_locked", 30.0),
        ("free base, gravity, until touchdown", "free_g", vehicle, "free", 30.0),
    ]
    metrics: dict[str, Any] = {"plant_acc_ref_rate_hz": ref_rate}
    lines = [
        f"plant accuracy: {params.physics_rate_hz:.0f} Hz vs {ref_rate:.0f} Hz reference (paper scenario)"
    ]
    for label, key, veh, mode, dur in cases:
        ref = _accuracy_case(veh, params, scenario, mode, ref_rate, dur)
        run = _accuracy_case(veh, params, scenario, mode, params.physics_rate_hz, dur)
        touch = ref[:, -1] > 0
        n = int(np.argmax(touch)) if touch.any() else len(ref)
        errs = {
            "pos_m": float(np.abs(run[:n, 0:3] - ref[:n, 0:3]).max()),
            "att_rad": float(_quat_angle(run[:n, 3:7], ref[:n, 3:7]).max()),
            "rate_rad_s": float(np.abs(run[:n, 7:10] - ref[:n, 7:10]).max()),
            "force_n": float(np.abs(run[:n, 10:13] - ref[:n, 10:13]).max()),
            "moment_nm": float(np.abs(run[:n, 13:16] - ref[:n, 13:16]).max()),
        }
        for k, v in errs.items():
            metrics[f"plant_acc_{key}_{k}"] = v
        lines.append(
            f"  {label} ({n * 0.01:.2f} s): max |dp| {errs['pos_m']:.1e} m, "
            f"attitude {errs['att_rad']:.1e} rad, rate {errs['rate_rad_s']:.1e} rad/s, "
            f"reaction {errs['force_n']:.1e} N / {errs['moment_nm']:.1e} N m"
        )
    return SectionResult(metrics, lines)


def _fc_section(args: argparse.Namespace) -> SectionResult:
    """FC tick (joint observer + model + CKF with projection + outer loops + INDI) timed inside the closed
    loop on the paper scenario (proposed controller), no logging."""
    from navig8_tools.sim import run

    run("paper", "proposed", args.seed, 2.0, overrides=args.overrides)  # warm-up: imports, numba cache load
    ticks: list[float] = []
    run("paper", "proposed", args.seed, 30.0, tick_times_s=ticks, overrides=args.overrides)
    us = np.array(ticks) * 1e6
    med, p99 = float(np.median(us)), float(np.percentile(us, 99))
    return SectionResult(
        {"fc_tick_us_median": med, "fc_tick_us_p99": p99},
        [f"fc: tick median {med:.0f} us, p99 {p99:.0f} us over {len(us)} ticks "
         f"(targets: median <= 300 us, p99 <= 1000 us)"],
    )


def _inprocess_section(args: argparse.Namespace) -> SectionResult:
    """Closed-loop real-time factor, plant + sensors + FC in one process, 30 s paper scenario:
    without logging (the loop itself) and with the full MCAP log written on a second process (navig8-sim's default,
    tools/log_writer.py) and in the loop (`--log-writer inline`, as campaign workers log), runs alternated."""
    import tempfile
    from pathlib import Path

    from navig8_tools.sim import run

    run("paper", "proposed", args.seed, 2.0, overrides=args.overrides)
    rtfs: dict[str, list[float]] = {"none": [], "process": [], "inline": []}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(3):
            rtfs["none"].append(run("paper", "proposed", args.seed, 30.0,
                                    overrides=args.overrides).summary["real_time_factor"])
            for writer in ("process", "inline"):
                rtfs[writer].append(run("paper", "proposed", args.seed, 30.0, Path(tmp) / "b.mcap",
                                        overrides=args.overrides, log_writer=writer).summary["real_time_factor"])
    rtf, logged, inline = (float(np.median(rtfs[k])) for k in ("none", "process", "inline"))
    return SectionResult(
        {"inprocess_rtf": rtf, "inprocess_rtf_logged": logged, "inprocess_rtf_logged_inline": inline},
        [f"inprocess: closed loop {rtf:.1f}x real time (median of 3, no log; target >= 50x), "
         f"{logged:.1f}x with the full MCAP log on a second process, {inline:.1f}x logged in the loop"],
    )


def _lockstep_section(args: argparse.Namespace) -> SectionResult:
    """The paper scenario through navig8-sitl (two processes, MAVLink over loopback UDP, --speed 0, MCAP on).
    The RTF is the bridge's own (sim time over wall time from the first answer to the end), read from the
    last NAVIG8_SIM_STATUS the FC logged; process start-up is excluded."""
    import subprocess
    import tempfile
    from pathlib import Path

    from navig8_fc.shell.mcap_log import read_metadata
    from navig8_tools.sim import run

    run("paper", "proposed", args.seed, 2.0, overrides=args.overrides)  # warm-up: imports, numba cache load
    inproc = float(np.median([run("paper", "proposed", args.seed, 30.0,
                                  overrides=args.overrides).summary["real_time_factor"] for _ in range(3)]))
    rtfs: list[float] = []
    fox_rtfs: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:

        def one(i: int, extra: list[str]) -> float:
            logs = Path(tmp) / f"l{i}"
            subprocess.run([sys.executable, "-m", "navig8_fc.shell.sitl", "--scenario", "paper", "--speed", "0",
                            "--until-done", "--instance", str(args.instance), "--log-dir", str(logs), "--state-dir",
                            str(Path(tmp) / "state"), "--defaults", *args.params_args, *extra], check=True,
                           capture_output=True,
                           timeout=600)
            meta = read_metadata(next(logs.glob("*.mcap")))
            return float(meta.get("bridge_status", {}).get("rtf", float("nan")))

        for i in range(args.repeat):
            rtfs.append(one(2 * i, []))
            if args.foxglove:  # alternated with the plain runs, so the VM's drift hits both alike
                fox_rtfs.append(one(2 * i + 1, ["--foxglove", "0"]))
    # Median of several runs: this 2-core VM's speed drifts by tens of percent from one run to the next.
    rtf = float(np.median(rtfs))
    fox: dict[str, Any] = {}
    fox_lines: list[str] = []
    if fox_rtfs:
        frtf = float(np.median(fox_rtfs))
        fox = {"lockstep_foxglove_rtf": frtf, "lockstep_foxglove_ratio": frtf / rtf}
        fox_lines = [f"lockstep --foxglove (server up, nobody connected): {frtf:.1f}x real time (median of "
                     f"{len(fox_rtfs)}, range {min(fox_rtfs):.1f}-{max(fox_rtfs):.1f}), {frtf / rtf:.3f} of without "
                     "(target within 5 %)"]
    return SectionResult(
        {"lockstep_rtf": rtf, "lockstep_over_inprocess": rtf / inproc if inproc else float("nan"),
         "lockstep_rtf_min": float(np.min(rtfs)), "lockstep_rtf_max": float(np.max(rtfs)),
         "lockstep_runs": len(rtfs), **fox},
        [f"lockstep: {rtf:.1f}x real time over MAVLink (median of {len(rtfs)}, range {min(rtfs):.1f}-"
         f"{max(rtfs):.1f}; MCAP on; target >= 20x), {rtf / inproc:.2f} of the in-process closed loop "
         f"({inproc:.1f}x, median of 3, no log)", *fox_lines],
    )


def _stability_section(args: argparse.Namespace) -> SectionResult:
    """Section 3's K-bounds analysis over the workspace (navig8-stability) and the workspace floor the parameter
    registry checks on every K-bound PARAM_SET: seconds per call (median of 3, after a warm-up call)."""
    from navig8_fc.core import k_xi
    from navig8_fc.core.vehicle import VehicleConfig

    cfg = VehicleConfig.load()

    def med_s(fn: Callable[[], Any]) -> float:
        fn()
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
        return float(np.median(times))

    full = med_s(lambda: k_xi.k_bounds_analysis(cfg, 0.5, 1.0))
    floor = med_s(lambda: k_xi.min_eigenvalue_over_workspace(cfg, 0.5, 1.0))
    return SectionResult(
        {"stability_k_bounds_s": full, "stability_floor_s": floor},
        [f"stability: K-bounds analysis {full:.2f} s (target < 2 s), workspace floor {floor * 1e3:.0f} ms "
         f"(target < 1 s; run on every K-bound PARAM_SET)"],
    )
# ---------------------------------------------------------------------------------------------
# --campaign
# ---------------------------------------------------------------------------------------------


def _campaign_rate(arrivals: list[tuple[str, float]]) -> float:
    """Runs per minute in steady state, summed over the workers: each worker's results after its first over the
    time from its first result to its last (the first carries the worker's start: process spawn, imports, warm-up,
    or waiting for the other workers to be spawned; the end of a finite campaign, where one worker has no row left
    while another finishes, is no worker's window)."""
    by_worker: dict[str, list[float]] = {}
    for worker, t in arrivals:
        by_worker.setdefault(worker, []).append(t)
    rates = [(len(ts) - 1) / (ts[-1] - ts[0]) for ts in by_worker.values() if len(ts) > 1 and ts[-1] > ts[0]]
    return 60.0 * sum(rates) if rates else float("nan")


def _serial_runs(rows: list[Any]) -> list[tuple[str, float, float]]:
    """The rows one after another in this (warm) process: (worker, end time from the first start, run_cpu_s)."""
    from navig8_tools.campaign_run import execute_row

    out = []
    t0 = time.perf_counter()
    for r in rows:
        rec = execute_row(r)
        if rec["status"] != "ok":
            raise RuntimeError(f"{r.run_id}: {rec['error']}")
        out.append((rec["worker"], time.perf_counter() - t0, rec["run_cpu_s"]))
    return out


def _campaign_round(rows: list[Any], workers: int) -> dict[str, float]:
    """One round of the campaign section: the rows on each backend in turn; its metrics (keys without prefix)."""
    from navig8_tools.campaign_run import dask_results, pool_results, worker_pool

    with worker_pool(1, "inprocess") as one:
        serial = one.submit(_serial_runs, rows).result()
    single = 60.0 * len(rows) / serial[-1][1]
    single_cpu = float(np.median([c for _, _, c in serial]))
    m = {"single_runs_per_min": single, "single_cpu_s_per_run": single_cpu}
    for name, source in (("pool", lambda: pool_results(rows, workers)),
                         ("dask_local", lambda: dask_results(rows, "local", workers))):
        t0 = time.perf_counter()
        parent_cpu0 = time.process_time()
        arrivals: list[tuple[str, float]] = []
        cpu: list[float] = []
        parent_cpu_at: list[float] = []
        for _row, rec in source():
            assert rec["status"] == "ok", rec
            arrivals.append((rec["worker"], time.perf_counter() - t0))
            parent_cpu_at.append(time.process_time())
            cpu.append(rec["run_cpu_s"])
        first: dict[str, float] = {}
        for w, t in arrivals:
            first.setdefault(w, t)
        rate = _campaign_rate(arrivals)
        run_cpu = float(np.median(cpu))
        # the parent's CPU per run between the first result and the last (the driver, Dask's scheduler): steady
        parent_steady = (parent_cpu_at[-1] - parent_cpu_at[0]) / max(1, len(rows) - 1)
        m.update({
            f"{name}_runs_per_min": rate, f"{name}_over_single": rate / single,
            f"{name}_startup_s": max(first.values()) if len(first) == workers else float("nan"),
            f"{name}_end_to_end_runs_per_min": 60.0 * len(rows) / arrivals[-1][1],
            f"{name}_cpu_s_per_run": run_cpu, f"{name}_cpu_over_single": run_cpu / single_cpu,
            # the driver's CPU per run (with Dask's scheduler, which runs in it; start-up and imports included)
            f"{name}_parent_cpu_s_per_run": (time.process_time() - parent_cpu0) / len(rows),
            f"{name}_parent_steady_cpu_s_per_run": parent_steady,
            # the ratio on idle cores when CPU is what limits: `workers` cores' worth of runs at the workers' and the
            # parent's CPU per run, over one core's worth at the single process's (a machine-independent estimate;
            # the nannies' CPU, a few ms per second, is left out)
            f"{name}_cpu_bound_ratio": workers * single_cpu / (run_cpu + parent_steady)})
    return m


def _campaign_section(args: argparse.Namespace) -> SectionResult:
    """navig8-campaign throughput, in-process kind: a campaign of 3 controllers x seeds on the paper scenario
    (10 s each, MCAP log + summary as every campaign run) run (1) serially in one warm process, (2) on the local
    process pool and (3) on a Dask LocalCluster, both with --workers (default 2); --campaign-rounds times in
    turn (so a shared machine's drift hits all three alike), medians over the rounds. The single process is a
    worker like the others (campaign_run.worker_pool(1): spawned with WORKER_ENV, warmed, then given all the rows
    in one task, run one after another with no IPC between them), so the ratios compare like with like. Rates
    are steady state (start-up reported apart); the machine-independent figure is each backend's median CPU
    seconds per run (time.process_time of the worker process around each run) against the single process's."""
    import os
    from pathlib import Path

    from navig8_tools.campaign_spec import Campaign, expand

    workers = args.workers or os.cpu_count() or 1
    n_seeds = max(2, args.campaign_runs // 3)
    rows = expand(Campaign.from_dict({
        "name": "bench", "scenario": "paper", "duration_s": 10.0, "seeds": list(range(1, n_seeds + 1)),
        "variants": {c: {"controller": c} for c in ("proposed", "unconstrained", "fixed")}}))
    rounds = [_campaign_round(rows, workers) for _ in range(max(1, args.campaign_rounds))]
    med = {k: float(np.median([r[k] for r in rounds])) for k in rounds[0]}
    metrics: dict[str, Any] = {"campaign_runs": len(rows), "campaign_workers": workers,
                               "campaign_rounds": len(rounds), **{f"campaign_{k}": v for k, v in med.items()}}
    of = f" (median of {len(rounds)} rounds)" if len(rounds) > 1 else ""
    lines = [f"campaign: {len(rows)} runs (paper 10 s, MCAP + summary) per backend{of}: single warm process "
             f"{med['single_runs_per_min']:.1f} runs/min, {med['single_cpu_s_per_run']:.3f} s CPU per run"]
    for name in ("pool", "dask_local"):
        lines.append(
            f"campaign: {name} x{workers}: {med[f'{name}_runs_per_min']:.1f} runs/min steady = "
            f"{med[f'{name}_over_single']:.2f}x the single process (target >= 1.7x on 2 idle cores); "
            f"{med[f'{name}_cpu_s_per_run']:.3f} s CPU per run = {med[f'{name}_cpu_over_single']:.2f}x the single "
            f"process's, {med[f'{name}_parent_steady_cpu_s_per_run'] * 1e3:.0f} ms in the parent (steady; "
            f"{med[f'{name}_parent_cpu_s_per_run'] * 1e3:.0f} ms with start-up) -> CPU-bound ratio "
            f"{med[f'{name}_cpu_bound_ratio']:.2f}x; "
            f"{med[f'{name}_end_to_end_runs_per_min']:.1f} runs/min end to end with the workers' start-up "
            f"({med[f'{name}_startup_s']:.1f} s to every worker's first result)")
    try:
        lines.append(f"campaign: load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores while measuring")
        metrics["campaign_loadavg_1min"] = os.getloadavg()[0]
        autogroup = Path("/proc/sys/kernel/sched_autogroup_enabled")
        if autogroup.exists() and autogroup.read_text().strip() == "1":
            # Linux's CFS autogroup shares the CPU between sessions, not processes: this bench and its workers
            # are one session, so while any other session keeps a core busy the workers split one session's
            # share and the wall ratios tend to 1x; the CPU-bound ratios do not depend on it
            lines.append("campaign: CFS autogroup is on: the wall ratios hold only with no other busy session")
    except OSError:
        pass
    return SectionResult(metrics, lines)


# ---------------------------------------------------------------------------------------------
# --startup
# ---------------------------------------------------------------------------------------------

# What a process imports before its first step: the SITL lane starts ~75 FCs and ~69 bridges (docs/results.md, "Test
# suite time"), so their imports are most of its CPU
STARTUP_IMPORTS = (("fc", "navig8_fc.shell.fc_process"), ("bridge", "sim_bridge.bridge"))


def _child_cpu_s(code: str) -> tuple[float, float]:
    """(CPU s, wall s) of `python -c code` in a fresh interpreter (its user + system time, from wait4)."""
    import os
    import subprocess

    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.DEVNULL)
    _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f"`python -c {code!r}` exited with {proc.returncode}")
    return ru.ru_utime + ru.ru_stime, wall


def _startup_section(args: argparse.Namespace) -> SectionResult:
    """The FC's and the bridge's imports in a fresh interpreter (byte-compiled, numba's cache warm: what a SITL test's
    start pays before its first step), and the interpreter with numpy alone for scale: CPU s, median of --repeat,
    the processes alternated."""
    cases = [("python_numpy", "import numpy")] + [(name, f"import {mod}") for name, mod in STARTUP_IMPORTS]
    for _, code in cases:  # byte-compile and fill the OS's caches first
        _child_cpu_s(code)
    cpu: dict[str, list[float]] = {name: [] for name, _ in cases}
    for _ in range(max(1, args.repeat)):
        for name, code in cases:
            cpu[name].append(_child_cpu_s(code)[0])
    med = {name: float(np.median(v)) for name, v in cpu.items()}
    metrics = {f"startup_{name}_cpu_s": v for name, v in med.items()}
    lines = [f"startup: imports in a fresh interpreter, CPU s (median of {max(1, args.repeat)}): "
             + ", ".join(f"{name} {v:.2f}" for name, v in med.items())]
    return SectionResult(metrics, lines)


SECTIONS: list[Section] = [
    Section("plant", "plant alone: us per physics step with sensors, real-time factor", _plant_section),
    Section("plant-accuracy", "plant integration error vs a 10x finer step", _plant_accuracy_section),
    Section("fc", "flight-controller tick: median and p99 us", _fc_section),
    Section("inprocess", "closed loop in one process: real-time factor", _inprocess_section),
    Section("lockstep", "two processes over MAVLink at --speed 0: real-time factor", _lockstep_section),
    Section("stability", "Section 3 K-bounds analysis and the workspace floor: seconds per call", _stability_section),
    Section("campaign", "navig8-campaign runs/min: single process, local pool, Dask LocalCluster", _campaign_section),
    Section("startup", "the FC's and the bridge's imports in a fresh interpreter: CPU s", _startup_section),
]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    for s in SECTIONS:
        ap.add_argument(f"--{s.flag}", action="store_true", help=s.help)
    ap.add_argument("--json", action="store_true", help="print one JSON object with every metric")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=5, help="lockstep runs to take the median of (--lockstep)")
    ap.add_argument("--workers", type=int, default=2, help="pool / LocalCluster workers for --campaign")
    ap.add_argument("--campaign-runs", type=int, default=12,
                    help="runs per backend for --campaign (3 controllers x N // 3 seeds)")
    ap.add_argument("--campaign-rounds", type=int, default=1,
                    help="--campaign: rounds of single, pool, Dask in turn (medians reported)")
    ap.add_argument("--instance", type=int, default=9,
                    help="navig8-sitl instance for --lockstep (its ports: 4560+2N, ...; two benches need two)")
    ap.add_argument("--foxglove", action="store_true",
                    help="--lockstep also with navig8-sitl --foxglove (nobody connected), runs alternated")
    ap.add_argument("--plant-dt", type=float, default=0.01, help="control period for --plant (s)")
    ap.add_argument("--params", default=None, metavar="FILE",
                    help="fly --fc, --inprocess and --lockstep with a parameter set (params/presets/*.parm)")
    args = ap.parse_args(argv)
    from navig8_fc.params.store import read_overrides

    args.overrides = read_overrides([args.params] if args.params else [])
    args.params_args = ["--params", args.params] if args.params else []
    chosen = [s for s in SECTIONS if getattr(args, s.flag.replace("-", "_"))] or SECTIONS
    metrics: dict[str, Any] = {}
    for s in chosen:
        res = s.run(args)
        metrics.update(res.metrics)
        if not args.json:
            print("\n".join(res.lines))
            sys.stdout.flush()
    if args.json:
        print(json.dumps({k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                          for k, v in metrics.items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
