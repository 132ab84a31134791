"""Every test under tests/sitl starts real processes over real UDP: they are the `slow` lane.

`make test` runs the fast lane (unit, integration) in parallel with pytest-xdist and then this lane on its own:
SITL tests pace themselves on the wall clock and start two processes each, so running them side by side on a
2-core machine would only make them slower and their timing-dependent checks flakier.
"""

from __future__ import annotations

from pathlib import Path

import pytest

_HERE = Path(__file__).resolve().parent


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "local_only(reason): needs the local pair (its log, its processes, its "
                            "ports); skipped with the reason when pointed at an FC elsewhere (--fc-gcs)")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Every test here is slow. Pointed at an FC elsewhere (--fc-gcs, `make test-hil`), only the tests on the
    `fc` fixture (MAVLink only, docs/hil.md) run; the rest start their own processes and skip, with the reason
    their local_only marker gives."""
    elsewhere = config.getoption("--fc-gcs", default=None) is not None
    for item in items:
        if _HERE not in Path(str(item.fspath)).resolve().parents:
            continue
        item.add_marker(pytest.mark.slow)
        if elsewhere and "fc" not in getattr(item, "fixturenames", ()):
            mark = item.get_closest_marker("local_only")
            why = mark.args[0] if mark is not None and mark.args else "starts its own local processes"
            item.add_marker(pytest.mark.skip(reason=f"needs the local pair: {why}"))


@pytest.hookimpl(trylast=True)  # after tests/conftest.py's wait for numba's warm-up: the server loads its kernels
def pytest_collection_finish(session: pytest.Session) -> None:
    """A run with SITL or client tests starts its fork server now (tests/sitl/prefork.py): it imports and warms
    while the first test sets up, instead of in the first start."""
    if session.config.getoption("--fc-gcs", default=None) is not None:
        return
    dirs = (_HERE, _HERE.parent / "clients")
    if any(any(d in Path(str(it.fspath)).resolve().parents for d in dirs) for it in session.items):
        from sitl_helpers import start_fork_server

        start_fork_server()


def pytest_unconfigure(config: pytest.Config) -> None:
    import sys

    if "sitl_helpers" in sys.modules:
        sys.modules["sitl_helpers"].stop_fork_server()


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


@pytest.fixture(scope="module")
def fc(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN201
    """The FC a module's MAVLink-only tests talk to (sitl_helpers.FcTarget): --fc-gcs/--fc-api/--bridge when given
    (`make test-hil`), else one local pair for the whole module, started as the module's FC_LOCAL dict says
    (scenario, speed, fc_args; default: ground at 1x). Tests reach it with fc.session() and check the local log
    only through fc.require_local(...)."""
    from sitl_helpers import fc_target

    with fc_target(request.config, tmp_path_factory.mktemp("fc"), **getattr(request.module, "FC_LOCAL", {})) as t:
        yield t
