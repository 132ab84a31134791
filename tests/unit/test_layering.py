"""Pure core, thin shell: navig8_fc/core (and the pure parameter registry) import no I/O libraries."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FORBIDDEN = {
    "socket", "select", "selectors", "asyncio", "threading", "multiprocessing", "subprocess",
    "time", "datetime", "pymavlink", "mcap", "logging", "signal", "urllib", "http", "random",
}
FORBIDDEN_CALLS = {"print", "open", "input"}


def _modules(folder: Path):
    return sorted(p for p in folder.rglob("*.py"))


def _violations(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            bad += [a.name for a in node.names if a.name.split(".")[0] in FORBIDDEN]
        elif isinstance(node, ast.ImportFrom) and node.module:
            if node.module.split(".")[0] in FORBIDDEN:
                bad.append(node.module)
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in FORBIDDEN_CALLS:
            bad.append(f"{node.func.id}() at line {node.lineno}")
    return bad


def test_core_has_no_io_imports() -> None:
    files = _modules(ROOT / "navig8_fc" / "core") + [ROOT / "navig8_fc" / "params" / "registry.py"]
    assert len(files) >= 2
    problems = {str(p.relative_to(ROOT)): v for p in files if (v := _violations(p))}
    assert not problems, f"I/O in the pure core: {problems}"


def test_checker_catches_io(tmp_path: Path) -> None:
    p = tmp_path / "m.py"
    p.write_text("import socket\nfrom pymavlink import mavutil\nprint('x')\n")
    assert len(_violations(p)) == 3
