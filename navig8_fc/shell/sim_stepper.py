"""The control steps the sim link brings (navig8-fc): each step's sensors through the flight stack, the answer sent
at once (an arm request before it), a duplicate answered with the same frame, and the step's log record queued to
be written after the answer. A tick that raises is contained: the last good command is held and the stack's
failsafe lands. The sim link's format and the timing are the strategies of navig8_fc/shell/sim_peer.py."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.flight import ArmRequest, FlightStack, Notice
from navig8_fc.links.mavlink_link import UdpLink
from navig8_fc.links.sim_guard import SimGuard, SimInput
from navig8_fc.mavlink import seam
from navig8_fc.params.registry import ParamRegistry
from navig8_fc.shell.fc_log import StepRecord
from navig8_fc.shell.loop_watchdog import LoopWatchdog
from navig8_fc.shell.realtime import LinkDelayMeter
from navig8_fc.shell.sim_peer import BundlePeer, Lockstep, Px4Peer, Realtime

ANSWERS_REMEMBERED = 32  # real time: the answers the bridge's echo is looked up in (0.32 s at 100 Hz, > the FC's 16)

_GRIPPER_CODES = {None: seam.GRIPPER_NONE, "grab": seam.GRIPPER_GRAB, "release": seam.GRIPPER_RELEASE}


class SimStepper:
    """Steps in, answers out (module docstring); `announce` and `statustext` reach the ground stations and the log."""

    def __init__(self, sim: UdpLink, peer: BundlePeer | Px4Peer, timing: Lockstep | Realtime, guard: SimGuard,
                 stack: FlightStack, vehicle: VehicleConfig, watchdog: LoopWatchdog, log_active: Callable[[], bool],
                 announce: Callable[[tuple[Notice, ...]], None], statustext: Callable[[str, int], None],
                 log_event: Callable[[str], None]) -> None:
        self.sim, self.peer, self.timing, self.guard, self.stack = sim, peer, timing, guard, stack
        self.vehicle, self.watchdog = vehicle, watchdog
        self._log_active, self._announce = log_active, announce
        self._statustext, self._log_event = statustext, log_event
        self.last_step_time_us: int | None = None
        self.n_tick_errors = 0  # exceptions in the control tick (contained: last command held, land requested)
        self._last_cmd: tuple[Any, bool] | None = None  # (command, armed) of the last good tick
        self._last_answer: bytes | None = None  # the frame answering the last step (re-sent on duplicates)
        # real time: the FC's clock at the ticks that answered the last bundles, by the bundle's stamp (the bridge
        # echoes the stamp of the answer it flew; the controller knows its commands by its own clock)
        self._answered_clock_us: dict[int, int] = {}
        self.link_delay = LinkDelayMeter()  # real time: how late the answers fly (the stability floor's link)
        self.pending_tick: StepRecord | None = None  # the last step's log record, written after its answer
        self.sim_status: Any = None
        self.sim_done = False
        self.n_ticks = 0
        self.n_duplicates = 0
        self.last_bundle_wall = time.monotonic()

    def sim_ns(self) -> int:
        """The last step's sim time (ns; 0 before the first)."""
        t = self.last_step_time_us
        return seam.sim_us_from_time_usec(t) * 1000 if t else 0

    @property
    def paced(self) -> bool:
        """The simulator runs paced (--speed > 0): no busy wait for its next bundle."""
        return self.sim_status is not None and self.sim_status.speed > 0.0

    def on_sim(self, received: list[Any]) -> None:
        """The sim link's frames through the peer (the guard's pairing, sequencing, validation, or PX4's assembler):
        steps to the timing (now in lockstep, at the next tick in real time), the simulator's status kept."""
        now = time.monotonic()
        peer, timing = self.peer, self.timing
        for inp in peer.inputs(received, now):
            kind = inp.kind
            if kind == "step":
                if timing.realtime:  # the newest step waits for the FC's next tick
                    self.last_bundle_wall = now
                run = timing.offer(inp, now)
                if run is not None:
                    self.on_step(*run)
            elif kind == "duplicate":
                self.n_duplicates += 1  # a re-sent bundle: answer with the same command, do not re-run control
                if self._last_answer is not None and peer.answers_duplicates and (
                        not timing.realtime or inp.time_usec == self.last_step_time_us):
                    # real time: only a re-send of the step last flown (its answer was lost: a bridge waiting for
                    # it would wait for ever); one still waiting for its tick is answered by that tick
                    self.sim.send_raw(self._last_answer, peer.sim_to)
            elif kind == "status":
                self.sim_status = inp.status
                if inp.status.state == seam.SIM_STATE_DONE:
                    self.sim_done = True
        for severity, text in peer.reports(now):
            self._statustext(text, severity)

    def on_step(self, inp: SimInput, clock_us: int | None = None) -> None:
        """One step: control, answer, and queue the step's log records (written after the answer). An exception in
        the tick holds the last command and lands (reported, counted), never ends the process."""
        self.last_bundle_wall = time.monotonic()
        b = inp.bundle
        assert b is not None
        t_us = int(b.time_usec)
        if inp.bad_groups and not self.guard.has_good:
            return  # nothing valid to fly on yet: no answer (the bridge re-sends; counted by the guard)
        # invalid sensor data (the guard holds the last good values): the stack's failsafe decides
        self._announce(self.stack.sensor_data(inp.bad_groups, self.guard.bad_data_s() if inp.bad_groups else 0.0))
        self.last_step_time_us = t_us
        sensors = b.fc_sensors()
        if clock_us is not None:  # real time: the control step runs on the FC's clock (realtime.py)
            sensors = replace(sensors, t_s=clock_us * 1e-6, cmd_applied_t_s=self._flown_at(b.cmd_time_usec, t_us,
                                                                                           clock_us))
        try:
            res = self.stack.step(sensors, b.imu_fresh, t_us if clock_us is None else clock_us)
        except Exception as e:  # noqa: BLE001 - contained: the vehicle keeps an answer, the operator is told
            self._tick_failed(e, t_us)
            return
        cmd = res.command
        self._last_cmd = (cmd, res.armed)
        out = seam.pack_actuator_controls(self.sim.mav, t_us, cmd, self.vehicle, armed=res.armed)
        self._last_answer = out
        sim_to = self.peer.sim_to
        if res.arm_request is not None:  # before the step's answer, so the bridge applies it on this step
            self.sim.send(seam.encode_arm_cmd(_arm_command(res.arm_request, t_us)), sim_to)
        self.sim.send_raw(out, sim_to)
        self.peer.commanded(cmd, res.arm_request)
        self.n_ticks += 1
        self._announce(res.notices)
        if (note := self.watchdog.step(self.last_bundle_wall, self.paced)) is not None:
            self._log_event(note)  # a loaded host overruns too: /fc/event and stderr, not a STATUSTEXT
        if self._log_active():
            self.pending_tick = StepRecord(t_us, b.truth, res.status, cmd, res.setpoint, inp.wire, out, sensors)

    def follow_link(self, registry: ParamRegistry) -> None:
        """Real time: the stability floor (LAM_CRIT, LAM_MARGIN, the margin rule) follows how late the simulator flies
        the answers, as measured (realtime.LinkDelayMeter); lockstep's floor until a block of answers is measured."""
        link = self.link_delay.link
        if link is None or link == registry.link:
            return
        registry.set_link(link)
        d = link.delay_ticks
        how = (f"answers fly {d} tick{'s' if d != 1 else ''} later than in lockstep" if link.model_told else
               "does not say which answer it flew: taken as one tick late, the actuator model blind")
        self._statustext(f"Sim link {how}; LAM_MARGIN and the margin rule are now that loop's", 6)

    def _flown_at(self, cmd_time_usec: int, t_us: int, clock_us: int) -> float | None:
        """Real time: the FC's time (s) of the tick whose answer the bridge says it flew up to this bundle (None:
        not one of the last ANSWERS_REMEMBERED); this bundle's tick is remembered under its stamp."""
        answered = self._answered_clock_us
        flown = answered.get(cmd_time_usec)
        self.link_delay.add(flown, clock_us, self.stack.core.config.dt_s * 1e6)
        answered[t_us] = clock_us
        if len(answered) > ANSWERS_REMEMBERED:
            del answered[next(iter(answered))]  # the oldest (dicts keep insertion order)
        return None if flown is None else flown * 1e-6

    def _tick_failed(self, e: Exception, t_us: int) -> None:
        """The tick raised: answer the step with the last good command (the bridge must not stall), ask the stack to
        land, and report (the first error at once, then every 100th)."""
        self.n_tick_errors += 1
        n, what = self.n_tick_errors, type(e).__name__
        if n == 1 or n % 100 == 0:
            print(f"navig8-fc: control tick failed at t={seam.sim_us_from_time_usec(t_us) * 1e-6:.3f} s "
                  f"({n}x): {what}: {e}", file=sys.stderr)
        try:
            notices = self.stack.tick_failed(what, n)  # the failsafe: land, said at the first and every 100th
        except Exception:  # noqa: BLE001 - the stack itself is failing: the held command is all there is
            notices = (Notice(2, f"Control error {what} ({n}x): holding the last command"),) if n == 1 else ()
        self._announce(notices)
        if self._last_cmd is not None:
            cmd, armed = self._last_cmd
            self._last_answer = seam.pack_actuator_controls(self.sim.mav, t_us, cmd, self.vehicle, armed=armed)
            self.sim.send_raw(self._last_answer, self.peer.sim_to)

    def take_pending(self) -> StepRecord | None:
        """The last step's log record, once (None: nothing queued)."""
        tick, self.pending_tick = self.pending_tick, None
        return tick


def _arm_command(req: ArmRequest, t_us: int) -> seam.ArmCommand:
    return seam.ArmCommand(t_us, req.joint_target_rad, _GRIPPER_CODES[req.gripper])
