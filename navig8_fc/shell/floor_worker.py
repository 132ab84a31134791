"""PARAM_SETs off the control path (GcsService's): `ParamSets` limits them per source (PARAM_SET_RATE), queues those
whose stability floor must be computed, and writes the parameter file on a worker thread; `FloorWorker` computes the
floors off the control thread (docs/gcs.md, "Parameters"): a spawned worker
process at idle priority (its start-up and the analysis must not take CPU from the control loop and the simulator),
raised to normal priority when a ground station waits on it or a floor has starved; a thread when processes cannot
be started, and inline (the caller) when the worker died."""

from __future__ import annotations

import math
import multiprocessing
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from typing import Any

from navig8_fc.gcs.params import ParamProtocol
from navig8_fc.params.registry import ParamRegistry, run_floor
from navig8_fc.shell.telemetry_service import Source

FLOOR_IDLE_GRACE_S = 10.0  # a floor pending this long (wall) at idle priority: the worker is raised to normal


def _idle_priority() -> None:
    """The calling thread at idle priority (Linux SCHED_IDLE, per thread; a process it starts inherits it). Idle, not
    a nice level: in lockstep the FC and the bridge wake each other every tick, and a nice-10 worker on the other
    core still delayed each wake-up enough to halve the real-time factor; an idle-class task is preempted at once."""
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):  # not Linux
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 19)
        except (AttributeError, OSError):
            pass


def _floor_worker_init(parent_pid: int) -> None:
    """The stability-floor worker lives only as long as the FC: a killed FC (SIGKILL, no shutdown) must not leave
    it running, nor leave it holding the FC's stdout/stderr (a supervisor reading them would wait forever). It runs
    at idle priority from birth (_start_floor_pool): its start-up (a spawned interpreter importing the FC's modules
    and scipy, ~3 s of CPU) and the analysis (~1.5 s for a new configuration) must not take CPU from the control loop
    and the simulator (at normal priority they had cut the lockstep real-time factor to a third on two cores)."""
    _idle_priority()
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)  # its results and errors go back through the futures, not the console
    os.dup2(devnull, 2)
    os.close(devnull)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(0.2)
        os._exit(0)  # re-parented: the FC is gone

    threading.Thread(target=watch, name="navig8-floor-parent-watch", daemon=True).start()


class FloorWorker:
    """One floor job at a time on the worker; its result goes into the registry's floor cache."""

    def __init__(self, registry: ParamRegistry, fallback: Executor) -> None:
        self._registry = registry
        self._fallback = fallback  # a thread: no processes here still keeps the sweep off the loop
        self._pool: Executor | None = None
        self.failed = False  # the worker died: from now on floors are computed inline
        self._job: tuple[dict[str, float | int], Future[Any]] | None = None
        self._job_t0 = math.inf  # wall time the pending job was submitted
        self._raised = False  # the worker left idle priority (a PARAM_SET waits, or it starved)

    def start(self) -> None:
        """Spawn the worker and compute the configuration in force once (its start-up takes seconds, more on a busy
        machine: the first PARAM_SET that needs a floor is then answered in the analysis' own time)."""
        self._start()
        assert self._pool is not None
        self._pool.submit(run_floor, self._registry.stability_check, self._registry.as_dict())

    def _start(self) -> None:
        # A spawned process: nothing of this one (threads, sockets) is inherited. It is started from a thread set to
        # idle priority, which the worker (and multiprocessing's resource tracker) inherit from their first
        # instruction: the import of the FC's modules in a spawned interpreter then runs on idle CPU only.
        made: list[Executor | BaseException] = []

        def spawn() -> None:
            _idle_priority()
            try:
                pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                           initializer=_floor_worker_init, initargs=(os.getpid(),))
                pool.submit(os.getpid)  # the worker starts now, from this thread
                made.append(pool)
            except (OSError, ValueError) as exc:
                made.append(exc)

        t = threading.Thread(target=spawn, name="navig8-floor-spawn", daemon=True)
        t.start()
        t.join()
        got = made[0] if made else None
        self._pool = got if isinstance(got, Executor) else self._fallback

    def submit(self, values: dict[str, float | int], now_wall: float) -> None:
        if self._pool is None:
            self._start()
        assert self._pool is not None
        self._job = (values, self._pool.submit(run_floor, self._registry.stability_check, values))
        self._job_t0 = now_wall

    def done(self) -> bool:
        """Store the worker's finished floor in the registry; False while one is still being computed."""
        if self._job is None:
            return True
        values, job = self._job
        if not job.done():
            return False
        self._job = None
        try:
            self._registry.store_floor(values, job.result())
        except Exception:  # noqa: BLE001 - a dead worker: from now on floors are computed inline
            self.failed = True
        return True

    def starved(self, now_wall: float) -> bool:
        """A floor has been pending FLOOR_IDLE_GRACE_S (a busy machine starves an idle-class task)."""
        return self._job is not None and now_wall - self._job_t0 > FLOOR_IDLE_GRACE_S

    def raise_priority(self) -> None:
        """The worker from idle to normal priority, once: a PARAM_SET waits on it, or it starved. Needs
        CAP_SYS_NICE (root) or an RLIMIT_NICE that allows it; without, the worker stays idle and answers when the
        machine has a spare moment."""
        if self._raised:
            return
        self._raised = True
        for pid in list(getattr(self._pool, "_processes", None) or {}):  # a process pool's workers
            try:
                os.sched_setscheduler(pid, os.SCHED_OTHER, os.sched_param(0))
            except (AttributeError, OSError):
                pass

    def close(self) -> None:
        if self._pool is not None and self._pool is not self._fallback:
            self._pool.shutdown(wait=False, cancel_futures=True)
        self._pool = None


PARAM_QUEUE_MAX = 32  # PARAM_SETs waiting for a stability floor; more are refused (busy) at once

Route = Callable[[str, Source | None, list[Any]], None]


class ParamSets:
    """The PARAM_SET path (module docstring). `route` sends a request's answers back (GcsService's routing),
    `refusal_text` a rate-limited STATUSTEXT, `statustext` a save's failure."""

    def __init__(self, params: ParamProtocol, registry: ParamRegistry, background: bool, route: Route,
                 refusal_text: Callable[[str], list[Any]], statustext: Callable[[str, int], None]) -> None:
        self.params, self._registry = params, registry
        self._route, self._refusal_text, self._statustext = route, refusal_text, statustext
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="navig8-params") if background else None
        self._queue: deque[tuple[Any, Source | None]] = deque()
        self._save_job: Future[str | None] | None = None
        self._tokens: dict[Source | None, tuple[float, float]] = {}  # source -> (tokens, last time)
        # the stability floors of PARAM_SETs, off the control thread (started with the background worker)
        self._floor = FloorWorker(registry, self._pool) if self._pool is not None else None
        if self._floor is not None:
            self._floor.start()

    def refuse(self, m: Any, why: str) -> list[Any]:
        """The value in force for a refused PARAM_SET, and (at most one a second) the reason."""
        values = [r for r in self.params.refuse_set(m, why) if r.get_type() == "PARAM_VALUE"]
        return values + (self._refusal_text(f"PARAM_SET {why}") if values else [])

    def set(self, m: Any, source: Source | None, now_wall: float, rate_hz: float) -> list[Any]:
        """Rate limit, then at once when nothing is queued and no stability sweep is needed; else queued."""
        tokens, last = self._tokens.get(source, (rate_hz, now_wall))
        tokens = min(rate_hz, tokens + (now_wall - last) * rate_hz)
        if tokens < 1.0:
            self._tokens[source] = (tokens, now_wall)
            return self.refuse(m, f"refused: more than {rate_hz:g} PARAM_SET/s, retry")
        self._tokens[source] = (tokens - 1.0, now_wall)
        if len(self._tokens) > 64:  # forget idle sources (bounded memory under spoofed floods)
            self._tokens = {k: v for k, v in self._tokens.items() if now_wall - v[1] < 2.0}
        if self._pool is None or (not self._queue and self.params.floor_needed(m) is None):
            return self.params.handle(m, now_wall, source)
        if len(self._queue) >= PARAM_QUEUE_MAX:
            return self.refuse(m, "refused: busy checking the stability floor, retry")
        self._queue.append((m, source))
        return []

    def poll(self, now_wall: float) -> None:
        """Between control steps: the queue, the floor in force, a starving worker's priority, a due save."""
        self._run_queue(now_wall)
        self._floor_in_force(now_wall)
        if self._floor is not None and self._floor.starved(now_wall):
            self._floor.raise_priority()
        self._save()

    def _floor_job_done(self) -> bool:
        return self._floor is None or self._floor.done()

    def _run_queue(self, now_wall: float) -> None:
        """Queued PARAM_SETs in order, each once its floor is computed (the worker)."""
        while self._queue:
            m, source = self._queue[0]
            if not self._floor_job_done():
                return
            need = self.params.floor_needed(m)
            if need is not None and self._floor is not None and not self._floor.failed:
                self._floor.submit(need, now_wall)
                self._floor.raise_priority()  # a ground station waits for this answer
                return
            self._queue.popleft()
            self._route("PARAM_SET", source, self.params.handle(m, now_wall, source))

    def _floor_in_force(self, now_wall: float) -> None:
        """The stability floor of the values in force for LAM_MARGIN and the log, when no PARAM_SET has computed it
        (at start, after a reset or load): on the worker, as a PARAM_SET's; inline without one."""
        reg = self._registry
        if reg.stability_check is None or self._queue or not self._floor_job_done():
            return
        if reg.floor_in_force() is not None:
            return
        values = reg.as_dict()
        if self._floor is not None and not self._floor.failed:
            self._floor.submit(values, now_wall)
        else:
            reg.store_floor(values, reg.compute_floor(values))

    def _save(self) -> None:
        """A due save on the worker (its outcome reported when done); one at a time, the latest values."""
        if self._save_job is not None:
            if not self._save_job.done():
                return
            err, self._save_job = self._save_job.result(), None
            if err:
                self._statustext(err, 4)  # MAV_SEVERITY_WARNING
        values = self.params.take_save()
        if values is not None and self._pool is not None:
            self._save_job = self._pool.submit(self.params.write_values, values)

    @property
    def busy(self) -> bool:
        """PARAM_SETs queued or a save being written."""
        return bool(self._queue) or self._save_job is not None or self.params.save_due

    def close(self) -> None:
        """Finish the queue's last save and stop the worker."""
        if self._pool is not None:
            values = self.params.take_save()
            if values is not None:
                self._pool.submit(self.params.write_values, values)
            self._pool.shutdown(wait=True)
            self._pool = None
        if self._floor is not None:
            self._floor.close()
