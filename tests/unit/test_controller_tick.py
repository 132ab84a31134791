"""FlightControllerCore.step (the tick's fast path: packed inputs, views, the components' array entry points)
equals the tick composed of the components' public APIs, built independently from the same config
(AdaptiveLawInputs/AdaptiveLaw.step, outer_loop_step, IndiInputs/IndiController.step), bit for bit, status record
included. No private field of the core is read."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from navig8_fc.core import front_end, g_c
from navig8_fc.core.adaptive_law import AdaptiveLaw, AdaptiveLawConfig, AdaptiveLawInputs
from navig8_fc.core.ckf_config import CkfMode
from navig8_fc.core.controller import (
    JOINT_OBS_TAU_S,
    MOTORS_OFF,
    ActuatorCommand,
    ControllerConfig,
    ControllerStatus,
    FcSensors,
    FlightControllerCore,
)
from navig8_fc.core.indi import IndiController, IndiInputs
from navig8_fc.core.outer_loop import Setpoint, outer_loop_config_array, outer_loop_step
from navig8_fc.core.vehicle import UamModel, VehicleConfig
from navig8_fc.params.registry import ParamRegistry


class _ReferenceTick:
    """The tick composed of the components' public APIs, each built here from the same config (the form
    FlightControllerCore.step had before its fast path): the front-end kernel (joint observer, UAM model, Acc_m,
    U0) on state of its own, AdaptiveLaw.step, outer_loop_step, IndiController.step. The law gets the last
    command's U (CKF_U_SRC), the last INDI saturation flag (CKF_SAT_GATE) and Acc_m at the estimated CoM
    (CKF_ACC_REF, front_end.com_accel_offset)."""

    def __init__(self, vehicle: VehicleConfig, config: ControllerConfig) -> None:
        self.vehicle, self.config = vehicle, config
        self.model = UamModel(vehicle)
        self.adapt = AdaptiveLaw(AdaptiveLawConfig(config.ckf, config.k_min, config.k_max))
        self.indi = IndiController(config.indi)
        self.outer_cfg = outer_loop_config_array(config.outer)
        self.front_state = front_end.FST.zeros()
        self.obs_gain = config.dt_s / (JOINT_OBS_TAU_S + config.dt_s)
        self.last_u_cmd: np.ndarray | None = None
        self.last_saturated = False

    def step(self, s: FcSensors, sp: Setpoint, engaged: bool) -> tuple[ActuatorCommand, ControllerStatus]:
        cfg = self.config
        m_hat = self.adapt.mass_estimate_kg
        m_obj_est = 0.0 if m_hat is None else max(m_hat - self.vehicle.uam_mass_kg, 0.0)
        inertia, rate = np.empty((3, 3)), np.empty((3, 3))
        gc, gc_inv = np.empty((5, 5)), np.empty((5, 5))
        uo, fo = g_c.UO.zeros(), front_end.FO.zeros()
        sens = front_end.TIN.zeros()
        t = front_end.TIN.views(sens)
        t.gyro[:], t.accel[:] = s.gyro_frd_rad_s, s.accel_frd_m_s2
        t.tilt[:], t.speed[:] = s.duct_tilt_rad, s.prop_speed_rad_s
        t.jpos[:], t.jrate[:] = s.joint_pos_rad, s.joint_rate_rad_s
        m = self.model
        front_end.fc_front(self.front_state, cfg.dt_s, self.obs_gain, 1.0 / cfg.dt_s, sens, float(m_obj_est),
                           m.geometry, m.force_per_input, m.moment_o_per_input, inertia, rate, gc, gc_inv, uo, fo,
                           0.0, 0.0)
        f = front_end.FO.views(fo)
        mass = uo[g_c.UO.MASS]
        acc_m = f.acc_m.tolist()
        if cfg.ckf.acc_at_com and not cfg.acc_ref:
            dx, dz = front_end.com_accel_offset(*s.gyro_frd_rad_s, acc_m[1], uo[g_c.UO.CEX], uo[g_c.UO.CEZ])
            acc_m[3] += dx
            acc_m[4] += dz
        gc_law_inv = gc_inv
        if cfg.ckf.gc_at_com and s.gripper_closed and m_obj_est > 0.0:  # the law's G_C about the estimated CoM
            gc_law_inv = np.empty((5, 5))
            assert g_c.gc_inv_about(m.force_per_input, m.moment_o_per_input, uo[g_c.UO.CEX], uo[g_c.UO.CEZ],
                                   np.empty((5, 5)), gc_law_inv)
        gi_hat, adapt_status = self.adapt.step(AdaptiveLawInputs(
            t_s=s.t_s, u_meas=f.u_meas.tolist(), acc_m=acc_m, gc_uam_inv=gc_law_inv, inertia_uam=inertia,
            mass_uam_kg=float(mass), inertia_rate_uam=rate, indi_saturated=self.last_saturated,
            u_cmd=self.last_u_cmd, gripper_closed=s.gripper_closed,
        ))
        outer = indi_status = None
        if engaged:
            outer = outer_loop_step(self.outer_cfg, sp, s.pos_ned_m, s.vel_ned_m_s, s.quat_wxyz, s.gyro_frd_rad_s)
            out, indi_status = self.indi.step(IndiInputs(s.gyro_frd_rad_s, s.accel_frd_m_s2, s.duct_tilt_rad,
                                                         s.prop_speed_rad_s,
                                                         outer.accel_cmd, gc, gi_hat, gc_inv))
            cmd = ActuatorCommand(out.tilt_cmd_rad, out.speed_cmd_rad_s)
            self.last_u_cmd = np.empty(5)
            g_c.actuators_to_u(*cmd.tilt_rad, *cmd.speed_rad_s, self.last_u_cmd, 0)
            self.last_saturated = indi_status.saturated
        else:
            self.last_u_cmd, self.last_saturated = None, False
            self.indi.measure(IndiInputs(s.gyro_frd_rad_s, s.accel_frd_m_s2, s.duct_tilt_rad, s.prop_speed_rad_s,
                                         (0.0,) * 5, gc, gi_hat))
            cmd = MOTORS_OFF
        j = inertia
        return cmd, ControllerStatus(
            t_s=s.t_s, engaged=engaged, q_est_rad=tuple(f.qest.tolist()), qdd_est_rad_s2=tuple(f.qdd.tolist()),
            mass_uam_kg=float(mass), inertia_uam_diag=(float(j[0, 0]), float(j[1, 1]), float(j[2, 2])),
            gi_hat=tuple(gi_hat.ravel().tolist()), gc_uam=tuple(gc.ravel().tolist()), outer=outer,
            indi=indi_status, adapt=adapt_status,
        )


@pytest.mark.parametrize("mode", [CkfMode.CONSTRAINED, CkfMode.UNCONSTRAINED, CkfMode.FIXED])
def test_step_equals_public_api_tick_bit_for_bit(cfg: VehicleConfig, mode: CkfMode) -> None:
    values = ParamRegistry.from_defaults().as_dict()
    # The defaults without the parts the reference composition leaves out (each has its tests: test_reference_point,
    # test_arm_wrench, test_command_shaping, test_flown_gain): the CoM as the INDI's reference point, the arm
    # feed-forward, shaping, the flown loop gain (lambda* and its floor).
    values.update(INDI_ACC_REF=0, INDI_ARM_FF=0, OL_JERK_MAX=0.0, OL_ATT_ACC_REF=0.0, INDI_LAM_REF=1.0,
                  INDI_KFL_MIN=0.0)
    base = ControllerConfig.from_params(values, cfg)
    config = replace(base, ckf=replace(base.ckf, mode=mode, start_delay_s=0.05))
    fast, ref = FlightControllerCore(cfg, config), _ReferenceTick(cfg, config)
    rng = np.random.default_rng(7)
    dt = config.dt_s
    n_projected = 0
    for i in range(400):
        t = i * dt
        w = 620.0 + 40.0 * math.sin(3.0 * t)
        s = FcSensors(
            t_s=t, gyro_frd_rad_s=tuple(rng.normal(0.0, 0.05, 3).tolist()),
            accel_frd_m_s2=(0.3 * math.sin(t), 0.05, -cfg.gravity_m_s2 + 0.2 * math.cos(2.0 * t)),
            pos_ned_m=(0.1 * math.sin(t), 0.0, -2.0), vel_ned_m_s=(0.1, -0.05, 0.0),
            quat_wxyz=(math.cos(0.1 * t), 0.0, math.sin(0.1 * t), 0.0),
            duct_tilt_rad=(0.2 + 0.1 * math.sin(5.0 * t), 0.15), prop_speed_rad_s=(w, 80.0 * math.sin(7.0 * t),
                                                                                   w - 10.0),
            joint_pos_rad=(0.4 * math.sin(t), 0.2, -0.3 * math.sin(0.5 * t)),
            joint_rate_rad_s=(0.4 * math.cos(t), 0.0, -0.15 * math.cos(0.5 * t)),
        )
        sp = Setpoint((0.0, 0.5, -2.0), 0.3, 0.1 * i * dt)
        engaged = not (i < 10 or 200 <= i < 205)  # disengaged ticks at the start and in between
        got = fast.step(s, sp, engaged=engaged)
        want = ref.step(s, sp, engaged)
        assert repr(got) == repr(want), f"tick {i}"
        n_projected += got[1].adapt.x_hat != got[1].adapt.x_unconstrained
    if mode == CkfMode.CONSTRAINED:
        assert n_projected > 10


def test_update_gains_takes_effect_at_the_next_tick(cfg: VehicleConfig) -> None:
    # A core whose outer-loop gains and K bounds change mid-run flies from then on exactly like a core built
    # with the new values (same filter state up to the change), and differently from one that kept the old.
    reg = ParamRegistry.from_defaults()
    # The law learns from the measured U here (CKF_U_SRC = 0) and the INDI's U0 is the measured one (INDI_U0_SRC = 0):
    # from the command's U, the estimate and the U0 model would follow the gains' own history before the change, and
    # the cores would differ for that reason alone.
    reg.set("CKF_U_SRC", 0)
    reg.set("INDI_U0_SRC", 0)
    # Command shaping off: update_gains restarts the shaper's reference (seeded from the vehicle), which a core that
    # had the new gains from the start does not; the gains themselves take effect at once either way.
    reg.set("OL_JERK_MAX", 0.0)
    reg.set("OL_ATT_ACC_REF", 0.0)
    old = ControllerConfig.from_params(reg.as_dict(), cfg)
    values = reg.as_dict()
    values.update(OL_POS_K=float(values["OL_POS_K"]) * 1.5, OL_ATT_K=float(values["OL_ATT_K"]) * 0.7,
                  INDI_K_MIN=0.6)
    new = ControllerConfig.from_params(values, cfg)
    assert new.outer != old.outer and new.indi == old.indi and new.ckf == old.ckf
    changed, built_new, kept_old = (FlightControllerCore(cfg, old), FlightControllerCore(cfg, new),
                                    FlightControllerCore(cfg, old))
    dt = old.dt_s
    for i in range(120):
        t = i * dt
        s = FcSensors(t_s=t, gyro_frd_rad_s=(0.01, -0.02, 0.0), accel_frd_m_s2=(0.1, 0.0, -cfg.gravity_m_s2),
                      pos_ned_m=(0.2 * math.sin(t), 0.1, -1.8), vel_ned_m_s=(0.1, 0.0, 0.05), quat_wxyz=(1.0, 0.0,
                                                                                                         0.0, 0.0),
                      duct_tilt_rad=(0.2, 0.2), prop_speed_rad_s=(620.0, 10.0, 615.0), joint_pos_rad=(0.3, 0.1, -0.2),
                      joint_rate_rad_s=(0.1, 0.0, 0.0))
        sp = Setpoint((0.0, 0.0, -2.0), 0.2, 0.0)
        if i == 60:
            changed.update_gains(new.outer, new.k_min, new.k_max)
        a, b, c = changed.step(s, sp), built_new.step(s, sp), kept_old.step(s, sp)
        if i >= 60:
            assert a[0] == b[0] and a[1].outer == b[1].outer, f"tick {i}"
            assert a[0] != c[0], f"tick {i}: the new gains did not take effect"


def test_saturation_gate_reads_the_indi_status(cfg: VehicleConfig) -> None:
    """The law's saturation flag is the INDI's public IndiStatus.saturated of the previous tick (one-step windows
    make every tick a window, and CKF_LPF_TAU = 0 makes the hold after a saturated step empty): a climb demand near
    full speed saturates the INDI on some ticks and not on others, and the law skips exactly the windows that follow
    a saturated command."""
    base = ControllerConfig.from_params(ParamRegistry.from_defaults().as_dict(), cfg)
    config = replace(base, ckf=replace(base.ckf, inc_window=1, start_delay_s=0.0, sat_gate=True, lpf_tau_s=0.0))
    core = FlightControllerCore(cfg, config)
    prev_sat, n_sat, skips = False, 0, 0
    for i in range(150):
        t = i * config.dt_s
        s = FcSensors(t_s=t, gyro_frd_rad_s=(0.02 * math.sin(9.0 * t), -0.3 * math.sin(3.0 * t), 0.0),
                      accel_frd_m_s2=(0.1, 0.0, -cfg.gravity_m_s2), pos_ned_m=(0.0, 0.0, -2.0), vel_ned_m_s=(0.0, 0.0,
                                                                                                             0.0),
                      quat_wxyz=(1.0, 0.0, 0.0, 0.0), duct_tilt_rad=(0.0, 0.0), prop_speed_rad_s=(930.0, 0.0, 930.0),
                      joint_pos_rad=(0.0, 0.0, 0.0), joint_rate_rad_s=(0.0, 0.0, 0.0))
        sp = Setpoint((0.0, 0.0, -30.0 if (i // 30) % 2 else -2.0), 0.0, 0.0)  # climb demands at full speed
        _, st = core.step(s, sp)
        if i > 0:
            assert st.adapt.saturated == prev_sat, f"tick {i}"
            skips += prev_sat
        assert st.adapt.n_saturation_skips == skips
        prev_sat = st.indi.saturated
        n_sat += prev_sat
    assert 0 < n_sat < 149
