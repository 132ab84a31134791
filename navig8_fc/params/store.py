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
half-written file. A corrupt or unreadable file is reported (`LoadResult.reason`) and left where it is,
so nothing is destroyed before a person has looked at it; the next successful save replaces it.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import NamedTuple

FORMAT_NAME = "navig8-fc-params"
FORMAT_VERSION = 1


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
        """Stored values by name. Missing or corrupt file -> ({}, reason); bad entries are skipped with a reason."""
        try:
            text = self._path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return LoadResult({}, f"no parameter file at {self._path}")
        except OSError as exc:
            return LoadResult({}, f"cannot read parameter file {self._path}: {exc}")
        except UnicodeDecodeError as exc:
            return LoadResult({}, f"parameter file {self._path} is corrupt: {exc}")
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            return LoadResult({}, f"parameter file {self._path} is corrupt: {exc}")
        if not isinstance(doc, dict) or doc.get("format") != FORMAT_NAME:
            return LoadResult({}, f"parameter file {self._path} is not a {FORMAT_NAME} file")
        version = doc.get("version")
        if version != FORMAT_VERSION:
            return LoadResult({}, f"parameter file {self._path} has version {version!r}, expected {FORMAT_VERSION}")
        params = doc.get("params")
        if not isinstance(params, dict):
            return LoadResult({}, f"parameter file {self._path} has no 'params' object")
        values: dict[str, float] = {}
        bad: list[str] = []
        for name, value in params.items():
            # bool is an int subclass in Python; a stored true/false is not a parameter value.
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                bad.append(str(name))
                continue
            values[str(name)] = value
        reason = f"skipped non-numeric entries in {self._path}: {', '.join(sorted(bad))}" if bad else None
        return LoadResult(values, reason)

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
