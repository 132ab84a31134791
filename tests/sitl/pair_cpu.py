"""The CPU time of an FC-and-bridge pair started through sitl_helpers.sitl(), forked (the default) or as two
interpreters (NAVIG8_TEST_PREFORK=0): each pair started, idle on the ground at 1x for 2 s, stopped.

    .venv/bin/python tests/sitl/pair_cpu.py; NAVIG8_TEST_PREFORK=0 .venv/bin/python tests/sitl/pair_cpu.py

Forked children report their CPU (their own children's, the FC's floor worker, included) through the fork server;
interpreters through this process's reaped children.
"""

from __future__ import annotations

import os
import resource
import sys
import tempfile
import time
from pathlib import Path

from navig8_fc.blas import ONE_THREAD_ENV

for _var, _value in ONE_THREAD_ENV.items():  # as tests/conftest.py sets it for the tests
    os.environ.setdefault(_var, _value)
sys.path.insert(0, str(Path(__file__).resolve().parent))

import sitl_helpers  # noqa: E402


def main(pairs: int = 3) -> None:
    for _ in range(pairs):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.monotonic()
            with sitl_helpers.sitl(Path(tmp)) as run:
                up = time.monotonic() - t0
                time.sleep(2.0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        reaped = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
        forked = [getattr(p, "cpu_s", None) for p in (run.fc, run.bridge)]
        cpu = reaped + sum(c for c in forked if c is not None)
        how = "forked" if all(c is not None for c in forked) else "interpreters"
        print(f"pair up in {up:.2f} s; CPU {cpu:.2f} s (FC, floor worker and bridge; {how})")
    sitl_helpers.stop_fork_server()


if __name__ == "__main__":
    main()
