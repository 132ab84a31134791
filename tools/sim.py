"""navig8-sim: plant + sensors + flight controller in one process (no sockets), logged to MCAP.

    navig8-sim --scenario paper --controller proposed|unconstrained|fixed|pinned|lms [--seed N] [--duration S]
               [--log run.mcap] [--summary summary.json] [--plots DIR] [--params FILE] [--set NAME=VALUE ...]
               [--world NAME=VALUE ...] [--world NAME*=VALUE ...] [--log-writer process|inline]

--set changes a flight-controller parameter (params/fc_params.yaml), --params a set of them from a file
(`params/presets/paper.parm` is the paper's method; the defaults are the robust controller);
--world changes the world the run flies in: the plant, the scenario, the vehicle, or the controller's model of it
(sim_bridge/world.py lists the names).

The flight controller is the same `FlightStack` navig8-fc runs (mode manager, failsafes, controller core),
stepped at INDI_RATE_HZ on the sensor bundle's time; the plant integrates in between with the command held
(zero-order hold), as in lockstep SITL.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from navig8_fc.core import vehicle as vm
from navig8_fc.core.controller import ActuatorCommand, ControllerStatus, FcSensors, warm_up_kernels
from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.flight import FlightStack, StepResult
from navig8_fc.mavlink.seam import TruthFloats
from navig8_fc.params.registry import ParamRegistry
from navig8_fc.params.store import read_overrides
from navig8_fc.shell.foxglove_out import FoxgloveOutput, script_waypoints
from navig8_fc.shell.mcap_log import McapLogger
from navig8_fc.shell.step_log import StepLog
from navig8_fc.viz import VehicleViz, packaged_uav_size_m
from navig8_tools.log_writer import LogWriterError, ProcessTickLog, process_writer_available
from navig8_tools.logdata import load_run
from navig8_tools.summary import summarize
from sim_bridge.messages import ActuatorCommand as PlantCommand
from sim_bridge.plant import Plant
from sim_bridge.world import load_world, parse_world_items

LOG_WRITERS = ("inline", "process")
CONTROLLERS = {"fixed": 0, "unconstrained": 1, "proposed": 2, "pinned": 3, "lms": 4}  # CKF_MODE


@dataclass(frozen=True)
class RunResult:
    summary: dict[str, Any]
    log_path: Path | None
    run_log: Any = None  # the log as read back for the summary (navig8_tools.logdata.RunLog), for more analysis


def _floats(v: Any) -> tuple[float, ...]:
    # .tolist() gives Python floats: numpy scalars would slow every plain-float operation in the FC ~3x
    return tuple(v.tolist()) if hasattr(v, "tolist") else tuple(float(x) for x in v)


def sensors_to_fc(sb: Any) -> FcSensors:
    """The plant's SensorBundle or WireSensors (the same sample as plain floats) as the FC's input (what the bridge
    seam delivers over MAVLink)."""
    f = tuple if type(sb.gyro_frd_rad_s) is list else _floats  # WireSensors: lists of Python floats already
    return FcSensors(
        t_s=sb.time_us * 1e-6,
        gyro_frd_rad_s=f(sb.gyro_frd_rad_s),
        accel_frd_m_s2=f(sb.accel_frd_m_s2),
        pos_ned_m=f(sb.pos_ned_m),
        vel_ned_m_s=f(sb.vel_ned_m_s),
        quat_wxyz=f(sb.quat_wxyz),
        duct_tilt_rad=f(sb.duct_tilt_rad),
        prop_speed_rad_s=f(sb.prop_speed_rad_s),
        joint_pos_rad=f(sb.joint_pos_rad),
        joint_rate_rad_s=f(sb.joint_rate_rad_s),
        gripper_closed=bool(sb.gripper_closed),
    )


class TickLog:
    """One FC tick into the run's log: the step's records (shell.step_log.StepLog, as navig8-fc writes them) and what
    the FC announced (as navig8-fc logs what it announces: mode events, failsafes). `tick` is fly's step hook (the
    truth read from `plant`); `record` takes the truth given (the writer process: tools.log_writer)."""

    def __init__(self, steps: StepLog, plant: Plant | None, lambda_min: float, lambda_crit: float) -> None:
        self.steps, self.plant = steps, plant
        self.lambda_min, self.lambda_crit = lambda_min, lambda_crit

    def tick(self, t_ns: int, s: FcSensors, res: StepResult) -> None:
        self.record(t_ns, self.plant.truth_floats(), s, res.status, res.command, res.setpoint,
                    [(n.severity, n.statustext) for n in res.notices if n.statustext])

    def record(self, t_ns: int, truth: TruthFloats, s: FcSensors, status: ControllerStatus, command: ActuatorCommand,
               setpoint: Setpoint, statustexts: list[tuple[int, str]], status_json: bytes | None = None) -> None:
        steps = self.steps
        steps.tick(t_ns, truth, s, status, command, setpoint, self.lambda_min, self.lambda_crit,
                   status_json=status_json)
        for severity, text in statustexts:
            steps.logger.log("/fc/statustext", t_ns, {"severity": severity, "text": text})
            if steps.fox is not None:
                steps.fox.statustext(t_ns, severity, text)

    def finish(self) -> None:
        self.steps.finish()

    def close(self) -> None:
        """finish, then close the log (the writer process's end of a run)."""
        self.finish()
        self.steps.logger.close()


StepHook = Callable[[int, FcSensors, StepResult], None]  # (the step's time in ns, the FC's input, its result)


def fly(plant: Plant, stack: FlightStack, n_steps: int, on_step: StepHook | None = None,
        tick_times_s: list[float] | None = None, progress: bool = False) -> None:
    """The closed loop in one process, n_steps + 1 FC steps: the plant's sensors to the FC's step (as the bridge seam
    delivers them), `on_step` (the log, a tool's trace), the plant stepped with the FC's command over the FC's dt.
    With `tick_times_s`, the wall time of every FC step is appended. navig8-sim (`run`), navig8-bench and the
    convergence tools fly through it."""
    dt_s = stack.core.config.dt_s
    last_print = time.perf_counter()
    for k in range(n_steps + 1):
        sb = plant.sense_wire()  # the sample as Python floats: ~4 us a step less than from sense()'s arrays
        s = sensors_to_fc(sb)
        if tick_times_s is not None:
            t_tick = time.perf_counter()
            res = stack.step(s, True, sb.time_us)
            tick_times_s.append(time.perf_counter() - t_tick)
        else:
            res = stack.step(s, True, sb.time_us)
        if on_step is not None:
            on_step(int(sb.time_us) * 1000, s, res)
        if k == n_steps:
            break
        plant.step(PlantCommand(tilt_rad=res.command.tilt_rad, speed_rad_s=res.command.speed_rad_s), dt_s)
        if progress and time.perf_counter() - last_print > 2.0:
            last_print = time.perf_counter()
            print(f"\r  t = {s.t_s:6.2f} / {n_steps * dt_s:.1f} s", end="", file=sys.stderr, flush=True)


def run(
    scenario: str,
    controller: str = "proposed",
    seed: int = 1,
    duration_s: float | None = None,
    log_path: str | Path | None = None,
    overrides: dict[str, float] | None = None,
    progress: bool = False,
    tick_times_s: list[float] | None = None,
    world: dict[str, float] | None = None,
    log_writer: str = "inline",
) -> RunResult:
    """Fly `scenario` in one process. With `tick_times_s`, the wall time of every FC tick is appended.
    `world`: overrides of the plant, scenario and vehicle ({NAME: VALUE} or {NAME*: factor}, sim_bridge.world).
    `log_writer`: "inline" logs in the loop; "process" on a forked writer process (tools.log_writer: the same file,
    the loop about twice as fast; inline where a process cannot fork, e.g. a daemonic pool worker)."""
    reg = ParamRegistry.from_defaults()
    reg.set("CKF_MODE", CONTROLLERS[controller])
    for name, value in (overrides or {}).items():
        res = reg.set(name, value)
        if not res.accepted:
            raise ValueError(res.reason)
    w = load_world(scenario, world)
    vehicle, sc = w.fc_vehicle, w.scenario  # the FC's constants (model errors, if any, live here)
    duration = sc.duration_s if duration_s is None else float(duration_s)
    # One BLAS thread while the run flies: at <= 10 x 10 OpenBLAS's threads only cost, and after the set-up's ~90
    # expm (its LU solve goes parallel at any size) they spin ~0.1 s into the flight on the writer's core
    # (docs/results.md, "Speed"); threadpoolctl sets every BLAS in the process and gives the counts back after.
    with threadpool_limits(limits=1, user_api="blas"):
        rng = np.random.default_rng(seed)
        plant = Plant(w.vehicle, w.plant, sc, rng)
        stack = FlightStack(vehicle, reg, sc.script)
        cfg = stack.core.config
        warm_up_kernels(vehicle, cfg)  # numba's cache loads now, not inside the timed loop

        def open_log() -> TickLog:  # in the writer process with log_writer "process"
            logger = McapLogger(log_path)
            logger.metadata("run", {"scenario": sc.name, "controller": controller, "seed": seed,
                                    "duration_s": duration, "world": dict(world or {})})
            logger.metadata("params", reg.as_dict())
            fox = FoxgloveOutput(VehicleViz(vehicle, packaged_uav_size_m()), logger, None, "navig8-sim")
            fox.set_mission(script_waypoints(sc.script))
            # the eigenvalues with the TRUE vehicle's G (w.vehicle: model errors live in the FC's constants)
            return TickLog(StepLog(logger, fox, vm.UamModel(w.vehicle)), plant, stack.lambda_min, stack.lambda_crit)

        if log_writer not in LOG_WRITERS:
            raise ValueError(f"log_writer {log_writer!r}: one of {', '.join(LOG_WRITERS)}")
        hook: TickLog | ProcessTickLog | None = None
        if log_path and log_writer == "process" and process_writer_available():
            hook = ProcessTickLog(plant, open_log)
        elif log_path:
            hook = open_log()
        n_steps = int(round(duration / cfg.dt_s))
        wall0 = time.perf_counter()
        try:
            fly(plant, stack, n_steps, hook.tick if hook else None, tick_times_s, progress)
        finally:
            if isinstance(hook, TickLog):
                hook.close()
            elif hook is not None:
                hook.finish()
        wall = time.perf_counter() - wall0
    if progress:
        print(file=sys.stderr)
    summary: dict[str, Any] = {"sim_time_s": n_steps * cfg.dt_s, "wall_time_s": wall,
                               "real_time_factor": n_steps * cfg.dt_s / wall}
    run_log = load_run(log_path) if log_path else None
    if run_log is not None:
        summary = summarize(run_log, wall)
    summary.update({"scenario": sc.name, "controller": controller, "seed": seed})
    return RunResult(summary, Path(log_path) if log_path else None, run_log)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--controller", choices=sorted(CONTROLLERS), default="proposed")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=None)
    ap.add_argument("--log", default="out/run.mcap")
    ap.add_argument("--summary", default=None)
    ap.add_argument("--log-writer", choices=LOG_WRITERS, default="process",
                    help="process: the log written on a second process (the same file, the run about twice as fast); "
                         "inline: in the loop")
    ap.add_argument("--plots", default=None, help="also write Figures 10-16 here")
    ap.add_argument("--params", action="append", default=[], metavar="FILE",
                    help="a parameter set (.parm, MAVProxy's param load format), e.g. params/presets/paper.parm; "
                         "applied before --set")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override a parameter")
    ap.add_argument("--world", action="append", default=[], metavar="NAME=VALUE",
                    help="override the world (NAME*=VALUE scales; names: sim_bridge/world.py)")
    args = ap.parse_args(argv)
    try:
        overrides = read_overrides(args.params, args.set)
    except (OSError, ValueError) as exc:
        ap.error(str(exc))
    try:
        res = run(args.scenario, args.controller, args.seed, args.duration, args.log, overrides,
                  progress=True, world=parse_world_items(args.world), log_writer=args.log_writer)
    except (LogWriterError, OSError) as exc:  # the log's path, a full disk: the reason, not a traceback
        print(f"navig8-sim: {exc}", file=sys.stderr)
        return 1
    text = json.dumps(res.summary, indent=2, allow_nan=True)
    print(text)
    if args.summary:
        Path(args.summary).parent.mkdir(parents=True, exist_ok=True)
        Path(args.summary).write_text(text + "\n")
    print(f"log: {res.log_path}", file=sys.stderr)
    if args.plots:
        from navig8_tools.plot import plot_runs

        for p in plot_runs([args.log], args.plots):
            print(f"figure: {p}", file=sys.stderr)
    return 0 if not res.summary.get("lost_control", False) else 2


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["run", "main"]
