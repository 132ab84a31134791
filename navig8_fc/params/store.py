"""Parameter persistence: one JSON file per vehicle instance, written atomically.

This is the persistence shell of the registry (navig8_fc.params.registry): the only parameter code that
touches files. The registry stays pure; the MAVLink parameter protocol (navig8_fc.gcs.params) calls
`save` after an accepted PARAM_SET and `load` for MAV_CMD_PREFLIGHT_STORAGE(read); the process shell
calls `load` at startup unless told to start from defaults.

File format (version 1)::

    {"format": "navig8-fc-params", "version": 1, "params": {"INDI_K_MIN": 0.6, "CKF_MODE": 2}}

Only values are stored, never definitions: names, order, types and limits come from params/fc_params.yaml
at boot, and the registry validates every stored value again when it is loaded (a stored value that the
current definitions refuse is reported, not applied).

Atomic write: the JSON goes to a temporary file in the same directory, is flushed and fsync'ed, then
os.replace()d over the target (atomic on POSIX and Windows), and the directory is fsync'ed so the rename
itself survives a power cut. A crash at any point leaves either the old file or the new one, never a
half-written file.

Bounded reading: a stored file is at most MAX_FILE_BYTES and MAX_DEPTH deep (the format is 2 deep), checked
before the JSON parser runs, so a hostile file (200,000 `[`) cannot exhaust the parser's recursion; NaN/Infinity
literals are refused by the parser itself. A file that cannot be used as a whole (unreadable, a directory,
garbage, truncated, the wrong format, a non-finite or non-numeric entry) gives no values and a reason; the
caller (gcs.params.ParamProtocol.load_stored) then starts from the defaults, reports the reason and moves the
file aside with `set_aside` (`<name>.rejected-<n>`), so nothing is destroyed before a person has looked at it and
the next save does not silently replace it.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, NamedTuple

FORMAT_NAME = "navig8-fc-params"
FORMAT_VERSION = 1
MAX_FILE_BYTES = 64 * 1024  # ~100 bytes per stored value: room for every parameter many times over
MAX_DEPTH = 4  # nesting of [ and { (the format needs 2)


class LoadResult(NamedTuple):
    """Stored values (empty when there is nothing usable) and why, when something was not usable."""

    values: dict[str, float]
    reason: str | None


def default_state_path(state_dir: str | Path, instance: int, stem: str = "fc_params") -> Path:
    """Where instance N keeps its parameters: `<state_dir>/fc_params_<N>.json` (one file per vehicle); other
    per-instance state (the mission plans: stem "fc_mission") sits beside it."""
    if instance < 0:
        raise ValueError(f"instance must be >= 0, got {instance}")
    return Path(state_dir) / f"{stem}_{int(instance)}.json"


def parse_parm_text(text: str, source: str = "<text>") -> dict[str, float]:
    """A parameter set in ArduPilot's / MAVProxy's `.parm` format (what MAVProxy's `param load` and `param save`
    read and write): one `NAME VALUE` (or `NAME,VALUE`) per line, `#` starts a comment. Names are not checked here
    (the registry does that when the values are applied); a malformed line, a non-finite value or a name given
    twice raises ValueError naming the line."""
    values: dict[str, float] = {}
    for n, line in enumerate(text.splitlines(), 1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        parts = body.replace(",", " ").split()
        if len(parts) != 2:
            raise ValueError(f"{source}:{n}: expected 'NAME VALUE', got {line.strip()!r}")
        name, raw = parts
        try:
            value = float(raw)
        except ValueError:
            raise ValueError(f"{source}:{n}: {name}: {raw!r} is not a number") from None
        if not math.isfinite(value):
            raise ValueError(f"{source}:{n}: {name}: {raw!r} is not finite")
        if name in values:
            raise ValueError(f"{source}:{n}: {name} is given twice")
        values[name] = value
    return values


def read_parm_file(path: str | Path) -> dict[str, float]:
    """parse_parm_text of a file of at most MAX_FILE_BYTES (UTF-8); ValueError/OSError with the reason."""
    p = Path(path)
    with p.open("rb") as f:
        raw = f.read(MAX_FILE_BYTES + 1)
    if len(raw) > MAX_FILE_BYTES:
        raise ValueError(f"{p}: larger than {MAX_FILE_BYTES} bytes")
    return parse_parm_text(raw.decode("utf-8"), str(p))


def parse_set_item(item: str) -> tuple[str, float]:
    """One command-line `NAME=VALUE` (`--set`); ValueError naming the item when it is not that."""
    name, sep, value = item.partition("=")
    try:
        number = float(value)
    except ValueError:
        sep = ""
    if not sep or not name.strip():
        raise ValueError(f"--set expects NAME=VALUE with a number, got {item!r}")
    return name.strip(), number


def read_overrides(files: Iterable[str | Path] = (), set_items: Iterable[str] = ()) -> dict[str, float]:
    """The parameter values of `--params FILE ...` (in order) and then `--set NAME=VALUE ...` (which win), as the
    command-line tools take them; ValueError (or OSError) naming the file or item at fault. Names and values are
    checked by the registry when applied."""
    out: dict[str, float] = {}
    for f in files:
        try:
            out.update(read_parm_file(f))
        except (OSError, ValueError) as exc:
            raise ValueError(f"--params {f}: {exc}") from None
    out.update(parse_set_item(it) for it in set_items)
    return out


class ParamStore:
    """Load and save the parameter values of one vehicle instance."""

    def __init__(self, path: str | Path) -> None:
        self._path = Path(path)

    @property
    def path(self) -> Path:
        return self._path

    def exists(self) -> bool:
        return self._path.is_file()

    def load(self) -> LoadResult:
        """Stored values by name. Missing or unusable file -> ({}, reason): a file is used whole or not at all
        (module docstring)."""
        path = self._path
        try:
            if path.exists() and not path.is_file():
                return LoadResult({}, f"parameter file {path} is not a regular file")
            with path.open("rb") as f:
                raw = f.read(MAX_FILE_BYTES + 1)
        except FileNotFoundError:
            return LoadResult({}, f"no parameter file at {path}")
        except OSError as exc:
            return LoadResult({}, f"cannot read parameter file {path}: {exc}")
        if len(raw) > MAX_FILE_BYTES:
            return LoadResult({}, f"parameter file {path} is corrupt: larger than {MAX_FILE_BYTES} bytes")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            return LoadResult({}, f"parameter file {path} is corrupt: {exc}")
        depth = json_depth(text)
        if depth > MAX_DEPTH:
            return LoadResult({}, f"parameter file {path} is corrupt: nested {depth} deep (at most {MAX_DEPTH})")
        try:
            doc = json.loads(text, parse_constant=_refuse_constant, object_pairs_hook=_refuse_duplicates)
        except (json.JSONDecodeError, ValueError, RecursionError) as exc:
            return LoadResult({}, f"parameter file {path} is corrupt: {exc}")
        if not isinstance(doc, dict) or doc.get("format") != FORMAT_NAME:
            return LoadResult({}, f"parameter file {path} is not a {FORMAT_NAME} file")
        version = doc.get("version")
        if version != FORMAT_VERSION:
            return LoadResult({}, f"parameter file {path} has version {version!r}, expected {FORMAT_VERSION}")
        params = doc.get("params")
        if not isinstance(params, dict):
            return LoadResult({}, f"parameter file {path} has no 'params' object")
        values: dict[str, float] = {}
        bad: list[str] = []
        for name, value in params.items():
            # bool is an int subclass in Python; a stored true/false is not a parameter value.
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                bad.append(str(name))
                continue
            values[str(name)] = value
        if bad:
            return LoadResult({}, f"parameter file {path} is corrupt: non-numeric entries {', '.join(sorted(bad))}")
        return LoadResult(values, None)

    def set_aside(self) -> Path | None:
        """Move an unusable file out of the way (`<name>.rejected-<n>`, the first free n) and return where it
        went; None when there is nothing at the path or it cannot be moved (the reason is already reported)."""
        if not (self._path.exists() or self._path.is_symlink()):
            return None
        for n in range(1, 1000):
            dest = self._path.with_name(f"{self._path.name}.rejected-{n}")
            if not (dest.exists() or dest.is_symlink()):
                try:
                    os.replace(self._path, dest)
                except OSError:
                    return None
                return dest
        return None

    def save(self, values: Mapping[str, float]) -> None:
        """Write `values` atomically (temp file + fsync + os.replace). Raises OSError/ValueError on failure."""
        clean: dict[str, float | int] = {}
        for name, value in values.items():
            v = value if isinstance(value, int) and not isinstance(value, bool) else float(value)
            if not math.isfinite(v):
                raise ValueError(f"{name}: refusing to store non-finite value {v}")
            clean[str(name)] = v
        doc = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "params": dict(sorted(clean.items()))}
        write_atomic(self._path, (json.dumps(doc, indent=2, allow_nan=False) + "\n").encode("utf-8"))


def json_depth(text: str) -> int:
    """The deepest nesting of [ and { in a JSON text (brackets inside strings do not count); a linear scan,
    so checking it costs no recursion whatever the input."""
    depth = deepest = 0
    in_string = escaped = False
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth -= 1
    return deepest


def _refuse_constant(name: str) -> float:
    raise ValueError(f"{name} is not a parameter value")


def _refuse_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object whose key repeats is refused (json's default keeps the last silently: a hand-edited file
    with a parameter twice would fly a value nobody chose knowingly)."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"{key!r} is given twice")
        out[key] = value
    return out


def write_atomic(path: Path, data: bytes) -> None:
    """Replace `path` with `data` atomically (module docstring: temp file + fsync + os.replace + directory
    fsync). The parameter and mission stores both write this way. Raises OSError on failure."""
    directory = path.parent
    directory.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp_name, path)
    except BaseException:
        try:
            os.unlink(tmp_name)
        except FileNotFoundError:
            pass
        raise
    _fsync_dir(directory)


def _fsync_dir(directory: Path) -> None:
    """Make the rename durable. Not every platform can open a directory (Windows): best effort there."""
    try:
        dfd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dfd)
    except OSError:
        pass
    finally:
        os.close(dfd)
