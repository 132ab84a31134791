"""One control step into the log and the Foxglove view (docs/logs.md, "Rates"), the same in both processes: navig8-sim
(tools/sim.py, the in-process runner) and navig8-fc (shell/fc_log.py, after the step's answer has gone out).

Every step: /truth, /analysis/eig (when the plant's truth is known: a bridge sends it, a board does not),
/fc/status, /fc/command. /fc/setpoint when it changes, with the held value again at the step before each change
(so a plot's lines between records are the steps they were at every step) and at the last step (`finish`): a
zero-order hold of these records at any step gives that step's setpoint (navig8_tools.summary reads it so). The
Foxglove 3D channels at their display rates (docs/foxglove.md)."""

from __future__ import annotations

from typing import Any

from navig8_fc.core.controller import ActuatorCommand, ControllerStatus, FcSensors
from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.core.vehicle import UamModel
from navig8_fc.logrecords import eig_record, log_truth_record
from navig8_fc.mavlink.seam import TruthFloats
from navig8_fc.shell.foxglove_out import FoxgloveOutput
from navig8_fc.viz import VehiclePose

SetpointKey = tuple[Any, float, float]  # pos_ned_m, pitch_rad, yaw_rad


class StepLog:
    """The per-step records of one run (logger: shell.mcap_log.McapLogger or None; fox: the 3D view or None)."""

    def __init__(self, logger: Any, fox: FoxgloveOutput | None, model: UamModel) -> None:
        self.logger, self.fox, self.model = logger, fox, model
        self._sp: SetpointKey | None = None  # the setpoint last logged
        self._sp_t = -1  # the step it was logged at
        self._t_prev = -1  # the previous step's time

    def tick(self, t_ns: int, truth: TruthFloats | None, sensors: FcSensors | None, status: ControllerStatus,
             command: ActuatorCommand, setpoint: Setpoint, lambda_min: float, lambda_crit: float,
             publish_ns: int | None = None, status_json: bytes | None = None) -> None:
        """status_json: the status already serialised (mcap_log.dumps_json(status)); `status` then needs only what
        the eigenvalues and the 3D view read (q_est_rad, gi_hat, gc_uam, ref_frd_m: tools/log_writer.py)."""
        fox, tr, st, sp = self.fox, truth, status, setpoint
        if fox is not None and tr is not None and t_ns >= fox.next_due_ns:  # rate-limited inside
            act = tr.actuator_pos  # alpha1, alpha3, w1, w2, w3
            s = sensors
            est = None if s is None else VehiclePose(s.pos_ned_m, s.quat_wxyz, s.duct_tilt_rad, st.q_est_rad)
            fox.step(t_ns, VehiclePose(tr.pos_ned_m, tr.quat_wxyz, act[:2], tr.joint_pos_rad), act[2:],
                     tr.object_mass_kg, est, sp, publish_ns)
        lg = self.logger
        if lg is None:
            return
        if tr is not None:
            lg.log("/truth", t_ns, log_truth_record(tr), publish_ns=publish_ns)
            lg.log("/analysis/eig", t_ns, eig_record(self.model, st, tr, lambda_min, lambda_crit),
                   publish_ns=publish_ns)
        if status_json is None:
            lg.log("/fc/status", t_ns, st, publish_ns=publish_ns)
        else:
            lg.log_json("/fc/status", t_ns, status_json, publish_ns=publish_ns)
        self._setpoint(t_ns, (sp.pos_ned_m, sp.pitch_rad, sp.yaw_rad), publish_ns)
        lg.log("/fc/command", t_ns, command, publish_ns=publish_ns)
        self._t_prev = t_ns

    def _setpoint(self, t_ns: int, sp: SetpointKey, publish_ns: int | None) -> None:
        if sp == self._sp:
            return
        if self._sp is not None and self._sp_t != self._t_prev:
            self._log_setpoint(self._t_prev, self._sp, publish_ns)
        self._log_setpoint(t_ns, sp, publish_ns)
        self._sp, self._sp_t = sp, t_ns

    def _log_setpoint(self, t_ns: int, sp: SetpointKey, publish_ns: int | None) -> None:
        self.logger.log("/fc/setpoint", t_ns, {"pos_ned_m": sp[0], "pitch_rad": sp[1], "yaw_rad": sp[2]},
                        publish_ns=publish_ns)

    def finish(self, publish_ns: int | None = None) -> None:
        """The setpoint held to the last step."""
        if self.logger is not None and self._sp is not None and self._sp_t != self._t_prev:
            self._log_setpoint(self._t_prev, self._sp, publish_ns)
            self._sp_t = self._t_prev
