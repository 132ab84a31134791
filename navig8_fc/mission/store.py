"""Mission persistence: the plans in force (MISSION, FENCE and RALLY) of one vehicle instance, one JSON file written
atomically the way the parameters are (navig8_fc.params.store.write_atomic). The only mission code that touches
files; the protocol (navig8_fc.gcs.mission_protocol) calls `save` after every accepted upload, clear or change of the
start item, and the process shell calls `load` at startup (`<state_dir>/fc_mission_<N>.json`).

File format (version 1); NaN parameters (yaw "keep") are stored as null::

    {"format": "navig8-fc-mission", "version": 1,
     "plans": {"0": {"current": 0, "items": [[frame, command, autocontinue, p1, p2, p3, p4, x, y, z], ...]}}}

Every loaded item is validated again (`plan.check_item`/`check_plan`): a plan that the current rules refuse is
reported and not loaded, so a file can never put an unflyable plan in force. A corrupt file is reported and left
where it is (as the parameter store does).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import NamedTuple

from navig8_fc.mission.plan import MissionItem, MissionType, Plan, check_item, check_plan
from navig8_fc.params.store import write_atomic

FORMAT_NAME = "navig8-fc-mission"
FORMAT_VERSION = 1
STORED_TYPES = (MissionType.MISSION, MissionType.FENCE, MissionType.RALLY)


class MissionLoad(NamedTuple):
    plans: dict[int, Plan]  # mission_type -> plan (only the types that loaded)
    reason: str | None  # what was not usable, if anything


def _num(v: float) -> float | None:
    return None if math.isnan(v) else float(v)


class MissionStore:
    def __init__(self, path: str | Path) -> None:
        self._path = Path(path)

    @property
    def path(self) -> Path:
        return self._path

    def save(self, plans: dict[int, Plan]) -> None:
        """Write every stored type's plan atomically. Raises OSError on failure."""
        doc = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "plans": {
            str(int(t)): {"current": p.current,
                          "items": [[it.frame, it.command, it.autocontinue, _num(it.param1), _num(it.param2),
                                     _num(it.param3), _num(it.param4), it.x, it.y, _num(it.z)] for it in p.items]}
            for t, p in sorted(plans.items()) if p.items}}
        write_atomic(self._path, (json.dumps(doc, indent=1, allow_nan=False) + "\n").encode("utf-8"))

    def load(self) -> MissionLoad:
        try:
            doc = json.loads(self._path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return MissionLoad({}, None)
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            return MissionLoad({}, f"mission file {self._path} is unreadable: {exc}")
        if not isinstance(doc, dict) or doc.get("format") != FORMAT_NAME or doc.get("version") != FORMAT_VERSION:
            return MissionLoad({}, f"mission file {self._path} is not a {FORMAT_NAME} v{FORMAT_VERSION} file")
        plans: dict[int, Plan] = {}
        problems: list[str] = []
        for key, entry in (doc.get("plans") or {}).items():
            try:
                plan = _plan_from_json(int(key), entry)
            except (TypeError, ValueError, KeyError) as exc:
                problems.append(f"plan {key}: {exc}")
                continue
            plans[plan.mission_type] = plan
        return MissionLoad(plans, f"mission file {self._path}: " + "; ".join(problems) if problems else None)


def _plan_from_json(mission_type: int, entry: dict) -> Plan:
    if mission_type not in STORED_TYPES:
        raise ValueError(f"mission type {mission_type} is not stored")
    rows = entry["items"]
    items = []
    for row in rows:
        frame, command, autocontinue, p1, p2, p3, p4, x, y, z = row
        f = [math.nan if v is None else float(v) for v in (p1, p2, p3, p4, z)]
        items.append(MissionItem(int(frame), int(command), int(autocontinue), f[0], f[1], f[2], f[3],
                                 int(x), int(y), f[4]))
    t = tuple(items)
    for i, it in enumerate(t):
        problem = check_item(it, mission_type, len(t))
        if problem is not None:
            raise ValueError(f"item {i}: {problem.reason}")
    problem = check_plan(t, mission_type)
    if problem is not None:
        raise ValueError(problem.reason)
    current = int(entry.get("current", 0))
    return Plan(mission_type, t, current if 0 <= current < len(t) else 0)
