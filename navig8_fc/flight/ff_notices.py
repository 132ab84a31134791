"""What the flight stack says about the model-based feed-forwards' checks (docs/model.md, "Feed-forward that cannot
hurt"): the arm preview withdrawn (a WARNING when its trust falls to 0 from above it, the servo model's error
named), the arm servo and the actuators re-identified (INFO, when an estimate moved by more than 10 % from the one
last announced), the actuator model distrusted and trusted again. Pure: the controller's status in, notices out."""

from __future__ import annotations

from navig8_fc.core.controller import ControllerConfig, ControllerStatus
from navig8_fc.flight.state import SEVERITY_INFO, SEVERITY_WARNING, Notice


class FeedforwardNotices:
    """What was last announced, so each change is said once."""

    def __init__(self, act_wn_rad_s: float, arm_servo_vmax_rad_s: float, arm_servo_amax_rad_s2: float) -> None:
        self._last: dict = {"arm_drops": 0, "arm_idents": 0, "u0_trusted": True,
                            "act_wn": (act_wn_rad_s, act_wn_rad_s),
                            "arm_servo": (arm_servo_vmax_rad_s, arm_servo_amax_rad_s2)}

    @staticmethod
    def of(config: ControllerConfig) -> FeedforwardNotices:
        """Starting from the models' parameters of `config` (ACT_WN, ARM_SERVO_VMAX, ARM_SERVO_AMAX)."""
        ap = config.indi.arm_preview
        return FeedforwardNotices(config.indi.act_wn_rad_s, ap.v_max_rad_s, ap.a_max_rad_s2)

    def new_core(self) -> None:
        """A rebuilt controller core counts its checks' events from zero."""
        self._last.update(arm_drops=0, arm_idents=0)

    def notices(self, st: ControllerStatus) -> list[Notice]:
        out: list[Notice] = []
        last = self._last
        ff, ind = st.ff, st.indi
        if ff is not None and ff.arm_drops > last["arm_drops"]:
            last["arm_drops"] = ff.arm_drops
            out.append(Notice(SEVERITY_WARNING, f"Arm preview off: the joints move {ff.arm_err_rad_s:.2f} "
                              "rad/s off the servo model; flying the measured reaction"))
        if ff is not None and ff.arm_idents > last["arm_idents"]:
            last["arm_idents"] = ff.arm_idents
            v0, a0 = last["arm_servo"]
            if abs(ff.arm_v_hat_rad_s - v0) > 0.1 * v0 or abs(ff.arm_a_hat_rad_s2 - a0) > 0.1 * a0:
                last["arm_servo"] = (ff.arm_v_hat_rad_s, ff.arm_a_hat_rad_s2)
                out.append(Notice(SEVERITY_INFO, f"Arm servo identified: {ff.arm_v_hat_rad_s:.2f} rad/s, "
                                  f"{ff.arm_a_hat_rad_s2:.1f} rad/s^2"))
        if ind is not None and ind.act_wn_rad_s[0] > 0.0:
            wt, ws = ind.act_wn_rad_s
            t0, s0 = last["act_wn"]
            if abs(wt - t0) > 0.1 * t0 or abs(ws - s0) > 0.1 * s0:
                last["act_wn"] = (wt, ws)
                out.append(Notice(SEVERITY_INFO, f"Actuator bandwidth identified: tilt {wt:.0f} rad/s, "
                                  f"speed {ws:.0f} rad/s"))
            if ind.u0_model_trusted != last["u0_trusted"]:
                last["u0_trusted"] = ind.u0_model_trusted
                rt, rs = ind.act_innov_rms
                out.append(
                    Notice(SEVERITY_INFO, "Actuator model agrees with the measurement again: model U0") if
                    ind.u0_model_trusted else
                    Notice(SEVERITY_WARNING, f"Actuator model off (innovation {rt:.2f} rad, {rs:.0f} rad/s): "
                           "flying the measured U0"))
        return out
