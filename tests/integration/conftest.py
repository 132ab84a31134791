"""The estimator tests' shared flights (shared_trace.py) live in the run's temporary directory."""

from __future__ import annotations

from pathlib import Path

import pytest
import shared_trace


@pytest.fixture(scope="session", autouse=True)
def _shared_k_traces(run_shared_dir: Path) -> None:
    shared_trace.CACHE_DIR = run_shared_dir / "k_traces"
