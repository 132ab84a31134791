"""MAVSDK-Python's own examples, unmodified, against the SITL (docs/gcs.md, "Client examples"): real processes
over real UDP, so the `slow` lane (`make test` runs it after the fast lane)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

_HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(_HERE.parent / "sitl"))  # sitl_helpers: the pair's start and stop


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if _HERE in Path(str(item.fspath)).resolve().parents:
            item.add_marker(pytest.mark.slow)
