"""navig8_tools.estimator_convergence.k_trace, with each flight flown once a run.

The estimator tests check many figures of the same flights: a flight is the parameters in force (the registry's values
after the overrides, however they were spelled), the scenario, the world and the seed. It is flown once, to the
longest duration asked of it so far (or `fly_s`, when a test knows a longer use of it is coming), and kept as
arrays: a shorter duration is its first ticks (the flight does not depend on its length), and the truth is clipped
to each test's box afterwards (elementwise, as k_trace clips it per tick). The arrays are the same bytes k_trace
returns. Under xdist the workers share them through the run's temporary directory (`CACHE_DIR`, set by
tests/integration/conftest.py), the first to ask flying under a lock; without it (a plain import) they are kept in
the process only.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
from pathlib import Path

import numpy as np

from navig8_tools.estimator_convergence import k_trace_unclipped, registry_with

CACHE_DIR: Path | None = None
_memo: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, float]] = {}


def _key(reg_values: dict, scenario: str | Path, world: dict[str, float] | None, seed: int) -> str:
    p = Path(scenario)
    where = (str(p), p.read_bytes()) if p.suffix in (".yaml", ".yml") and p.is_file() else str(scenario)
    text = repr((sorted(reg_values.items()), where, sorted((world or {}).items()), int(seed)))
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def _covers(flight: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None, duration_s: float) -> bool:
    return flight is not None and len(flight[0]) >= int(round(duration_s / flight[3])) + 1


def _load(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, float] | None:
    if not path.exists():
        return None
    with np.load(path) as z:
        return z["t"], z["k"], z["k_true"], float(z["dt_s"])


def k_trace(overrides: dict[str, float], duration_s: float, seed: int = 1, scenario: str | Path = "ident",
            world: dict[str, float] | None = None, truth_box: tuple[float, float] | None = None,
            fly_s: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """As estimator_convergence.k_trace; `fly_s`: fly at least this long when the flight is not yet flown (another
    test reads the same flight further)."""
    reg = registry_with(overrides)
    box = truth_box if truth_box is not None else (reg["INDI_K_MIN"], reg["INDI_K_MAX"])
    key = _key(reg.as_dict(), scenario, world, seed)
    flight = _memo.get(key)
    if not _covers(flight, duration_s):
        longest = max(duration_s, fly_s or 0.0)
        if CACHE_DIR is None:
            flight = k_trace_unclipped(reg, longest, seed, scenario, world)
        else:
            CACHE_DIR.mkdir(exist_ok=True)
            path = CACHE_DIR / f"{key}.npz"
            with open(CACHE_DIR / f"{key}.lock", "w") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
                flight = _load(path)
                if not _covers(flight, duration_s):
                    flight = k_trace_unclipped(reg, longest, seed, scenario, world)
                    tmp = CACHE_DIR / f"{key}.tmp.npz"
                    t, k, k_true, dt_s = flight
                    np.savez(tmp, t=t, k=k, k_true=k_true, dt_s=dt_s)
                    os.replace(tmp, path)
        _memo[key] = flight
    t, k, k_true, dt_s = flight
    n = int(round(duration_s / dt_s)) + 1
    return t[:n].copy(), k[:n].copy(), np.clip(k_true[:n], *box)
