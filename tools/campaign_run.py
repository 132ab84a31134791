"""One campaign run and the executors that fly them (navig8-campaign, tools/campaign.py): the runners of the
in-process and sitl kinds, `execute_row` (never raises: the record says ok / error / timeout / crashed), the
per-run timeout, the worker set-up (WORKER_ENV, warm_worker) and the two backends, a local process pool and Dask
distributed. docs/campaigns.md, "Backends, failures, resume" and "Throughput".
"""

from __future__ import annotations

import ctypes
import gc
import io
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import yaml

from navig8_fc.blas import ONE_THREAD_ENV
from navig8_tools.campaign_spec import Row, sitl_argv

# Scalar summary keys of navig8_tools.summary.summarize kept per run (settle is folded to two counts).
METRICS = ("sim_time_s", "wall_time_s", "real_time_factor", "lost_control", "lost_control_t_s", "min_eigenvalue",
           "max_eigenvalue", "bound_violations", "max_pos_error_m", "pos_rms_error_m", "max_att_error_deg",
           "att_rms_error_deg", "peak_reaction_force_n", "peak_reaction_torque_nm", "max_joint_rate_rad_s",
           "max_joint_accel_rad_s2", "steps_settled", "steps_total")
# Columns of a sitl run that flies a plan (from navig8-mission's fly(): items, items reached, complete, path length)
MISSION_METRICS = ("mission_items", "mission_reached", "mission_complete", "mission_path_m")
# Columns of a run with `authority: true` (navig8_tools.authority.bound_from_log on its log)
AUTHORITY_COLUMNS = ("authority_bound_deg", "authority_trim_feasible", "authority_worst_t_s")
# Thread counts of a worker process: the ones Dask's nanny gives its workers (distributed.nanny.pre-spawn-environ).
# A run's linear algebra is on matrices of 3x3 to 12x12, where OpenBLAS's second thread only spins: in one process
# it burns the idle core, in a pool of one process per core it takes the other worker's core (navig8_fc/blas.py).
WORKER_ENV = ONE_THREAD_ENV
# Dask configuration of the LocalCluster's workers (docs/campaigns.md: the same for a cluster's workers).
DASK_WORKER_CONFIG = {"distributed.worker.profile.enabled": False,
                      "distributed.admin.system-monitor.gil.enabled": False}


# ---------------------------------------------------------------------------------------------
# One run (executes in a worker: a pool process or a Dask worker)
# ---------------------------------------------------------------------------------------------


class RunTimeout(Exception):
    pass


def call_with_timeout(fn: Callable[[], Any], timeout_s: float) -> Any:
    """fn() in this thread, interrupted with RunTimeout after timeout_s of wall time. The exception is raised
    asynchronously in this thread (PyThreadState_SetAsyncExc) at its next Python bytecode, so it works in a pool
    process's main thread and in a Dask worker's thread alike; a run spends its time in a Python loop calling
    short numba kernels, so it is interrupted within a tick."""
    tid = threading.get_ident()
    lock = threading.Lock()
    state = {"done": False, "fired": False}

    def _fire() -> None:
        with lock:
            if not state["done"]:
                state["fired"] = True
                ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(tid), ctypes.py_object(RunTimeout))

    timer = threading.Timer(timeout_s, _fire)
    timer.daemon = True
    timer.start()
    try:
        out = fn()
        with lock:
            state["done"] = True
        return out
    finally:
        timer.cancel()
        with lock:
            state["done"] = True


def _flatten_summary(s: Mapping[str, Any]) -> dict[str, Any]:
    out = {k: s.get(k) for k in (*METRICS, *MISSION_METRICS, *AUTHORITY_COLUMNS, "authority_error") if k in s}
    settle = s.get("settle") or []
    out["steps_settled"] = sum(1 for x in settle if x.get("settle_s") is not None)
    out["steps_total"] = len(settle)
    return out


def _inprocess(row: Row, tmp: Path) -> dict[str, Any]:
    from navig8_tools.sim import run

    scenario = row.scenario
    if row.scenario_doc is not None:  # the worker's own copy: a Dask worker elsewhere need not see DIR
        scenario = str(tmp / "scenario.yaml")
        Path(scenario).write_text(yaml.safe_dump(dict(row.scenario_doc), sort_keys=False))
    res = run(scenario, row.controller, row.seed, row.duration_s, tmp / "run.mcap", dict(row.params),
              world=dict(row.world))
    summary = dict(res.summary)
    if row.authority:
        summary |= authority_columns(res.run_log, scenario, row.world)
    return summary


def authority_columns(run_log: Any, scenario: str, world: Mapping[str, float]) -> dict[str, Any]:
    """navig8_tools.authority.bound_from_log(run_log, vehicle) on this run's log and true vehicle, as columns:
    the smallest peak pitch excursion any controller could reach on the logged arm motion (deg), whether the
    trim is feasible, when the bound's worst moment falls. NaN (and `authority_error` saying why) while that
    function is not there, or when it fails: the run's own metrics are kept either way."""
    nan = {k: math.nan for k in AUTHORITY_COLUMNS}
    try:
        from navig8_tools.authority import bound_from_log
    except ImportError as exc:
        return nan | {"authority_error": f"navig8_tools.authority.bound_from_log is not available ({exc})"}
    from sim_bridge.world import load_world

    try:
        b = bound_from_log(run_log, load_world(scenario, dict(world)).vehicle)
        return {"authority_bound_deg": float(b["bound_deg"]), "authority_trim_feasible": bool(b["trim_feasible"]),
                "authority_worst_t_s": float(b["worst_t_s"]), "authority_error": None}
    except Exception as exc:  # noqa: BLE001 - a failed bound is a missing column, not a failed run
        return nan | {"authority_error": f"{type(exc).__name__}: {exc}"}


class _RunEnded(Exception):
    pass


class _GcsUntil:
    """The GCS connection as navig8-mission's fly() uses it, whose recv_match raises _RunEnded once `stop` is set:
    fly() waits for the plan's end, and the run may end first (the scenario's duration)."""

    def __init__(self, conn: Any, stop: threading.Event) -> None:
        self._conn, self._stop = conn, stop

    def __getattr__(self, name: str) -> Any:
        return getattr(self._conn, name)

    def recv_match(self, *args: Any, **kwargs: Any) -> Any:
        if self._stop.is_set():
            raise _RunEnded
        return self._conn.recv_match(*args, **kwargs)


def _fly_plan(gcs: Any, row: Row, proc: subprocess.Popen, deadline: float) -> dict[str, Any]:
    """Be this run's ground station: wait for navig8-fc's HEARTBEAT, then navig8-mission's fly() (upload the plan,
    Mission, arm, follow the progress) until the plan completes or navig8-sitl ends. The mission's columns."""
    from navig8_tools.mission import fly

    hb = None
    while hb is None:
        if proc.poll() is not None:
            raise RuntimeError(f"navig8-sitl exited ({proc.returncode}) before navig8-fc's first HEARTBEAT")
        if time.monotonic() > deadline:
            raise RunTimeout(f"no HEARTBEAT from navig8-fc within {row.timeout_s:.0f} s")
        m = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
        hb = m if m is not None and m.get_srcComponent() == 1 else None
    gcs.target_system, gcs.target_component = hb.get_srcSystem(), 1
    stop = threading.Event()
    out: dict[str, Any] = {}
    log = io.StringIO()

    def _fly() -> None:
        try:
            out["summary"] = fly(_GcsUntil(gcs, stop), row.plan, timeout_s=max(0.0, deadline - time.monotonic()),
                                 out=log)
        except _RunEnded:
            pass
        except Exception as exc:  # noqa: BLE001 - re-raised in the worker's thread below
            out["error"] = exc

    th = threading.Thread(target=_fly, name="navig8-campaign-gcs", daemon=True)
    th.start()
    while th.is_alive() and proc.poll() is None:
        th.join(0.1)
    stop.set()  # navig8-sitl has ended: fly() stops at its next receive (within 0.5 s)
    th.join()
    if "error" in out:
        raise RuntimeError(f"flying the plan: {out['error']} | {' | '.join(log.getvalue().splitlines()[-2:])}")
    s = out.get("summary")
    if s is None:  # the run ended before the plan did
        return {"mission_items": len(row.plan), "mission_reached": None, "mission_complete": False,
                "mission_path_m": None}
    return {"mission_items": s["items"], "mission_reached": len(s["reached"]), "mission_complete": s["complete"],
            "mission_path_m": s["path_m"]}


def _sitl(row: Row, tmp: Path) -> dict[str, Any]:
    """navig8-sitl on the row's own --instance (two processes over MAVLink/UDP: the command of replay_command,
    with this run's directories). With a plan, this worker is the run's ground station (_fly_plan), on a UDP port
    of its own that navig8-fc is told to send to."""
    # navig8-fc reads params/vehicle.yaml and the scenario's setpoint script itself; only the plant's side of the
    # world travels (--bridge-arg=--world)
    # navig8-sitl --world gives the FC the world's vehicle (vehicle.*, fc_vehicle.*, tail_max_thrust_n); the FC's
    # flight script it reads from the scenario file itself, so overrides of the script cannot reach it
    fc_only = [k for k in row.world if k.startswith(("scenario.setpoints", "scenario.duration_s", "scenario.armed"))]
    if fc_only:
        raise ValueError(f"the sitl kind cannot apply {fc_only} (navig8-fc's side of the world); use inprocess")
    argv = sitl_argv(row, tmp)
    gcs = None
    if row.plan:
        from pymavlink import mavutil

        gcs = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255, source_component=190,
                                         dialect="common")
        argv.append(f"--fc-arg=--gcs-port={gcs.port.getsockname()[1]}")
    deadline = time.monotonic() + row.timeout_s
    mission: dict[str, Any] = {}
    # stderr to a file, not a pipe: nobody reads a pipe while the plan is flown, and a full one would block the FC
    with open(tmp / "navig8-sitl.stderr", "wb") as err:
        proc = subprocess.Popen([sys.executable, "-m", "navig8_fc.shell.sitl", *argv[1:]], stdin=subprocess.DEVNULL,
                                stdout=subprocess.DEVNULL, stderr=err, start_new_session=True)
        try:
            if gcs is not None:
                mission = _fly_plan(gcs, row, proc, deadline)
            proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            _stop_group(proc)
            raise RunTimeout(f"navig8-sitl did not finish within {row.timeout_s:.0f} s") from None
        except BaseException:
            _stop_group(proc)
            raise
        finally:
            if gcs is not None:
                gcs.close()
    if not (tmp / "summary.json").exists():  # exit 1 with a summary: it lost control, which is a result
        tail = (tmp / "navig8-sitl.stderr").read_text(errors="replace").strip().splitlines()[-3:]
        raise RuntimeError(f"navig8-sitl exited with {proc.returncode}: {' | '.join(tail)}")
    return json.loads((tmp / "summary.json").read_text()) | mission


def _stop_group(proc: subprocess.Popen) -> None:
    """Stop navig8-sitl's process group: SIGINT (it stops both children), then SIGKILL."""
    if proc.poll() is not None:
        return
    os.killpg(proc.pid, signal.SIGINT)
    try:
        proc.wait(timeout=15.0)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


RUNNERS: dict[str, Callable[[Row, Path], dict[str, Any]]] = {"inprocess": _inprocess, "sitl": _sitl}


def execute_row(row: Row) -> dict[str, Any]:
    """Fly one row; never raises: the record says ok / error / timeout (with the error) and the metrics, and the
    run's wall and CPU time in its worker (`run_cpu_s`: the whole worker process, its other threads included)."""
    rec: dict[str, Any] = {"run_id": row.run_id, "status": "ok", "error": None,
                           "worker": f"{os.uname().nodename}:{os.getpid()}"}
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    try:
        with tempfile.TemporaryDirectory(prefix="navig8_campaign_") as tmp:
            if row.kind == "sitl":  # the subprocess has its own timeout and is killed by it
                summary = RUNNERS[row.kind](row, Path(tmp))
            else:
                summary = call_with_timeout(lambda: RUNNERS[row.kind](row, Path(tmp)), row.timeout_s)
        rec.update(_flatten_summary(summary))
    except RunTimeout as exc:
        rec.update(status="timeout", error=str(exc) or f"no result within {row.timeout_s:.0f} s")
    except Exception as exc:  # noqa: BLE001 - a run's failure is data, recorded with its traceback's last line
        tb = traceback.extract_tb(exc.__traceback__)
        where = f" ({Path(tb[-1].filename).name}:{tb[-1].lineno})" if tb else ""
        rec.update(status="error", error=f"{type(exc).__name__}: {exc}{where}")
    rec["run_wall_s"] = time.perf_counter() - t0
    rec["run_cpu_s"] = time.process_time() - cpu0
    return rec


def warm_worker(kind: str) -> None:
    """Load once per worker process what every in-process run needs (the imports, numba's on-disk cache of the
    plant's and the controller's kernels, the MCAP writer/reader and the summary) by flying 0.1 s of the hover
    scenario with a log: the first row's run then costs what every other row costs, and its timeout_s counts
    the run, not the worker's start. Then gc.freeze(): the ~150,000 objects alive now (modules, functions,
    numba's dispatchers; ~185,000 in a Dask worker) live as long as the worker, and without the freeze the
    cyclic garbage collector walks them all at each full collection a run's allocations trigger: ~20 % of a
    run's CPU, and more the bigger the worker's heap (docs/campaigns.md, "Throughput"). Never raises: a broken
    installation shows as each row's error instead."""
    if kind != "inprocess":  # a sitl run is two new processes: nothing to keep warm here
        return
    try:
        from navig8_tools.sim import run

        with tempfile.TemporaryDirectory(prefix="navig8_warm_") as tmp:
            run("hover", "proposed", 1, 0.1, Path(tmp) / "warm.mcap")
    except Exception:  # noqa: BLE001, S110 - see the docstring
        pass
    gc.collect()
    gc.freeze()


@contextmanager
def worker_pool(workers: int, kind: str) -> Iterator[Any]:
    """A concurrent.futures process pool of `workers` spawned processes (spawn: they start clean, without the
    parent's threads), each started with WORKER_ENV and warmed once (warm_worker). WORKER_ENV is in os.environ
    while the pool lives (its processes are spawned on demand and load numpy with it; the parent's own thread
    pools, loaded already, are unaffected) and restored after."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    old = {k: os.environ.get(k) for k in WORKER_ENV}
    os.environ.update(WORKER_ENV)
    try:
        with ProcessPoolExecutor(workers, multiprocessing.get_context("spawn"), warm_worker, (kind,)) as pool:
            yield pool
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


# ---------------------------------------------------------------------------------------------
# Backends: a local process pool, or Dask distributed
# ---------------------------------------------------------------------------------------------


def pool_results(rows: list[Row], workers: int) -> Iterator[tuple[Row, dict[str, Any]]]:
    """A local process pool (worker_pool). At most 2 x workers runs are in flight, so a worker that dies
    (BrokenProcessPool) costs only the runs in flight: they are recorded as crashed and a new pool takes the rest."""
    from concurrent.futures import FIRST_COMPLETED, wait
    from concurrent.futures.process import BrokenProcessPool

    todo = list(rows)
    todo.reverse()
    kind = rows[0].kind if rows else "inprocess"
    while todo:
        with worker_pool(workers, kind) as pool:
            inflight: dict[Any, Row] = {}
            broken = False
            while (todo or inflight) and not broken:
                while todo and len(inflight) < 2 * workers:
                    r = todo.pop()
                    inflight[pool.submit(execute_row, r)] = r
                done, _ = wait(inflight, return_when=FIRST_COMPLETED)
                for fut in done:
                    r = inflight.pop(fut)
                    try:
                        yield r, fut.result()
                    except BrokenProcessPool as exc:
                        broken = True
                        yield r, {"run_id": r.run_id, "status": "crashed", "worker": "",
                                  "error": f"worker process died while this run was in flight ({exc})"}
            if broken:
                for r in inflight.values():
                    yield r, {"run_id": r.run_id, "status": "crashed", "worker": "",
                              "error": "worker process died while this run was in flight"}


def dask_results(rows: list[Row], cluster: str, workers: int) -> Iterator[tuple[Row, dict[str, Any]]]:
    """Dask distributed as its users drive it: a Client on the scheduler's address (or on a LocalCluster this
    campaign starts and stops), submit, as_completed. A worker that dies is the engine's business (the nanny
    restarts it, the scheduler reschedules; after allowed-failures the task raises KilledWorker, recorded here).
    Every worker, also one that joins or restarts later, is warmed once by a worker plugin (warm_worker); its
    thread counts are WORKER_ENV already (the nanny's pre-spawn-environ)."""
    import dask
    from distributed import Client, LocalCluster, as_completed
    from distributed.diagnostics.plugin import WorkerPlugin

    class WarmWorker(WorkerPlugin):
        name = "navig8-warm-worker"

        def __init__(self, kind: str) -> None:
            self.kind = kind

        def setup(self, worker: Any) -> None:
            warm_worker(self.kind)

    local = None
    if cluster == "local":
        # the workers' own sampling profiler walks the running task's stack every 10 ms (and a GIL monitor, when
        # gilknocker is installed, every 1 ms): CPU and GIL taken from the runs, for a dashboard nobody reads here.
        with dask.config.set(DASK_WORKER_CONFIG):
            local = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                 dashboard_address="127.0.0.1:0")  # a private cluster: loopback, free ports
        client = Client(local)
    else:
        client = Client(cluster)
    try:
        client.register_plugin(WarmWorker(rows[0].kind if rows else "inprocess"))
        futs = {client.submit(execute_row, r, key=f"navig8-run-{r.run_id}", pure=False): r for r in rows}
        for fut in as_completed(futs):
            r = futs[fut]
            try:
                yield r, fut.result()
            except Exception as exc:  # noqa: BLE001 - KilledWorker, a lost scheduler: recorded per run
                yield r, {"run_id": r.run_id, "status": "crashed", "worker": "",
                          "error": f"{type(exc).__name__}: {exc}"}
    finally:
        client.close()
        if local is not None:
            local.close()


__all__ = ["execute_row", "call_with_timeout", "RunTimeout", "worker_pool", "warm_worker", "pool_results",
           "dask_results", "RUNNERS", "WORKER_ENV"]
