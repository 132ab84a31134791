"""Every test under tests/sitl starts real processes over real UDP: they are the `slow` lane.

`make test` runs the fast lane (unit, integration) in parallel with pytest-xdist and then this lane on its own:
SITL tests pace themselves on the wall clock and start two processes each, so running them side by side on a
2-core machine would only make them slower and their timing-dependent checks flakier.
"""

from __future__ import annotations

from pathlib import Path

import pytest

_HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if _HERE in Path(str(item.fspath)).resolve().parents:
            item.add_marker(pytest.mark.slow)
