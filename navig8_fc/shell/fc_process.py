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
from typing import Any

from navig8_fc.blas import limit_to_one_thread
from navig8_fc.core import vehicle as vm
from navig8_fc.core.controller import warm_up_kernels
from navig8_fc.flight import FlightStack, Notice, load_flight_script
from navig8_fc.links.mavlink_link import PortInUseError, UdpLink, write_ports_file
from navig8_fc.links.signing import LinkSigning
from navig8_fc.links.sim_guard import SensorLimits, SimGuard
from navig8_fc.links.transport import parse_connection
from navig8_fc.mavlink import codec
from navig8_fc.mavlink import dialect as dialect_mod
from navig8_fc.mavlink.px4sim import PX4_SIM_MESSAGES
from navig8_fc.mission.geo import origin_from_params
from navig8_fc.params.link_floor import AUTO_PARAM, LinkFloor
from navig8_fc.params.registry import ParamRegistry, StabilityStatus, WorkspaceStabilityCheck
from navig8_fc.shell.fc_log import FcLog, StepRecord
from navig8_fc.shell.fc_options import FcOptions, build_arg_parser, options_from_args
from navig8_fc.shell.fc_state import FcState
from navig8_fc.shell.foxglove_out import FoxgloveOutput, FoxglovePortError, LiveServer, MissionView
from navig8_fc.shell.gcs_links import GcsLinks
from navig8_fc.shell.gcs_service import GcsService
from navig8_fc.shell.log_files import LogDirectory
from navig8_fc.shell.loop_watchdog import LoopWatchdog
from navig8_fc.shell.mcap_log import open_logger
from navig8_fc.shell.origin_gate import DEFAULT_ALLOWED_ORIGINS
from navig8_fc.shell.sim_peer import Px4Peer, sim_peer_for, timing_from_params
from navig8_fc.shell.sim_stepper import SimStepper
from navig8_fc.shell.telemetry_service import MAV_AUTOPILOT_GENERIC, MAV_AUTOPILOT_PX4
from navig8_fc.shell.xi_cache import XiDiskCache
from navig8_fc.viz import VehicleViz, packaged_uav_size_m

FC_COMPID = 1
SPIN_S = 0.002  # busy-poll window for the next bundle in lockstep at --speed 0
WALL_TICK_S = 0.001  # GCS services (telemetry schedule, paced parameter list) run at most this often
FLOOR_READY_WAIT_S = 10.0  # at most this long at start for the stability-floor worker (a loaded machine)
EXIT_USAGE = 2  # bad arguments, or a port in use
CONTROLLERS = ("fixed", "unconstrained", "proposed", "pinned", "lms")  # by CKF_MODE (the run's metadata)
_PORT_OPTIONS = {"sim": "--sim-port", "gcs": "--gcs-bind-port", "api": "--api-bind-port"}


def link_margin_warning(stab: StabilityStatus, auto: bool = False) -> str | None:
    """The warning when the floor in force over a late sim link leaves less than INDI_LAM_MARGIN (docs/stability.md,
    "Over a real-time link") and the FC does not raise the flown K's floor itself (INDI_KFL_LINK 0; with it on,
    link_floor_text says what it did); None otherwise."""
    if stab.link_delay_ticks == 0 or stab.meets_margin or auto:
        return None
    return (f"Stability margin {stab.margin:.2f} over this link < INDI_LAM_MARGIN {stab.required_margin:g} "
            f"(lambda_crit {stab.lambda_crit:.3f}); INDI_KFL_LINK 1 raises the flown K floor to meet it")


def link_floor_text(found: LinkFloor | None, before: float, after: float, k_param: float) -> tuple[int, str]:
    """The STATUSTEXT (severity, text) for a change of the automatic link floor from `before` to `after` (0: none;
    navig8_fc/params/link_floor.py); found: the search behind `after` (None: the floor went back to none because no
    link floor is wanted: INDI_KFL_LINK 0 or no delay measured); k_param: INDI_KFL_MIN."""
    was, now = max(k_param, before), max(k_param, after)
    if found is None:
        return 6, f"Link floor off: flown K floor {was:g} -> INDI_KFL_MIN {k_param:g}"
    d = found.link.delay_ticks
    late = f"Link {d} tick{'s' if d != 1 else ''} late" + ("" if found.link.model_told else ", actuator model blind")
    if after < before:  # on the ground, the link quicker again
        return 6, (f"{late}: flown K floor lowered {was:g} -> {now:g} (margin {found.margin:.2f} >= INDI_LAM_MARGIN "
                   f"{found.required:g})")
    why = (f"{late}: margin {found.margin_own:.2f} < INDI_LAM_MARGIN {found.required:g} at INDI_KFL_MIN "
           f"{k_param:g}; flown K floor {was:g} -> {now:g}")
    if found.meets:
        return 5, f"{why} (margin {found.margin:.2f}, lambda_crit {found.lambda_crit:.3f})"
    return 4, f"{why}, the K box's best: margin {found.margin:.2f} still < {found.required:g}"


LINK_UNMEASURED = "sim link's delay not measured yet (its stability floor follows it)"


def link_fault_reason(stab: StabilityStatus, auto: bool) -> str | None:
    """A pre-arm failure when, with the automatic link floor on, even the floor flown over a late link leaves less than
    INDI_LAM_MARGIN (no floor up to INDI_K_MIN meets it: the defaults two or more ticks late); None otherwise. As the
    margin rule refuses such a configuration from a ground station, arming refuses it from the link: beside other work
    the serial line's flights at two or three ticks late were lost at the K box's best floor (docs/hil.md, "The
    link's delay"). In flight it is a warning (link_floor_text) and MAV_STATE_CRITICAL, not an action. INDI_KFL_LINK 0
    (warn only) or a lower INDI_LAM_MARGIN accepts the smaller margin."""
    if not auto or stab.link_delay_ticks == 0 or stab.meets_margin:
        return None
    d = stab.link_delay_ticks
    return (f"stability margin {stab.margin:.2f} over this link ({d} tick{'s' if d != 1 else ''} late) < "
            f"INDI_LAM_MARGIN {stab.required_margin:g} at the K box's best floor {stab.link_k_floor:g}")


class FlightControllerProcess:
    """Sockets, clocks and logs around the pure FlightStack (control, modes, failsafes) and the GCS service: the
    sim link's steps (SimStepper), the GCS and API links (GcsLinks, the GCS service's Outbox), one loop."""

    def __init__(self, opts: FcOptions) -> None:
        self.opts = opts
        self.d = dialect_mod.load()
        self.vehicle = vm.VehicleConfig.load(opts.vehicle_path)
        # the floor worker reads the workspace Xi from disk when an earlier start left it (shell/xi_cache.py)
        self.registry = ParamRegistry.from_defaults(
            stability_check=WorkspaceStabilityCheck(workspace_cache=XiDiskCache.default()))
        self._stop = False
        self.model = vm.UamModel(self.vehicle)
        self.mission_view: MissionView | None = None
        self.steps: SimStepper | None = None  # the sim link's control steps (built once the timing is known)
        # A log that cannot be opened (read-only dir, full disk) is reported and the FC flies without one.
        logger, open_error = open_logger(opts.log_path, opts.log_max_mb, opts.log_keep)
        if open_error is not None:
            print(f"navig8-fc: cannot open the log: {open_error}; flying without a log", file=sys.stderr)
        script = load_flight_script(opts.scenario)  # the scenario's setpoint script (a scripted run: AUTO.MISSION)
        self.log = FcLog(logger, open_error, self._mk_foxglove(script, logger), self.model, self._sim_ns)
        self.guard = SimGuard(opts.sysid, SensorLimits.from_vehicle(self.vehicle), lambda: secrets.randbits(32))
        self._spin_until = 0.0
        self._mk_links()
        self.stack = FlightStack(self.vehicle, self.registry, script)
        self.peer = sim_peer_for(self.sim, self.guard, self._bridge_target, opts.sim_messages, bool(opts.sim_link),
                                 self.stack.core.config, origin_from_params(self.registry))
        if isinstance(self.peer, Px4Peer):
            self.log_event("sim link: PX4 simulator messages (HIL_SENSOR, HIL_STATE_QUATERNION; actuator states "
                           "modelled unless NAVIG8_ACTUATOR_STATE comes)")
        self.watchdog = LoopWatchdog()
        state = FcState.open(opts.state_dir, opts.instance)
        self.signing = LinkSigning((self.gcs.mav, self.api.mav), state.signing_key)  # docs/security.md
        self.gcs_service = GcsService(self._mav(), opts.sysid, self.stack.state, self.stack, self.gcs_links,
                                      self.registry, self.vehicle, state.params, state.missions,
                                      autopilot=MAV_AUTOPILOT_PX4 if opts.autopilot == "px4" else MAV_AUTOPILOT_GENERIC,
                                      trusted_sources=self.gcs_links.trusted_sources(),
                                      background_params=True, signing=self.signing,
                                      logs=LogDirectory(opts.log_path.parent) if opts.log_path else None)
        self._stability_logged: StabilityStatus | None = None  # the last /fc/stability record
        self._link_fault: str | None = None  # the sim link's pre-arm failure in force (None: none)
        self.gcs_links.guard(self.gcs_service.admits_peer, lambda: self.signing.active)  # docs/security.md
        state.restore(self.gcs_service, self.signing, opts.defaults, self.log_event)
        self.stack.reconfigure()
        self.timing = timing_from_params(self.registry, opts.timing, time.monotonic())
        if self.timing.realtime:
            self.log_event(f"real-time timing: own clock at {round(1.0 / self.stack.core.config.dt_s)} Hz, newest "
                           "bundle per tick")
        self.guard.monotonic = self.timing.realtime or isinstance(self.peer, Px4Peer)  # PX4: its own IMU rate
        self.steps = SimStepper(self.sim, self.peer, self.timing, self.guard, self.stack, self.vehicle, self.watchdog,
                                lambda: self.log.active, self.announce, self.statustext, self.log_event)
        # Real time: no arming until the link's delay is measured and the floor it needs is in force (a block of
        # answers, ~2.6 s, then the floor's search on the worker), so the link floor engages on the ground, not at
        # takeoff (docs/stability.md, "Over a real-time link"). Lockstep measures nothing: no such check.
        self._link_measured = not self.timing.realtime
        if not self._link_measured:
            self._set_link_fault(LINK_UNMEASURED)
        config = self.stack.core.config
        warm_up_kernels(self.vehicle, config)  # numba's cache loads before the first step, not in it
        if self.logger:
            self.logger.metadata("run", {"scenario": opts.scenario, "controller": CONTROLLERS[config.ckf.mode],
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
    def _mav(self) -> Any:
        m = self.d.MAVLink(None, srcSystem=self.opts.sysid, srcComponent=FC_COMPID)
        m.robust_parsing = True
        return m

    def _mk_foxglove(self, script: Any, logger: Any) -> FoxgloveOutput | None:
        """The Foxglove 3D channels: into the log, and live with --foxglove (docs/foxglove.md)."""
        o = self.opts
        live = None
        if o.foxglove_port is not None:
            live = LiveServer(o.foxglove_host, o.foxglove_port, f"navig8-fc sysid {o.sysid}",
                              DEFAULT_ALLOWED_ORIGINS | set(o.foxglove_origins))
            print(f"navig8-fc: Foxglove WebSocket ws://{o.foxglove_host}:{live.port}", file=sys.stderr)
        if logger is None and live is None:
            return None
        fox = FoxgloveOutput(VehicleViz(self.vehicle, packaged_uav_size_m()), logger, live, "navig8-fc")
        self.mission_view = MissionView(fox, script)
        return fox

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
        self.sim.admit_peer = _no_peer  # the guard decides where the sim link's answers go, never a mere sender
        self.gcs_links = GcsLinks(o, self._mav, FC_COMPID, self.fox, self._sim_ns)
        self.gcs, self.api = self.gcs_links.gcs, self.gcs_links.api
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

    # --- lockstep --------------------------------------------------------------------------------
    def _sim_ns(self) -> int:
        return self.steps.sim_ns() if self.steps is not None else 0

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
        # The stability-floor worker warm before any ground station hears us: its start-up (~1 s: a spawned
        # interpreter, its imports, the workspace) would otherwise fall on the first stability-checked PARAM_SET.
        if not self.gcs_service.param_sets.wait_floor_in_force(FLOOR_READY_WAIT_S):
            self.log_event(f"the stability-floor worker is not ready after {FLOOR_READY_WAIT_S:g} s; going on (the "
                           "first stability-checked PARAM_SET waits for it)")
        socks = {link.sock: link for link in self.links}
        # Everything alive now (imports, numba, the parameter registry) lives for the whole run: a full collection
        # would walk it all (~70 ms here, a stall of several lockstep steps); freezing keeps the collector to the
        # run's own short-lived objects.
        gc.collect()
        gc.freeze()
        hb_due = wall_tick_due = 0.0
        sock_list = list(socks)
        steps = self.steps
        assert steps is not None
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
                        steps.on_sim(got)
                    else:
                        t0 = time.monotonic()
                        self.on_gcs(link, got)
                        self._watch(self.watchdog.gcs_work(time.monotonic() - t0, t0))
                if (due := self.timing.due(time.monotonic())) is not None:
                    steps.on_step(*due)  # (its SimInput, the FC's clock)
                # The step's answer is out: now log (this overlaps with the bridge's physics step).
                if (tick := steps.take_pending()) is not None:
                    self._log_step(tick)
                    if not self.timing.realtime and not steps.paced:
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
                if until_done and steps.sim_done:
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
        steps = self.steps
        assert steps is not None
        notices = self.stack.check_links(now - steps.last_bundle_wall if steps.n_ticks > 0 else None,
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
        mine = self.gcs_links.mine(link, received)  # our own echo or another vehicle's traffic left out
        for change in self.gcs_service.handle(mine, time.monotonic()):  # replies go back to link and sender
            self.log_param_change(change)

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
        self.signing.checkpoint(now)  # the signed streams' timestamps beside the key (replays after a restart)
        if self.steps is not None:
            self.steps.follow_link(self.registry)
        self._link_floor_changes()
        stab = self.gcs_service.stability
        if stab is not None and stab != self._stability_logged:
            self._stability_logged = stab
            self.log.stability(stab)
            if (text := link_margin_warning(stab, self._auto_link_floor)) is not None:
                self.statustext(text, 4)  # MAV_SEVERITY_WARNING
        if stab is not None:
            self._link_check(stab)
        if self.mission_view is not None:  # /foxglove/mission follows the uploaded plan
            m = self.gcs_service.mission
            self.mission_view.show(m.generation, m.plan, self.gcs_service.origin, lambda: self.stack.state().home_ned_m)

    @property
    def _auto_link_floor(self) -> bool:
        return int(self.registry.get(AUTO_PARAM)) == 1

    def _link_check(self, stab: StabilityStatus) -> None:
        """The sim link's pre-arm check: in real time until the delay is measured and its floor is in force, then
        link_fault_reason's (no guarantee left at the floor flown)."""
        if not self._link_measured:
            if self.steps is None or self.steps.link_delay.link != self.registry.link:  # None: not measured yet
                return
            self._link_measured = True  # measured, and the floor in force (`stab`, with any link floor) is its
        if (fault := link_fault_reason(stab, self._auto_link_floor)) != self._link_fault:
            self._set_link_fault(fault)
            if fault is not None:
                self.statustext(f"Arming refused: {fault}", 2)  # MAV_SEVERITY_CRITICAL

    def _set_link_fault(self, fault: str | None) -> None:
        self._link_fault = fault
        self.stack.link_fault(fault)

    def _link_floor_changes(self) -> None:
        """The automatic link floor's changes (navig8_fc/params/link_floor.py): a STATUSTEXT each (what, why, the
        numbers) and a /fc/link_floor record."""
        for found, before, after in self.gcs_service.param_sets.take_link_floor_changes():
            k_param = float(self.registry.get("INDI_KFL_MIN"))
            severity, text = link_floor_text(found, before, after, k_param)
            self.statustext(text, severity)
            rec: dict[str, Any] = {"k_floor_before": before, "k_floor": after, "k_param": k_param,
                                   "k_flown": max(k_param, after), "armed": self.stack.state().armed}
            if found is not None:
                rec.update(link_delay_ticks=found.link.delay_ticks, link_model_told=found.link.model_told,
                           margin_own=found.margin_own, margin=found.margin, required_margin=found.required,
                           lambda_crit=found.lambda_crit, min_eigenvalue=found.floor.min_eigenvalue,
                           meets_margin=found.meets)
            self.log.record("/fc/link_floor", rec)

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
            text = self.log.step(tick, self.sim.codec, self.stack.lambda_min, self.stack.lambda_crit)
        if text is not None:
            self.statustext(text, 3)

    def _guard_stats(self) -> dict[str, Any]:
        errors = self.steps.n_tick_errors if self.steps is not None else 0
        return {**vars(self.guard.counters), "tick_errors": errors, **self.log.stats()}

    def close(self) -> None:
        self.gcs_service.close()
        self.signing.save_timestamp()
        steps = self.steps
        if steps is not None and (tick := steps.take_pending()) is not None and self.log.active:
            self._log_step(tick)
        self._log_step(None)
        meta: dict[str, Any] = {}
        if self.logger:
            meta["link_counters"] = {link.name: vars(link.counters) for link in self.links}
            if steps is not None and steps.sim_status is not None:
                meta["bridge_status"] = steps.sim_status
            meta["fc_stats"] = {"ticks": steps.n_ticks if steps else 0,
                                "duplicates": steps.n_duplicates if steps else 0,
                                "sim_guard": self._guard_stats(), "incomplete_bundles": self.peer.incomplete,
                                **self.watchdog.stats()}
            if (rt_stats := self.timing.stats()) is not None:
                meta["realtime_stats"] = rt_stats
            meta["params_final"] = self.registry.as_dict()
        self.log.close(meta)
        for link in self.links:
            link.close()


def _no_peer(_msg: Any, _addr: tuple[str, int]) -> bool:
    return False


def main(argv: list[str] | None = None) -> int:
    ap = build_arg_parser()
    args = ap.parse_args(argv)
    limit_to_one_thread()  # navig8_fc/blas.py: why
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
