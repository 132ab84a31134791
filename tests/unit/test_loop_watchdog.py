"""The main loop's deadline watchdog: overruns counted, reports rate-limited per kind, paced steps only."""

from __future__ import annotations

from navig8_fc.shell.loop_watchdog import GCS_WORK_BUDGET_S, REPORT_PERIOD_S, STEP_DEADLINE_S, LoopWatchdog


def test_overruns_are_counted_and_reported_at_most_once_per_period() -> None:
    w = LoopWatchdog()
    assert w.gcs_work(GCS_WORK_BUDGET_S * 0.5, 0.0) is None
    first = w.gcs_work(0.126, 1.0)
    assert first is not None and "126 ms" in first
    assert w.gcs_work(0.2, 2.0) is None  # counted, not re-reported within the period
    assert w.gcs_work(0.2, 1.0 + REPORT_PERIOD_S) is not None
    assert w.stats()["gcs_overruns"] == 3 and w.stats()["gcs_work_max_s"] == 0.2


def test_late_steps_only_count_when_paced() -> None:
    w = LoopWatchdog()
    assert w.step(0.0, paced=True) is None
    assert w.step(0.010, paced=True) is None
    late = w.step(0.010 + STEP_DEADLINE_S * 3, paced=True)
    assert late is not None and w.late_steps == 1
    assert w.step(10.0, paced=False) is None and w.late_steps == 1  # lockstep at full speed: gaps are the bridge's
    assert w.gcs_work(1.0, 0.2) is not None  # its own report period, separate from the steps'
