"""A deadline watchdog on the FC's main loop (docs/security.md, "A control loop GCS work cannot stall").

Ground-station work runs on the control thread between two looks at the sim link: inbound GCS datagrams (at most
`GCS_DATAGRAMS_PER_PASS` per pass) and the wall-clock services (telemetry, paced downloads, queued PARAM_SETs; a
stability sweep runs on a worker, never here). The watchdog times each slice of that work against
`GCS_WORK_BUDGET_S` and the wall gap between control steps against `STEP_DEADLINE_S`; overruns are counted (the
log's `fc_stats`) and reported in `/fc/event` and on stderr, at most once per `REPORT_PERIOD_S` each (not by
STATUSTEXT: a loaded host overruns too, and the operator should not learn to ignore warnings), so a regression
that puts slow work back on the control path is seen rather than felt as a mysterious stall.
"""

from __future__ import annotations

from dataclasses import dataclass

GCS_WORK_BUDGET_S = 0.010  # one slice of GCS work (a 100 Hz control period)
STEP_DEADLINE_S = 0.020  # wall gap between two control steps when the simulation is paced (speed > 0)
REPORT_PERIOD_S = 10.0


@dataclass
class LoopWatchdog:
    gcs_overruns: int = 0
    gcs_work_max_s: float = 0.0
    late_steps: int = 0
    step_gap_max_s: float = 0.0
    _last_step_wall: float | None = None
    _last_report: dict[str, float] | None = None

    def gcs_work(self, duration_s: float, now_wall: float) -> str | None:
        """One slice of GCS work took `duration_s`: the report when it overran (rate-limited)."""
        self.gcs_work_max_s = max(self.gcs_work_max_s, duration_s)
        if duration_s <= GCS_WORK_BUDGET_S:
            return None
        self.gcs_overruns += 1
        return self._report("gcs", now_wall, f"GCS work took {duration_s * 1e3:.0f} ms on the control thread "
                                      f"({self.gcs_overruns} overruns)")

    def step(self, now_wall: float, paced: bool) -> str | None:
        """A control step ran: the report when it came late after the previous one (paced runs)."""
        last, self._last_step_wall = self._last_step_wall, now_wall
        if last is None or not paced:
            return None
        gap = now_wall - last
        self.step_gap_max_s = max(self.step_gap_max_s, gap)
        if gap <= STEP_DEADLINE_S:
            return None
        self.late_steps += 1
        return self._report("step", now_wall, f"control step {gap * 1e3:.0f} ms after the previous one "
                                      f"({self.late_steps} late)")

    def stats(self) -> dict[str, float | int]:
        return {"gcs_overruns": self.gcs_overruns, "gcs_work_max_s": self.gcs_work_max_s,
                "late_steps": self.late_steps, "step_gap_max_s": self.step_gap_max_s}

    def _report(self, kind: str, now_wall: float, text: str) -> str | None:
        last = self._last_report if self._last_report is not None else {}
        if now_wall - last.get(kind, -1e9) < REPORT_PERIOD_S:
            return None
        self._last_report = {**last, kind: now_wall}
        return text
