"""What the vehicle says about its mission (for the mission microservice, navig8_fc/gcs/mission_protocol.py):
MISSION_CURRENT (seq, total = n or 65535 without a plan, mission_state, mission_mode, and the plans' opaque ids where
the dialect has them) at 1 Hz and at once when it changes; MISSION_ITEM_REACHED(seq) at once and then once a second
up to REACHED_REPEATS more times (PX4). It follows the executor's progress and the plan in force."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from navig8_fc.mission.plan import MissionType, Plan, Progress

UINT16_MAX = 65535
REACHED_REPEATS = 10  # MISSION_ITEM_REACHED repeated once a second this many times (PX4 _reached_sent_count)


class MissionState:
    """MISSION_STATE (common.xml)."""

    UNKNOWN, NO_MISSION, NOT_STARTED, ACTIVE, PAUSED, COMPLETE = range(6)


class MissionStatus:
    """MISSION_CURRENT and MISSION_ITEM_REACHED (module docstring); `plan(mission_type)` is the plan in force."""

    def __init__(self, mav: Any, plan: Callable[[int], Plan], current_period_s: float) -> None:
        self._mav, self._plan = mav, plan
        self._current_period_s = float(current_period_s)
        self.progress = Progress()
        self._current_sent: tuple[int, int, int, int] | None = None
        self._current_t = -math.inf
        self._reached_seq = -1
        self._reached_left = 0
        self._reached_t = -math.inf
        self._reached_n = 0  # the executor's reached counter already announced
        self._now = -math.inf  # the last poll's time

    def report(self, progress: Progress) -> list[Any]:
        """The executor's progress: MISSION_CURRENT follows it; a newly reached item is announced (returned)."""
        fresh = [seq for n, seq in progress.reached_log if n > self._reached_n]
        out = [self._mav.mission_item_reached_encode(seq) for seq in fresh]
        if fresh:
            self._reached_n = progress.reached_log[-1][0]
            self._reached_seq, self._reached_left, self._reached_t = fresh[-1], REACHED_REPEATS, self._now
        self.progress = progress
        return out

    def new_plan(self, current: int) -> None:
        """A new mission plan in force (starting at `current`): nothing reached, MISSION_CURRENT at once."""
        self._reached_seq, self._reached_left = -1, 0
        self.progress = Progress(current, reached_log=self.progress.reached_log)
        self._current_sent = None

    def set_current(self, seq: int, reset: bool) -> None:
        """The item to fly next moved (reset: what was reached forgotten); MISSION_CURRENT at once."""
        if reset:
            self._reached_seq, self._reached_left = -1, 0
        self._current_sent = None
        pr = self.progress
        self.progress = Progress(seq, pr.reached if not reset else -1, pr.active, False, pr.reached_log)

    def poll(self, now_s: float) -> list[Any]:
        """MISSION_CURRENT when due, a MISSION_ITEM_REACHED repeat when due (broadcasts)."""
        self._now = now_s
        out = []
        key = self._key()
        if key != self._current_sent or now_s - self._current_t >= self._current_period_s:
            self._current_sent, self._current_t = key, now_s
            out.append(self.mission_current())
        if self._reached_left > 0 and now_s - self._reached_t >= 1.0:
            self._reached_left -= 1
            self._reached_t = now_s
            out.append(self._mav.mission_item_reached_encode(self._reached_seq))
        return out

    def mission_current(self) -> Any:
        m = self._mav.mission_current_encode(*self._key())
        if "mission_id" in m.fieldnames:  # the navig8 dialect's common.xml extensions (navig8_fc.mavlink.dialect)
            m.mission_id = self._plan(MissionType.MISSION).opaque_id
            m.fence_id = self._plan(MissionType.FENCE).opaque_id
            m.rally_points_id = self._plan(MissionType.RALLY).opaque_id
        return m

    def _key(self) -> tuple[int, int, int, int]:
        p = self._plan(MissionType.MISSION)
        pr = self.progress
        n = len(p.items)
        mode = 1 if pr.active else 2  # MISSION_CURRENT.mission_mode: 1 in mission mode, 2 suspended
        if n == 0:
            return 0, UINT16_MAX, MissionState.NO_MISSION, mode
        if pr.finished:
            state = MissionState.COMPLETE
        elif pr.active:
            state = MissionState.ACTIVE
        elif pr.reached >= 0:
            state = MissionState.PAUSED
        else:
            state = MissionState.NOT_STARTED
        seq = pr.current if (pr.active or pr.reached >= 0 or pr.finished) else p.current
        return min(max(seq, 0), n - 1), n, state, mode
