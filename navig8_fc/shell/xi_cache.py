"""The stability floor's workspace Xi (k_xi.workspace_xi) kept on disk between FC starts (registry.WorkspaceCache).

Every FC start's floor worker needs Xi over the workspace for the vehicle file in force before its first floor:
computing it costs ~0.3 s of CPU and loads numba and the model's kernels (~0.5 s more), on every one of the ~75 FC
starts of the SITL tests and every `navig8-sitl`. Xi is a pure function of the vehicle file and the core's code, so
it is kept under `$XDG_CACHE_HOME/navig8` (default `~/.cache/navig8`), one .npy file per key:

- the key is a SHA-256 of the vehicle file's text, the source of every module of navig8_fc/core (conservative:
  any change of the core's code misses), and the versions of Python, numpy and numba and the machine type;
- a file is written to a temporary name and renamed into place (a reader sees a whole file or none), read without
  pickles, and used only with Xi's shape and dtype and finite; anything else is a miss and Xi is computed as before;
- a directory that cannot be created or written is no error: Xi is computed, as without a cache;
- at most KEEP files stay (the newest): every change of the core's code leaves a key behind.
"""

from __future__ import annotations

import hashlib
import os
import platform
import sys
import tempfile
from dataclasses import dataclass
from importlib import metadata
from importlib.resources import files
from pathlib import Path

import numpy as np

import navig8_fc.core

PREFIX = "workspace_xi-"
KEEP = 8  # files kept in the directory (newest first): a few vehicles and checkouts side by side
CORE_DIR = Path(navig8_fc.core.__file__).parent  # the modules whose code Xi depends on (all of the core)
XI_SHAPE_TAIL = (5, 5)  # Xi's last axes (rows and columns [L, M, N, Fx, Fz]); the leading ones are the workspace's


def default_directory() -> Path:
    """$XDG_CACHE_HOME/navig8, else ~/.cache/navig8 (the XDG base directory rule)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "navig8"


def _vehicle_text(vehicle_path: str | None) -> bytes:
    if vehicle_path is None:  # VehicleConfig.load's default: the packaged vehicle file
        return (files("navig8_params") / "vehicle.yaml").read_bytes()
    return Path(vehicle_path).read_bytes()


def library_versions() -> str:
    """The interpreter, numpy and numba (Xi's kernels) and the machine type: a change of any may change Xi's floats."""
    try:
        numba = metadata.version("numba")
    except metadata.PackageNotFoundError:
        numba = "none"
    return f"python {sys.version}; numpy {np.__version__}; numba {numba}; {platform.machine()}"


def xi_key(vehicle_path: str | None, core_dir: Path = CORE_DIR) -> str:
    """What Xi depends on, hashed: the vehicle file, the core's code (core_dir's modules), the numeric libraries'
    versions."""
    h = hashlib.sha256(library_versions().encode())
    h.update(hashlib.sha256(_vehicle_text(vehicle_path)).digest())
    for src in sorted(core_dir.glob("*.py")):
        h.update(src.name.encode())
        h.update(hashlib.sha256(src.read_bytes()).digest())
    return h.hexdigest()


@dataclass(frozen=True)
class XiDiskCache:
    """registry.WorkspaceCache on disk (module docstring). Picklable: it travels to the floor worker with the
    check."""

    directory: Path

    @classmethod
    def default(cls) -> XiDiskCache:
        return cls(default_directory())

    def path(self, vehicle_path: str | None) -> Path:
        return self.directory / f"{PREFIX}{xi_key(vehicle_path)}.npy"

    def load(self, vehicle_path: str | None) -> np.ndarray | None:
        """The cached Xi, or None (absent, unreadable, damaged, not Xi)."""
        try:
            xi = np.load(self.path(vehicle_path), allow_pickle=False)
        except (OSError, ValueError, EOFError):
            return None
        if (xi.dtype != np.float64 or xi.ndim != 4 or xi.shape[2:] != XI_SHAPE_TAIL
                or not np.all(np.isfinite(xi))):
            return None
        return xi

    def store(self, vehicle_path: str | None, xi: np.ndarray) -> None:
        """Write Xi atomically (a temporary file renamed); any OSError leaves the cache as it was."""
        tmp: str | None = None
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=".xi-", suffix=".tmp", dir=self.directory)
            with os.fdopen(fd, "wb") as f:
                np.save(f, np.ascontiguousarray(xi, dtype=np.float64), allow_pickle=False)
            os.replace(tmp, self.path(vehicle_path))
            tmp = None
            self._prune()
        except OSError:
            pass
        finally:
            if tmp is not None:
                try:
                    os.unlink(tmp)
                except OSError:
                    pass

    def _prune(self) -> None:
        """Keep the KEEP newest Xi files (a file another process removes first is no error)."""
        cached = sorted(self.directory.glob(f"{PREFIX}*.npy"), key=_mtime, reverse=True)
        for old in cached[KEEP:]:
            try:
                old.unlink()
            except OSError:
                pass


def _mtime(p: Path) -> float:
    try:
        return p.stat().st_mtime
    except OSError:
        return 0.0
