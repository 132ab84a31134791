"""Session-wide test set-up.

numba compiles every kernel on its first call and keeps the result in its disk cache (`cache=True`). On a
fresh clone that first compilation takes tens of seconds; done inside a test it would land in whichever test
happens to run first, and with pytest-xdist in every worker at once. `pytest_configure` runs once in the
controlling process (before xdist starts its workers, and in a plain run before collection), flies a short
in-process hover through the public `navig8-sim` entry point so every FC and plant kernel is compiled and
cached; workers and SITL child processes then load the kernels from the cache.
"""

from __future__ import annotations

import time

import pytest

WARM_S = pytest.StashKey[float]()  # how long the warm-up took, for the report header


def pytest_configure(config: pytest.Config) -> None:
    if hasattr(config, "workerinput"):  # an xdist worker: the controller has warmed the cache already
        return
    if config.option.collectonly:
        return
    from navig8_tools.sim import run

    t0 = time.perf_counter()
    run("hover", duration_s=0.05, log_path=None)
    config.stash[WARM_S] = time.perf_counter() - t0


def pytest_report_header(config: pytest.Config) -> str | None:
    warm = config.stash.get(WARM_S, None)
    return None if warm is None else f"navig8: numba kernels warmed in {warm:.1f} s (tests/conftest.py)"
