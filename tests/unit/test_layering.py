"""Pure core, thin shell, one direction of imports (AST walks of every module, function-level imports included):
- navig8_fc/core, navig8_fc/flight, navig8_fc/modes (and the pure parameter registry) import no I/O libraries and
  call no print/open/input;
- the FlightStack, modes, the GCS protocol pieces and GcsService import no shell module (GcsService depends on
  VehicleState, VehicleCommands and an Outbox, never on the process);
- navig8_fc imports nothing from sim_bridge (the bridge may import the FC's pure model, not the other way)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FC = ROOT / "navig8_fc"
FORBIDDEN = {
    "socket", "select", "selectors", "asyncio", "threading", "multiprocessing", "subprocess",
    "time", "datetime", "pymavlink", "mcap", "logging", "signal", "urllib", "http", "random",
}
FORBIDDEN_CALLS = {"print", "open", "input"}


def _modules(folder: Path):
    return sorted(p for p in folder.rglob("*.py"))


def _package(path: Path) -> str:
    return ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1]) if path.is_relative_to(ROOT) else ""


def _imported(path: Path, pkg: str | None = None, names: bool = True) -> list[str]:
    """Every module an import statement in `path` names (relative imports resolved against `pkg`, by default the
    package the file sits in); with `names`, also pkg.name for each `from pkg import name` (it may be a module)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    pkg = _package(path) if pkg is None else pkg
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.rsplit(".", node.level - 1)[0] if node.level > 1 else pkg
                mod = f"{base}.{node.module}" if node.module else base
            else:
                mod = node.module or ""
            out.append(mod)
            if names:
                out += [f"{mod}.{a.name}" for a in node.names]
    return out


def _violations(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    bad = [m for m in _imported(path, names=False) if m.split(".")[0] in FORBIDDEN]
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in FORBIDDEN_CALLS:
            bad.append(f"{node.func.id}() at line {node.lineno}")
    return bad


def _rel(p: Path) -> str:
    return str(p.relative_to(ROOT))


def test_core_flight_and_modes_have_no_io() -> None:
    files = (_modules(FC / "core") + _modules(FC / "flight") + _modules(FC / "modes")
             + [FC / "params" / "registry.py"]
             + [FC / "mission" / f for f in ("plan.py", "geo.py", "executor.py")])
    assert len(files) >= 4 and any(p.parent.name == "flight" for p in files)
    problems = {_rel(p): v for p in files if (v := _violations(p))}
    assert not problems, f"I/O in the pure code: {problems}"


def test_stack_modes_gcs_and_gcs_service_import_no_shell_module() -> None:
    files = (_modules(FC / "flight") + _modules(FC / "modes") + _modules(FC / "gcs") + _modules(FC / "mission")
             + [FC / "shell" / "gcs_service.py"])
    problems = {_rel(p): bad for p in files
                if (bad := [m for m in _imported(p) if m.startswith("navig8_fc.shell")])}
    assert not problems, f"a pure piece (or GcsService) imports the shell: {problems}"


def test_navig8_fc_imports_nothing_from_sim_bridge() -> None:
    files = _modules(FC)
    assert len(files) > 30
    problems = {_rel(p): bad for p in files if (bad := [m for m in _imported(p) if m.split(".")[0] == "sim_bridge"])}
    assert not problems, f"navig8_fc imports the bridge: {problems}"


def test_checker_catches_io(tmp_path: Path) -> None:
    p = tmp_path / "m.py"
    p.write_text("import socket\nfrom pymavlink import mavutil\nprint('x')\n")
    assert len(_violations(p)) == 3


def test_import_walk_sees_deferred_and_type_checking_imports(tmp_path: Path) -> None:
    """The walk covers imports inside functions and `if TYPE_CHECKING:` blocks (both were ways in before)."""
    p = tmp_path / "probe.py"
    p.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from navig8_fc.shell import fc_process\n"
                 "def f():\n    from sim_bridge.scenario import load_scenario\n    from . import mcap_log\n")
    got = _imported(p, pkg="navig8_fc.shell")
    assert {"navig8_fc.shell.fc_process", "sim_bridge.scenario", "navig8_fc.shell.mcap_log"} <= set(got), got
