"""The FC's background job process (navig8_fc.shell.job_process): real child processes, bounded waits."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time

import pytest

from navig8_fc.shell.job_process import JobProcess, WorkerDied

pytestmark = pytest.mark.slow

WAIT_S = 60.0  # a cold interpreter on a loaded machine


def _local_function() -> None:
    """Defined in a test module the child cannot import."""


def test_jobs_run_in_a_child_in_order_and_their_errors_come_back() -> None:
    jobs = JobProcess()
    try:
        pid = jobs.submit(os.getpid).result(WAIT_S)
        assert pid != os.getpid()
        assert [jobs.submit(math.sqrt, float(v)).result(WAIT_S) for v in (4, 9, 16)] == [2.0, 3.0, 4.0]
        assert jobs.submit(print, "a job's print must not reach the result pipe").result(WAIT_S) is None
        with pytest.raises(ModuleNotFoundError):
            jobs.submit(_local_function).result(WAIT_S)
        with pytest.raises(ValueError):
            jobs.submit(math.sqrt, -1.0).result(WAIT_S)
        assert jobs.submit(math.hypot, 3.0, 4.0).result(WAIT_S) == 5.0  # still serving after a failure
    finally:
        jobs.shutdown()


def test_the_childs_blas_runs_on_one_thread() -> None:
    """The floors' matrices are tens wide: OpenBLAS's threads would only wait for a core on a busy machine."""
    import numpy as np
    from threadpoolctl import threadpool_info

    jobs = JobProcess()
    try:
        assert jobs.submit(np.zeros, 1).result(WAIT_S).shape == (1,)  # numpy (and its BLAS) loaded in the child
        blas = [lib for lib in jobs.submit(threadpool_info).result(WAIT_S) if lib["user_api"] == "blas"]
        assert blas and all(lib["num_threads"] == 1 for lib in blas), blas
    finally:
        jobs.shutdown()


def test_a_killed_child_fails_the_pending_and_later_jobs_and_shutdown_ends_it() -> None:
    jobs = JobProcess()
    pid = jobs.submit(os.getpid).result(WAIT_S)
    os.kill(pid, signal.SIGKILL)
    with pytest.raises(WorkerDied):
        for _ in range(1000):  # the broken pipe shows at the latest on a later write
            jobs.submit(math.sqrt, 1.0).result(WAIT_S)
    jobs.shutdown()


def test_the_child_exits_when_its_parent_closes_the_pipe() -> None:
    jobs = JobProcess()
    pid = jobs.submit(os.getpid).result(WAIT_S)
    jobs.shutdown(wait=True)
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_the_child_does_not_outlive_a_killed_parent() -> None:
    """A SIGKILLed FC runs no shutdown: its job process must still go (its stdin reaches EOF)."""
    parent = subprocess.Popen(
        [sys.executable, "-c", "import os, sys, time\n"
         "from navig8_fc.shell.job_process import JobProcess\n"
         "print(JobProcess().submit(os.getpid).result(60), flush=True)\n"
         "time.sleep(60)"], stdout=subprocess.PIPE, text=True)
    try:
        assert parent.stdout is not None
        child = int(parent.stdout.readline())
        assert _alive(child)
    finally:
        parent.kill()
        parent.wait(timeout=10)
    deadline = time.monotonic() + 10.0
    while _alive(child) and time.monotonic() < deadline:
        time.sleep(0.02)
    assert not _alive(child)
