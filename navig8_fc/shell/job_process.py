"""One worker process for the FC's background jobs (the stability floors of PARAM_SETs: floor_worker.FloorWorker),
as a concurrent.futures Executor.

Not multiprocessing's spawn: a spawned child first re-imports the parent's main module (all of navig8-fc, ~0.8 s)
before its first job; this child is `python -m navig8_fc.shell.job_process`, which imports only what its jobs need
(pickled functions import their own modules). Jobs and results go as length-prefixed pickles over the child's
stdin and stdout (a private pipe between the FC and its own child). The child exits when its stdin closes, so a
killed FC (SIGKILL, no shutdown) does not leave it running; it never holds the FC's stdout or stderr.
"""

from __future__ import annotations

import os
import pickle
import struct
import subprocess
import sys
import threading
from collections.abc import Callable
from concurrent.futures import Executor, Future
from typing import IO, Any

_HEADER = struct.Struct("<QI")  # the job's id, the length of the pickle that follows


class WorkerDied(RuntimeError):
    """The worker process ended (killed, crashed) with jobs pending."""


def _write_frame(out: IO[bytes], job_id: int, obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    out.write(_HEADER.pack(job_id, len(data)) + data)
    out.flush()


def _read_frame(inp: IO[bytes]) -> tuple[int, bytes]:
    """The next (job id, pickle), or raise EOFError when the pipe closed."""
    head = inp.read(_HEADER.size)
    if len(head) < _HEADER.size:
        raise EOFError
    job_id, n = _HEADER.unpack(head)
    data = inp.read(n)
    if len(data) < n:
        raise EOFError
    return job_id, data


class JobProcess(Executor):
    """A one-process Executor (jobs run in submission order). `submit` raises OSError where no process can be
    started; a job's future fails with WorkerDied if the process ends first."""

    def __init__(self) -> None:
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "navig8_fc.shell.job_process"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL, close_fds=True)
        self._lock = threading.Lock()
        self._pending: dict[int, Future[Any]] = {}
        self._next_id = 0
        self._reader = threading.Thread(target=self._read_results, name="navig8-job-results", daemon=True)
        self._reader.start()

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        fut: Future[Any] = Future()
        with self._lock:
            job_id, self._next_id = self._next_id, self._next_id + 1
            self._pending[job_id] = fut
            try:
                assert self._proc.stdin is not None
                _write_frame(self._proc.stdin, job_id, (fn, args, kwargs))
            except (OSError, ValueError) as exc:  # the child is gone (broken pipe) or the pipe closed
                del self._pending[job_id]
                fut.set_exception(WorkerDied(f"the job process is gone: {exc}"))
        return fut

    def _read_results(self) -> None:
        assert self._proc.stdout is not None
        try:
            while True:
                job_id, data = _read_frame(self._proc.stdout)
                try:
                    ok, value = pickle.loads(data)
                except Exception as exc:  # noqa: BLE001 - a result this process cannot load fails that job alone
                    ok, value = False, exc
                with self._lock:
                    fut = self._pending.pop(job_id, None)
                if fut is not None and ok:
                    fut.set_result(value)
                elif fut is not None:
                    fut.set_exception(value)
        except (EOFError, OSError):
            pass
        with self._lock:
            pending, self._pending = self._pending, {}
        for fut in pending.values():
            fut.set_exception(WorkerDied("the job process ended"))

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        with self._lock:
            if self._proc.stdin is not None and not self._proc.stdin.closed:
                try:
                    self._proc.stdin.close()  # the child's EOF: it finishes its job and exits
                except OSError:
                    pass
        if cancel_futures:
            self._proc.kill()
        try:
            self._proc.wait(timeout=5.0 if wait else 0.5)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait(timeout=5.0)
        if self._proc.stdout is not None:
            self._proc.stdout.close()


def serve(inp: IO[bytes], out: IO[bytes]) -> None:
    """Run (fn, args, kwargs) jobs until the input closes; answer each with (ok, result or exception)."""
    while True:
        try:
            job_id, data = _read_frame(inp)
        except EOFError:
            return
        try:
            fn, args, kwargs = pickle.loads(data)  # a function this process cannot import fails here, alone
            result: tuple[bool, Any] = (True, fn(*args, **kwargs))
        except Exception as exc:  # noqa: BLE001 - the job's failure goes back to its future
            result = (False, exc)
        try:
            _write_frame(out, job_id, result)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:  # a result or an exception that cannot pickle
            _write_frame(out, job_id, (False, RuntimeError(f"job result cannot be sent back: {exc!r}")))


if __name__ == "__main__":
    # One BLAS thread, as the FC's own, set before a job's module loads numpy (navig8_fc/blas.py: why)
    from navig8_fc.blas import ONE_THREAD_ENV

    os.environ.update(ONE_THREAD_ENV)
    results = os.fdopen(os.dup(1), "wb")  # the result pipe; fd 1 itself to /dev/null, so a job's print cannot
    devnull = os.open(os.devnull, os.O_WRONLY)  # corrupt the frames
    os.dup2(devnull, 1)
    os.close(devnull)
    serve(sys.stdin.buffer, results)
