"""navig8_fc.core.jit: a cached kernel is recompiled when a kernel it calls in another module changes
(plain numba.njit(cache=True) would keep the callee's old machine code: numba issue #6845)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

CALLER = """
import callee
from navig8_fc.core.jit import njit_cached

@njit_cached(callee)
def f(x):
    return callee.g(x) * 2.0
"""


def _run(tmp_path: Path) -> str:
    code = "import caller; print(caller.f(1.0), sum(caller.f.stats.cache_hits.values()))"
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True,
                         timeout=120)
    return out.stdout.strip()


def test_callee_change_recompiles_the_cached_caller(tmp_path: Path) -> None:
    (tmp_path / "caller.py").write_text(CALLER)
    callee = tmp_path / "callee.py"
    callee.write_text("from numba import njit\n\n@njit(cache=True)\ndef g(x):\n    return x + 1.0\n")
    assert _run(tmp_path) == "4.0 0"  # compiled
    assert _run(tmp_path) == "4.0 1"  # from the cache
    callee.write_text("from numba import njit\n\nK = 100.0\n\n@njit(cache=True)\ndef g(x):\n    return x + K\n")
    assert _run(tmp_path) == "202.0 0"  # recompiled with the new callee
    callee.write_text("from numba import njit\n\nK = 5.0\n\n@njit(cache=True)\ndef g(x):\n    return x + K\n")
    assert _run(tmp_path) == "12.0 0"  # a module constant numba froze into the code counts too


def test_kernels_run_as_python_with_numba_disabled(tmp_path: Path) -> None:
    """NUMBA_DISABLE_JIT=1 (stepping through a kernel in a debugger) leaves njit_cached's kernels plain functions."""
    (tmp_path / "caller.py").write_text(CALLER)
    (tmp_path / "callee.py").write_text("from numba import njit\n\n@njit(cache=True)\ndef g(x):\n    return x + 1.0\n")
    code = "import caller; print(caller.f(1.0), hasattr(caller.f, 'stats'))"
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True,
                         timeout=120, env={**os.environ, "NUMBA_DISABLE_JIT": "1"})
    assert out.stdout.strip() == "4.0 False"
