"""The workspace Xi kept on disk between FC starts (navig8_fc/shell/xi_cache.py): a cached Xi is the computed one and
gives the same floors; any change of what Xi depends on misses; a damaged file or an unwritable directory is only a
miss."""

from __future__ import annotations

import os
import pickle
import shutil
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest

from navig8_fc.core import k_xi
from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.params.registry import ParamRegistry, WorkspaceStabilityCheck, run_floor
from navig8_fc.shell import xi_cache
from navig8_fc.shell.xi_cache import CORE_DIR, KEEP, XiDiskCache, xi_key

CONFIGS = ({}, {"INDI_K_MIN": 0.3}, {"INDI_K_MAX": 1.6}, {"ACT_WN": 60.0}, {"INDI_LPF_TAU": 0.05},
           {"INDI_LAM_REF": 0.7, "INDI_KFL_MIN": 0.4})


class CountingCache:
    """An XiDiskCache that counts what the check asked of it."""

    def __init__(self, inner: XiDiskCache) -> None:
        self.inner, self.loads, self.hits, self.stores = inner, 0, 0, 0

    def load(self, vehicle_path: str | None) -> np.ndarray | None:
        self.loads += 1
        xi = self.inner.load(vehicle_path)
        self.hits += xi is not None
        return xi

    def store(self, vehicle_path: str | None, xi: np.ndarray) -> None:
        self.stores += 1
        self.inner.store(vehicle_path, xi)


def _vehicle_copy(tmp_path: Path, name: str) -> str:
    """The packaged vehicle file under a new path: a path this process has not computed Xi for."""
    p = tmp_path / name
    p.write_bytes((files("navig8_params") / "vehicle.yaml").read_bytes())
    return str(p)


def _floors(check: WorkspaceStabilityCheck, configs: tuple[dict, ...] = CONFIGS) -> list:
    base = ParamRegistry.from_defaults(check_stability=False).floor_values()
    return [run_floor(check, {**base, **c}) for c in configs]


def test_a_cached_xi_is_the_computed_one_and_gives_the_same_floors(tmp_path: Path) -> None:
    cache = XiDiskCache(tmp_path / "cache")
    first = CountingCache(cache)
    computed = _floors(WorkspaceStabilityCheck(_vehicle_copy(tmp_path, "a.yaml"), first))
    assert (first.loads, first.hits, first.stores) == (1, 0, 1)  # a miss, computed once, stored
    fresh = k_xi.workspace_xi(VehicleConfig.load(_vehicle_copy(tmp_path, "b.yaml")))
    stored = cache.load(_vehicle_copy(tmp_path, "c.yaml"))  # the same text: the same key
    assert stored is not None and stored.tobytes() == fresh.tobytes()
    second = CountingCache(cache)
    from_cache = _floors(WorkspaceStabilityCheck(_vehicle_copy(tmp_path, "d.yaml"), second))
    assert (second.loads, second.hits, second.stores) == (1, 1, 0)  # read, not computed
    uncached = _floors(WorkspaceStabilityCheck(_vehicle_copy(tmp_path, "e.yaml")))
    assert from_cache == computed == uncached


def test_the_check_with_its_cache_pickles_for_the_worker(tmp_path: Path) -> None:
    check = WorkspaceStabilityCheck(None, XiDiskCache(tmp_path))
    again = pickle.loads(pickle.dumps(check))
    values = ParamRegistry.from_defaults(check_stability=False).floor_values()
    assert run_floor(again, values) == run_floor(WorkspaceStabilityCheck(), values)


def test_a_change_of_what_xi_depends_on_misses(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    vehicle = _vehicle_copy(tmp_path, "v.yaml")
    key = xi_key(vehicle)
    assert xi_key(None) == key  # the packaged file by its text, wherever it is
    text = Path(vehicle).read_text()
    assert "gravity_m_s2:" in text
    Path(vehicle).write_text(text.replace("gravity_m_s2:", "gravity_m_s2:  ", 1))  # the text, not the values
    assert xi_key(vehicle) != key
    core = tmp_path / "core"
    shutil.copytree(CORE_DIR, core, ignore=shutil.ignore_patterns("__pycache__"))
    assert xi_key(None, core) == key
    (core / "g_c.py").write_text((core / "g_c.py").read_text() + "\n# a comment\n")
    assert xi_key(None, core) != key
    monkeypatch.setattr(xi_cache, "library_versions", lambda: "numpy 0.0")
    assert xi_key(None) != key


def test_a_damaged_or_foreign_file_is_a_miss_and_is_replaced(tmp_path: Path) -> None:
    cache = XiDiskCache(tmp_path)
    vehicle = _vehicle_copy(tmp_path, "v.yaml")
    path = cache.path(vehicle)
    for bad in (b"", b"\x93NUMPY garbage", None):
        if bad is None:
            np.save(path, np.full((3, 5, 5), np.nan))  # a readable array that is not Xi
        else:
            path.write_bytes(bad)
        assert cache.load(vehicle) is None
    np.save(path, np.ones((127, 3, 5, 5)) * np.nan)
    assert cache.load(vehicle) is None
    counting = CountingCache(cache)
    floors = _floors(WorkspaceStabilityCheck(vehicle, counting), CONFIGS[:2])
    assert (counting.hits, counting.stores) == (0, 1)
    assert floors == _floors(WorkspaceStabilityCheck(_vehicle_copy(tmp_path, "w.yaml")), CONFIGS[:2])
    assert cache.load(vehicle) is not None


def test_an_unwritable_directory_is_no_error(tmp_path: Path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    cache = XiDiskCache(blocker / "navig8")  # cannot be created, even by root
    vehicle = _vehicle_copy(tmp_path, "v.yaml")
    counting = CountingCache(cache)
    assert _floors(WorkspaceStabilityCheck(vehicle, counting), CONFIGS[:2]) == _floors(
        WorkspaceStabilityCheck(_vehicle_copy(tmp_path, "w.yaml")), CONFIGS[:2])
    assert counting.stores == 1 and cache.load(vehicle) is None
    assert list(tmp_path.glob("**/.xi-*")) == []


def test_the_newest_files_are_kept(tmp_path: Path) -> None:
    cache = XiDiskCache(tmp_path)
    for i in range(KEEP + 3):
        old = tmp_path / f"{xi_cache.PREFIX}{i:04d}.npy"
        old.write_bytes(b"old")
        os.utime(old, (1000.0 + i, 1000.0 + i))
    cache.store(None, np.zeros((2, 3, 5, 5)))
    kept = sorted(p.name for p in tmp_path.glob(f"{xi_cache.PREFIX}*.npy"))
    assert len(kept) == KEEP and cache.path(None).name in kept
    assert f"{xi_cache.PREFIX}{KEEP + 2:04d}.npy" in kept and f"{xi_cache.PREFIX}0000.npy" not in kept


def test_the_directory_follows_xdg(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert XiDiskCache.default().directory == tmp_path / "navig8"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert XiDiskCache.default().directory == tmp_path / "home" / ".cache" / "navig8"
