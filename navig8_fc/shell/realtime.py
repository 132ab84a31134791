"""The FC's real-time timing mode (FC_TIMING = 1; docs/hil.md, "Timing modes"): its own clock, the latest data.

In lockstep (FC_TIMING = 0, the default) the bridge's step is the clock: the FC runs one control step per bundle.
In real time the FC ticks on its own monotonic clock every 1/INDI_RATE_HZ, as firmware on a board does, and each
tick uses the newest bundle that arrived since the last tick:

- a bundle whose stamp is not newer than the last one used (a duplicate, a reordered or stale one) is dropped
  and counted `out_of_order`: a step never runs on data older than the data of the step before it;
- a bundle replaced by a newer one before any tick used it is counted `superseded` (only the newest is used);
- a tick with no new bundle is counted `missing` and runs no control step: the last command stands (running the
  incremental INDI law twice on the same measurements would apply its increment twice). Data missing for longer
  than FS_SENS_TOUT trips the sensor-stale failsafe as in lockstep;
- a bundle is `late` when its latency (arrival on this clock minus its stamp) exceeds the least latency seen so far
  by more than RT_LATE_S: the least latency estimates the offset between the two clocks, the excess is jitter;
- the spacing of the stamps of the bundles used is kept as statistics (mean, min, max, count outside
  (1 ± RT_SPACING_TOL)/INDI_RATE_HZ), instead of lockstep's exact-spacing check.

Counters are announced in a STATUSTEXT at most once per REPORT_PERIOD_S when they rose (`report`) and kept in the
log's metadata (`stats`). The controller's time counts its control steps (step n at n/INDI_RATE_HZ): its
fixed-rate filters and the stack's spacing check see exact periods, and a missing tick delays the modes' timers
by one period instead of reading as a rate mismatch; the answer echoes the stamp of the bundle it used. The
least-latency estimate of the clock offset assumes the two clocks run at the same rate (a crystal drift of
d ppm moves it by d us per second: a run of hours against a board would need it to age).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from navig8_fc.params.registry import LinkTiming

TIMING_LOCKSTEP, TIMING_REALTIME = 0, 1
REPORT_PERIOD_S = 1.0
BEHIND_RESYNC_PERIODS = 5  # a loop this many periods late (a stall) restarts the schedule instead of bursting
# Phase alignment: the ticks are kept about a third of a period after the bundles' arrivals, so arrival jitter of up
# to that much neither leaves a tick without its bundle nor lets two bundles fall between two ticks
PHASE_TARGET_PERIODS = 1.0 / 3.0  # the wanted time from a bundle's arrival to the tick that uses it, in periods
PHASE_TOLERANCE_PERIODS = 1.0 / 6.0  # the mean lead this far from the target: the schedule is moved onto it
PHASE_EMA = 0.05  # weight of each arrival in the running (circular) mean of the lead
PHASE_MIN_SAMPLES = 50  # arrivals averaged before (and between) moves


@dataclass
class RealtimeStats:
    ticks: int = 0  # control periods of the FC's clock
    steps: int = 0  # ticks that ran a control step (a new bundle was there)
    missing: int = 0  # ticks without a new bundle (the last command stood)
    superseded: int = 0  # bundles replaced by a newer one before a tick used them
    out_of_order: int = 0  # bundles not newer than the last one used or held: dropped
    late: int = 0  # bundles whose latency exceeded the least seen by more than RT_LATE_S
    resyncs: int = 0  # the loop fell BEHIND_RESYNC_PERIODS behind its schedule and restarted it
    phase_moves: int = 0  # the schedule moved to keep its ticks PHASE_TARGET_PERIODS after the arrivals
    spacing_n: int = 0  # stamp spacings of consecutive used bundles
    spacing_off_tol: int = 0  # of those, outside (1 +- RT_SPACING_TOL) / INDI_RATE_HZ
    spacing_mean_us: float = 0.0
    spacing_min_us: float = math.inf
    spacing_max_us: float = 0.0
    latency_min_ms: float = math.inf  # least arrival-minus-stamp seen (the clock offset estimate)
    latency_max_excess_ms: float = 0.0  # the largest latency above that least one (jitter)


class RealtimeClock:
    """The schedule and the latest-bundle slot of the real-time mode (see the module docstring). Pure: the caller
    gives the monotonic time `now_s` (seconds) to every call."""

    def __init__(self, rate_hz: float, late_s: float, spacing_tol: float, now_s: float) -> None:
        self.period_s = 1.0 / rate_hz
        self.period_us = 1e6 / rate_hz
        self.late_s, self.spacing_tol = late_s, spacing_tol
        self.next_tick_s = now_s + self.period_s
        self.stats = RealtimeStats()
        self._pending: tuple[Any, Any] | None = None  # (bundle, its wire messages), the newest not yet used
        self._last_used_us: int | None = None
        self._reported = RealtimeStats()
        self._report_due_s = now_s + REPORT_PERIOD_S
        self._lead_cos = self._lead_sin = 0.0  # running circular mean of the arrival-to-tick lead (phase)
        self._lead_n = 0

    def offer(self, bundle: Any, wire: Any, now_s: float) -> None:
        """A complete bundle arrived (bundle.time_usec: its stamp)."""
        s = self.stats
        t_us = int(bundle.time_usec)
        newest = self._pending[0].time_usec if self._pending is not None else self._last_used_us
        if newest is not None and t_us <= newest:
            s.out_of_order += 1
            return
        if self._pending is not None:
            s.superseded += 1
        if t_us <= 1:  # step 0 (stamp 1) is the startup handshake, held at t = 0 until the FC answers: no latency
            self._pending = (bundle, wire)
            return
        self._align(now_s)
        latency_ms = (now_s - t_us * 1e-6) * 1e3
        if latency_ms < s.latency_min_ms:
            s.latency_min_ms = latency_ms
        excess = latency_ms - s.latency_min_ms
        if excess > s.latency_max_excess_ms:
            s.latency_max_excess_ms = excess
        if excess > self.late_s * 1e3:
            s.late += 1
        self._pending = (bundle, wire)

    def _align(self, now_s: float) -> None:
        """Keep the ticks PHASE_TARGET_PERIODS after the bundles' arrivals (module constants): two free clocks at one
        rate keep whatever phase they started with, and a tick that falls where the bundles arrive turns every
        arrival jitter into a missing step and a superseded bundle. A running circular mean of the lead (time from
        an arrival to the next tick) moves the schedule, once it is known, when it strays by more than
        PHASE_TOLERANCE_PERIODS."""
        angle = 2.0 * math.pi * ((self.next_tick_s - now_s) / self.period_s % 1.0)
        a = PHASE_EMA if self._lead_n else 1.0
        self._lead_cos += a * (math.cos(angle) - self._lead_cos)
        self._lead_sin += a * (math.sin(angle) - self._lead_sin)
        self._lead_n += 1
        if self._lead_n < PHASE_MIN_SAMPLES:
            return
        lead = math.atan2(self._lead_sin, self._lead_cos) / (2.0 * math.pi) % 1.0  # periods
        error = (PHASE_TARGET_PERIODS - lead + 0.5) % 1.0 - 0.5  # wrapped to [-0.5, 0.5)
        if abs(error) > PHASE_TOLERANCE_PERIODS:
            self.next_tick_s += error * self.period_s
            self._lead_n = 0  # measured afresh on the new schedule
            self.stats.phase_moves += 1

    def timeout_s(self, now_s: float) -> float:
        return max(0.0, self.next_tick_s - now_s)

    def tick(self, now_s: float) -> tuple[Any, Any, int] | None:
        """At or after the due time: advance the schedule and hand over (bundle, wire, clock_us) when a new
        bundle is there (clock_us: this tick on the FC's clock), else None (counted missing). Before it: None."""
        if now_s < self.next_tick_s:
            return None
        s = self.stats
        self.next_tick_s += self.period_s
        if now_s - self.next_tick_s > BEHIND_RESYNC_PERIODS * self.period_s:
            self.next_tick_s = now_s + self.period_s
            s.resyncs += 1
        s.ticks += 1
        if self._pending is None:
            if self._last_used_us is not None:  # before the first bundle nothing is missing yet
                s.missing += 1
            return None
        (bundle, wire), self._pending = self._pending, None
        t_us = int(bundle.time_usec)
        if self._last_used_us is not None:
            d = t_us - self._last_used_us
            s.spacing_n += 1
            s.spacing_mean_us += (d - s.spacing_mean_us) / s.spacing_n
            s.spacing_min_us = min(s.spacing_min_us, d)
            s.spacing_max_us = max(s.spacing_max_us, d)
            if abs(d - self.period_us) > self.spacing_tol * self.period_us:
                s.spacing_off_tol += 1
        self._last_used_us = t_us
        s.steps += 1
        return bundle, wire, round(s.steps * self.period_us)

    def report(self, now_s: float) -> str | None:
        """A STATUSTEXT when late, missing, out-of-order or superseded data was counted since the last report (at
        most once per REPORT_PERIOD_S), else None."""
        if now_s < self._report_due_s:
            return None
        self._report_due_s = now_s + REPORT_PERIOD_S
        s, r = self.stats, self._reported
        d = {k: getattr(s, k) - getattr(r, k) for k in ("late", "missing", "out_of_order", "superseded")}
        if not any(d.values()):
            return None
        self._reported = RealtimeStats(**vars(s))
        return (f"Sim link: {d['late']} late, {d['missing']} missing, {d['out_of_order']} out of order, "
                f"{d['superseded']} superseded (totals {s.late}/{s.missing}/{s.out_of_order}/{s.superseded})")


__all__ = ["TIMING_LOCKSTEP", "TIMING_REALTIME", "RealtimeClock", "RealtimeStats"]


LINK_DELAY_BLOCK = 256  # answers per estimate (2.6 s at 100 Hz): the delay the floor is computed for moves at most once
# a block, so a link at the edge between two delays does not recompute the floor (nor announce it) every tick
LINK_DELAY_QUANTILE = 0.95  # the delay 95 % of a block's answers met: an answer late now and then is jitter
# A simulator that never says which answer it flew (PX4's messages: no NAVIG8_ACTUATOR_STATE) leaves the delay unknown
# and the FC's actuator model untold: in real time the loop is then taken one tick late and blind, the usual worst
# (docs/hil.md: the defaults' margin 0.97 there)
UNECHOED_LINK = LinkTiming(1, False)


class LinkDelayMeter:
    """How many ticks later than in lockstep the simulator flies the FC's answers (docs/hil.md, "The link's delay and
    the actuator model"), from the answer it says it flew up to each bundle (NAVIG8_ACTUATOR_STATE.cmd_time_usec,
    mapped to the FC's tick that answered it): in lockstep the answer of the tick before flies, so a tick's delay is
    the ticks between the two less one. Per block of LINK_DELAY_BLOCK bundles, the delay LINK_DELAY_QUANTILE of the
    echoed answers met, the actuator model told; a block with fewer than half its answers echoed gives UNECHOED_LINK.
    `link` is None until a block is full."""

    def __init__(self) -> None:
        self._counts: dict[int, int] = {}
        self._n = 0
        self.link: LinkTiming | None = None

    def add(self, answered_clock_us: int | None, clock_us: int, period_us: float) -> None:
        """One bundle: the FC's clock at the tick whose answer flew up to it (None: the simulator did not say, or not
        one of the answers remembered) and at the tick now."""
        d = -1 if answered_clock_us is None else max(0, int(round((clock_us - answered_clock_us) / period_us)) - 1)
        self._counts[d] = self._counts.get(d, 0) + 1
        self._n += 1
        if self._n < LINK_DELAY_BLOCK:
            return
        echoed = self._n - self._counts.get(-1, 0)
        need, seen = LINK_DELAY_QUANTILE * echoed, 0
        self.link = UNECHOED_LINK
        if echoed >= self._n / 2:  # a lost echo now and then (the answer not remembered) is not a silent simulator
            for delay in sorted(k for k in self._counts if k >= 0):
                seen += self._counts[delay]
                if seen >= need:
                    self.link = LinkTiming(delay, True)
                    break
        self._counts, self._n = {}, 0
