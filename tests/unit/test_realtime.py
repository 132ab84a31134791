"""The real-time mode's clock (navig8_fc/shell/realtime.py) against a synthetic link: a sender stepping at the
FC's rate with seeded jitter, drops and reordering. Checked against what the scenario was built with, not against
the module's own arithmetic: which stamps were sent, dropped, swapped."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from navig8_fc.shell.realtime import RealtimeClock

RATE_HZ = 100.0
PERIOD_S = 0.01


@dataclass(frozen=True)
class FakeBundle:
    time_usec: int


def _arrivals(n: int, rng: np.random.Generator, jitter_s: float, drop: float, swap: float, t0: float = 100.0
              ) -> tuple[list[tuple[float, int]], set[int], int]:
    """(arrival time, stamp) of bundles k = 1..n sent at t0 + k * period with uniform +-jitter, a share `drop` lost
    and a share `swap` of neighbours delivered in swapped order; the dropped stamps and the number of swaps."""
    out, dropped, swaps = [], set(), 0
    for k in range(1, n + 1):
        stamp = round(k * PERIOD_S * 1e6) + 1
        if rng.random() < drop:
            dropped.add(stamp)
            continue
        out.append((t0 + k * PERIOD_S + rng.uniform(-jitter_s, jitter_s) + jitter_s, stamp))
    out.sort()
    i = 0
    while i < len(out) - 1:
        if rng.random() < swap:  # the older one is held up and arrives 1 ms after the newer one
            (_, sa), (tb, sb) = out[i], out[i + 1]
            out[i], out[i + 1] = (tb, sb), (tb + 0.001, sa)
            swaps += 1
            i += 2
        else:
            i += 1
    return out, dropped, swaps


def _run(arrivals: list[tuple[float, int]], late_s: float = 0.005, t0: float = 100.0
         ) -> tuple[RealtimeClock, list[tuple[int, int]]]:
    """Feed arrivals and tick the clock as the FC's loop does; the (stamp, clock_us) of every step run."""
    clock = RealtimeClock(RATE_HZ, late_s, 0.25, t0)
    used: list[tuple[int, int]] = []
    events = sorted([(t, 0, s) for t, s in arrivals])
    for t, _, stamp in events:
        while (due := clock.tick(min(t, clock.next_tick_s))) is not None or clock.next_tick_s <= t:
            if due is not None:
                used.append((due[0].time_usec, due[2]))
        clock.offer(FakeBundle(stamp), None, t)
    end = events[-1][0] + 0.05
    while clock.next_tick_s <= end:
        due = clock.tick(clock.next_tick_s)
        if due is not None:
            used.append((due[0].time_usec, due[2]))
    return clock, used


def test_clean_link_steps_once_per_bundle_on_exact_periods() -> None:
    arr = [(100.0 + k * PERIOD_S + 0.003, round(k * PERIOD_S * 1e6) + 1) for k in range(1, 301)]
    clock, used = _run(arr)
    s = clock.stats
    assert [u for u, _ in used] == [st for _, st in arr]
    assert [c for _, c in used] == [round((i + 1) * 1e4) for i in range(len(used))]  # exact 10 ms control time
    assert s.late == s.out_of_order == s.superseded == 0 and s.spacing_off_tol == 0
    assert s.spacing_mean_us == pytest.approx(1e4)


def test_jitter_drops_and_reordering_never_step_on_older_data_and_are_counted() -> None:
    rng = np.random.default_rng(7)
    arr, dropped, swaps = _arrivals(2000, rng, jitter_s=0.002, drop=0.05, swap=0.05)
    clock, used = _run(arr)
    s = clock.stats
    stamps = [u for u, _ in used]
    assert all(b > a for a, b in zip(stamps, stamps[1:], strict=False))  # strictly newer data every step
    assert not set(stamps) & dropped
    assert swaps > 50 and s.out_of_order == swaps  # every older half of a reordered pair is dropped
    assert s.missing > 0.5 * len(dropped)  # most lost bundles leave a tick without new data
    assert s.spacing_max_us >= 2e4 and s.spacing_off_tol > 0  # the gaps show in the statistics
    assert s.late == 0  # +-2 ms jitter stays within RT_LATE_S = 5 ms
    assert s.latency_max_excess_ms <= 4.0 + 1e-6
    assert clock.report(1e9) is not None and clock.report(1e9 + 2) is None  # reported once, then quiet


def test_late_bundles_are_counted_against_the_least_latency() -> None:
    arr = [(100.0 + k * PERIOD_S + (0.009 if k % 10 == 0 else 0.001), round(k * PERIOD_S * 1e6) + 1)
           for k in range(1, 201)]
    clock, _ = _run(arr)
    assert clock.stats.late == 20  # every tenth bundle 8 ms later than the rest (still before the next one)
    assert clock.stats.out_of_order == 0
    assert "20 late" in (clock.report(1e9) or "")


def test_a_stalled_loop_resyncs_instead_of_bursting() -> None:
    clock = RealtimeClock(RATE_HZ, 0.005, 0.25, 0.0)
    clock.offer(FakeBundle(10001), None, 0.005)
    assert clock.tick(0.5) is not None  # half a second late: one tick, not fifty
    assert clock.stats.resyncs == 1 and clock.tick(0.5) is None and clock.next_tick_s == pytest.approx(0.51)


def test_ticks_move_off_the_bundles_arrival_phase_so_jitter_costs_no_steps() -> None:
    """Two free clocks at one rate keep their starting phase: bundles arriving right at the FC's ticks with +-1.2 ms of
    jitter (what a loaded 921600-baud serial line showed) would leave every other tick without data and supersede a
    bundle each time (about 40 % of the steps lost in this scenario without the alignment). The clock moves its
    ticks a third of a period after the arrivals, once it has averaged them, and then loses none."""
    rng = np.random.default_rng(11)
    n = 3000
    arr = [(100.0 + k * PERIOD_S - 0.0002 + rng.uniform(-0.0012, 0.0012), round(k * PERIOD_S * 1e6) + 1)
           for k in range(1, n + 1)]
    clock, used = _run(arr)
    s = clock.stats
    assert s.phase_moves >= 1
    assert s.superseded + s.missing <= 0.02 * n, vars(s)  # the first ~50 arrivals, before the move, at most
    assert len(used) >= 0.98 * n and s.out_of_order == 0
