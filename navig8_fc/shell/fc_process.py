"""navig8-fc: the flight-controller process, the only FC code that touches sockets and clocks (its options and
ports: navig8_fc/shell/fc_options.py). One loop: the sim link's frames become control steps through two
strategies (what the sim link carries, when a step runs: navig8_fc/shell/sim_peer.py), the GCS and API links go to
the GCS service, and the log is written after each step's answer has gone out (navig8_fc/shell/fc_log.py)."""

from __future__ import annotations

import gc
import secrets
import select
import signal
import sys
import time
from dataclasses import replace
from typing import Any

from navig8_fc.core import vehicle as vm
from navig8_fc.core.controller import FlightControllerCore, warm_up_kernels
from navig8_fc.flight import ArmRequest, FlightStack, Notice, load_flight_script
from navig8_fc.links.mavlink_link import PortInUseError, UdpLink, write_ports_file
from navig8_fc.links.signing import LinkSigning
from navig8_fc.links.sim_guard import SensorLimits, SimGuard, SimInput
from navig8_fc.links.transport import StreamTransport, parse_connection
from navig8_fc.mavlink import codec, seam
from navig8_fc.mavlink import dialect as dialect_mod
from navig8_fc.mavlink.px4sim import PX4_SIM_MESSAGES, ActuatorModel, Px4SimAssembler
from navig8_fc.mission.executor import planned_path
from navig8_fc.mission.store import MissionStore
from navig8_fc.params.registry import ParamRegistry, StabilityStatus
from navig8_fc.params.store import ParamStore, default_state_path
from navig8_fc.shell.fc_log import FcLog, StepRecord
from navig8_fc.shell.fc_options import FcOptions, build_arg_parser, options_from_args
from navig8_fc.shell.foxglove_out import FoxgloveOutput, FoxglovePortError, LiveServer, script_waypoints
from navig8_fc.shell.gcs_service import GcsService
from navig8_fc.shell.loop_watchdog import LoopWatchdog
from navig8_fc.shell.mcap_log import open_logger
from navig8_fc.shell.realtime import TIMING_REALTIME, RealtimeClock
from navig8_fc.shell.signing_keys import KeyFile
from navig8_fc.shell.sim_peer import BundlePeer, Lockstep, Px4Peer, Realtime
from navig8_fc.shell.telemetry_service import MAV_AUTOPILOT_GENERIC, MAV_AUTOPILOT_PX4, Source, origin_from_params
from navig8_fc.viz import VehicleViz, packaged_uav_size_m, waypoint_poses

FC_COMPID = 1
SPIN_S = 0.002  # busy-poll window for the next bundle in lockstep at --speed 0
GCS_DATAGRAMS_PER_PASS = 16  # ~2-5 ms of GCS work at most between two looks at the sim link
WALL_TICK_S = 0.001  # GCS services (telemetry schedule, paced parameter list) run at most this often
_GRIPPER_CODES = {None: seam.GRIPPER_NONE, "grab": seam.GRIPPER_GRAB, "release": seam.GRIPPER_RELEASE}
EXIT_USAGE = 2  # bad arguments, or a port in use
_PORT_OPTIONS = {"sim": "--sim-port", "gcs": "--gcs-bind-port", "api": "--api-bind-port"}


class FlightControllerProcess:
    """Sockets, clocks and logs around the pure FlightStack (control, modes, failsafes) and the GCS service.
    It is the GCS service's Outbox (`broadcast`, `reply`) over the GCS and API links."""

    def __init__(self, opts: FcOptions) -> None:
        self.opts = opts
        self.d = dialect_mod.load()
        self.vehicle = vm.VehicleConfig.load(opts.vehicle_path)
        self.registry = ParamRegistry.from_defaults()
        self._stop = False
        self.model = vm.UamModel(self.vehicle)
        self._last_step_time_us: int | None = None
        # A log that cannot be opened (read-only dir, full disk) is reported and the FC flies without one.
        logger, open_error = open_logger(opts.log_path, opts.log_max_mb, opts.log_keep)
        if open_error is not None:
            print(f"navig8-fc: cannot open the log: {open_error}; flying without a log", file=sys.stderr)
        script = load_flight_script(opts.scenario)  # the scenario's setpoint script (a scripted run: AUTO.MISSION)
        self.log = FcLog(logger, open_error, self._mk_foxglove(script, logger), self.model, self._sim_ns)
        self.n_tick_errors = 0  # exceptions in the control tick (contained: last command held, land requested)
        self._last_cmd: tuple[Any, bool] | None = None  # (command, armed) of the last good tick
        self.guard = SimGuard(opts.sysid, SensorLimits.from_vehicle(self.vehicle), lambda: secrets.randbits(32))
        self._pending_tick: StepRecord | None = None
        self._spin_until = 0.0
        self._mk_links()
        self.stack = FlightStack(self.vehicle, self.registry, script)
        self.sim_status: Any = None
        # what the sim link carries: the bridge's bundle, or PX4's simulator messages (their own assembler, no
        # pairing: answers go to the link's peer, the simulator that connected; docs/hil.md)
        stream = isinstance(self.sim.sock, StreamTransport)
        self.peer = (BundlePeer(self.sim, self.guard, self._bridge_target, stream) if opts.sim_messages == "navig8"
                     else Px4Peer(self.sim, self.guard, self._bridge_target, self._mk_px4_assembler()))
        self._last_answer: bytes | None = None  # the frame answering the last step (re-sent on duplicates)
        self.n_ticks = 0
        self.watchdog = LoopWatchdog()
        self.n_duplicates = 0
        self.last_bundle_wall = time.monotonic()
        self.sim_done = False
        store = ParamStore(default_state_path(opts.state_dir, opts.instance)) if opts.state_dir else None
        self.signing = LinkSigning((self.gcs.mav, self.api.mav), KeyFile(default_state_path(
            opts.state_dir, opts.instance, "fc_signing")) if opts.state_dir else None)  # docs/security.md
        missions = MissionStore(default_state_path(opts.state_dir, opts.instance, "fc_mission")) if opts.state_dir \
            else None
        self.gcs_service = GcsService(self._mav(), opts.sysid, self.stack.state, self.stack, self, self.registry,
                                      self.vehicle, store, missions,
                                      autopilot=MAV_AUTOPILOT_PX4 if opts.autopilot == "px4" else MAV_AUTOPILOT_GENERIC,
                                      trusted_sources=[(link.name, t) for link in (self.gcs, self.api)
                                                       for t in link.targets],
                                      background_params=True, signing=self.signing)
        self._stability_logged: StabilityStatus | None = None  # the last /fc/stability record
        for link in (self.gcs, self.api):  # telemetry only to confirmed peers (docs/security.md)
            link.admit_peer = self.gcs_service.admits_peer
        for line in self.signing.load():
            self.log_event(line)
        if missions is not None:
            reason = self.gcs_service.mission.load_stored()
            n = len(self.gcs_service.mission.plan().items)
            self.log_event(f"mission plan loaded from {missions.path} ({n} items)" if n else "no stored mission plan")
            if reason:
                self.log_event(reason)
        if store is not None and not opts.defaults:
            loaded = self.gcs_service.load_stored_params()
            if loaded.ok:
                self.log_event(f"parameters loaded from {store.path} ({loaded.applied} values)")
            for line in loaded.report():  # also STATUSTEXT at the first ground-station contact
                self.log_event(line)
        elif opts.defaults:
            self.log_event("starting from default parameters (--defaults)")
        self.stack.reconfigure()
        self.timing = self._mk_timing()
        self.guard.monotonic = self.timing.realtime
        warm_up_kernels(self.vehicle, self.core.config)  # numba's cache loads before the first step, not in it
        if self.logger:
            self.logger.metadata("run", {"scenario": opts.scenario, "controller": self._controller_name(),
                                         "sysid": opts.sysid, "process": "navig8-fc"})
            self.logger.metadata("params", self.registry.as_dict())

    @property
    def logger(self) -> Any:
        """The MCAP logger (None: no log, or it could not be opened)."""
        return self.log.logger

    @property
    def fox(self) -> FoxgloveOutput | None:
        return self.log.fox

    # --- setup -----------------------------------------------------------------------------------
    def _mk_px4_assembler(self) -> Px4SimAssembler:
        """PX4's simulator messages as the sensor source (navig8_fc/mavlink/px4sim.py, docs/hil.md)."""
        reg = self.registry
        model = ActuatorModel(float(reg["ACT_WN"]), float(reg["ACT_ZETA"]), 1.0 / float(reg["INDI_RATE_HZ"]),
                              (0.0,) * 5)
        self.log_event("sim link: PX4 simulator messages (HIL_SENSOR, HIL_STATE_QUATERNION; actuator states "
                       "modelled unless NAVIG8_ACTUATOR_STATE comes)")
        return Px4SimAssembler(origin_from_params(reg), model)

    def _mk_timing(self) -> Lockstep | Realtime:
        """When a step runs (FC_TIMING, --timing): lockstep, or the real-time mode's clock (shell/realtime.py)."""
        reg = self.registry
        if self.opts.timing is not None:
            reg.set("FC_TIMING", 1.0 if self.opts.timing == "realtime" else 0.0)
        if int(reg["FC_TIMING"]) != TIMING_REALTIME:
            return Lockstep()
        self.log_event(f"real-time timing: own clock at {int(reg['INDI_RATE_HZ'])} Hz, newest bundle per tick")
        return Realtime(RealtimeClock(float(reg["INDI_RATE_HZ"]), float(reg["RT_LATE_S"]),
                                      float(reg["RT_SPACING_TOL"]), time.monotonic()))

    def _mav(self) -> Any:
        m = self.d.MAVLink(None, srcSystem=self.opts.sysid, srcComponent=FC_COMPID)
        m.robust_parsing = True
        return m

    def _mk_foxglove(self, script: Any, logger: Any) -> FoxgloveOutput | None:
        """The Foxglove 3D channels: into the log, and live with --foxglove (docs/foxglove.md)."""
        o = self.opts
        live = None
        self._fox_plan_generation: int | None = None  # the uploaded plan last drawn on /foxglove/mission
        if o.foxglove_port is not None:
            live = LiveServer(o.foxglove_host, o.foxglove_port, f"navig8-fc sysid {o.sysid}")
            print(f"navig8-fc: Foxglove WebSocket ws://{o.foxglove_host}:{live.port}", file=sys.stderr)
        if logger is None and live is None:
            return None
        fox = FoxgloveOutput(VehicleViz(self.vehicle, packaged_uav_size_m()), logger, live, "navig8-fc")
        self._script_waypoints = script_waypoints(script)
        fox.set_mission(self._script_waypoints)
        return fox

    def _show_plan(self) -> None:
        """/foxglove/mission follows the uploaded plan (its planned path from home), or the script without one."""
        mission = self.gcs_service.mission
        if self.fox is None or mission.generation == self._fox_plan_generation:
            return
        self._fox_plan_generation = mission.generation
        plan = mission.plan()
        if not plan.items:
            self.fox.set_mission(self._script_waypoints)
            return
        home = self.stack.state().home_ned or (0.0, 0.0, 0.0)
        path = planned_path(plan, self.gcs_service.origin, home)
        self.fox.set_mission(waypoint_poses([(p, 0.0, 0.0) for p in path]))

    def _mk_links(self) -> None:
        """Bind the three links (PortInUseError names a busy one; port 0: any free port), write the ports file,
        and announce the FC to the bridge (DESIGN §4: a bridge that does not know our port learns it from this)."""
        o = self.opts
        # the sim link speaks only the seam's messages (PX4 mode: and PX4's simulator messages), decoded by the codec
        sim_codec = codec.seam_codec() if o.sim_messages == "navig8" else codec.Codec(PX4_SIM_MESSAGES)
        sim_enc = codec.Encoder(sim_codec, o.sysid, FC_COMPID)
        if o.sim_link:
            self.sim = UdpLink.connect("sim", sim_enc, parse_connection(o.sim_link), codec=sim_codec)
        else:
            self.sim = UdpLink.open("sim", sim_enc, (o.host, o.port("sim")), [(o.host, o.port("bridge"))],
                                    codec=sim_codec)
            self.sim.max_datagrams = 1  # one bundle per step; more stay readable for the run loop's next select
        self.gcs = (UdpLink.connect("gcs", self._mav(), parse_connection(o.gcs_link)) if o.gcs_link else
                    UdpLink.open("gcs", self._mav(), (o.bind_host, o.port("gcs_bind")), [(o.gcs_host, o.gcs_port)]))
        self.api = (UdpLink.connect("api", self._mav(), parse_connection(o.api_link)) if o.api_link else
                    UdpLink.open("api", self._mav(), (o.bind_host, o.port("api_bind")),
                                 [(o.gcs_host, o.port("api"))]))
        for link in (self.gcs, self.api):  # a GCS flood is handled a slice per loop pass, between control steps
            link.max_datagrams = GCS_DATAGRAMS_PER_PASS
        if o.ports_file is not None:
            ports = {"sim": self.sim.local_port, "gcs": self.gcs.local_port, "api": self.api.local_port}
            if self.fox is not None and self.fox.live is not None:
                ports["foxglove"] = self.fox.live.port
            write_ports_file(o.ports_file, ports)
        # where the announcement goes: the bridge's port, or the connection string's peer (a stream has only one)
        self._bridge_target = self.sim.targets[0] if o.sim_link and self.sim.targets else (o.host, o.port("bridge"))
        self.sim.send(self.guard.announce_record(), [self._bridge_target])  # before the log hooks are set up
        for link in (self.sim, self.gcs, self.api):
            link.on_datagram = self.log.datagram
        for link in (self.gcs, self.api):  # the sim link's messages are logged decoded as /truth, /fc/...
            link.on_frame = self.log.decoded
        self.links = (self.sim, self.gcs, self.api)

    def _controller_name(self) -> str:
        return {0: "fixed", 1: "unconstrained", 2: "proposed", 3: "pinned", 4: "lms"}[int(self.registry["CKF_MODE"])]

    @property
    def core(self) -> FlightControllerCore:
        """The stack's controller core (rebuilt by the stack when rate, filter or estimator settings change)."""
        return self.stack.core

    @property
    def lambda_crit(self) -> float:
        return self.stack.lambda_crit

    # --- lockstep --------------------------------------------------------------------------------
    def _sim_ns(self) -> int:
        return seam.sim_us_from_time_usec(self._last_step_time_us) * 1000 if self._last_step_time_us else 0

    def _on_sim(self, received: list[Any]) -> None:
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
                    self._on_step(*run)
            elif kind == "duplicate":
                self.n_duplicates += 1  # a re-sent bundle: answer with the same command, do not re-run control
                if self._last_answer is not None and not timing.realtime and peer.answers_duplicates:
                    self.sim.send_raw(self._last_answer, peer.sim_to)
            elif kind == "status":
                self._on_sim_status(inp.status)
        for severity, text in peer.reports(now):
            self.statustext(text, severity)

    def _on_sim_status(self, status: seam.SimStatus) -> None:
        self.sim_status = status
        if status.state == seam.SIM_STATE_DONE:
            self.sim_done = True

    def _on_step(self, inp: SimInput, clock_us: int | None = None) -> None:
        """One lockstep step: control, answer, and queue the step's log records (written after the answer).
        An exception in the tick holds the last command and lands (reported, counted), never ends the process."""
        self.last_bundle_wall = time.monotonic()
        b = inp.bundle
        assert b is not None
        t_us = int(b.time_usec)
        if inp.bad_groups and not self.guard.has_good:
            return  # nothing valid to fly on yet: no answer (the bridge re-sends; counted by the guard)
        # invalid sensor data (the guard holds the last good values): the stack's failsafe decides
        self.announce(self.stack.sensor_data(inp.bad_groups, self.guard.bad_data_s() if inp.bad_groups else 0.0))
        self._last_step_time_us = t_us
        sensors = b.fc_sensors()
        if clock_us is not None:  # real time: the control step runs on the FC's clock (realtime.py)
            sensors = replace(sensors, t_s=clock_us * 1e-6)
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
        self.announce(res.notices)
        paced = self.sim_status is not None and self.sim_status.speed > 0.0
        self._watch(self.watchdog.step(self.last_bundle_wall, paced))
        if self.log.active:
            self._pending_tick = StepRecord(t_us, b.truth, res.status, cmd, res.setpoint, inp.wire, out, sensors)

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
        self.announce(notices)
        if self._last_cmd is not None:
            cmd, armed = self._last_cmd
            self._last_answer = seam.pack_actuator_controls(self.sim.mav, t_us, cmd, self.vehicle, armed=armed)
            self.sim.send_raw(self._last_answer, self.peer.sim_to)

    def _watch(self, note: str | None) -> None:
        """The watchdog's rate-limited report: /fc/event and stderr (a loaded host overruns too: not a STATUSTEXT)."""
        if note is not None:
            self.log_event(note)

    def statustext(self, text: str, severity: int = 6) -> None:
        """STATUSTEXT to every GCS (and the log keeps it)."""
        self.gcs_service.statustext(text, severity)
        self.log.statustext(text, severity)

    def _spin_for_sim(self) -> list[Any]:
        """Busy-poll the sim socket until the next bundle arrives or the spin window closes.

        Waking a process blocked in select() costs ~0.2 ms on these VMs, more than a control tick; in
        lockstep at --speed 0 the next bundle follows within a few hundred microseconds, and the FC and
        the bridge each have a core. Paced runs (--speed > 0) never spin."""
        sock = self.sim.sock
        while time.perf_counter() < self._spin_until:
            r, _, _ = select.select([sock], [], [], 0.0)
            if r:
                return r
        return []

    # --- main loop -------------------------------------------------------------------------------
    def request_stop(self, *_: Any) -> None:
        self._stop = True

    def run(self, until_done: bool = False) -> int:
        print(f"navig8-fc: sysid {self.opts.sysid}, sim link :{self.sim.local_port} -> bridge "
              f":{self.opts.port('bridge')}, GCS :{self.gcs.local_port} -> {self.opts.gcs_port}, API "
              f":{self.api.local_port} -> {self.opts.port('api')}, scenario {self.opts.scenario}", file=sys.stderr)
        socks = {link.sock: link for link in self.links}
        # Everything alive now (imports, numba, the parameter registry) lives for the whole run: a full collection
        # would walk it all (~70 ms here, a stall of several lockstep steps); freezing keeps the collector to the
        # run's own short-lived objects.
        gc.collect()
        gc.freeze()
        hb_due = wall_tick_due = 0.0
        sock_list = list(socks)
        try:
            while not self._stop:
                ready = self._spin_for_sim() if self._spin_until > time.perf_counter() else []
                if not ready:
                    wait = self.timing.timeout_s(time.monotonic())
                    ready, _, _ = select.select(sock_list, [], [], wait)
                for sock in ready:
                    link = socks[sock]
                    got = link.receive()
                    if link is self.sim:
                        self._on_sim(got)
                    else:
                        t0 = time.monotonic()
                        self.on_gcs(link, got)
                        self._watch(self.watchdog.gcs_work(time.monotonic() - t0, t0))
                if (due := self.timing.due(time.monotonic())) is not None:
                    self._on_step(*due)  # (its SimInput, the FC's clock)
                # The step's answer is out: now log (this overlaps with the bridge's physics step).
                if self._pending_tick is not None:
                    tick, self._pending_tick = self._pending_tick, None
                    self._log_step(tick)
                    if not self.timing.realtime and (self.sim_status is None or self.sim_status.speed == 0.0):
                        self._spin_until = time.perf_counter() + SPIN_S  # the next bundle is due very soon
                self._log_step(None)
                now = time.monotonic()
                if now >= hb_due:
                    hb_due = now + 1.0
                    self.on_wall_second(now)
                if now >= wall_tick_due:  # not on every lockstep step: at --speed 0 steps come every ~0.3 ms
                    wall_tick_due = now + WALL_TICK_S
                    self.on_wall_tick(now)
                    self._watch(self.watchdog.gcs_work(time.monotonic() - now, now))
                if until_done and self.sim_done:
                    break
                self._check_timeouts(now)
        finally:
            self.close()
        return 0

    def _check_timeouts(self, now: float) -> None:
        """The failsafe inputs, measured on the wall clock (lockstep has no sim time without bundles): the age of
        the last sensor bundle (once one has arrived) and of the last GCS heartbeat (once a GCS has sent one).
        The stack decides (sensor-stale fault, GCS-loss landing: navig8_fc.flight.stack); this announces."""
        last_hb = self.gcs_service.last_gcs_heartbeat
        last_sp = self.gcs_service.last_offboard_setpoint
        notices = self.stack.check_links(now - self.last_bundle_wall if self.n_ticks > 0 else None,
                                         None if last_hb is None else now - last_hb,
                                         None if last_sp is None else now - last_sp)
        if notices:
            self.announce(notices)

    def announce(self, notices: tuple[Notice, ...]) -> None:
        """The stack's notices: STATUSTEXT to every GCS (and /fc/statustext), events to /fc/event."""
        for n in notices:
            if n.statustext:
                self.statustext(n.statustext, n.severity)
            if n.event:
                self.log_event(n.event)

    # --- GCS side --------------------------------------------------------------------------------
    def on_gcs(self, link: UdpLink, received: list[Any]) -> None:
        mine = []
        for r in received:
            m = r.msg
            # Our own echo or another vehicle's traffic is not for us (counted, never acted on).
            if m.get_srcSystem() == self.opts.sysid and m.get_srcComponent() == FC_COMPID:
                link.counters.foreign += 1
                continue
            mine.append((m, (link.name, r.addr) if r.addr is not None else None))
        for change in self.gcs_service.handle(mine, time.monotonic()):  # replies go back to link and sender
            self.log_param_change(change)

    # --- Outbox (GcsService) ---------------------------------------------------------------------
    def broadcast(self, msgs: list[Any], exclude: frozenset[Source] = frozenset()) -> None:
        """To every peer of both GCS-facing links (telemetry, HEARTBEAT, STATUSTEXT, PARAM_VALUE announcements),
        except the sources in `exclude` (source = (link name, address)). Every STATUSTEXT (the FC's events and the
        GCS service's refusal reasons alike) also goes to /foxglove/log."""
        for link in (self.gcs, self.api):
            dest = None
            if exclude:
                dest = [a for a in link.destinations() if (link.name, a) not in exclude]
                if not dest:
                    continue
            for m in msgs:
                link.send(m, dest)
        if self.fox is not None:
            for m in msgs:
                if m.get_type() == "STATUSTEXT":
                    text = m.text.decode(errors="replace") if isinstance(m.text, bytes) else str(m.text)
                    self.fox.statustext(self._sim_ns(), int(m.severity), text.rstrip("\0"), time.time_ns())

    def reply(self, source: Source, msgs: list[Any]) -> None:
        """To the one peer a request came from, on its link: source = (link name, sender address)."""
        name, addr = source  # type: ignore[misc]
        link = self.api if name == self.api.name else self.gcs
        dest = [addr]
        for m in msgs:
            link.send(m, dest)

    def on_wall_second(self, now: float) -> None:
        for severity, text in self.peer.on_wall_second(now):  # announcements; counts held back within a period
            self.statustext(text, severity)
        log = self.log
        if log.open_error is not None and not log.fail_reported:
            log.fail_reported = True  # at the first wall second: a GCS that is already listening hears it
            self.statustext(f"Log disabled: {log.open_error}", 3)
        if log.logger is not None:
            log.record_contained("/fc/sim_guard", self._guard_stats())
        if (text := self.timing.report(now)) is not None:
            self.statustext(text, 4)  # MAV_SEVERITY_WARNING

    def on_wall_tick(self, now: float) -> None:
        for change in self.gcs_service.poll(now):  # PARAM_SETs that waited for their stability floor
            self.log_param_change(change)
        stab = self.gcs_service.stability
        if stab is not None and stab != self._stability_logged:
            self._stability_logged = stab
            self.log_stability(stab)
        self._show_plan()

    def log_stability(self, stab: StabilityStatus) -> None:
        self.log.stability(stab)

    def log_event(self, text: str) -> None:
        print(f"navig8-fc: {text}", file=sys.stderr)
        self.log.record("/fc/event", {"text": text})

    def log_param_change(self, change: Any) -> None:
        self.log.record("/fc/param_change", change)

    def _log_step(self, tick: StepRecord | None) -> None:
        """Log a step's records (tick) or the queued datagrams (None); contained (FcLog.step)."""
        if tick is None:
            text = self.log.step(None)
        else:
            text = self.log.step(tick, self.sim.codec, float(self.registry["INDI_LAMBDA_MIN"]), self.lambda_crit)
        if text is not None:
            self.statustext(text, 3)

    def _guard_stats(self) -> dict[str, Any]:
        return {**vars(self.guard.counters), "tick_errors": self.n_tick_errors, **self.log.stats()}

    def close(self) -> None:
        self.gcs_service.close()
        self.signing.save_timestamp()
        if self._pending_tick is not None and self.log.active:
            tick, self._pending_tick = self._pending_tick, None
            self._log_step(tick)
        self._log_step(None)
        meta: dict[str, Any] = {}
        if self.logger:
            meta["link_counters"] = {link.name: vars(link.counters) for link in self.links}
            if self.sim_status is not None:
                meta["bridge_status"] = self.sim_status
            meta["fc_stats"] = {"ticks": self.n_ticks, "duplicates": self.n_duplicates,
                                "sim_guard": self._guard_stats(), "incomplete_bundles": self.peer.incomplete,
                                **self.watchdog.stats()}
            if (rt_stats := self.timing.stats()) is not None:
                meta["realtime_stats"] = rt_stats
            meta["params_final"] = self.registry.as_dict()
        self.log.close(meta)
        for link in self.links:
            link.close()


def _arm_command(req: ArmRequest, t_us: int) -> seam.ArmCommand:
    return seam.ArmCommand(t_us, req.joint_target_rad, _GRIPPER_CODES[req.gripper])


def main(argv: list[str] | None = None) -> int:
    ap = build_arg_parser()
    args = ap.parse_args(argv)
    for text in (args.sim_link, args.gcs_link, args.api_link):
        if text:
            try:
                parse_connection(text)
            except ValueError as e:
                ap.error(str(e))
    # Ctrl-C / SIGTERM during the start (numba, dialect, parameters) ends it cleanly too: exit 0, no traceback.
    stop_early: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, _f: stop_early.append(signum))
    signal.signal(signal.SIGTERM, lambda signum, _f: stop_early.append(signum))
    try:
        proc = FlightControllerProcess(options_from_args(args))
    except PortInUseError as e:
        print(f"navig8-fc: {e.strerror}; choose another with {_PORT_OPTIONS[e.link]} or --{e.link}-link "
              "(port 0: any free port)", file=sys.stderr)
        return EXIT_USAGE
    except FoxglovePortError as e:
        print(f"navig8-fc: {e}; choose another with --foxglove=PORT (0: any free port)", file=sys.stderr)
        return EXIT_USAGE
    except OSError as e:  # a serial device that cannot be opened (after FoxglovePortError, also an OSError)
        print(f"navig8-fc: {e.strerror or e}", file=sys.stderr)
        return 1
    signal.signal(signal.SIGINT, proc.request_stop)
    signal.signal(signal.SIGTERM, proc.request_stop)
    if stop_early:
        proc.request_stop()
    rc = proc.run(until_done=args.until_done)
    if proc.opts.log_path and proc.log.open_error is None:
        print(f"navig8-fc: log {proc.opts.log_path}", file=sys.stderr)
    return rc


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["FlightControllerProcess", "main"]
