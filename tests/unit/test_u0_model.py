"""Model-based U0 for the INDI (INDI_U0_SRC = 1): the command flown through the FC's actuator model
(navig8_fc.core.actuator_model), complemented by the measurement.

Checked against independent references: the simulator's own actuator dynamics (sim_bridge.plant, its own
discretisation) with the sensor noise off, a first-order low-pass written here, and the noise a complementary
filter must leave (a closed form)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.core import vehicle as vm
from navig8_fc.core.actuator_model import ActuatorModel
from navig8_fc.core.indi import U0_MEASURED, U0_MODEL, ActuatorLimits, IndiConfig, IndiController, IndiInputs
from sim_bridge.messages import ActuatorCommand as PlantCommand
from sim_bridge.plant import Plant
from sim_bridge.world import load_world

CFG = vm.VehicleConfig.load()
DT = 0.01
LPF_TAU = 0.03


def _indi(src: int, u0_tau_s: float = 0.2, wn: float = 120.0, lpf_tau_s: float = LPF_TAU) -> IndiController:
    return IndiController(IndiConfig(DT, lpf_tau_s, ActuatorLimits.from_vehicle(CFG), u0_src=src, u0_tau_s=u0_tau_s,
                                     act_wn_rad_s=wn, act_zeta=1.0))


def _gc_gi(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mp = vm.mass_properties(CFG, q)
    return vm.control_effectiveness_gc(CFG, mp.com_frd_m), vm.inertia_matrix_gi(mp.inertia_com, mp.mass_kg)


def _lpf(xs: list[np.ndarray], tau_s: float) -> list[np.ndarray]:
    """y_k = y_{k-1} + (1 - e^(-dt/tau)) (x_k - y_{k-1}), y_0 = x_0: the INDI's filter, written out here."""
    a = 1.0 - math.exp(-DT / tau_s)
    ys = [xs[0]]
    for x in xs[1:]:
        ys.append(ys[-1] + a * (x - ys[-1]))
    return ys


def _fly_open_loop(src: int, noise: float, seed: int = 1, n: int = 150) -> tuple[np.ndarray, np.ndarray]:
    """The INDI's commands (a demand stepping every 0.1 s on every axis, so the actuators never settle) drive the
    simulator open loop (the vehicle's motion is not fed back: only the actuators matter here); the INDI's
    filtered U0 per tick and the plant's true actuators (as U) per tick."""
    w = load_world("hover", {"sensor_noise_scale": noise})
    plant = Plant(w.vehicle, w.plant, w.scenario, np.random.default_rng(seed))
    gc, gi = _gc_gi(np.zeros(3))
    gc_inv = np.linalg.inv(gc)
    indi = _indi(src, u0_tau_s=5.0 if noise == 0.0 else 0.2)
    true_u, got_u0 = [], []
    rng = np.random.default_rng(1)
    v = np.zeros(5)
    for k in range(n):
        sb = plant.sense()
        if k % 10 == 0:
            v = rng.normal(0.0, [3.0, 3.0, 1.0, 1.5, 1.5]) - np.array([0.0, 0.0, 0.0, 0.0, 9.81])
        tilt, speed = tuple(sb.duct_tilt_rad.tolist()), tuple(sb.prop_speed_rad_s.tolist())
        out, st = indi.step(IndiInputs((0.0, 0.0, 0.0), (0.0, 0.0, -9.81), tilt, speed, tuple(v), gc, gi, gc_inv))
        true_u.append(np.array(vm.actuators_to_u(*plant.truth().actuator_pos.tolist())))
        got_u0.append(np.array(st.u0_filtered))
        plant.step(PlantCommand(tilt_rad=out.tilt_cmd_rad, speed_rad_s=out.speed_cmd_rad_s), DT)
    return np.array(got_u0), np.array(true_u)


def test_model_u0_equals_the_simulated_actuators_without_sensor_noise() -> None:
    """The plant's actuators follow its own (independently written) second-order dynamics; the FC never reads
    them except through the (here noise-free) sensors, and with a correction time constant of 5 s the model does
    the work: U0 must equal the low-passed true actuators."""
    got, true = _fly_open_loop(U0_MODEL, 0.0)
    assert np.all(np.ptp(true, axis=0)[:4] > 2e4), np.ptp(true, axis=0)  # the duct inputs moved (w^2 ~ 3.6e5)
    want = np.array(_lpf(list(true), LPF_TAU))
    err = np.abs(got - want).max(axis=0)
    np.testing.assert_array_less(err, 1e-6 * np.abs(want).max(axis=0) + 1e-6)


def test_model_u0_keeps_the_speed_sensor_noise_out_of_the_increment() -> None:
    """With the paper's sensor noise (20 rad/s on the speeds, 0.08 rad on the tilts) the measured U0's error
    against the true actuators is the noise through the INDI's low-pass: for the duct's cos input
    2 w sigma_w sqrt(a / (2 - a)) (a = 1 - e^(-dt/tau_L)), ~9.6e3 at w ~ 600 rad/s. The model's estimate leaves
    less than a third of it."""
    rms = {}
    for src in (U0_MEASURED, U0_MODEL):
        got, true = _fly_open_loop(src, 1.0, n=400)
        want = np.array(_lpf(list(true), LPF_TAU))
        rms[src] = np.sqrt(np.mean((got[50:] - want[50:]) ** 2, axis=0))
    a = 1.0 - math.exp(-DT / LPF_TAU)
    w_hover = vm.u_to_actuators(vm.hover_trim(CFG, np.zeros(3), 0.0))[2]
    closed_form = 2.0 * w_hover * 20.0 * math.sqrt(a / (2.0 - a))
    assert rms[U0_MEASURED][0] == pytest.approx(closed_form, rel=0.3), (rms[U0_MEASURED][0], closed_form)
    ratio = rms[U0_MODEL] / rms[U0_MEASURED]
    assert np.all(ratio < 1.0 / 3.0), ratio


def _hover_inputs(indi: IndiController, n: int, bias_speed: float) -> np.ndarray:
    """n ticks at a hover demand with the actuators measured at trim + bias_speed on every speed; filtered U0."""
    q = np.zeros(3)
    gc, gi = _gc_gi(q)
    gc_inv = np.linalg.inv(gc)
    u_trim = vm.hover_trim(CFG, q, 0.0)
    a1, a3, w1, w2, w3 = vm.u_to_actuators(u_trim)
    acc0 = np.linalg.solve(gi, gc @ u_trim)
    u0 = []
    for _ in range(n):
        _, st = indi.step(IndiInputs((0.0, 0.0, 0.0), (acc0[3], 0.0, acc0[4]), (a1, a3),
                                     (w1 + bias_speed, w2 + bias_speed, w3 + bias_speed), tuple(acc0), gc, gi, gc_inv))
        u0.append(st.u0_filtered)
    return np.array(u0)


def test_model_error_is_removed_by_the_measurement() -> None:
    """A steady gap between what the model predicts and what is measured (here +30 rad/s on every speed: a
    sensor offset or a motor that does not reach its command) is taken from the measurement within a few
    INDI_U0_TAU: after 5 tau the estimate sits at the measurement to < 1 %."""
    tau = 0.1
    u0 = _hover_inputs(_indi(U0_MODEL, u0_tau_s=tau), int(5 * tau / DT) + 20, bias_speed=30.0)
    q = np.zeros(3)
    a1, a3, w1, w2, w3 = vm.u_to_actuators(vm.hover_trim(CFG, q, 0.0))
    want = np.array(vm.actuators_to_u(a1, a3, w1 + 30.0, w2 + 30.0, w3 + 30.0))
    np.testing.assert_allclose(u0[-1], want, rtol=1e-2)


def test_disengaging_restarts_the_estimate_at_the_measurement() -> None:
    """measure() (disarmed: no command flown) makes the next engaged tick start from the measured actuators,
    never from a stale command."""
    q = np.zeros(3)
    gc, gi = _gc_gi(q)
    indi = _indi(U0_MODEL, lpf_tau_s=0.0)  # LPF off: U0 is the estimate itself
    a1, a3, w1, w2, w3 = vm.u_to_actuators(vm.hover_trim(CFG, q, 0.0))
    inp = IndiInputs((0.0,) * 3, (0.0, 0.0, -9.81), (a1, a3), (w1, w2, w3), (0.0, 0.0, 0.0, 0.0, -9.81), gc, gi)
    indi.step(inp)  # flies some command
    off = IndiInputs((0.0,) * 3, (0.0, 0.0, 0.0), (0.1, 0.2), (10.0, 0.0, 20.0), (0.0,) * 5, gc, gi)
    _, u0 = indi.measure(off)
    np.testing.assert_allclose(u0, vm.actuators_to_u(0.1, 0.2, 10.0, 0.0, 20.0), rtol=1e-12, atol=1e-9)
    _, st = indi.step(off)
    np.testing.assert_allclose(st.u0_filtered, vm.actuators_to_u(0.1, 0.2, 10.0, 0.0, 20.0), rtol=1e-12, atol=1e-9)


def test_actuator_model_matches_the_simulators_discretisation() -> None:
    """The FC's ActuatorModel against the plant's own actuator trajectory (sim_bridge, noise off) for an
    arbitrary command sequence inside the limits."""
    w = load_world("hover", {"sensor_noise_scale": 0.0})
    plant = Plant(w.vehicle, w.plant, w.scenario, np.random.default_rng(0))
    sb = plant.sense()
    model = ActuatorModel(120.0, 1.0, DT, (*sb.duct_tilt_rad.tolist(), *sb.prop_speed_rad_s.tolist()))
    rng = np.random.default_rng(4)
    for _ in range(40):
        cmd = (rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(400, 700), rng.uniform(-200, 200),
               rng.uniform(400, 700))
        plant.step(PlantCommand(tilt_rad=cmd[:2], speed_rad_s=cmd[2:]), DT)
        want = plant.sense()
        got = model.step(cmd)
        np.testing.assert_allclose(got, (*want.duct_tilt_rad.tolist(), *want.prop_speed_rad_s.tolist()),
                                   rtol=1e-9, atol=1e-9)


def test_bad_u0_source_is_refused() -> None:
    with pytest.raises(ValueError, match="INDI_U0_SRC"):
        _indi(2)


def test_restart_takes_the_running_mean_of_the_measurements() -> None:
    """After a restart the correction gain is 1/(n+1) until it reaches the complementary gain: with the actuators
    holding still (the INDI's increment zero, so the command is U0 and the model predicts no motion) the estimate
    on tick n is exactly the mean of the first n+1 measurements (closed form), not the first sample slowly
    forgotten."""
    q = np.zeros(3)
    gc, gi = _gc_gi(q)
    gc_inv = np.linalg.inv(gc)
    indi = _indi(U0_MODEL, u0_tau_s=0.2, lpf_tau_s=0.0)  # LPF off: U0 is U(estimate); gain 0.049, so n <= 19
    a1, a3, w1, w2, w3 = vm.u_to_actuators(vm.hover_trim(CFG, q, 0.0))
    true = np.array([a1, a3, w1, w2, w3])
    rng = np.random.default_rng(5)
    meas = []
    for _ in range(15):
        m = true + rng.normal(0.0, [0.08, 0.08, 20.0, 20.0, 20.0])
        meas.append(m)
        # zero angular acceleration and v equal to the measured specific force: Delta Acc = 0, U = U0
        _, st = indi.step(IndiInputs((0.0, 0.0, 0.0), (0.0, 0.0, -9.81), (m[0], m[1]), (m[2], m[3], m[4]),
                                     (0.0, 0.0, 0.0, 0.0, -9.81), gc, gi, gc_inv))
        want = vm.actuators_to_u(*np.mean(meas, axis=0))
        np.testing.assert_allclose(st.u0_filtered, want, rtol=1e-9)


def _identify_behind_a_delay(extra_delay_ticks: int, echo: bool, bandwidth_scale: float = 1.0,
                             n: int = 900) -> tuple[float, float]:
    """ACT_ID (from ACT_WN 120 rad/s) on the simulator's actuators (true omega_n 120 rad/s x bandwidth_scale) over a
    link that delivers each command `extra_delay_ticks` periods late (a real-time link: docs/hil.md); echo: the FC
    is told which command the actuators flew (NAVIG8_ACTUATOR_STATE.cmd_time_usec), as the bridge tells it. Open
    loop, a demand stepping every 0.1 s (the transients identify omega_n). Returns the identified (tilt, speed)
    omega_n."""
    w = load_world("hover", {"actuator_bandwidth_scale": bandwidth_scale})
    plant = Plant(w.vehicle, w.plant, w.scenario, np.random.default_rng(3))
    gc, gi = _gc_gi(np.zeros(3))
    gc_inv = np.linalg.inv(gc)
    indi = IndiController(IndiConfig(DT, LPF_TAU, ActuatorLimits.from_vehicle(CFG), u0_src=U0_MODEL, u0_tau_s=0.2,
                                     act_wn_rad_s=120.0, act_zeta=1.0, act_identify=True))
    rng = np.random.default_rng(1)
    v = np.zeros(5)
    in_flight: list[tuple[float, PlantCommand]] = []  # (the sample it answers, the command), oldest first
    flown_t_s = None
    for k in range(n):
        t_s = k * DT
        sb = plant.sense()
        if k % 10 == 0:
            v = rng.normal(0.0, [3.0, 3.0, 1.0, 1.5, 1.5]) - np.array([0.0, 0.0, 0.0, 0.0, 9.81])
        if echo and flown_t_s is not None:
            indi.fly_applied(flown_t_s, t_s)
        tilt, speed = tuple(sb.duct_tilt_rad.tolist()), tuple(sb.prop_speed_rad_s.tolist())
        out, st = indi.step(IndiInputs((0.0, 0.0, 0.0), (0.0, 0.0, -9.81), tilt, speed, tuple(v), gc, gi, gc_inv))
        in_flight.append((t_s, PlantCommand(tilt_rad=out.tilt_cmd_rad, speed_rad_s=out.speed_cmd_rad_s)))
        flown_t_s, cmd = in_flight[0] if len(in_flight) > extra_delay_ticks else in_flight[-1]
        if len(in_flight) > extra_delay_ticks:
            in_flight.pop(0)
        plant.step(cmd, DT)
    return st.act_wn_rad_s


@pytest.mark.parametrize(("extra_delay_ticks", "bandwidth_scale"), [(1, 1.0), (2, 1.0), (1, 0.6)])
def test_identification_flies_the_command_the_link_reports(extra_delay_ticks: int, bandwidth_scale: float) -> None:
    """Over a link that delivers commands late, the identification fed the last tick's command reads the delay as
    a slower actuator (omega_n well below the truth: 77 and 58 rad/s for a true 120 behind 1 and 2 periods); fed
    the command the link reports flown it finds the truth: exactly where it starts at the truth, and within two
    side steps of the bank (x 1.16^2) where it starts elsewhere (a true 0.6 x 120 = 72 rad/s: the noisy tilts'
    estimate wanders one step either side, 77 or 90 rad/s)."""
    true_wn = 120.0 * bandwidth_scale
    blind = _identify_behind_a_delay(extra_delay_ticks, echo=False, bandwidth_scale=bandwidth_scale)
    told = _identify_behind_a_delay(extra_delay_ticks, echo=True, bandwidth_scale=bandwidth_scale)
    assert max(blind) < true_wn / 1.16, blind
    side = 1.16 if bandwidth_scale == 1.0 else 1.16**2
    assert all(true_wn / side <= w <= true_wn * side for w in told), told


def test_identification_without_delay_is_the_same_with_and_without_the_echo() -> None:
    """Lockstep (no extra delay): the command the link reports is the last tick's, so the echo changes nothing."""
    assert _identify_behind_a_delay(0, echo=True) == _identify_behind_a_delay(0, echo=False)
