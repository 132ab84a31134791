"""navig8-bridge's step loop: the plant in lockstep with navig8-fc (docs/bridge.md is the contract).

The bridge is the time master (DESIGN §4). Each step k it sends ONE datagram with the sensor bundle stamped
time_usec = round(k * dt * 1e6) + 1 (ODOMETRY, NAVIG8_ACTUATOR_STATE, NAVIG8_ARM_STATE, NAVIG8_TRUTH, HIL_SENSOR
last) and waits for the FC's single HIL_ACTUATOR_CONTROLS echoing that stamp; it then holds that command for dt
(zero-order hold), steps the plant and sends step k + 1. Step 0 is re-sent until the FC answers (the plant waits at
t = 0); a missing answer is re-sent every 0.1 s on UDP (a lost datagram), reported as a stall every --step-timeout
and ends the run after --stall-abort (BridgeStalled);
--speed paces the steps on the wall clock; --free-run steps on the wall clock whatever the FC does. The socket,
pairing and datagrams are the link's (sim_bridge/fc_link.py). A thin I/O loop: no controller code.
"""

from __future__ import annotations

import gc
import math
import sys
import time

import numpy as np

from navig8_fc.links.transport import StreamTransport
from navig8_fc.mavlink import seam
from sim_bridge.bridge_options import BridgeOptions
from sim_bridge.fc_link import BridgeCounters, FcLink
from sim_bridge.messages import ActuatorCommand
from sim_bridge.plant import Plant
from sim_bridge.scenario import Scenario
from sim_bridge.world import load_world

STARTUP_RESEND_S = 0.1  # re-send step 0 this often until the FC answers
LOSS_RESEND_S = 0.1  # on UDP: an unanswered bundle is re-sent this often (a lost datagram costs 0.1 s, not a stall)
STREAM_STARTUP_RESEND_S = 1.0  # on TCP/serial: re-sent bundles queue in the stream, and the FC answers every one
STATUS_PERIOD_S = 1.0  # NAVIG8_SIM_STATUS period (wall)
REANCHOR_LAG_S = 0.5  # paced runs that fall this far behind (a stall) restart pacing instead of bursting
REMINDER_S = 10.0  # while waiting for the FC's first answer, a stderr line this often


class BridgeStalled(Exception):
    """navig8-fc did not answer in time (--startup-timeout, --stall-abort): the message says which."""


def default_grab_mass(sc: Scenario) -> float:
    """The object a GRAB picks up: the scenario's held object, else its first grasp event's, else nothing."""
    if sc.object_mass_kg > 0.0:
        return sc.object_mass_kg
    for ev in sc.events:
        if ev.kind in ("grasp", "mass") and ev.mass_kg > 0.0:
            return ev.mass_kg
    return 0.0


class Bridge:
    """The lockstep I/O loop around one Plant and its link to the FC."""

    def __init__(self, opts: BridgeOptions) -> None:
        if opts.speed < 0 or not math.isfinite(opts.speed):
            raise ValueError("--speed must be >= 0 (0: as fast as possible)")
        if opts.free_run and opts.speed <= 0:
            raise ValueError("--free-run needs a wall-clock pace: --speed > 0")
        if not (opts.step_timeout_s > 0 and opts.stall_abort_s > 0):
            raise ValueError("--step-timeout and --stall-abort must be > 0")
        self.opts = opts
        w = load_world(opts.scenario, dict(opts.world))
        self.scenario = w.scenario
        self.vehicle = w.vehicle
        self.plant = Plant(self.vehicle, w.plant, self.scenario, np.random.default_rng(opts.seed))
        self.dt_us = round(opts.dt_s * 1e6)
        if self.dt_us <= 0 or abs(self.dt_us - opts.dt_s * 1e6) > 1e-3 or self.dt_us % self.plant.physics_step_us:
            raise ValueError(f"--dt {opts.dt_s} s must be a positive multiple of the physics step "
                             f"{self.plant.physics_step_us} us")
        duration = self.scenario.duration_s if opts.duration_s is None else float(opts.duration_s)
        self.n_steps = int(round(duration * 1e6 / self.dt_us))
        self.limits = seam.ControlsScale.from_vehicle(self.vehicle)
        self.grab_mass_kg = default_grab_mass(self.scenario) if opts.grab_mass_kg is None else opts.grab_mass_kg
        self.link = FcLink(opts, self.dt_us, self.limits, self._send_status)
        self.arm = self.link.arm  # the FC's arm commands, applied at the next step
        self.step = 0
        self._wall_start: float | None = None  # when stepping began (answer to step 0)
        self._pace_anchor: tuple[float, int] = (0.0, 0)  # (wall, step) pacing is measured from
        self._status_due = 0.0
        self.state = seam.SIM_STATE_WAITING_FOR_FC

    @property
    def counters(self) -> BridgeCounters:
        return self.link.counters

    @property
    def port(self) -> int:
        return self.link.port

    @property
    def time_usec(self) -> int:
        return seam.time_usec_from_sim_us(self.plant.t_us)

    def _bundle(self, cmd_time_usec: int = 0) -> bytes:
        """cmd_time_usec: the stamp the answer the plant just flew echoed (0 before the first)."""
        # the plain-float views of sense() and truth(): the same samples and bytes, no numpy views to convert back
        plant = self.plant
        return seam.encode_bundle(self.link.mav, self.step, plant.sense_wire(), plant.truth_floats(), cmd_time_usec)

    def rtf(self, now: float) -> float:
        if self._wall_start is None or now <= self._wall_start:
            return 0.0
        return (self.plant.t_us * 1e-6) / (now - self._wall_start)

    def _send_status(self, now: float, state: int | None = None) -> None:
        st = seam.SimStatus(self.time_usec, self.step, self.state if state is None else state,
                            self.opts.speed, self.rtf(now), self.counters.stalls)
        self.link.send(self.link.mav.frame(*seam.encode_sim_status(st)))
        self._status_due = now + STATUS_PERIOD_S

    def _apply_arm(self) -> None:
        """Gripper actions take effect at the start of the step being taken (deterministic: see docs)."""
        for g in self.arm.pending_gripper:
            self.plant.command_gripper(g == seam.GRIPPER_GRAB, self.grab_mass_kg)
        self.arm.pending_gripper.clear()

    # ---- waiting for an answer ----------------------------------------------------------------------
    def _wait_answer(self, data: bytes, first_sent: float, resend_every_s: float, startup: bool
                     ) -> seam.ActuatorControls:
        """Re-send `data` every resend_every_s until the matching answer arrives. Past startup a stall is counted
        and reported every --step-timeout (the re-sends between are a lost datagram's recovery, not a stall), and
        BridgeStalled raised past --stall-abort."""
        link, o = self.link, self.opts
        next_resend = first_sent + resend_every_s
        next_reminder = first_sent + REMINDER_S
        next_stall = first_sent + o.step_timeout_s
        while True:
            now = time.perf_counter()
            if now >= self._status_due:
                self._send_status(now)
            ans = link.receive(min(next_resend, self._status_due) - now, self.time_usec)
            if ans is not None:
                return ans
            if link.resend_due:
                link.resend_due = False
                link.send(data)
            now = time.perf_counter()
            if now < next_resend:
                continue
            waited = now - first_sent
            if startup:
                next_reminder = self._still_waiting(waited, now, next_reminder)
            elif now >= next_stall:
                self._stalled(waited, now)
                # the next stall never reaches past the abort deadline by more than one step timeout
                next_stall = min(now + o.step_timeout_s, max(first_sent + o.stall_abort_s, now + 1e-3))
            link.send(data)
            self.counters.bundles_sent += 1
            self.counters.resends += 1
            next_resend = now + resend_every_s if startup else min(now + resend_every_s, next_stall)

    def _still_waiting(self, waited: float, now: float, next_reminder: float) -> float:
        """No answer to step 0 yet: give up past --startup-timeout, remind on stderr every REMINDER_S; the next
        reminder's time."""
        o = self.opts
        if o.startup_timeout_s > 0 and waited >= o.startup_timeout_s:
            raise BridgeStalled(f"navig8-bridge: no answer from navig8-fc at {self.link.fc_text()}"
                                f" within --startup-timeout {o.startup_timeout_s:g} s; "
                                "is navig8-fc running with the same --instance/ports?")
        if now >= next_reminder:
            next_reminder = now + REMINDER_S
            print(f"navig8-bridge: still waiting for navig8-fc at {self.link.fc_text()} "
                  f"({waited:.0f} s)", file=sys.stderr, flush=True)
        return next_reminder

    def _stalled(self, waited: float, now: float) -> None:
        """A step timeout: counted, reported (stderr, NAVIG8_SIM_STATUS stalled); past --stall-abort, BridgeStalled."""
        o = self.opts
        self.counters.stalls += 1
        if waited >= o.stall_abort_s:
            raise BridgeStalled(f"navig8-bridge: navig8-fc stalled: no actuator answer for step {self.step} "
                                f"(t={self.plant.t_s:.3f} s) for {waited:.1f} s (--stall-abort "
                                f"{o.stall_abort_s:g} s); stopping")
        print(f"navig8-bridge: no actuator answer from navig8-fc for step {self.step} "
              f"(t={self.plant.t_s:.3f} s) after {waited:.1f} s; re-sending", file=sys.stderr, flush=True)
        self.state = seam.SIM_STATE_STALLED
        self._send_status(now)

    def _pace(self) -> None:
        """At --speed N > 0, step k is not released before anchor + (t_k - t_anchor) / N."""
        if self.opts.speed <= 0:
            return
        w0, k0 = self._pace_anchor
        release = w0 + (self.step - k0) * self.dt_us * 1e-6 / self.opts.speed
        now = time.perf_counter()
        if now < release:
            time.sleep(release - now)
        elif now - release > REANCHOR_LAG_S:
            # after a stall, do not burst to catch up with wall time: continue at speed N from here
            self._pace_anchor = (now, self.step)

    # ---- the run ------------------------------------------------------------------------------------
    def startup_line(self) -> str:
        o = self.opts
        return (f"navig8-bridge: scenario {self.scenario.name} (seed {o.seed}), sysid {o.sysid}, dt {o.dt_s:g} s, "
                f"speed {o.speed:g}{' (as fast as possible)' if o.speed == 0 else 'x'}, "
                + (f"bound {o.host}:{self.port}" if o.link is None else f"link {o.link}")
                + f", FC at {self.link.fc_text()}"
                + (f", {self.link.budget.line()}" if self.link.budget is not None else "")
                + (f", until done at t={self.n_steps * self.dt_us * 1e-6:g} s" if o.until_done else ""))

    def run(self) -> None:
        """Run until done (--until-done; else until stopped): raises BridgeStalled, PlantDivergedError."""
        print(self.startup_line(), file=sys.stderr, flush=True)
        gc.collect()
        gc.freeze()  # start-up objects live for the whole run: keep them out of every later collection
        ans = self._first_answer()
        if self.opts.free_run:
            self._run_free(ans)
        else:
            self._run_lockstep(ans)
        self._finish()

    def _first_answer(self) -> seam.ActuatorControls:
        """Step 0: re-sent until the FC answers it (the plant waits at t = 0); then stepping begins."""
        data = self._bundle()
        now = time.perf_counter()
        self._send_status(now)
        self.link.send(data)
        self.counters.bundles_sent += 1
        ans = self._wait_answer(data, now, STREAM_STARTUP_RESEND_S if isinstance(self.link.sock, StreamTransport)
                                else STARTUP_RESEND_S, startup=True)
        now = time.perf_counter()
        self._wall_start = now
        self._pace_anchor = (now, 0)
        self.state = seam.SIM_STATE_RUNNING
        self._send_status(now)
        return ans

    def _run_lockstep(self, ans: seam.ActuatorControls) -> None:
        """Step on every answer until done (--until-done) or stopped; the hot path sends and receives directly."""
        o, c, dt_us = self.opts, self.counters, self.dt_us
        plant, link, arm = self.plant, self.link, self.arm
        mav, sock = link.mav, link.sock
        until_done, n_steps, paced = o.until_done, self.n_steps, o.speed > 0
        # a datagram link loses datagrams: re-send soon; a stream (TCP, serial) delivers, so wait a step timeout
        resend_s = o.step_timeout_s if isinstance(sock, StreamTransport) else min(LOSS_RESEND_S, o.step_timeout_s)
        encode_bundle, perf_counter = seam.encode_bundle, time.perf_counter
        while not (until_done and self.step >= n_steps):
            # zero-order hold of the answer for one control period
            cmd = ActuatorCommand(ans.tilt_rad, ans.speed_rad_s, arm.joint_targets_rad)
            if arm.pending_gripper:
                self._apply_arm()
            plant.step_us(cmd, dt_us)
            self.step += 1
            c.steps += 1
            data = encode_bundle(mav, self.step, plant.sense_wire(), plant.truth_floats(),
                                 ans.time_usec)  # self._bundle(ans.time_usec)
            if paced:
                self._pace()
            now = perf_counter()
            try:  # link.send(data); fc_addr is known: the FC answered step 0
                sock.sendto(data, link.fc_addr)
            except OSError:
                pass
            c.bundles_sent += 1
            if now >= self._status_due:
                self._send_status(now)
            ans = link.receive(min(resend_s, self._status_due - now), self.time_usec)
            if ans is None:  # slow answer or status due: the careful path (status, re-sends, stall abort)
                ans = self._wait_answer(data, now, resend_s, startup=False)
                self.state = seam.SIM_STATE_RUNNING

    def _finish(self) -> None:
        """Done: NAVIG8_SIM_STATUS done three times (the FC's --until-done exits on it: one lost datagram must not
        hang it)."""
        now = time.perf_counter()
        self.state = seam.SIM_STATE_DONE
        for _ in range(3):
            self._send_status(now)

    def _run_free(self, ans: seam.ActuatorControls) -> None:
        """Real time (--free-run): step k is released at anchor + t_k / speed whatever the FC does; the plant holds
        the newest answer (zero-order hold), answers to older bundles are counted stale. No answer for
        --stall-abort s: BridgeStalled, as in lockstep."""
        o, c, plant, arm = self.opts, self.counters, self.plant, self.arm
        period = self.dt_us * 1e-6 / o.speed
        last_answer = anchor = time.perf_counter()
        k0 = 0
        while not (o.until_done and self.step >= self.n_steps):
            release = anchor + (self.step + 1 - k0) * period
            while (now := time.perf_counter()) < release:
                if now >= self._status_due:
                    self._send_status(now)
                got = self.link.receive(release - now, self.time_usec)
                if got is not None:
                    ans, last_answer = got, time.perf_counter()
            if now - release > REANCHOR_LAG_S:  # fell behind (a stall): continue from here, no burst
                anchor, k0 = now, self.step
            if now - last_answer > o.stall_abort_s:
                raise BridgeStalled(f"navig8-bridge: navig8-fc stalled: no actuator answer for "
                                    f"{now - last_answer:.1f} s (--stall-abort {o.stall_abort_s:g} s, free run); "
                                    "stopping")
            if arm.pending_gripper:
                self._apply_arm()
            plant.step_us(ActuatorCommand(ans.tilt_rad, ans.speed_rad_s, arm.joint_targets_rad), self.dt_us)
            self.step += 1
            c.steps += 1
            self.link.send(self._bundle(ans.time_usec))  # the FC learns which of its answers was flown
            c.bundles_sent += 1

    def summary_line(self) -> str:
        now = time.perf_counter()
        wall = now - self._wall_start if self._wall_start is not None else 0.0
        return (f"navig8-bridge: {self.counters.steps} steps, t = {self.plant.t_s:.3f} s, wall {wall:.2f} s, "
                f"RTF {self.rtf(now):.1f}; {self.counters.line()}")

    def close(self) -> None:
        self.link.close()
