"""Pure core, thin shell, one direction of imports (AST walks of every module, function-level imports included):
- navig8_fc/core, navig8_fc/flight, navig8_fc/modes (and the pure parameter registry) import no I/O libraries,
  call no print/open/input and read or write no file (a path's read_text/open, np.load, json.load, ...; the reads
  left are listed by name);
- the FlightStack, modes, the GCS protocol pieces and GcsService import no shell module but GcsService's parts (its
  telemetry, its floor worker: GcsService depends on VehicleState, VehicleCommands and an Outbox, never on the
  process);
- navig8_fc imports nothing from sim_bridge (the bridge may import the FC's pure model, not the other way);
- navig8_fc/links (transports, MAVLink link, signing, sim guard) names nothing of the FC but itself and the dialect,
  codec and seam, and reaches (through everything it imports) no shell, GCS, flight, modes, mission or params
  module, nor sim_bridge or the tools;
- sim_bridge reaches no module of the FC's shell, directly or through anything it imports (it shares the links
  with the FC instead: docs/architecture.md);
- mission < modes < flight < gcs: each imports only the folders before it (no folder-level loops);
- no module of navig8_fc, sim_bridge, the tools or the tests reads another object's private (`_`) member: state
  leaves a component only through what it publishes (named lists hold the reads left)."""

from __future__ import annotations

import ast
import functools
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FC = ROOT / "navig8_fc"
LINKS = FC / "links"
BRIDGE = ROOT / "sim_bridge"
FIRST_PARTY = {"navig8_fc": FC, "sim_bridge": BRIDGE, "navig8_tools": ROOT / "tools", "navig8_params": ROOT / "params"}
# what navig8_fc/links may name of the FC: itself and the MAVLink pieces below it (not mavlink.px4sim: it takes
# the core's actuator model and the mission's geodesy)
LINKS_MAY_NAME = ("navig8_fc.links", "navig8_fc.mavlink.codec", "navig8_fc.mavlink.dialect", "navig8_fc.mavlink.seam")
LINKS_THIRD_PARTY = {"pymavlink", "serial", "numpy"}
# what the links must never reach. The core is not listed: navig8_fc.mavlink.seam's StepBundle.fc_sensors builds
# the controller's input with a function-level import of navig8_fc.core.controller (the FC calls it, the bridge
# never does); the links themselves name no core module (LINKS_MAY_NAME).
ABOVE_LINKS = ("navig8_fc.shell", "navig8_fc.gcs", "navig8_fc.flight", "navig8_fc.modes", "navig8_fc.mission",
               "navig8_fc.params", "navig8_fc.logrecords", "navig8_fc.viz", "sim_bridge", "navig8_tools",
               "navig8_params")
FORBIDDEN = {
    "socket", "select", "selectors", "asyncio", "threading", "multiprocessing", "subprocess",
    "time", "datetime", "pymavlink", "mcap", "logging", "signal", "urllib", "http", "random",
    "os", "io", "shutil", "glob", "tempfile", "pickle", "shelve", "mmap", "sqlite3",
}
FORBIDDEN_CALLS = {"print", "open", "input"}
# File reads and writes by call: a path's or a resource's methods, numpy's and json's file functions. A parser (yaml,
# json.loads) is no I/O; the read that gave it the text is (`open`, `read_text`).
FILE_METHODS = {"read_text", "read_bytes", "write_text", "write_bytes", "open", "tofile"}
FILE_FUNCTIONS = {
    **dict.fromkeys(("np", "numpy"), {"load", "loadtxt", "genfromtxt", "fromfile", "memmap", "save", "savez",
                                      "savez_compressed", "savetxt"}),
    "json": {"load", "dump"},
}
# File reads left in the pure code, each "file:line: call" when listed (matched on file and call). The vehicle file is
# the core's (VehicleConfig.load, the work on navig8_fc/core moves it); the scenario file is read in flight.script
# because sim_bridge/world.py and sim_bridge/scenario.py import read_scenario_file from there (docs/architecture.md,
# "Edges left"); the parameter definitions are read by ParamRegistry.definitions_text (from_defaults).
FILE_READS_LEFT = (
    "navig8_fc/core/vehicle.py:110: read_text()",
    "navig8_fc/core/vehicle.py:112: read_text()",
    "navig8_fc/flight/script.py:206: read_text()",
    "navig8_fc/flight/script.py:211: read_text()",
    "navig8_fc/params/registry.py:354: read_text()",
    "navig8_fc/params/registry.py:355: read_text()",
)


THIRD_PARTY = ROOT / "tests" / "clients" / "mavsdk_examples"  # MAVSDK-Python's examples, shipped unmodified


def _modules(folder: Path):
    return sorted(p for p in folder.rglob("*.py") if not p.is_relative_to(THIRD_PARTY))


def _package(path: Path) -> str:
    return ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1]) if path.is_relative_to(ROOT) else ""


@functools.cache
def _parsed(path: Path, text: str) -> ast.Module:
    """A file's syntax tree, parsed once a process for its text (the walks below read trees, never change them):
    the reach walks from every module parse the modules they share again and again."""
    return ast.parse(text, filename=str(path))


def _imported(path: Path, pkg: str | None = None, names: bool = True) -> list[str]:
    """Every module an import statement in `path` names (relative imports resolved against `pkg`, by default the
    package the file sits in); with `names`, also pkg.name for each `from pkg import name` (it may be a module)."""
    return list(_imported_in(path, path.read_text(), _package(path) if pkg is None else pkg, names))


@functools.cache
def _imported_in(path: Path, text: str, pkg: str, names: bool) -> tuple[str, ...]:
    """_imported's walk, once a process for a file's text (the reach walks ask for the modules they share again and
    again)."""
    tree = _parsed(path, text)
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
    return tuple(out)


def _io_calls(path: Path) -> list[tuple[int, str]]:
    """(line, call) of every print/open/input and every file read or write by call (FILE_METHODS, FILE_FUNCTIONS)."""
    out = []
    for node in ast.walk(_parsed(path, path.read_text())):
        if not isinstance(node, ast.Call):
            continue
        fn = node.func
        if isinstance(fn, ast.Name) and fn.id in FORBIDDEN_CALLS:
            out.append((node.lineno, f"{fn.id}()"))
        elif isinstance(fn, ast.Attribute):
            if isinstance(fn.value, ast.Name) and fn.attr in FILE_FUNCTIONS.get(fn.value.id, ()):
                out.append((node.lineno, f"{fn.value.id}.{fn.attr}()"))
            elif fn.attr in FILE_METHODS:
                out.append((node.lineno, f"{fn.attr}()"))
    return sorted(out)


def _violations(path: Path, allowed: Counter[str] | None = None) -> list[str]:
    """I/O imports and calls in `path`; `allowed`: calls (as _io_calls names them) to let through, with counts."""
    bad = [m for m in _imported(path, names=False) if m.split(".")[0] in FORBIDDEN]
    calls = _io_calls(path)
    extra = Counter(c for _, c in calls) - (allowed or Counter())
    for line, call in reversed(calls):
        if extra[call] > 0:
            extra[call] -= 1
            bad.append(f"{call} at line {line}")
    return bad


def _rel(p: Path) -> str:
    return str(p.relative_to(ROOT))


def _under(mod: str, prefixes: tuple[str, ...]) -> bool:
    return any(mod == p or mod.startswith(p + ".") for p in prefixes)


def _module_file(mod: str) -> Path | None:
    """The file of a first-party module or package (None: not ours, or `pkg.name` naming an object)."""
    top, *rest = mod.split(".")
    base = FIRST_PARTY.get(top)
    if base is None:
        return None
    p = base.joinpath(*rest)
    return next((c for c in (p.with_suffix(".py"), p / "__init__.py") if c.is_file()), None)


def _module_name(path: Path) -> str:
    for top, base in FIRST_PARTY.items():
        if path.is_relative_to(base):
            parts = path.relative_to(base).with_suffix("").parts
            return ".".join((top, *(parts[:-1] if parts[-1] == "__init__" else parts)))
    raise ValueError(path)


@functools.cache
def _reached(path: Path) -> frozenset[str]:
    """Every first-party module importing `path` can load: its imports (function-level ones included), the
    packages around them (their __init__ runs first), and theirs in turn."""
    seen: dict[str, Path] = {}
    todo = [path]
    while todo:
        p = todo.pop()
        name = _module_name(p)
        if name in seen:
            continue
        seen[name] = p
        for mod in _imported(p):
            parts = mod.split(".")
            todo += [f for i in range(1, len(parts) + 1) if (f := _module_file(".".join(parts[:i]))) is not None]
    return frozenset(seen)


def test_core_flight_and_modes_have_no_io() -> None:
    files = (_modules(FC / "core") + _modules(FC / "flight") + _modules(FC / "modes")
             + [FC / "params" / "registry.py"]
             + [FC / "mission" / f for f in ("plan.py", "geo.py", "executor.py")])
    assert len(files) >= 4 and any(p.parent.name == "flight" for p in files)
    left: dict[str, Counter[str]] = {}
    for e in FILE_READS_LEFT:
        where, call = _entry_key(e)
        left.setdefault(where, Counter())[call] += 1
    problems = {_rel(p): v for p in files if (v := _violations(p, left.get(_rel(p))))}
    assert not problems, f"I/O in the pure code (a file read belongs in the shell or the tools): {problems}"
    found = {_rel(p): Counter(c for _, c in _io_calls(p)) for p in files}
    stale = [e for where, calls in left.items() for call, n in calls.items()
             if found.get(where, Counter())[call] < n for e in FILE_READS_LEFT if _entry_key(e) == (where, call)]
    assert not stale, f"listed file reads that are gone (take them off FILE_READS_LEFT): {stale}"


GCS_SERVICE_PARTS = ("telemetry_service", "floor_worker", "job_process")  # shell modules GcsService is built from


def test_stack_modes_gcs_and_gcs_service_import_no_shell_module() -> None:
    files = (_modules(FC / "flight") + _modules(FC / "modes") + _modules(FC / "gcs") + _modules(FC / "mission")
             + [FC / "shell" / f"{m}.py" for m in ("gcs_service", *GCS_SERVICE_PARTS)])
    # GcsService is built from its parts (its telemetry, its floor worker), never from the process's modules
    problems = {_rel(p): bad for p in files
                if (bad := [m for m in _imported(p) if m.startswith("navig8_fc.shell")
                            and not m.startswith(tuple(f"navig8_fc.shell.{p}" for p in GCS_SERVICE_PARTS))])}
    assert not problems, f"a pure piece (or GcsService) imports the shell: {problems}"


# The deciding and serving folders, lowest first: each may import the ones before it, never one after it, so no two
# of them import each other (the GCS adapts MAVLink to the flight stack's records; the flight stack knows no MAVLink
# service; missions are plans the modes and the stack fly). docs/architecture.md.
FOLDER_ORDER = ("mission", "modes", "flight", "gcs")


def test_the_deciding_folders_import_only_downwards() -> None:
    problems = {}
    for i, lower in enumerate(FOLDER_ORDER):
        above = tuple(f"navig8_fc.{name}" for name in FOLDER_ORDER[i + 1:])
        for p in _modules(FC / lower):
            if bad := sorted({m for m in _imported(p, names=False) if _under(m, above)}):
                problems[_rel(p)] = bad
    assert not problems, f"an import runs upwards ({' < '.join(FOLDER_ORDER)}): {problems}"


def test_navig8_fc_imports_nothing_from_sim_bridge() -> None:
    files = _modules(FC)
    assert len(files) > 30
    problems = {_rel(p): bad for p in files if (bad := [m for m in _imported(p) if m.split(".")[0] == "sim_bridge"])}
    assert not problems, f"navig8_fc imports the bridge: {problems}"


def test_links_name_only_themselves_and_the_mavlink_pieces() -> None:
    files = _modules(LINKS)
    assert {"transport.py", "mavlink_link.py", "signing.py", "sim_guard.py"} <= {p.name for p in files}
    problems = {}
    for p in files:
        mods = _imported(p, names=False)
        bad = [m for m in mods if m.split(".")[0] in FIRST_PARTY and m != "navig8_fc" and m != "navig8_fc.mavlink"
               and not _under(m, LINKS_MAY_NAME)]
        bad += [m for m in mods if (top := m.split(".")[0]) not in FIRST_PARTY and top not in LINKS_THIRD_PARTY
                and top not in sys.stdlib_module_names and top != "__future__"]
        if bad:
            problems[_rel(p)] = bad
    assert not problems, f"navig8_fc/links imports what sits above it (or an unexpected library): {problems}"


def test_links_reach_nothing_above_them() -> None:
    problems = {_rel(p): sorted(m for m in _reached(p) if _under(m, ABOVE_LINKS)) for p in _modules(LINKS)}
    problems = {k: v for k, v in problems.items() if v}
    assert not problems, f"navig8_fc/links reaches a layer above it: {problems}"


def test_sim_bridge_reaches_nothing_of_the_fc_shell() -> None:
    files = _modules(BRIDGE)
    assert len(files) > 5
    reached = {_rel(p): _reached(p) for p in files}
    assert "navig8_fc.links.transport" in reached["sim_bridge/bridge.py"]  # the walk follows the bridge's links
    problems = {k: sorted(m for m in v if _under(m, ("navig8_fc.shell",))) for k, v in reached.items()}
    problems = {k: v for k, v in problems.items() if v}
    assert not problems, f"sim_bridge reaches the FC's shell (share navig8_fc/links instead): {problems}"


def test_reach_walk_follows_imports_through_other_modules(tmp_path: Path) -> None:
    """A module that reaches the shell only through another module (or a package's __init__) is caught."""
    p = tmp_path / "probe.py"
    p.write_text("def f():\n    from navig8_fc.links import sim_guard\n    import navig8_fc.shell.fc_process\n")
    # the probe sits outside the repository: walk from what it names
    reached = set().union(*(_reached(f) for m in _imported(p) if (f := _module_file(m)) is not None))
    assert {"navig8_fc.links.sim_guard", "navig8_fc.mavlink.seam", "navig8_fc.shell.fc_process",
            "navig8_fc.shell.mcap_log", "navig8_fc.links.transport"} <= reached, sorted(reached)


def test_checker_catches_io(tmp_path: Path) -> None:
    p = tmp_path / "m.py"
    p.write_text("import socket\nfrom pymavlink import mavutil\nprint('x')\n")
    assert len(_violations(p)) == 3


def test_checker_catches_file_reads(tmp_path: Path) -> None:
    p = tmp_path / "m.py"
    p.write_text("import json\nimport numpy as np\nimport yaml\nfrom importlib.resources import files\n"
                 "from pathlib import Path\n"
                 "def f(path, fh):\n    a = yaml.safe_load(Path(path).read_text())\n    b = np.load(path)\n"
                 "    c = json.load(fh)\n    d = (files('navig8_params') / 'x.yaml').read_bytes()\n"
                 "    with Path(path).open() as g:\n        e = yaml.safe_load(g)\n    yaml.safe_load(open(path))\n"
                 "    return yaml.safe_load('a: 1'), json.loads('{}'), np.asarray(a)\n")
    assert [c for _, c in _io_calls(p)] == ["read_text()", "np.load()", "json.load()", "read_bytes()", "open()",
                                            "open()"]
    assert _violations(p) == ["open() at line 13", "open() at line 11", "read_bytes() at line 10",
                              "json.load() at line 9", "np.load() at line 8", "read_text() at line 7"]
    # an allowed call is let through as many times as listed, no more
    assert _violations(p, Counter({"open()": 1, "read_text()": 1})) == [
        "open() at line 13", "read_bytes() at line 10", "json.load() at line 9", "np.load() at line 8"]


def test_import_walk_sees_deferred_and_type_checking_imports(tmp_path: Path) -> None:
    """The walk covers imports inside functions and `if TYPE_CHECKING:` blocks (both were ways in before)."""
    p = tmp_path / "probe.py"
    p.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from navig8_fc.shell import fc_process\n"
                 "def f():\n    from sim_bridge.scenario import load_scenario\n    from . import mcap_log\n")
    got = _imported(p, pkg="navig8_fc.shell")
    assert {"navig8_fc.shell.fc_process", "sim_bridge.scenario", "navig8_fc.shell.mcap_log"} <= set(got), got


# --- state leaves a component only through what it publishes ----------------------------------------------------
# A module reads no other object's private (`_name`) member: not `obj._x`, not `getattr(obj, "_x")`, not
# `from module import _x`. Its own (`self._x`, `cls._x`, `super()._x`) are its business; so are a package's private
# modules to the modules of that package (`from pkg import _private_module` inside pkg). Other libraries'
# modules imported as such may publish underscore names (`os._exit`), and namedtuples' API is underscored.
SCANNED = (FC, BRIDGE, ROOT / "tools", ROOT / "tests")
NAMEDTUPLE_API = {"_asdict", "_replace", "_fields", "_make", "_field_defaults"}
ATTR_FUNCTIONS = {"getattr", "hasattr", "setattr", "delattr"}
TEST_MODULES = frozenset(p.stem for p in (ROOT / "tests").rglob("*.py"))


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _own(node: ast.expr) -> bool:
    """`self`, `cls` or `super()`: the object's own members."""
    return ((isinstance(node, ast.Name) and node.id in ("self", "cls"))
            or (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "super"))


def _private_reads(path: Path, pkg: str | None = None) -> list[tuple[int, str]]:
    """(line, expression) of every read of another object's private member in `path` (module docstring above)."""
    return list(_private_reads_in(path, path.read_text(), _package(path) if pkg is None else pkg))


@functools.cache
def _private_reads_in(path: Path, text: str, pkg: str) -> tuple[tuple[int, str], ...]:
    """_private_reads's walk, once a process for a file's text (two tests read the whole tree's)."""
    tree = _parsed(path, text)
    libraries = {(a.asname or a.name).split(".")[0] for node in ast.walk(tree) if isinstance(node, ast.Import)
                 for a in node.names if (top := a.name.split(".")[0]) not in FIRST_PARTY and top not in TEST_MODULES}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = pkg.rsplit(".", node.level - 1)[0] if node.level > 1 else pkg
            mod = (f"{base}.{node.module}" if node.module else base) if node.level else node.module or ""
            for a in node.names:
                inside = pkg == mod or pkg.startswith(mod + ".")  # a private module of the importer's package
                if _is_private(a.name) and not (inside and _module_file(f"{mod}.{a.name}") is not None):
                    out.append((node.lineno, f"from {mod} import {a.name}"))
        elif isinstance(node, ast.Attribute) and _is_private(node.attr) and node.attr not in NAMEDTUPLE_API:
            v = node.value
            if not _own(v) and not (isinstance(v, ast.Name) and v.id in libraries):
                out.append((node.lineno, ast.unparse(node)))
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ATTR_FUNCTIONS
              and len(node.args) >= 2 and isinstance(node.args[1], ast.Constant)
              and isinstance(node.args[1].value, str) and _is_private(node.args[1].value) and not _own(node.args[0])):
            out.append((node.lineno, f"{node.func.id}({ast.unparse(node.args[0])}, {node.args[1].value!r})"))
    return tuple(sorted(out))


# Reads of privates left to the work on navig8_fc/core and sim_bridge (it publishes what these need), each as
# "file:line: expression" when listed. Matched on file and expression, so a moved line still matches; an entry whose
# read is gone fails test_private_read_allow_lists_hold_no_stale_entry: the lists only shrink.
PRIVATE_READS_LEFT_IN_CORE_AND_BRIDGE = (
    "navig8_fc/core/controller.py:50: from navig8_fc.core.outer_loop import _outer_loop_arrays",
    "navig8_fc/core/controller.py:425: self._indi._step",
    "navig8_fc/core/controller.py:510: core._model",
    "navig8_fc/core/controller.py:523: core._model",
    "navig8_fc/core/jit.py:72: disp._cache",  # numba's dispatcher: the dependent cache replaces its FunctionCache
    "navig8_fc/core/lms.py:121: kalman._regressor",
    "tests/sitl/test_fc_param_apply.py:34: core._outer_cfg",
    "tests/unit/test_command_shaping.py:174: core._shape_sp",
    "tests/unit/test_command_shaping.py:175: core._shape_ff",
    "tests/unit/test_varying_k.py:127: ly._svec_maps",
    "tests/unit/test_varying_k.py:128: ly._solve_sdp",
)
# Other libraries' privates where the library offers no public way, each with why.
PRIVATE_READS_OF_LIBRARIES = {
    "tests/sitl/test_sitl_mavsdk.py:25: drone._stop_mavsdk_server":
        "mavsdk_grpc.System starts its mavsdk_server and has no public stop (it stops it in __del__ or at exit)",
    "tests/sitl/test_sitl_mavsdk_guided.py:102: drone._stop_mavsdk_server":
        "mavsdk_grpc.System starts its mavsdk_server and has no public stop (it stops it in __del__ or at exit)",
}


def _entry_key(entry: str) -> tuple[str, str]:
    where, expr = entry.split(": ", 1)
    return where.rsplit(":", 1)[0], expr


def _private_reads_found() -> dict[tuple[str, str], list[int]]:
    found: dict[tuple[str, str], list[int]] = {}
    for folder in SCANNED:
        for p in _modules(folder):
            for line, expr in _private_reads(p):
                found.setdefault((_rel(p), expr), []).append(line)
    return found


def _private_reads_allowed() -> Counter[tuple[str, str]]:
    return Counter(_entry_key(e) for e in (*PRIVATE_READS_LEFT_IN_CORE_AND_BRIDGE, *PRIVATE_READS_OF_LIBRARIES))


def test_no_module_reads_another_objects_private_member() -> None:
    """navig8_fc, sim_bridge, the tools and the tests read what an object publishes (a property, a status record, a
    public function), never its `_` members: state leaves a component only through what it publishes."""
    found = _private_reads_found()
    assert len(found) > 10  # the walk sees the listed reads
    extra = Counter({k: len(v) for k, v in found.items()}) - _private_reads_allowed()
    problems = [f"{f}:{found[(f, e)][-1]}: {e}" + (f" (x{n})" if n > 1 else "") for (f, e), n in sorted(extra.items())]
    assert not problems, ("a module reads another object's private member (publish what it needs: a property, a "
                          f"status field, a public function): {problems}")


def test_private_read_allow_lists_hold_no_stale_entry() -> None:
    found = _private_reads_found()
    stale = _private_reads_allowed() - Counter({k: len(v) for k, v in found.items()})
    assert not stale, f"listed private reads that are gone (take them off the list): {sorted(stale)}"
    outside = [e for e in PRIVATE_READS_LEFT_IN_CORE_AND_BRIDGE
               if not _entry_key(e)[0].startswith(("navig8_fc/core/", "sim_bridge/", "tools/", "tests/"))]
    assert not outside, f"the core/bridge list holds a read in a module the rule has no exception for: {outside}"


def test_checker_catches_private_reads(tmp_path: Path) -> None:
    p = tmp_path / "m.py"
    p.write_text("import os\nfrom navig8_fc.core import lyapunov as ly\nfrom sim_bridge._kernels import _servo_accel\n"
                 "from sim_bridge import _kernels\n"
                 "class A:\n    def f(self, other, t):\n        self._x\n        super()._y()\n        os._exit\n"
                 "        t._asdict(), self.__class__, other.__dict__\n        other._z\n"
                 "        getattr(other, '_w', None)\n        hasattr(self, '_v')\n        ly._svec_maps\n")
    assert [e for _, e in _private_reads(p)] == [
        "from sim_bridge._kernels import _servo_accel", "from sim_bridge import _kernels", "other._z",
        "getattr(other, '_w')", "ly._svec_maps"]


def test_the_bridge_loads_no_flight_controller() -> None:
    """navig8-bridge reads scenario scripts (navig8_fc.flight.script) but never loads the flight stack or the
    controller core behind it (with scipy.optimize: ~0.6 s of CPU every bridge start)."""
    import subprocess

    code = ("import sys, sim_bridge.bridge; print(sorted(m for m in ('navig8_fc.flight.stack', "
            "'navig8_fc.core.controller', 'scipy.optimize') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]", out.stdout
