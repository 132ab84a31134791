"""One BLAS thread while a run flies (tools/sim.py `run`).

The control problem's matrices are at most 10 x 10, where OpenBLAS's threads only cost: its LU solve goes parallel
at any size (`dgetrs`, which scipy's `expm` calls: the set-up discretises the actuator models ~90 times), and after
a parallel call its worker threads spin ~0.1 s waiting for more work. Run after run, that left a thread busy on the
second core for the first ~0.1 s of the flight, beside the log writer there (docs/results.md, "Speed"). NumPy and
SciPy each load their own OpenBLAS; `one_blas_thread` asks every OpenBLAS mapped into the process for one thread and
gives each its count back afterwards (what threadpoolctl does, for the one library this project meets). Where the
libraries or their symbols are not found (another BLAS, another OS), it does nothing.
"""

from __future__ import annotations

import ctypes
from collections.abc import Iterator
from contextlib import contextmanager

# (set, get) by the names OpenBLAS exports: plain, and as the scipy-openblas wheels of SciPy and NumPy prefix them
_SYMBOLS = (
    ("scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"),
    ("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
    ("openblas_set_num_threads", "openblas_get_num_threads"),
    ("openblas_set_num_threads64_", "openblas_get_num_threads64_"),
)


def _openblas_paths() -> list[str]:
    try:
        with open("/proc/self/maps") as fh:
            lines = fh.read().splitlines()
    except OSError:
        return []
    paths = {line.split()[-1] for line in lines if line.count("/") and "openblas" in line.rsplit("/", 1)[-1].lower()}
    return sorted(p for p in paths if p.startswith("/"))


def _controls() -> list[tuple[object, object]]:
    found = []
    for path in _openblas_paths():
        try:
            lib = ctypes.CDLL(path)  # already mapped: the same library, not a second copy
        except OSError:
            continue
        for set_name, get_name in _SYMBOLS:
            setter, getter = getattr(lib, set_name, None), getattr(lib, get_name, None)
            if setter is not None and getter is not None:
                found.append((setter, getter))
                break
    return found


def blas_thread_counts() -> list[int]:
    """The thread count of every OpenBLAS mapped into the process (none found: empty)."""
    return [int(getter()) for _setter, getter in _controls()]


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Every OpenBLAS in the process on one thread inside the block; each library's count restored after it."""
    controls = _controls()
    before = [int(getter()) for _setter, getter in controls]
    for setter, _getter in controls:
        setter(1)
    try:
        yield
    finally:
        for (setter, _getter), n in zip(controls, before, strict=True):
            setter(n)


__all__ = ["blas_thread_counts", "one_blas_thread"]
