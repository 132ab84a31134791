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


def pytest_addoption(parser: pytest.Parser) -> None:
    """Point the interop tests (tests/sitl/test_hil_interop.py) at an FC running elsewhere (docs/hil.md)."""
    g = parser.getgroup("hil", "interop tests against any FC, by connection string (docs/hil.md)")
    g.addoption("--fc-gcs", default=None, metavar="CONN",
                help="how a GCS reaches the FC's GCS link: udpin:0.0.0.0:14550 (the FC sends there), "
                     "udpout:HOST:18570, tcp:HOST:5760, serial:/dev/ttyUSB1:57600; unset: start the local pair")
    g.addoption("--fc-api", default=None, metavar="CONN", help="the same for the API link (udpin:0.0.0.0:14540)")
    g.addoption("--bridge", default=None, metavar="DESC",
                help="the simulator behind the FC (free text for the report, e.g. its connection string); 'none': "
                     "no simulator (a board on the bench): the flight tests skip")
    g.addoption("--fc-sysid", type=int, default=1, help="the FC's system id (default 1)")
