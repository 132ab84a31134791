"""PARAM_SETs off the control path (GcsService's): `ParamSets` limits them per source (PARAM_SET_RATE), queues those
whose stability floor must be computed, flies the automatic link floor (INDI_KFL_LINK; navig8_fc/params/
link_floor.py: searched on the same worker, applied to the registry here, announced by the FC's process), and writes
the parameter file on a worker thread; `FloorWorker` computes the floors off the control thread (docs/gcs.md,
"Parameters"): a worker process (job_process.JobProcess), started and warm before the FC's loop (its start-up, ~0.3 s
of CPU with the workspace's Xi on disk, ~1.4 s without, then takes nothing from the control loop and the simulator;
a configuration's floor is ~20 ms, a link floor's search ~0.5 s); a thread when processes cannot be started, and
inline (the caller) when the worker died."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from typing import Any

from navig8_fc.gcs.params import ParamProtocol
from navig8_fc.params.link_floor import (
    LinkFloor,
    governed_link_floor,
    least_link_floor,
    link_floor_key,
    link_floor_values,
)
from navig8_fc.params.registry import LINK_KFL_KEY, ParamRegistry, run_floor
from navig8_fc.shell.job_process import JobProcess
from navig8_fc.shell.telemetry_service import Source


class FloorWorker:
    """One floor job at a time on the worker; its result goes into the registry's floor cache."""

    def __init__(self, registry: ParamRegistry, fallback: Executor) -> None:
        self._registry = registry
        self._fallback = fallback  # a thread: no processes here still keeps the sweep off the loop
        self._pool: Executor | None = None
        self.failed = False  # the worker died: from now on floors are computed inline
        self._job: tuple[Callable[[Any], None], Future[Any]] | None = None

    def start(self) -> None:
        """Start the worker and compute the configuration in force once: its start-up (an interpreter, its imports,
        the workspace's Xi, read from disk when an earlier start left it: ~0.3 s of CPU) then falls before the first
        PARAM_SET (wait_floor_in_force), which is answered in a configuration's own time (~20 ms)."""
        self._start()
        assert self._pool is not None
        self._pool.submit(run_floor, self._registry.stability_check, self._registry.floor_values())

    def _start(self) -> None:
        try:
            self._pool = JobProcess()  # idle priority from its first instruction (job_process)
        except OSError:  # no processes here: a thread
            self._pool = self._fallback

    def submit(self, values: dict[str, float | int], now_wall: float) -> None:
        """The floor of `values`, stored in the registry's floor cache when done."""
        self.submit_job(run_floor, values, lambda floor: self._registry.store_floor(values, floor))

    def submit_job(self, fn: Callable[[Any, dict[str, Any]], Any], values: dict[str, Any],
                   on_result: Callable[[Any], None]) -> None:
        """fn(the registry's stability check, values) on the worker; its result to on_result when done."""
        if self._pool is None:
            self._start()
        assert self._pool is not None
        self._job = (on_result, self._pool.submit(fn, self._registry.stability_check, values))

    def done(self) -> bool:
        """Hand the worker's finished result on (a floor: into the registry); False while one is still computed."""
        if self._job is None:
            return True
        on_result, job = self._job
        if not job.done():
            return False
        self._job = None
        try:
            result = job.result()
        except Exception:  # noqa: BLE001 - a dead worker: from now on floors are computed inline
            self.failed = True
            return True
        on_result(result)
        return True

    def close(self) -> None:
        if self._pool is not None and self._pool is not self._fallback:
            self._pool.shutdown(wait=False, cancel_futures=True)
        self._pool = None


LINK_FLOORS_KEPT = 64  # link floor searches kept (per delay and configuration: a few in a flight)
PARAM_QUEUE_MAX = 32  # PARAM_SETs waiting for a stability floor; more are refused (busy) at once

Route = Callable[[str, Source | None, list[Any]], None]


class ParamSets:
    """The PARAM_SET path (module docstring). `route` sends a request's answers back (GcsService's routing),
    `refusal_text` a rate-limited STATUSTEXT, `statustext` a save's failure."""

    def __init__(self, params: ParamProtocol, registry: ParamRegistry, background: bool, route: Route,
                 refusal_text: Callable[[str], list[Any]], statustext: Callable[[str, int], None],
                 armed: Callable[[], bool] = lambda: False) -> None:
        self.params, self._registry = params, registry
        self._armed = armed  # the automatic link floor only rises while armed (link_floor.governed_link_floor)
        self._link_floors: dict[tuple[float, ...], LinkFloor] = {}  # link_floor_key -> the worker's search
        # the link floor changes not yet announced: (the search behind the new floor, None when it was lowered to
        # none; the floor before; the floor now), taken by the FC's process (take_link_floor_changes)
        self._link_floor_changes: list[tuple[LinkFloor | None, float, float]] = []
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
        """Between control steps: the queue, the automatic link floor, the floor in force, a due save."""
        self._run_queue(now_wall)
        self._link_floor()
        self._floor_in_force(now_wall)
        self._save()

    def _link_floor(self) -> None:
        """The automatic link floor (INDI_KFL_LINK; navig8_fc/params/link_floor.py): searched on the worker for the
        values in force and the measured link (before the floor in force, so a late link's margin is first logged
        with the floor it flies), then flown as governed_link_floor says (armed: only up). The search's floor is
        stored as the floor in force's, so LAM_MARGIN and /fc/stability follow without a second computation."""
        reg = self._registry
        if reg.stability_check is None or self._queue or not self._floor_job_done():
            return
        values = link_floor_values(reg)
        found: LinkFloor | None = None
        if values is not None:
            key = link_floor_key(values)
            found = self._link_floors.get(key)
            if found is None:
                if self._floor is not None and not self._floor.failed:
                    self._floor.submit_job(least_link_floor, values, lambda r: self._keep_link_floor(key, r))
                    return
                found = self._keep_link_floor(key, least_link_floor(reg.stability_check, values))
        target = found.k_floor if found is not None else 0.0
        current = reg.link_k_floor
        new = current if target == current else governed_link_floor(current, target, self._armed())
        if new == current and (found is None or reg.floor_in_force() is not None):
            return  # nothing to change (the common case: this runs between control steps)
        if found is not None and new == found.k_floor:
            reg.store_floor({**values, LINK_KFL_KEY: new} if new > 0.0 else values, found.floor)  # type: ignore[dict-item]
        if new != current:
            reg.set_link_k_floor(new)
            self._link_floor_changes.append((found if new == target else None, current, new))

    def _keep_link_floor(self, key: tuple[float, ...], found: LinkFloor) -> LinkFloor:
        self._link_floors[key] = found
        while len(self._link_floors) > LINK_FLOORS_KEPT:
            del self._link_floors[next(iter(self._link_floors))]  # the oldest
        return found

    def take_link_floor_changes(self) -> list[tuple[LinkFloor | None, float, float]]:
        """The link floor's changes since the last call (the search behind each, the floor before, after)."""
        changes, self._link_floor_changes = self._link_floor_changes, []
        return changes

    def wait_floor_in_force(self, timeout_s: float) -> bool:
        """Block until the stability floor of the values in force is computed (the worker started, imported and
        warm: later PARAM_SETs are answered in its ~20 ms a configuration), at most timeout_s (wall); True when it
        is. The FC calls this once before its loop, so no ground station hears it before (docs/gcs.md)."""
        deadline = time.monotonic() + timeout_s
        while self._registry.stability_check is not None and self._registry.floor_in_force() is None:
            now = time.monotonic()
            if now >= deadline:
                return False
            self._floor_in_force(now)
            self._floor_job_done()  # stores a finished job's floor
            time.sleep(0.005)
        return True

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
        values = reg.floor_values()  # the values in force with the sim link's timing
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
