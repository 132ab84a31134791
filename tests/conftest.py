"""Session-wide test set-up.

numba compiles every kernel on its first call and keeps the result in its disk cache (`cache=True`). On a
fresh clone that first compilation takes tens of seconds; done inside a test it would land in whichever test
happens to run first, and with pytest-xdist in every worker at once. `pytest_configure` runs once in the
controlling process (before xdist starts its workers, and in a plain run before collection), flies a short
in-process hover through the public `navig8-sim` entry point so every FC and plant kernel is compiled and
cached; workers and SITL child processes then load the kernels from the cache. numba compiles on one core: a second
process (tests/warm_tail_kernels.py) compiles the kernels the hover reaches last on the other core meanwhile.
"""

from __future__ import annotations

import os
import subprocess
import sys
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

WARM_S = pytest.StashKey[float]()  # how long the warm-up took, for the report header
WARM_TAIL_RC = pytest.StashKey[int]()  # the second warm-up process's exit code (non-zero: it only cost time)
_HERE = Path(__file__).resolve().parent
_SLOW_DIRS = (_HERE / "sitl", _HERE / "clients")  # where the slow tests live (their conftests mark them)
# The SITL lane's longest modules (the most minutes, summed over their tests, measured with --durations=0), started
# first: `--dist loadfile` hands the modules out in collection order, so a long module collected last (alphabetically)
# would leave the other worker idle at the end.
LONGEST_FIRST = ("clients/test_mavsdk_examples.py", "sitl/test_sitl_paper.py", "sitl/test_sitl_paper_plan.py",
                 "sitl/test_sitl_tcp_links.py", "sitl/test_sitl_link_health.py", "sitl/test_sitl_robustness.py")


def pytest_configure(config: pytest.Config) -> None:
    if hasattr(config, "workerinput"):  # an xdist worker: the controller has warmed the cache already
        return
    if config.option.collectonly:
        return
    from navig8_tools.sim import run

    t0 = time.perf_counter()
    # On a fresh clone the hover compiles for ~70 s on one core while the other idles; its last ~20 s (the
    # eigenvalue record's and the plant step's kernels) compile beside it in a second process and are loaded from
    # the cache when the hover reaches them (docs/results.md, "Test suite time"). Whatever that process does not
    # reach, or if it fails, the hover compiles itself: it can cost time, never a kernel.
    tail = subprocess.Popen([sys.executable, str(_HERE / "warm_tail_kernels.py")], stdin=subprocess.DEVNULL)
    try:
        run("hover", duration_s=0.05, log_path=None)
    finally:
        config.stash[WARM_TAIL_RC] = tail.wait()
    config.stash[WARM_S] = time.perf_counter() - t0


def pytest_report_header(config: pytest.Config) -> str | None:
    warm = config.stash.get(WARM_S, None)
    if warm is None:
        return None
    rc = config.stash.get(WARM_TAIL_RC, 0)
    tail = "" if rc == 0 else f"; tests/warm_tail_kernels.py exited {rc}: the hover compiled its kernels itself"
    return f"navig8: numba kernels warmed in {warm:.1f} s (tests/conftest.py{tail})"


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
