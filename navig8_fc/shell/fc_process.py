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
import gc
import math
import os
import select
import signal
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from navig8_fc.core import stability
from navig8_fc.core import vehicle as vm
from navig8_fc.core.controller import (
    MOTORS_OFF,
    ActuatorCommand,
    ControllerConfig,
    ControllerStatus,
    FcSensors,
    FlightControllerCore,
    warm_up_kernels,
)
from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.core.rotation import quat_to_euler
from navig8_fc.logrecords import dialect_json_schema, mavlink_json_schema, mavlink_record_json, wire_truth_record
from navig8_fc.mavlink import codec, seam
from navig8_fc.mavlink import dialect as dialect_mod
from navig8_fc.modes import MissionScript, ModeConfig, ModeInputs, ModeManager, ModeOutput
from navig8_fc.params.registry import ParamRegistry
from navig8_fc.shell.gcs_service import GcsService
from navig8_fc.shell.mavlink_link import PortInUseError, UdpLink, write_ports_file
from navig8_fc.shell.mcap_log import McapLogger

FC_COMPID = 1
SPIN_S = 0.002  # busy-poll window for the next bundle in lockstep at --speed 0
WALL_TICK_S = 0.001  # GCS services (telemetry schedule, paced parameter list) run at most this often
ESTIMATOR_WARMUP_S = 0.5  # 5 time constants of the INDI feedback filter before arming is allowed
RATE_MISMATCH_STEPS = 3  # consecutive bundle spacings != 1/INDI_RATE_HZ before it is reported (not a glitch)
SEVERITY_CRITICAL, SEVERITY_ERROR, SEVERITY_WARNING, SEVERITY_INFO = 2, 3, 4, 6  # MAV_SEVERITY
FAULT_SENSORS = "sensors"  # ModeManager fault names
FAULT_RATE = "rate"
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
                                   st.gc_uam)


class FlightControllerProcess:
    """Sockets + lockstep tick + GCS services around the pure controller core."""

    def __init__(self, opts: FcOptions) -> None:
        self.opts = opts
        self.d = dialect_mod.load()
        self.vehicle = vm.VehicleConfig.load()
        self.registry = ParamRegistry.from_defaults()
        self._stop = False
        self.logger = McapLogger(opts.log_path) if opts.log_path else None
        # (topic, raw datagram or decoded message, peer for a datagram / None for a message, sim ns, wall ns)
        self._frame_queue: list[tuple[str, Any, str | None, int, int]] = []
        self._pending_tick: tuple[Any, ...] | None = None
        self._sim_channels: dict[tuple[str, str], int] = {}
        self._raw_topics: dict[tuple[str, str], str] = {}  # (link, direction) -> /mavlink/<link>/<direction>
        self._spin_until = 0.0
        self._mk_links()
        self._cfg_generation = -1
        self.core: FlightControllerCore | None = None
        self._reconfigure()
        self.model = vm.UamModel(self.vehicle)
        self._asm = seam.BundleAssembler()
        self.sim_status: Any = None
        self.last_sensors: FcSensors | None = None
        self.mode_out: ModeOutput | None = None
        self._last_step_time_us: int | None = None
        self._last_answer: bytes | None = None  # the frame answering the last step (re-sent on duplicates)
        self.n_ticks = 0
        self.n_duplicates = 0
        self.last_bundle_wall = time.monotonic()
        self._stall_reported = False  # the current sensor outage has been reported (cleared when data is back)
        self._stall_since_wall = 0.0
        self._dt_bad_n = 0  # consecutive bundle spacings that disagree with 1/INDI_RATE_HZ
        self.sim_done = False
        self.last_status: ControllerStatus | None = None
        self.last_cmd: ActuatorCommand = MOTORS_OFF
        self.gcs_service = GcsService(self)  # loads persisted parameters (unless --defaults)
        self._reconfigure()
        assert self.core is not None
        warm_up_kernels(self.vehicle, self.core.config)  # numba's cache loads before the first step, not in it
        if self.logger:
            self.logger.metadata("run", {"scenario": opts.scenario, "controller": self._controller_name(),
                                         "sysid": opts.sysid, "process": "navig8-fc"})
            self.logger.metadata("params", self.registry.as_dict())

    # --- setup -----------------------------------------------------------------------------------
    def _mav(self) -> Any:
        m = self.d.MAVLink(None, srcSystem=self.opts.sysid, srcComponent=FC_COMPID)
        m.robust_parsing = True
        return m

    def _mk_links(self) -> None:
        """Bind the three links (PortInUseError names a busy one; port 0: any free port), write the ports file,
        and announce the FC to the bridge (DESIGN §4: a bridge that does not know our port learns it from this)."""
        o = self.opts
        sim_codec = codec.seam_codec()  # the sim link speaks only the seam's messages, decoded by the codec
        self.sim = UdpLink.open("sim", codec.Encoder(sim_codec, o.sysid, FC_COMPID), (o.host, o.port("sim")),
                                [(o.host, o.port("bridge"))], codec=sim_codec)
        self.sim.max_datagrams = 1  # one bundle per step; more stay readable for the run loop's next select
        self.gcs = UdpLink.open("gcs", self._mav(), (o.bind_host, o.port("gcs_bind")), [(o.gcs_host, o.gcs_port)])
        self.api = UdpLink.open("api", self._mav(), (o.bind_host, o.port("api_bind")), [(o.gcs_host, o.port("api"))])
        if o.ports_file is not None:
            write_ports_file(o.ports_file, {"sim": self.sim.local_port, "gcs": self.gcs.local_port,
                                            "api": self.api.local_port})
        self.sim.send(seam.announce_record())  # before the log hooks: nothing is set up to log it yet
        for link in (self.sim, self.gcs, self.api):
            link.on_datagram = self._log_datagram
        for link in (self.gcs, self.api):  # the sim link's messages are logged decoded as /truth, /fc/...
            link.on_frame = self._log_decoded
        self.links = (self.sim, self.gcs, self.api)

    def _controller_name(self) -> str:
        return {0: "fixed", 1: "unconstrained", 2: "proposed"}[int(self.registry["CKF_MODE"])]

    def _reconfigure(self) -> None:
        """Parameter changes apply at the next control step: gains and bounds swap in place; a change of
        rate, filter or estimator settings rebuilds the core (its filters depend on them)."""
        if self.registry.generation == self._cfg_generation:
            return
        cfg = ControllerConfig.from_params(self.registry.as_dict(), self.vehicle)
        if self.core is None or cfg.indi != self.core.config.indi or cfg.ckf != self.core.config.ckf:
            self.core = FlightControllerCore(self.vehicle, cfg)
        else:
            self.core.update_gains(cfg.outer, cfg.k_min, cfg.k_max)
        self._cfg_generation = self.registry.generation
        step_us = 1e6 / float(self.registry["INDI_RATE_HZ"])  # the bundle spacing this rate needs
        self._dt_lo_us, self._dt_hi_us = math.floor(step_us), math.ceil(step_us)
        self.lambda_crit = stability.lambda_crit(float(self.registry["ACT_WN"]), float(self.registry["ACT_ZETA"]),
                                                 cfg.dt_s, float(self.registry["INDI_LPF_TAU"]))

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
        """The sim link's datagrams (lists of codec.Message records): bundles to _on_step, the bridge's status kept."""
        asm = self._asm
        for r in received:
            for m in r.msg:
                if m.name == "NAVIG8_SIM_STATUS":
                    self.sim_status = seam.decode_sim_status(m.fields)
                    if self.sim_status.state == seam.SIM_STATE_DONE:
                        self.sim_done = True
                    continue
                bundle = asm.add(m)
                if bundle is not None:
                    self._on_step(bundle, asm.completed)

    def _on_step(self, b: seam.StepBundle, wire: dict[str, dict[str, Any]] | None = None) -> None:
        """One lockstep step: control, answer, and queue the step's log records (written after the answer).
        wire: the bundle's messages decoded (field dicts), for the /mavlink/sim/in/<NAME> channels."""
        self.last_bundle_wall = time.monotonic()
        t_us = int(b.time_usec)
        prev_us = self._last_step_time_us
        if t_us == prev_us and self._last_answer is not None:
            self.n_duplicates += 1  # a re-sent bundle: answer with the same command, do not re-run control
            self.sim.send_raw(self._last_answer)
            return
        self._last_step_time_us = t_us
        self._reconfigure()
        if prev_us is not None and not self._dt_lo_us <= t_us - prev_us <= self._dt_hi_us:
            self._step_spacing_off(t_us - prev_us)  # rare: the bridge's --dt disagrees with INDI_RATE_HZ
        elif self._dt_bad_n:
            self._step_spacing_ok()
        sensors = b.fc_sensors()
        armed, engaged, sp = self.flight_state(sensors, imu_fresh=b.imu_fresh)
        assert self.core is not None
        cmd, st = self.core.step(sensors, sp, engaged=engaged)
        self.last_status, self.last_cmd, self.last_sensors = st, cmd, sensors
        self.gcs_service.telemetry.on_tick(sensors.t_s, sensors.speed_rad_s)
        out = seam.pack_actuator_controls(self.sim.mav, t_us, cmd, self.vehicle, armed=armed)
        self._last_answer = out
        arm_cmd = self.gcs_service.pending_arm_cmd
        if arm_cmd is not None:  # before the step's answer, so the bridge applies it on this step
            self.gcs_service.pending_arm_cmd = None
            self.sim.send(seam.encode_arm_cmd(replace(arm_cmd, time_usec=t_us)))
        self.sim.send_raw(out)
        self.n_ticks += 1
        if self.logger:
            self._pending_tick = (t_us, b.truth, st, cmd, sp, wire, out)

    def _mode_manager(self) -> ModeManager:
        sc = self._scenario
        script = None
        if sc.setpoint_steps or sc.armed:  # a scripted scenario (the paper's) runs as AUTO.MISSION

            def setpoint_at(t_s: float) -> Setpoint:
                spc = sc.setpoints(t_s)
                return Setpoint(tuple(spc.pos_ned_m), spc.pitch_rad, spc.yaw_rad)

            script = MissionScript(sc.name, setpoint_at, starts_armed_in_air=sc.armed, duration_s=sc.duration_s)
        return ModeManager(ModeConfig(), script)

    def flight_state(self, s: FcSensors, imu_fresh: bool = True) -> tuple[bool, bool, Setpoint]:
        """(armed, controller engaged, setpoint) from the mode manager, on sim time.

        Pre-arm inputs: sensors are ok when this step's IMU sample is fresh (the bundle is complete by
        construction); the estimator is ready once its filters have run ESTIMATOR_WARMUP_S of sim time."""
        _, _, yaw = quat_to_euler(s.quat_wxyz)
        w1, w2, w3 = s.speed_rad_s
        thrust_n = self.vehicle.k_thrust_duct * (w1 * w1 + w3 * w3) + self.vehicle.k_thrust_tail * w2 * abs(w2)
        weight_n = self.vehicle.uam_mass_kg * self.vehicle.gravity_m_s2
        was_armed = self.modes.armed
        out = self.modes.step(ModeInputs(t_s=s.t_s, pos_ned=s.pos_ned, vel_ned=s.vel_ned, yaw_rad=yaw,
                                         thrust_ratio=thrust_n / weight_n, sensors_ok=imu_fresh,
                                         estimator_ready=self.n_ticks * self.core.config.dt_s
                                         >= ESTIMATOR_WARMUP_S))
        if out.armed and not was_armed and self.core is not None:
            self.core.reset()  # the estimator's start delay counts from arming
        self.mode_out = out
        for ev in out.events:
            self.statustext(ev, severity=6)
        return out.armed, out.engaged, out.setpoint

    def _step_spacing_off(self, d_us: int) -> None:
        """A bundle spacing that is not 1/INDI_RATE_HZ: the controller would run with the wrong timing (its
        filters, the rate limits and the stability analysis all use 1/INDI_RATE_HZ). After RATE_MISMATCH_STEPS
        in a row: report once (STATUSTEXT, /fc/event) and fail pre-arm until the spacings agree again."""
        if d_us <= 0:  # time went back: a restarted bridge (a new run, not a spacing)
            self._dt_bad_n = 0
            return
        self._dt_bad_n += 1
        if self._dt_bad_n != RATE_MISMATCH_STEPS:
            return
        rate = int(self.registry["INDI_RATE_HZ"])
        bridge_ms, need_ms = d_us * 1e-3, 1e3 / rate
        fix = f"navig8-bridge --dt {1.0 / rate:g}"
        if 1_000_000 % d_us == 0 and 20 <= 1_000_000 // d_us <= 1000:
            fix += f" or restore INDI_RATE_HZ {1_000_000 // d_us}"
        text = (f"Control rate mismatch: navig8-bridge steps {bridge_ms:g} ms, INDI_RATE_HZ {rate} needs "
                f"{need_ms:g} ms; fix: {fix}")
        self.modes.set_fault(FAULT_RATE, f"control rate mismatch (bridge {bridge_ms:g} ms, INDI_RATE_HZ {rate}"
                                         f" needs {need_ms:g} ms)")
        self.statustext(text, severity=SEVERITY_ERROR)
        self.log_event(text)

    def _step_spacing_ok(self) -> None:
        if self._dt_bad_n >= RATE_MISMATCH_STEPS and self.modes.clear_fault(FAULT_RATE):
            text = f"Control rate matches navig8-bridge again ({1e3 / float(self.registry['INDI_RATE_HZ']):g} ms)"
            self.statustext(text, severity=SEVERITY_INFO)
            self.log_event(text)
        self._dt_bad_n = 0

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
                  wire: dict[str, Any] | None = None, answer: bytes | None = None) -> None:
        assert self.logger is not None
        t_ns = seam.sim_us_from_time_usec(t_us) * 1000
        w = time.time_ns()
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
        from sim_bridge.scenario import load_scenario  # the FC reads the scenario's script (setpoints)

        self._scenario = load_scenario(self.opts.scenario)
        self.modes = self._mode_manager()
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
                    ready, _, _ = select.select(sock_list, [], [], 0.05)
                for sock in ready:
                    link = socks[sock]
                    got = link.receive()
                    if link is self.sim:
                        self._on_sim(got)
                    else:
                        self.on_gcs(link, got)
                # The step's answer is out: now log (this overlaps with the bridge's physics step).
                if self._pending_tick is not None:
                    tick, self._pending_tick = self._pending_tick, None
                    self._log_tick(*tick)
                    if self.sim_status is None or self.sim_status.speed == 0.0:
                        self._spin_until = time.perf_counter() + SPIN_S  # the next bundle is due very soon
                self._flush_frames()
                now = time.monotonic()
                if now >= hb_due:
                    hb_due = now + 1.0
                    self.on_wall_second(now)
                if now >= wall_tick_due:  # not on every lockstep step: at --speed 0 steps come every ~0.3 ms
                    wall_tick_due = now + WALL_TICK_S
                    self.on_wall_tick(now)
                if until_done and self.sim_done:
                    break
                self._check_timeouts(now)
        finally:
            self.close()
        return 0

    @property
    def sensor_timeout_s(self) -> float:
        return float(self.registry["FS_SENS_TOUT"])

    def _check_timeouts(self, now: float) -> None:
        """Wall-clock watchdogs (lockstep has no sim time without bundles):
        - FS_SENS_TOUT: the bridge went silent -> STATUSTEXT (CRITICAL) naming navig8-bridge once per outage and
          a /fc/event; pre-arm fails (arming DENIED with that reason), an armed vehicle reports
          MAV_STATE_CRITICAL, SYS_STATUS drops the sensor and PREARM_CHECK health bits (Telemetry.snapshot);
          all of it clears, with a STATUSTEXT, when bundles arrive again. The vehicle cannot be commanded
          without bundles; in lockstep the plant waits too;
        - FS_GCS_TOUT: a GCS that sent heartbeats stops while the vehicle is armed in a GCS-commanded mode
          (not a scripted mission) -> land, as PX4's data-link-loss failsafe can."""
        if self.n_ticks > 0:
            if now - self.last_bundle_wall > self.sensor_timeout_s:
                if not self._stall_reported:
                    self._sensors_lost()
            elif self._stall_reported:
                self._sensors_back()
        g = self.gcs_service
        if (g.last_gcs_heartbeat is not None and now - g.last_gcs_heartbeat > float(self.registry["FS_GCS_TOUT"])
                and not g.gcs_lost):
            g.gcs_lost = True
            modes = getattr(self, "modes", None)
            if modes is not None and modes.armed and modes.flight_mode.name != "MISSION" and not modes.landed:
                modes.land()
                self.statustext("GCS link lost: landing", severity=4)
            else:
                self.log_event("GCS link lost")

    def _sensors_lost(self) -> None:
        self._stall_reported = True
        self._stall_since_wall = self.last_bundle_wall
        text = f"no sensor data from navig8-bridge for {self.sensor_timeout_s:.1f} s"
        self.modes.set_fault(FAULT_SENSORS, f"sensors stale: {text}")
        self.statustext(text.capitalize(), severity=SEVERITY_CRITICAL)
        self.log_event(f"{text} (last step t = {self._sim_ns() * 1e-9:.3f} s); waiting")

    def _sensors_back(self) -> None:
        self._stall_reported = False
        self.modes.clear_fault(FAULT_SENSORS)
        text = f"sensor data from navig8-bridge back after {self.last_bundle_wall - self._stall_since_wall:.1f} s"
        self.statustext(text.capitalize(), severity=SEVERITY_INFO)
        self.log_event(text)

    # --- GCS side --------------------------------------------------------------------------------
    def on_gcs(self, link: UdpLink, received: list[Any]) -> None:
        mine = []
        for r in received:
            m = r.msg
            # Our own echo or another vehicle's traffic is not for us (counted, never acted on).
            if m.get_srcSystem() == self.opts.sysid and m.get_srcComponent() == FC_COMPID:
                link.counters.foreign += 1
                continue
            mine.append((m, r.addr))
        self.gcs_service.handle(mine, time.monotonic(), link)  # replies go back to link and sender

    def on_wall_second(self, now: float) -> None:
        pass

    def on_wall_tick(self, now: float) -> None:
        self.gcs_service.poll(now)

    def log_event(self, text: str) -> None:
        print(f"navig8-fc: {text}", file=sys.stderr)
        if self.logger:
            self.logger.log("/fc/event", self._sim_ns(), {"text": text}, publish_ns=time.time_ns())

    def log_param_change(self, change: Any) -> None:
        if self.logger:
            self.logger.log("/fc/param_change", self._sim_ns(), change, publish_ns=time.time_ns())

    def close(self) -> None:
        if self._pending_tick is not None and self.logger:
            tick, self._pending_tick = self._pending_tick, None
            self._log_tick(*tick)
        self._flush_frames()
        if self.logger:
            counters = {link.name: vars(link.counters) for link in self.links}
            self.logger.metadata("link_counters", counters)
            if self.sim_status is not None:
                self.logger.metadata("bridge_status", self.sim_status)
            self.logger.metadata("fc_stats", {"ticks": self.n_ticks, "duplicates": self.n_duplicates,
                                              "incomplete_bundles": self._asm.incomplete})
            self.logger.metadata("params_final", self.registry.as_dict())
            self.logger.close()
            self.logger = None
        for link in self.links:
            link.close()


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
    ap.add_argument("--state-dir", default=None, help="directory for persisted parameters")
    ap.add_argument("--defaults", action="store_true", help="start from default parameters (ignore stored)")
    ap.add_argument("--until-done", action="store_true", help="exit when the bridge reports the scenario done")
    ap.add_argument("--ports-file", default=None,
                    help='after binding, write {"sim": p, "gcs": p, "api": p} here as JSON (for ports given as 0)')
    return ap


def options_from_args(a: argparse.Namespace) -> FcOptions:
    return FcOptions(
        instance=a.instance, scenario=a.scenario, host=a.host, gcs_host=a.gcs_host, bind_host=a.bind_host,
        sim_port=a.sim_port, bridge_port=a.bridge_port, gcs_bind_port=a.gcs_bind_port, gcs_port=a.gcs_port,
        api_bind_port=a.api_bind_port, api_port=a.api_port, log_path=Path(a.log) if a.log else None,
        state_dir=Path(a.state_dir) if a.state_dir else None, defaults=a.defaults,
        ports_file=Path(a.ports_file) if a.ports_file else None,
    )


def main(argv: list[str] | None = None) -> int:
    args = build_arg_parser().parse_args(argv)
    try:
        proc = FlightControllerProcess(options_from_args(args))
    except PortInUseError as e:
        print(f"navig8-fc: {e.strerror}; choose another with {_PORT_OPTIONS[e.link]} (0: any free port)",
              file=sys.stderr)
        return EXIT_USAGE
    signal.signal(signal.SIGINT, proc.request_stop)
    signal.signal(signal.SIGTERM, proc.request_stop)
    rc = proc.run(until_done=args.until_done)
    if proc.opts.log_path:
        print(f"navig8-fc: log {proc.opts.log_path}", file=sys.stderr)
    return rc


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["FcOptions", "FlightControllerProcess", "main", "math", "os"]
