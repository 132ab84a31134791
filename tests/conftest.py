"""Session-wide test set-up.

numba compiles every kernel on its first call and keeps the result in its disk cache (`cache=True`). On a
fresh clone that first compilation takes tens of seconds; done inside a test it would land in whichever test
happens to run first, and with pytest-xdist in every worker at once. `pytest_configure` runs once in the
controlling process (before xdist starts its workers, and in a plain run before collection) and starts
tests/warm_kernels.py, which flies a short in-process hover through the public `navig8-sim` entry point so every FC
and plant kernel is compiled and cached (with the kernels the hover reaches after its longest one compiled beside
it, on the other core). A plain run waits for it there; xdist workers start and collect meanwhile (on the core the
warm-up leaves idle) and wait for it before their first test. Workers and SITL child processes
then load the kernels from the cache.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from navig8_fc.blas import ONE_THREAD_ENV  # no numpy: the environment is set before numpy loads

# One BLAS thread in every test process and every process a test starts (they inherit the environment), set before
# anything loads numpy: the matrices here are tens wide, and on two busy cores OpenBLAS's threads turn each small LAPACK
# call (the actuator models' ~40 expm of every controller built) into a scheduler wait. The fast lane on a loaded
# machine: 3 min 50 s against 6 min 01 s (docs/results.md, "Test suite time"). navig8-fc and navig8-bridge set it
# themselves.
for _var, _value in ONE_THREAD_ENV.items():
    os.environ.setdefault(_var, _value)

# pytest keeps each test module's assert-rewritten code in __pycache__ only when bytecode may be written; under
# PYTHONDONTWRITEBYTECODE (CI) every worker of every lane rewrote every module it collected again. The test processes
# write it (the processes the tests start still inherit the variable): the fast lane's workers, which collect the
# whole tree, leave it for the SITL and real-time lanes' (tests/sitl and tests/clients collected in 2.1 s of CPU
# against 3.0 s; the whole tree 4.9 s against 10.8 s).
sys.dont_write_bytecode = False

WARM = pytest.StashKey[tuple[subprocess.Popen, Path]]()  # the warm-up process and the file it writes when done
WARM_TOOK = pytest.StashKey[list[str]]()  # what the warm-up wrote: its seconds and its tail's exit code
WARM_DONE_ENV = "NAVIG8_TEST_WARM_DONE"  # the workers inherit it from the controller (make test sets it too)
WARM_WAIT_S = 900.0  # a worker waits this long at most, then runs its tests (they compile what they need)
_HERE = Path(__file__).resolve().parent
_SLOW_DIRS = (_HERE / "sitl", _HERE / "clients")  # where the slow tests live (their conftests mark them)
# The SITL lane's longest modules (the most minutes, summed over their tests, measured with --durations=0), started
# first: `--dist loadfile` hands the modules out in collection order, so a long module collected last (alphabetically)
# would leave the other worker idle at the end.
LONGEST_FIRST = ("clients/test_mavsdk_examples.py", "sitl/test_sitl_paper.py", "sitl/test_sitl_paper_plan.py",
                 "sitl/test_sitl_tcp_links.py", "sitl/test_sitl_link_health.py", "sitl/test_sitl_robustness.py")


def pytest_configure(config: pytest.Config) -> None:
    if hasattr(config, "workerinput"):  # an xdist worker: it waits for the controller's warm-up after collecting
        return
    if config.option.collectonly:
        return
    outer = os.environ.get(WARM_DONE_ENV)
    # a pytest a test started (test_hil_external), or make test's lanes after the fast one: already warm
    if outer is not None and os.path.exists(outer):
        return
    done = Path(tempfile.mkdtemp(prefix="navig8-warm-")) / "done"
    proc = subprocess.Popen([sys.executable, str(_HERE / "warm_kernels.py"), str(done)], stdin=subprocess.DEVNULL)
    config.stash[WARM] = (proc, done)
    if config.getoption("numprocesses", None) and config.getoption("dist", "no") != "no":
        os.environ[WARM_DONE_ENV] = str(done)  # set before xdist starts its workers: they inherit it
    elif proc.wait() != 0:  # a plain run: every test after it
        raise pytest.UsageError("tests/warm_kernels.py failed: the warm-up hover did not fly (its output above)")


def pytest_collection_finish(session: pytest.Session) -> None:
    """An xdist worker's first test waits for the warm-up (a kernel compiled in two workers at once costs both)."""
    done = os.environ.get(WARM_DONE_ENV)
    if done is None or not hasattr(session.config, "workerinput"):
        return
    deadline = time.monotonic() + WARM_WAIT_S
    while not os.path.exists(done) and time.monotonic() < deadline:
        time.sleep(0.05)


def pytest_report_header(config: pytest.Config) -> str | None:
    if WARM not in config.stash:
        return None
    proc, _ = config.stash[WARM]
    how = "done" if proc.poll() is not None else "under way; the workers wait for it after collecting"
    return f"navig8: numba kernels warmed by tests/warm_kernels.py ({how})"


def pytest_sessionfinish(session: pytest.Session) -> None:
    """A warm-up that failed fails the run (its hover did not fly); its time is kept for the summary."""
    if WARM not in session.config.stash:
        return
    proc, done = session.config.stash[WARM]
    rc = proc.wait()
    os.environ.pop(WARM_DONE_ENV, None)
    session.config.stash[WARM_TOOK] = done.read_text().split() if done.exists() else ["?", "?"]
    shutil.rmtree(done.parent, ignore_errors=True)
    if rc != 0:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter, config: pytest.Config) -> None:
    took = config.stash.get(WARM_TOOK, None)
    if took is not None:
        tail = "" if took[1] == "0" else f"; its tail process exited {took[1]}: the hover compiled those kernels"
        terminalreporter.write_line(f"navig8: numba kernels warmed in {took[0]} s (tests/warm_kernels.py{tail})")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Fail on a slow, real-time or client test outside tests/sitl and tests/clients: `make test` collects its slow
    and real-time lanes from those two folders only. Then start the SITL lane's longest modules first (a stable
    sort: every module's tests keep their order)."""
    marks = ("slow", "realtime", "clients_all")
    stray = [it.nodeid for it in items if not any(d in Path(str(it.fspath)).resolve().parents for d in _SLOW_DIRS)
             and any(it.get_closest_marker(m) is not None for m in marks)]
    if stray:
        raise pytest.UsageError(f"{', '.join(marks)} tests belong in tests/sitl or tests/clients (make test collects "
                                f"its slow lanes there): {', '.join(stray)}")
    rank = {(_HERE / rel).resolve(): i for i, rel in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda it: rank.get(Path(str(it.fspath)).resolve(), len(rank)))


@pytest.fixture(scope="session")
def run_shared_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The run's temporary directory, the same for every xdist worker: what a run flies once lives there."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the workers' temporary directories are its children
    return root


@pytest.fixture(scope="session")
def paper_reference(run_shared_dir: Path) -> tuple[dict, Path]:
    """The paper scenario flown in-process with the defaults, seed 1, logged: (its summary, its log). Four modules
    check this same flight (two in each lane); it is deterministic, so it is flown once a run: under xdist the
    first worker to ask flies it, holding a lock in the run's shared temporary directory, and the others read its
    summary (JSON, floats round-trip exactly) and its log."""
    from navig8_tools.sim import run

    d = run_shared_dir / "paper_reference"
    d.mkdir(exist_ok=True)
    summary, log = d / "summary.json", d / "ref.mcap"
    with open(d / "lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not summary.exists():
            s = run("paper", "proposed", seed=1, log_path=log).summary
            tmp = d / "summary.json.tmp"
            tmp.write_text(json.dumps(s))
            tmp.replace(summary)
        return json.loads(summary.read_text()), log
