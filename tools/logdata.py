"""Load a run's MCAP log (in-process or SITL) into numpy time series for plots and summaries.

Topics written by the runners (navig8-sim, and later the SITL processes):
- /truth         the plant's truth (state, mass properties, reaction wrench, actuators, joints)
- /fc/status     the controller's status record (outer loop, INDI, adaptive law)
- /fc/setpoint   the active setpoint (NED, rad)
- /fc/command    actuator commands
- /analysis/eig  eigenvalues of G_hat G^-1 with G from the truth, and the true G_I entries
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from navig8_fc.shell.mcap_log import read_mcap, read_metadata


def _get(d: Any, path: str) -> Any:
    for key in path.split("."):
        if d is None:
            return None
        d = d.get(key) if isinstance(d, dict) else None
    return d


@dataclass
class Series:
    """Messages of one topic: times (s) and the list of decoded dicts."""

    t: np.ndarray
    msgs: list[dict[str, Any]]

    def field(self, path: str, width: int | None = None) -> np.ndarray:
        """Array of a (possibly nested, dotted) field; missing values become NaN."""
        vals = [_get(m, path) for m in self.msgs]
        if width is None:
            width = next((len(v) for v in vals if isinstance(v, list)), 0)
        if width:
            out = np.full((len(vals), width), np.nan)
            for i, v in enumerate(vals):
                if isinstance(v, list):
                    out[i, : len(v)] = [np.nan if x is None else x for x in v[:width]]
            return out
        return np.array([np.nan if v is None else float(v) for v in vals])


@dataclass
class RunLog:
    path: Path
    topics: dict[str, Series]
    metadata: dict[str, dict[str, Any]]

    def __getitem__(self, topic: str) -> Series:
        if topic not in self.topics:
            raise KeyError(f"{self.path}: no topic {topic!r} (has {sorted(self.topics)})")
        return self.topics[topic]

    @property
    def label(self) -> str:
        run = self.metadata.get("run", {})
        return str(run.get("controller", self.path.stem))


def load_run(path: str | Path, topics: list[str] | None = None) -> RunLog:
    t: dict[str, list[float]] = defaultdict(list)
    m: dict[str, list[dict[str, Any]]] = defaultdict(list)
    # the Foxglove 3D channels (docs/foxglove.md) are for viewers: no plot or summary reads them
    for topic, t_ns, data in read_mcap(path, topics, skip_prefix=None if topics else "/foxglove/"):
        if isinstance(data, dict):
            if topic == "/fc/setpoint" and "pos_ned" in data:  # a log written before the key had its unit
                data["pos_ned_m"] = data.pop("pos_ned")
            t[topic].append(t_ns * 1e-9)
            m[topic].append(data)
    series = {k: Series(np.array(t[k]), m[k]) for k in t}
    return RunLog(Path(path), series, read_metadata(path))
