"""navig8-sitl: starts navig8-bridge and navig8-fc as two processes, stops both on SIGINT/SIGTERM (exit 0), and
exits non-zero when either ends by itself before the run is done (its code, or 128 + N for signal N).

    navig8-sitl [--scenario NAME|FILE] [--speed X] [--until-done] [--summary FILE] [--log-dir DIR]
                [--state-dir DIR] [--instance N] [--seed N] [--defaults] [--params FILE] [--set NAME=VALUE ...]
                [--foxglove[=PORT]]

Default: the `ground` scenario (on the ground, disarmed, waiting for a GCS) in real time. With
--until-done the scenario runs to its end, both processes exit, and the summary (the same keys as
navig8-sim) is computed from the flight controller's MCAP log. --set NAME=VALUE writes a parameter into the
instance's parameter file in --state-dir before navig8-fc starts (checked as a GCS's PARAM_SET is; a refused
value stops here with the reason), so a campaign run is one command; --params FILE does the same for a
parameter set (`params/presets/*.parm`, MAVProxy's `param load` format), and with --defaults the stored file
becomes the defaults plus those values; world overrides reach the plant with
--bridge-arg=--world --bridge-arg=NAME=VALUE.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

STOP_TIMEOUT_S = 10.0
EXIT_CHILD_DIED = 1  # a child ended by itself (no --until-done end, no signal to us): its own code if positive


def exit_code_of(returncode: int) -> int:
    """A child's return code as an exit code: as it is if >= 0, 128 + N for a child killed by signal N (the
    shell's convention)."""
    return returncode if returncode >= 0 else 128 - returncode


def stopped_cleanly(returncode: int) -> bool:
    """A child we asked to stop that exited 0 or died of the signal (SIGTERM while its interpreter was still
    starting): a clean stop, not a failure."""
    return returncode in (0, -signal.SIGINT, -signal.SIGTERM)


def _die_with_parent(parent_pid: int) -> None:
    """In the child before exec: SIGTERM when navig8-sitl dies (Linux PR_SET_PDEATHSIG), so no orphan keeps running
    after a kill -9 of the launcher (and if it died before this ran, do not start at all)."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        return  # not Linux: the signals forwarded by _stop are all there is
    if os.getppid() != parent_pid:
        os._exit(1)


def _spawn(module: str, args: list[str]) -> subprocess.Popen:
    """A child in a process group of its own: a Ctrl-C in the terminal reaches only navig8-sitl, which forwards
    SIGTERM (a SIGINT landing while a child's interpreter still starts would be a fatal error or a traceback; SIGTERM
    then ends it quietly, and once running it stops cleanly)."""
    return subprocess.Popen([sys.executable, "-m", module, *args], stdin=subprocess.DEVNULL, process_group=0,
                            preexec_fn=functools.partial(_die_with_parent, os.getpid()))


def _stop(proc: subprocess.Popen, name: str) -> int:
    """SIGTERM, then kill after STOP_TIMEOUT_S; the child's return code (0 also for one that died of our SIGTERM)."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            print(f"navig8-sitl: {name} did not stop within {STOP_TIMEOUT_S:.0f} s; killing it", file=sys.stderr)
            proc.kill()
            proc.wait(timeout=STOP_TIMEOUT_S)
            return int(proc.returncode)
        return 0 if stopped_cleanly(proc.returncode) else int(proc.returncode)
    return int(proc.returncode)


def build_arg_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="navig8-sitl", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="ground")
    ap.add_argument("--speed", type=float, default=1.0, help="1 real time, N N-times real time, 0 as fast as possible")
    ap.add_argument("--until-done", action="store_true")
    ap.add_argument("--summary", default=None)
    ap.add_argument("--log-dir", default="logs")
    ap.add_argument("--state-dir", default="state")
    ap.add_argument("--instance", type=int, default=0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=None)
    ap.add_argument("--defaults", action="store_true",
                    help="start from default parameters (with --params/--set: the defaults plus those, stored)")
    ap.add_argument("--params", action="append", default=[], metavar="FILE",
                    help="store a parameter set (.parm: NAME VALUE per line, as MAVProxy's param load) for this "
                         "instance before the FC starts, e.g. params/presets/paper.parm; before --set")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="store a parameter for this instance before the FC starts")
    ap.add_argument("--bind-host", default="127.0.0.1", help="GCS/API bind address (0.0.0.0 in a container)")
    ap.add_argument("--gcs-host", default="127.0.0.1", help="where GCS/API traffic goes before a GCS talks")
    ap.add_argument("--foxglove", nargs="?", type=int, const=8765, default=None, metavar="PORT",
                    help="navig8-fc serves the Foxglove 3D channels live over WebSocket (default 8765; 0: any free)")
    ap.add_argument("--world", action="append", default=[], metavar="NAME=VALUE",
                    help="a world override (sim_bridge/world.py, as navig8-sim --world) for the bridge; the vehicle's "
                         "(vehicle.*, fc_vehicle.*, tail_max_thrust_n) reach navig8-fc as its --vehicle file too, "
                         "e.g. --world tail_max_thrust_n=200")
    ap.add_argument("--fc-arg", action="append", default=[], help="extra argument for navig8-fc (repeatable)")
    ap.add_argument("--bridge-arg", action="append", default=[], help="extra argument for navig8-bridge")
    return ap


def store_params(state_dir: str, instance: int, items: list[str], files: Sequence[str] = (),
                  from_defaults: bool = False) -> str | None:
    """Merge the parameter files' values, then NAME=VALUE items, into the instance's stored parameters (into the
    defaults when from_defaults); the reason of the first refusal, else None (nothing is stored on a refusal)."""
    from navig8_fc.params.registry import ParamRegistry
    from navig8_fc.params.store import ParamStore, default_state_path, parse_set_item, read_parm_file

    store = ParamStore(default_state_path(state_dir, instance))
    reg = ParamRegistry.from_defaults()
    if not from_defaults:
        reg.load_values(store.load().values)
    pairs: list[tuple[str, float, str]] = []
    for f in files:
        try:
            pairs += [(k, v, f) for k, v in read_parm_file(f).items()]
        except (OSError, ValueError) as exc:
            return f"--params {f}: {exc}"
    for it in items:
        try:
            pairs.append((*parse_set_item(it), "--set"))
        except ValueError as exc:
            return str(exc)
    for name, value, src in pairs:
        res = reg.set(name, value)
        if not res.accepted:
            return f"{src}: {res.reason}"
    Path(state_dir).mkdir(parents=True, exist_ok=True)
    store.save(reg.as_dict())
    return None


def _child_args(a: argparse.Namespace, log: Path, stored: bool) -> tuple[list[str], list[str]] | str:
    """navig8-fc's and navig8-bridge's arguments, or why the run cannot start (a bad --world)."""
    fc_args = ["--instance", str(a.instance), "--scenario", a.scenario, "--log", str(log),
               "--state-dir", a.state_dir, "--bind-host", a.bind_host, "--gcs-host", a.gcs_host, *a.fc_arg]
    if a.defaults and not stored:  # with --params/--set the stored file is already the defaults plus those
        fc_args.append("--defaults")
    if a.foxglove is not None:
        fc_args.append(f"--foxglove={a.foxglove}")
    if a.until_done:
        fc_args.append("--until-done")
    world = [arg for item in a.world for arg in ("--world", item)]
    if world:  # the FC flies with the vehicle of this world: the bridge writes it (one reader of the world names)
        vfile = Path(a.state_dir) / f"vehicle_i{a.instance}.yaml"
        p = subprocess.run([sys.executable, "-m", "sim_bridge.bridge", "--scenario", a.scenario, *world,
                            "--write-fc-vehicle", str(vfile)], stdin=subprocess.DEVNULL, capture_output=True,
                           text=True, timeout=120)
        if p.returncode != 0:
            return p.stderr.strip().splitlines()[-1] if p.stderr.strip() else "bad --world"
        fc_args += ["--vehicle", str(vfile)]
    br_args = ["--instance", str(a.instance), "--scenario", a.scenario, "--speed", str(a.speed),
               "--seed", str(a.seed), *world, *a.bridge_arg]
    if a.until_done:
        br_args.append("--until-done")
    if a.duration is not None:
        br_args += ["--duration", str(a.duration)]
    return fc_args, br_args


def _run_pair(fc_args: list[str], br_args: list[str], until_done: bool) -> tuple[int, int, tuple[str, int] | None,
                                                                                    bool, float]:
    """Start the FC, then the bridge; wait until one ends (or Ctrl-C / SIGTERM), stop the other. Returns the exit
    codes (FC, bridge), the child that ended by itself before the run was done (name, code), whether we were
    stopped by a signal, and the wall time."""
    stopping = {"flag": False}

    def _on_signal(signum: int, _frame: Any) -> None:
        stopping["flag"] = True

    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    wall0 = time.perf_counter()
    fc = _spawn("navig8_fc.shell.fc_process", fc_args)
    time.sleep(0.2)  # let the FC bind its sim port before the bridge starts sending
    bridge = _spawn("sim_bridge.bridge", br_args)
    rc_bridge: int | None = None
    died: tuple[str, int] | None = None  # the child that ended by itself, and its code
    try:
        while not stopping["flag"]:
            if bridge.poll() is not None:
                rc_bridge = bridge.returncode
                if not (until_done and rc_bridge == 0):
                    died = ("navig8-bridge", rc_bridge)
                break
            if fc.poll() is not None:
                if until_done and fc.returncode == 0:  # done: the bridge is finishing too, let it
                    try:
                        rc_bridge = bridge.wait(timeout=STOP_TIMEOUT_S)
                    except subprocess.TimeoutExpired:
                        pass
                else:
                    died = ("navig8-fc", fc.returncode)
                break
            time.sleep(0.05)
    finally:
        if until_done and rc_bridge == 0:
            try:  # the FC exits by itself once the bridge reports done; give it time to flush the log
                fc.wait(timeout=STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                pass
        rc_fc = _stop(fc, "navig8-fc")
        rc_b = _stop(bridge, "navig8-bridge") if rc_bridge is None else rc_bridge
    return rc_fc, rc_b, died, stopping["flag"], time.perf_counter() - wall0


def _write_summary(a: argparse.Namespace, log: Path, scen_name: str, wall: float) -> dict[str, Any]:
    """The run's summary from its log (--until-done), printed and written to --summary."""
    from navig8_fc.shell.mcap_log import read_metadata
    from navig8_tools.logdata import load_run
    from navig8_tools.summary import summarize

    # wall_time_s / real_time_factor: the lockstep's own (the bridge's, from its first answered step to the
    # end), as navig8-sim times its loop; process_wall_time_s: the whole command, start-up included.
    bridge_rtf = float(read_metadata(log).get("bridge_status", {}).get("rtf") or 0.0)
    summary = summarize(load_run(log), wall)
    if bridge_rtf > 0.0:
        summary.update(wall_time_s=summary["sim_time_s"] / bridge_rtf, real_time_factor=bridge_rtf)
    summary.update({"scenario": scen_name, "transport": "mavlink-udp", "speed": a.speed, "seed": a.seed,
                    "process_wall_time_s": wall, "log": str(log)})
    text = json.dumps(summary, indent=2)
    print(text)
    if a.summary:
        Path(a.summary).parent.mkdir(parents=True, exist_ok=True)
        Path(a.summary).write_text(text + "\n")
    return summary


def main(argv: list[str] | None = None) -> int:
    a = build_arg_parser().parse_args(argv)
    stored = bool(a.set or a.params)
    if stored:
        err = store_params(a.state_dir, a.instance, a.set, a.params, from_defaults=a.defaults)
        if err:
            print(f"navig8-sitl: {err}", file=sys.stderr)
            return 2
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    log_dir = Path(a.log_dir)
    log_dir.mkdir(parents=True, exist_ok=True)
    scen_name = Path(a.scenario).stem
    log = log_dir / f"navig8_{scen_name}_i{a.instance}_{stamp}_{os.getpid()}.mcap"
    args = _child_args(a, log, stored)
    if isinstance(args, str):
        print(f"navig8-sitl: {args}", file=sys.stderr)
        return 2
    rc_fc, rc_b, died, signalled, wall = _run_pair(*args, a.until_done)
    if signalled:  # Ctrl-C / SIGTERM to us: a child that went first went by the same signal
        died = None
        rc_fc = 0 if stopped_cleanly(rc_fc) else rc_fc
        rc_b = 0 if stopped_cleanly(rc_b) else rc_b
    if died is not None:
        name, code = died
        print(f"navig8-sitl: {name} ended by itself (exit {code}) before the run was done; stopped the other",
              file=sys.stderr)
    if rc_fc != 0 or rc_b != 0:
        print(f"navig8-sitl: navig8-fc exited with {rc_fc}, navig8-bridge with {rc_b}", file=sys.stderr)
    print(f"navig8-sitl: log {log}", file=sys.stderr)
    if a.until_done and died is None and not log.is_file():  # the FC could not write it (docs/logs.md)
        print("navig8-sitl: no log was written, so no summary", file=sys.stderr)
        return 0 if rc_b == 0 and rc_fc == 0 else 1
    if a.until_done and died is None:
        summary = _write_summary(a, log, scen_name, wall)
        return 0 if rc_b == 0 and rc_fc == 0 and not summary.get("lost_control") else 1
    if died is not None:
        return exit_code_of(died[1]) or EXIT_CHILD_DIED
    return exit_code_of(rc_fc) or exit_code_of(rc_b)


if __name__ == "__main__":
    raise SystemExit(main())
