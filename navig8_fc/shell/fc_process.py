"""navig8-fc: the flight-controller process. The only FC code that touches sockets and clocks.

Links (PX4 SITL layout, ports offset per instance N):
- sim link: binds 127.0.0.1:4561+2N, talks to the bridge at 127.0.0.1:4560+2N (lockstep, docs/bridge.md);
- GCS link: binds :18570+N, sends to 14550 (QGroundControl, MAVProxy) until a GCS talks, then replies to it;
- API link: binds :14580+N, sends to 14540+N (MAVSDK, scripts).

Time: control, estimator, modes and sensor timeouts run on the bundle's time_usec (sim time, lockstep);
GCS telemetry, heartbeats and parameter pacing run on the wall clock, so a GCS sees 1 Hz heartbeats
whatever the simulation speed (mavlink_notes §1.3).
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import secrets
import select
import signal
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from navig8_fc.core import vehicle as vm
from navig8_fc.core.controller import ActuatorCommand, ControllerStatus, FlightControllerCore, warm_up_kernels
from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.flight import ArmRequest, FlightStack, Notice, load_flight_script
from navig8_fc.links.mavlink_link import PortInUseError, UdpLink, write_ports_file
from navig8_fc.links.signing import LinkSigning
from navig8_fc.links.sim_guard import BAD_DATA_FAILSAFE_S, SensorLimits, SimGuard, SimInput, StreamRegrouper
from navig8_fc.links.transport import StreamTransport, parse_connection
from navig8_fc.logrecords import dialect_json_schema, mavlink_json_schema, mavlink_record_json, wire_truth_record
from navig8_fc.mavlink import codec, seam
from navig8_fc.mavlink import dialect as dialect_mod
from navig8_fc.mavlink.px4sim import PX4_SIM_MESSAGES, ActuatorModel, Px4SimAssembler
from navig8_fc.mission.executor import planned_path
from navig8_fc.mission.store import MissionStore
from navig8_fc.params.registry import ParamRegistry, StabilityStatus
from navig8_fc.params.store import ParamStore, default_state_path
from navig8_fc.shell.foxglove_out import DEFAULT_PORT as FOXGLOVE_DEFAULT_PORT
from navig8_fc.shell.foxglove_out import FoxgloveOutput, FoxglovePortError, LiveServer, script_waypoints
from navig8_fc.shell.gcs_service import (
    MAV_AUTOPILOT_GENERIC,
    MAV_AUTOPILOT_PX4,
    GcsService,
    Source,
    origin_from_params,
)
from navig8_fc.shell.loop_watchdog import LoopWatchdog
from navig8_fc.shell.mcap_log import open_logger
from navig8_fc.shell.realtime import TIMING_REALTIME, RealtimeClock
from navig8_fc.shell.signing_keys import KeyFile
from navig8_fc.viz import VehiclePose, VehicleViz, packaged_uav_size_m, waypoint_poses

FC_COMPID = 1
SPIN_S = 0.002  # busy-poll window for the next bundle in lockstep at --speed 0
GCS_DATAGRAMS_PER_PASS = 16  # ~2-5 ms of GCS work at most between two looks at the sim link
WALL_TICK_S = 0.001  # GCS services (telemetry schedule, paced parameter list) run at most this often
_GRIPPER_CODES = {None: seam.GRIPPER_NONE, "grab": seam.GRIPPER_GRAB, "release": seam.GRIPPER_RELEASE}
EXIT_USAGE = 2  # bad arguments, or a port in use
_PORT_OPTIONS = {"sim": "--sim-port", "gcs": "--gcs-bind-port", "api": "--api-bind-port"}


@dataclass(frozen=True)
class FcOptions:
    instance: int = 0
    scenario: str = "ground"
    host: str = "127.0.0.1"
    gcs_host: str = "127.0.0.1"
    bind_host: str = "127.0.0.1"
    sim_port: int | None = None
    bridge_port: int | None = None
    gcs_bind_port: int | None = None
    gcs_port: int = 14550
    api_bind_port: int | None = None
    api_port: int | None = None
    log_path: Path | None = None
    state_dir: Path | None = None
    defaults: bool = False
    ports_file: Path | None = None  # written after binding: {"sim": p, "gcs": p, "api": p}
    autopilot: str = "generic"  # HEARTBEAT.autopilot: "generic" or "px4" (docs/gcs.md, "Autopilot identity")
    foxglove_port: int | None = None  # --foxglove[=PORT]: serve the Foxglove channels live (0: any free port)
    foxglove_host: str = "127.0.0.1"
    log_max_mb: float = 1024.0  # --log-max-mb: rotate the log at this size (0: no cap)
    log_keep: int = 4  # --log-keep: rotated parts kept (the oldest is deleted)
    # connection strings (navig8_fc/links/transport.py: udpin:, udpout:, tcp:, tcpin:, serial:) replacing a link's
    # host/port options; None: UDP as the port options say
    sim_link: str | None = None
    gcs_link: str | None = None
    api_link: str | None = None
    sim_messages: str = "navig8"  # --sim-messages: navig8 (the private bundle) or px4 (PX4's simulator messages)
    timing: str | None = None  # --timing lockstep|realtime: overrides the FC_TIMING parameter (docs/hil.md)
    vehicle_path: Path | None = None  # --vehicle: its constants (vehicle.yaml format); None: packaged

    @property
    def sysid(self) -> int:
        return self.instance + 1

    def port(self, name: str) -> int:
        n = self.instance
        defaults = {"sim": 4561 + 2 * n, "bridge": 4560 + 2 * n, "gcs_bind": 18570 + n, "api_bind": 14580 + n,
                    "api": 14540 + n}
        v = getattr(self, f"{name}_port")
        return int(v) if v is not None else defaults[name]


def _eig_record(model: vm.UamModel, st: ControllerStatus, truth: Any, lam_min: float, lam_crit: float
                ) -> dict[str, Any]:
    i = truth.inertia  # NAVIG8_TRUTH: xx, yy, zz, xy, xz, yz about the composite CoM
    j = np.array([[i[0], i[3], i[4]], [i[3], i[1], i[5]], [i[4], i[5], i[2]]], dtype=float)
    return vm.ghat_ginv_eig_record(model, st.q_est_rad, st.gi_hat, truth.com_frd, j, truth.mass, lam_min, lam_crit,
                                   st.gc_uam, st.ref_frd_m)


class FlightControllerProcess:
    """Sockets, clocks and logs around the pure FlightStack (control, modes, failsafes) and the GCS service.
    It is the GCS service's Outbox (`broadcast`, `reply`) over the GCS and API links."""

    def __init__(self, opts: FcOptions) -> None:
        self.opts = opts
        self.d = dialect_mod.load()
        self.vehicle = vm.VehicleConfig.load(opts.vehicle_path)
        self.registry = ParamRegistry.from_defaults()
        self._stop = False
        # A log that cannot be opened (read-only dir, full disk) is reported and the FC flies without one.
        self.logger, self._log_open_error = open_logger(opts.log_path, opts.log_max_mb, opts.log_keep)
        self._log_fail_reported = False
        self.n_log_errors = 0  # exceptions while logging a step (contained: reported, never an exit)
        self.n_tick_errors = 0  # exceptions in the control tick (contained: last command held, land requested)
        self._bad_data_fs = False  # the invalid-sensor-data failsafe is in force
        self._last_cmd: tuple[Any, bool] | None = None  # (command, armed) of the last good tick
        self.guard = SimGuard(opts.sysid, SensorLimits.from_vehicle(self.vehicle), lambda: secrets.randbits(32))
        if self._log_open_error is not None:
            print(f"navig8-fc: cannot open the log: {self._log_open_error}; flying without a log", file=sys.stderr)
        # (topic, raw datagram or decoded message, peer for a datagram / None for a message, sim ns, wall ns)
        self._frame_queue: list[tuple[str, Any, str | None, int, int]] = []
        self._pending_tick: tuple[Any, ...] | None = None
        self._sim_channels: dict[tuple[str, str], int] = {}
        self._raw_topics: dict[tuple[str, str], str] = {}  # (link, direction) -> /mavlink/<link>/<direction>
        self._spin_until = 0.0
        script = load_flight_script(opts.scenario)  # the scenario's setpoint script (a scripted run: AUTO.MISSION)
        self.fox = self._mk_foxglove(script)  # before the links: the ports file names its port
        self._mk_links()
        self.stack = FlightStack(self.vehicle, self.registry, script)
        self.model = vm.UamModel(self.vehicle)
        self.sim_status: Any = None
        self._last_step_time_us: int | None = None
        # PX4's simulator messages (--sim-messages px4): their own assembler, no pairing (docs/hil.md)
        self._px4: Px4SimAssembler | None = None if opts.sim_messages == "navig8" else self._mk_px4_assembler()
        if self._px4 is not None:
            self._sim_to = None  # no pairing: answers go to the link's peer (the simulator that connected)
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
        self.rt = self._mk_timing()
        self.guard.monotonic = self.rt is not None
        warm_up_kernels(self.vehicle, self.core.config)  # numba's cache loads before the first step, not in it
        if self.logger:
            self.logger.metadata("run", {"scenario": opts.scenario, "controller": self._controller_name(),
                                         "sysid": opts.sysid, "process": "navig8-fc"})
            self.logger.metadata("params", self.registry.as_dict())

    # --- setup -----------------------------------------------------------------------------------
    def _mk_px4_assembler(self) -> Px4SimAssembler:
        """PX4's simulator messages as the sensor source (navig8_fc/mavlink/px4sim.py, docs/hil.md)."""
        reg = self.registry
        model = ActuatorModel(float(reg["ACT_WN"]), float(reg["ACT_ZETA"]), 1.0 / float(reg["INDI_RATE_HZ"]),
                              (0.0,) * 5)
        self.log_event("sim link: PX4 simulator messages (HIL_SENSOR, HIL_STATE_QUATERNION; actuator states "
                       "modelled unless NAVIG8_ACTUATOR_STATE comes)")
        return Px4SimAssembler(origin_from_params(reg), model)

    def _mk_timing(self) -> RealtimeClock | None:
        """The real-time mode's clock (navig8_fc/shell/realtime.py), or None in lockstep (FC_TIMING, --timing)."""
        reg = self.registry
        if self.opts.timing is not None:
            reg.set("FC_TIMING", 1.0 if self.opts.timing == "realtime" else 0.0)
        if int(reg["FC_TIMING"]) != TIMING_REALTIME:
            return None
        self.log_event(f"real-time timing: own clock at {int(reg['INDI_RATE_HZ'])} Hz, newest bundle per tick")
        return RealtimeClock(float(reg["INDI_RATE_HZ"]), float(reg["RT_LATE_S"]), float(reg["RT_SPACING_TOL"]),
                             time.monotonic())

    def _mav(self) -> Any:
        m = self.d.MAVLink(None, srcSystem=self.opts.sysid, srcComponent=FC_COMPID)
        m.robust_parsing = True
        return m

    def _mk_foxglove(self, script: Any) -> FoxgloveOutput | None:
        """The Foxglove 3D channels: into the log, and live with --foxglove (docs/foxglove.md)."""
        o = self.opts
        live = None
        if o.foxglove_port is not None:
            live = LiveServer(o.foxglove_host, o.foxglove_port, f"navig8-fc sysid {o.sysid}")
            print(f"navig8-fc: Foxglove WebSocket ws://{o.foxglove_host}:{live.port}", file=sys.stderr)
        if self.logger is None and live is None:
            return None
        fox = FoxgloveOutput(VehicleViz(self.vehicle, packaged_uav_size_m()), self.logger, live, "navig8-fc")
        self._script_waypoints = script_waypoints(script)
        self._fox_plan_generation: int | None = None  # the uploaded plan last drawn on /foxglove/mission
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
        self._stream_sim = isinstance(self.sim.sock, StreamTransport)
        self._regroup = StreamRegrouper().split  # a stream's reads cut anywhere between frames: one bundle each
        self._sim_to: list[tuple[str, int]] | None = []  # answers go to the paired bridge only (sim_guard)
        self.sim.send(self.guard.announce_record(), [self._bridge_target])  # before the log hooks are set up
        for link in (self.sim, self.gcs, self.api):
            link.on_datagram = self._log_datagram
        for link in (self.gcs, self.api):  # the sim link's messages are logged decoded as /truth, /fc/...
            link.on_frame = self._log_decoded
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

    # --- logging ---------------------------------------------------------------------------------
    def _log_datagram(self, link: str, direction: str, raw: bytes, peer: str) -> None:
        """Queue a datagram (raw, as it crossed the link) for the log; `_flush_frames` writes the queue after the
        step's answer has gone out, so logging overlaps with the bridge's physics step instead of delaying the
        lockstep round trip."""
        if self.logger:
            topic = self._raw_topics.get((link, direction))
            if topic is None:
                topic = self._raw_topics[(link, direction)] = f"/mavlink/{link}/{direction}"
            self._frame_queue.append((topic, raw, peer, self._sim_ns(), time.time_ns()))

    def _log_decoded(self, link: str, direction: str, raw: bytes, msg: Any, peer: tuple[str, int]) -> None:
        """Queue a decoded GCS/API message for its /mavlink/<link>/<dir>/<TYPE> channel."""
        if self.logger:
            self._frame_queue.append((f"/mavlink/{link}/{direction}/{msg.get_type()}", msg, None, self._sim_ns(),
                                      time.time_ns()))

    def _flush_frames(self) -> None:
        q, self._frame_queue = self._frame_queue, []
        if not self.logger:
            return
        for topic, item, peer, t_ns, wall_ns in q:
            if peer is not None:  # a raw datagram
                self.logger.log_raw(topic, t_ns, item, publish_ns=wall_ns, peer=peer)
            else:  # a decoded GCS message (pymavlink)
                self.logger.log(topic, t_ns, item.to_dict(), publish_ns=wall_ns, schema=mavlink_json_schema(type(item)))

    def _sim_ns(self) -> int:
        return seam.sim_us_from_time_usec(self._last_step_time_us) * 1000 if self._last_step_time_us else 0

    # --- lockstep --------------------------------------------------------------------------------
    def _on_sim(self, received: list[Any]) -> None:
        """The sim link's datagrams (codec.Message records per datagram) through the guard (pairing, sequencing,
        validation: navig8_fc/links/sim_guard.py): steps to _on_step, the paired bridge's status kept."""
        guard = self.guard
        now = time.monotonic()
        for r in received:
            if self._px4 is not None:  # PX4's simulator messages: no pairing or sequencing (docs/hil.md)
                self._on_px4(r.msg, now)
                continue
            for msgs in (self._regroup(r.msg) if self._stream_sim else (r.msg,)):
                inp, announce_to = guard.on_datagram(msgs, r.addr, now)
                if announce_to is not None:  # a bridge asked to pair: our announcement with a fresh nonce
                    self.sim.send(guard.announce_record(), [announce_to])
                if guard.peer is not None and self._sim_to[:1] != [guard.peer]:
                    self._sim_to = [guard.peer]
                kind = inp.kind
                if kind == "step":
                    if self.rt is not None:  # real time: the newest step waits for the FC's next tick
                        self.last_bundle_wall = now
                        self.rt.offer(inp.bundle, inp, now)
                    else:
                        self._on_step(inp)
                elif kind == "duplicate":
                    self.n_duplicates += 1  # a re-sent bundle: answer with the same command, do not re-run control
                    if self._last_answer is not None and self.rt is None:
                        self.sim.send_raw(self._last_answer, self._sim_to)
                elif kind == "status":
                    self._on_sim_status(inp.status)
        if guard.has_reports:  # refusals: the first of each kind at once, then one per kind and period
            for severity, text in guard.reports(now):
                self.statustext(text, severity)

    def _on_sim_status(self, status: seam.SimStatus) -> None:
        self.sim_status = status
        if status.state == seam.SIM_STATE_DONE:
            self.sim_done = True

    def _on_px4(self, msgs: list[Any], now: float) -> None:
        """PX4's simulator messages (navig8_fc/mavlink/px4sim.py): HIL_SENSOR completes a step."""
        asm = self._px4
        assert asm is not None
        for m in msgs:
            if m.name == "NAVIG8_SIM_STATUS":
                self._on_sim_status(seam.decode_sim_status(m.fields))
                continue
            bundle = asm.add(m)
            if bundle is None:
                continue
            inp = SimInput("step", bundle, dict(asm.completed))
            if self.rt is not None:
                self.last_bundle_wall = now
                self.rt.offer(bundle, inp, now)
            else:
                self._on_step(inp)

    def _on_step(self, inp: SimInput, clock_us: int | None = None) -> None:
        """One lockstep step: control, answer, and queue the step's log records (written after the answer).
        An exception in the tick holds the last command and lands (reported, counted), never ends the process."""
        self.last_bundle_wall = time.monotonic()
        b = inp.bundle
        assert b is not None
        t_us = int(b.time_usec)
        if inp.bad_groups:
            if not self.guard.has_good:
                return  # nothing valid to fly on yet: no answer (the bridge re-sends; counted by the guard)
            self._check_bad_data(inp.bad_groups)
        elif self._bad_data_fs:
            self._bad_data_fs = False
            self.statustext("Sensor data valid again", 6)
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
        if res.arm_request is not None:  # before the step's answer, so the bridge applies it on this step
            self.sim.send(seam.encode_arm_cmd(_arm_command(res.arm_request, t_us)), self._sim_to)
        self.sim.send_raw(out, self._sim_to)
        if self._px4 is not None:  # the actuator model's input: what the simulator will hold
            self._px4.command(cmd.tilt_rad, cmd.speed_rad_s)
            if res.arm_request is not None and res.arm_request.joint_target_rad is not None:
                self._px4.joint_target_rad = res.arm_request.joint_target_rad
        self.n_ticks += 1
        self.announce(res.notices)
        paced = self.sim_status is not None and self.sim_status.speed > 0.0
        self._watch(self.watchdog.step(self.last_bundle_wall, paced))
        if self.logger or self.fox:
            self._pending_tick = (t_us, b.truth, res.status, cmd, res.setpoint, inp.wire, out, sensors)

    def _check_bad_data(self, groups: tuple[str, ...]) -> None:
        """Invalid sensor data for BAD_DATA_FAILSAFE_S of sim time: land (the guard holds the last good values)."""
        if self._bad_data_fs or self.guard.bad_data_s() < BAD_DATA_FAILSAFE_S:
            return
        self._bad_data_fs = True
        verb = "landing" if self.stack.state().armed and self.stack.land().ok else "no action"
        self.statustext(f"Bad sensor data ({','.join(groups)}) {self.guard.bad_data_s():.2f} s: {verb}", 2)

    def _tick_failed(self, e: Exception, t_us: int) -> None:
        """The tick raised: answer the step with the last good command (the bridge must not stall), ask the stack to
        land, and report (the first error at once, then every 100th)."""
        self.n_tick_errors += 1
        if self.n_tick_errors == 1 or self.n_tick_errors % 100 == 0:
            print(f"navig8-fc: control tick failed at t={seam.sim_us_from_time_usec(t_us) * 1e-6:.3f} s "
                  f"({self.n_tick_errors}x): {type(e).__name__}: {e}", file=sys.stderr)
            try:
                verb = "landing" if self.stack.land().ok else "holding the last command"
            except Exception:  # noqa: BLE001 - the stack itself is failing: the held command is all there is
                verb = "holding the last command"
            self.statustext(f"Control error {type(e).__name__} ({self.n_tick_errors}x): {verb}", 2)
        if self._last_cmd is not None:
            cmd, armed = self._last_cmd
            self._last_answer = seam.pack_actuator_controls(self.sim.mav, t_us, cmd, self.vehicle, armed=armed)
            self.sim.send_raw(self._last_answer, self._sim_to)

    def _watch(self, note: str | None) -> None:
        """The watchdog's rate-limited report: /fc/event and stderr (a loaded host overruns too: not a STATUSTEXT)."""
        if note is not None:
            self.log_event(note)

    def statustext(self, text: str, severity: int = 6) -> None:
        """STATUSTEXT to every GCS (and the log keeps it)."""
        self.gcs_service.statustext(text, severity)
        if self.logger:
            self.logger.log("/fc/statustext", self._sim_ns(), {"severity": severity, "text": text},
                            publish_ns=time.time_ns())


    def _sim_channel(self, direction: str, name: str) -> int:
        """The decoded /mavlink/sim/<direction>/<NAME> channel (schema from the message definition)."""
        cid = self._sim_channels.get((direction, name))
        if cid is None:
            assert self.logger is not None
            cid = self._sim_channels[(direction, name)] = self.logger.json_channel(
                f"/mavlink/sim/{direction}/{name}", dialect_json_schema(name))
        return cid

    def _log_tick(self, t_us: int, tr: Any, st: ControllerStatus, cmd: ActuatorCommand, sp: Setpoint,
                  wire: dict[str, Any] | None = None, answer: bytes | None = None, sensors: Any = None) -> None:
        t_ns = seam.sim_us_from_time_usec(t_us) * 1000
        w = time.time_ns()
        fox = self.fox
        if fox is not None and tr is not None and t_ns >= fox.next_due_ns:  # the Foxglove 3D channels, rate-limited
            act = tr.actuators  # NAVIG8_TRUTH: alpha1, alpha3, w1, w2, w3
            est = None if sensors is None else VehiclePose(sensors.pos_ned, sensors.quat_wxyz, sensors.tilt_rad,
                                                           st.q_est_rad)
            fox.step(t_ns, VehiclePose(tr.pos_ned, tr.quat, act[:2], tr.joint_pos), act[2:], tr.object_mass, est,
                     sp, w)
        if self.logger is None:
            return
        # The sim link decoded, as the GCS links are: the FC's raw sensor inputs and its answer, plottable.
        # NAVIG8_TRUTH's decoded form is /truth. Lean path: channel ids cached, orjson straight to the writer.
        if wire:
            for name, m in wire.items():  # codec.Message records (BundleAssembler.completed)
                if name != "NAVIG8_TRUTH":
                    self.logger.log_json_bytes(self._sim_channel("in", name), t_ns, mavlink_record_json(m), w)
        if answer is not None:
            got = self.sim.codec.decode_frame(answer) if self.sim.codec is not None else None
            if got is not None:
                self.logger.log_json_bytes(self._sim_channel("out", got.name), t_ns, mavlink_record_json(got), w)
        if tr is not None:
            self.logger.log("/truth", t_ns, wire_truth_record(tr), publish_ns=w)
            self.logger.log("/analysis/eig", t_ns, _eig_record(self.model, st, tr,
                                                               float(self.registry["INDI_LAMBDA_MIN"]),
                                                               self.lambda_crit), publish_ns=w)
        self.logger.log("/fc/status", t_ns, st, publish_ns=w)
        self.logger.log("/fc/setpoint", t_ns, {"pos_ned": sp.pos_ned, "pitch_rad": sp.pitch_rad,
                                               "yaw_rad": sp.yaw_rad}, publish_ns=w)
        self.logger.log("/fc/command", t_ns, cmd, publish_ns=w)

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
                    wait = 0.05 if self.rt is None else min(0.05, self.rt.timeout_s(time.monotonic()))
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
                if self.rt is not None and (due := self.rt.tick(time.monotonic())) is not None:
                    self._on_step(due[1], due[2])  # (bundle, its SimInput, the FC's clock)
                # The step's answer is out: now log (this overlaps with the bridge's physics step).
                if self._pending_tick is not None:
                    tick, self._pending_tick = self._pending_tick, None
                    self._log_step(tick)
                    if self.rt is None and (self.sim_status is None or self.sim_status.speed == 0.0):
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
        if self.guard.needs_announce(now):  # unpaired or the bridge silent: announce, for a bridge started after us
            self.sim.send(self.guard.announce_record(), [self._bridge_target])
        for severity, text in self.guard.reports(now):  # counts held back within a period
            self.statustext(text, severity)
        if self._log_open_error is not None and not self._log_fail_reported:
            self._log_fail_reported = True  # at the first wall second: a GCS that is already listening hears it
            self.statustext(f"Log disabled: {self._log_open_error}", 3)
        if self.logger is not None:
            try:
                self.logger.log("/fc/sim_guard", self._sim_ns(), self._guard_stats(), publish_ns=time.time_ns())
            except Exception as e:  # noqa: BLE001 - logging must never end the flight
                self.n_log_errors += 1
                self.logger.fail(f"{type(e).__name__}: {e}")
        if self.rt is not None and (text := self.rt.report(now)) is not None:
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
        """/fc/stability: lambda_crit, the guaranteed min eigenvalue and the margin of the configuration in force
        (LAM_CRIT, LAM_MARGIN), once at start and again whenever a parameter they depend on changes them."""
        if self.logger:
            rec = {**dataclasses.asdict(stab), "meets_margin": stab.meets_margin}
            self.logger.log("/fc/stability", self._sim_ns(), rec, publish_ns=time.time_ns())

    def log_event(self, text: str) -> None:
        print(f"navig8-fc: {text}", file=sys.stderr)
        if self.logger:
            self.logger.log("/fc/event", self._sim_ns(), {"text": text}, publish_ns=time.time_ns())

    def log_param_change(self, change: Any) -> None:
        if self.logger:
            self.logger.log("/fc/param_change", self._sim_ns(), change, publish_ns=time.time_ns())

    def _log_step(self, tick: tuple[Any, ...] | None) -> None:
        """Log a step's records (tick) or the queued datagrams (None). Contained: an exception here is counted
        and reported and logging stops; a logger that lost its file (disk full) drops and counts by itself."""
        try:
            if tick is not None:
                self._log_tick(*tick)
                if self.logger is not None:
                    self.logger.maybe_rotate()  # once per step: the size check is a syscall
            else:
                self._flush_frames()
        except Exception as e:  # noqa: BLE001 - logging must never end the flight
            self.n_log_errors += 1
            self._frame_queue.clear()
            if self.logger is not None:
                self.logger.fail(f"{type(e).__name__}: {e}")
        lg = self.logger
        if lg is not None and lg.error is not None and not self._log_fail_reported:
            self._log_fail_reported = True
            self.statustext(f"Log stopped: {lg.error}", 3)
            print(f"navig8-fc: logging stopped ({lg.error}); records from now on are dropped and counted",
                  file=sys.stderr)

    def _guard_stats(self) -> dict[str, Any]:
        lg = self.logger
        return {**vars(self.guard.counters), "tick_errors": self.n_tick_errors, "log_errors": self.n_log_errors,
                "log_dropped": lg.dropped if lg is not None else 0, "log_rotations": lg.rotations if lg else 0,
                "log_error": (lg.error if lg is not None else self._log_open_error)}

    def close(self) -> None:
        self.gcs_service.close()
        self.signing.save_timestamp()
        if self._pending_tick is not None and (self.logger or self.fox):
            tick, self._pending_tick = self._pending_tick, None
            self._log_step(tick)
        self._log_step(None)
        if self.logger and self.logger.error is not None:
            print(f"navig8-fc: log {self.logger.path}: {self.logger.dropped} records dropped after "
                  f"{self.logger.error}", file=sys.stderr)
        if self.logger:
            counters = {link.name: vars(link.counters) for link in self.links}
            self.logger.metadata("link_counters", counters)
            if self.sim_status is not None:
                self.logger.metadata("bridge_status", self.sim_status)
            self.logger.metadata("fc_stats", {"ticks": self.n_ticks, "duplicates": self.n_duplicates,
                                              "sim_guard": self._guard_stats(),
                                              "incomplete_bundles": self._px4.incomplete if self._px4 else 0,
                                              **self.watchdog.stats()})
            if self.rt is not None:
                self.logger.metadata("realtime_stats", vars(self.rt.stats))
            self.logger.metadata("params_final", self.registry.as_dict())
            self.logger.close()
            self.logger = None
        if self.fox is not None:
            self.fox.close()
            self.fox = None
        for link in self.links:
            link.close()


def _arm_command(req: ArmRequest, t_us: int) -> seam.ArmCommand:
    return seam.ArmCommand(t_us, req.joint_target_rad, _GRIPPER_CODES[req.gripper])


def build_arg_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="navig8-fc", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--instance", type=int, default=0, help="sysid N+1, all ports offset by N")
    ap.add_argument("--scenario", default="ground")
    ap.add_argument("--host", default="127.0.0.1", help="sim-link host (bridge)")
    ap.add_argument("--gcs-host", default="127.0.0.1", help="where to send GCS/API traffic before a peer talks")
    ap.add_argument("--bind-host", default="127.0.0.1", help="address the GCS/API links bind (0.0.0.0 in Docker)")
    ap.add_argument("--sim-port", type=int, default=None)
    ap.add_argument("--bridge-port", type=int, default=None)
    ap.add_argument("--gcs-bind-port", type=int, default=None)
    ap.add_argument("--gcs-port", type=int, default=14550)
    ap.add_argument("--api-bind-port", type=int, default=None)
    ap.add_argument("--api-port", type=int, default=None)
    ap.add_argument("--log", default=None, help="MCAP log path")
    ap.add_argument("--log-max-mb", type=float, default=FcOptions.log_max_mb,
                    help="rotate the log at this size in MB: PATH, PATH-stem.1.mcap, ... (0: no cap; docs/logs.md)")
    ap.add_argument("--log-keep", type=int, default=FcOptions.log_keep,
                    help="log parts kept when rotating (the oldest is deleted)")
    ap.add_argument("--state-dir", default=None, help="directory for persisted parameters")
    ap.add_argument("--defaults", action="store_true", help="start from default parameters (ignore stored)")
    ap.add_argument("--autopilot", choices=["generic", "px4"], default="generic",
                    help="HEARTBEAT.autopilot: generic (default) or px4 (QGroundControl's mode menu; docs/gcs.md)")
    ap.add_argument("--until-done", action="store_true", help="exit when the bridge reports the scenario done")
    ap.add_argument("--ports-file", default=None,
                    help='after binding, write {"sim": p, "gcs": p, "api": p} here as JSON (for ports given as 0; '
                         'with --foxglove also "foxglove")')
    ap.add_argument("--foxglove", nargs="?", type=int, const=FOXGLOVE_DEFAULT_PORT, default=None, metavar="PORT",
                    help=f"serve the Foxglove 3D channels live over WebSocket (default port {FOXGLOVE_DEFAULT_PORT}; "
                         "0: any free port)")
    ap.add_argument("--foxglove-host", default="127.0.0.1", help="address the Foxglove server binds")
    conn = ("a connection string instead of the port options: udpin:H:P, udpout:H:P, tcp:H:P, tcpin:H:P, "
            "serial:DEVICE:BAUD (docs/hil.md)")
    ap.add_argument("--sim-link", default=None, metavar="CONN", help=f"the bridge/simulator link as {conn}; PX4's "
                    "simulator interface is tcp:127.0.0.1:4560")
    ap.add_argument("--gcs-link", default=None, metavar="CONN", help=f"the GCS link as {conn}")
    ap.add_argument("--api-link", default=None, metavar="CONN", help=f"the API link as {conn}")
    ap.add_argument("--sim-messages", choices=["navig8", "px4"], default="navig8",
                    help="what the sim link carries: navig8 (the private bundle, docs/bridge.md) or px4 (PX4's "
                         "simulator messages HIL_SENSOR + HIL_STATE_QUATERNION; docs/hil.md)")
    ap.add_argument("--vehicle", default=None, metavar="FILE",
                    help="the vehicle's constants (params/vehicle.yaml's format; default the packaged file): a board's "
                         "own airframe, or the world navig8-sitl --world gives the bridge (navig8-bridge "
                         "--write-fc-vehicle)")
    ap.add_argument("--timing", choices=["lockstep", "realtime"], default=None,
                    help="timing mode, overriding the FC_TIMING parameter: lockstep (one step per bundle) or realtime "
                         "(own clock at INDI_RATE_HZ; the bridge then runs --free-run; docs/hil.md)")
    return ap


def options_from_args(a: argparse.Namespace) -> FcOptions:
    return FcOptions(
        instance=a.instance, scenario=a.scenario, host=a.host, gcs_host=a.gcs_host, bind_host=a.bind_host,
        sim_port=a.sim_port, bridge_port=a.bridge_port, gcs_bind_port=a.gcs_bind_port, gcs_port=a.gcs_port,
        api_bind_port=a.api_bind_port, api_port=a.api_port, log_path=Path(a.log) if a.log else None,
        state_dir=Path(a.state_dir) if a.state_dir else None, defaults=a.defaults,
        ports_file=Path(a.ports_file) if a.ports_file else None, autopilot=a.autopilot, foxglove_port=a.foxglove,
        foxglove_host=a.foxglove_host, log_max_mb=a.log_max_mb, log_keep=a.log_keep, sim_link=a.sim_link,
        gcs_link=a.gcs_link, api_link=a.api_link, timing=a.timing, sim_messages=a.sim_messages,
        vehicle_path=Path(a.vehicle) if a.vehicle else None,
    )


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
    if proc.opts.log_path and proc._log_open_error is None:
        print(f"navig8-fc: log {proc.opts.log_path}", file=sys.stderr)
    return rc


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["FcOptions", "FlightControllerProcess", "main"]
