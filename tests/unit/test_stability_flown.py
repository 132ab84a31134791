"""The configuration actually flown: lambda_crit with the model-based U0 and a mismatched actuator model, the sampled
loop, the stated margin (INDI_LAM_MARGIN) over MAVLink, and the live LAM_CRIT / LAM_MARGIN telemetry.

Independent checks: the Routh-Hurwitz boundary of Eq. 13 in closed form, a state-space of the loop assembled block by
block with scipy.signal (its eigenvalues against the characteristic polynomial derived in core.stability), and the
z-domain loop of scipy's zero-order-hold discretisation against the sampled loop's tick recursion."""

from __future__ import annotations

import math
from io import BytesIO
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2
from scipy import optimize, signal

from navig8_fc.core import sampled_loop
from navig8_fc.core import stability as st
from navig8_fc.gcs.params import ParamProtocol, decode_param_value
from navig8_fc.params.registry import ParamRegistry, StabilityFloor

PAPER = (120.0, 1.0, 0.01, 0.1)
FLOWN = (120.0, 1.0, 0.01, 0.02)  # the defaults: INDI_LPF_TAU 0.02, ACT_WN 120, zeta 1, 100 Hz
PAPER_PRESET = "params/presets/paper.parm"
REAL32, INT32 = mavlink2.MAV_PARAM_TYPE_REAL32, mavlink2.MAV_PARAM_TYPE_INT32


# --- lambda_crit: closed form ---------------------------------------------------------------------------------
def _routh_hurwitz_lambda_crit(wn: float, zeta: float, ts: float, tl: float) -> float:
    """The quartic a4 s^4 + ... + a0 of Eq. 13 loses stability where the Hurwitz determinant
    a3 a2 a1 - a4 a1^2 - a0 a3^2 vanishes; every a_i is affine in lam, so that is a cubic in lam (numpy.polynomial)."""
    from numpy.polynomial import Polynomial as Poly

    lam = Poly([0.0, 1.0])
    a4 = lam * ts * tl
    a3 = lam * (2 * ts * tl * zeta * wn + 2 * tl + ts)
    a2 = lam * (ts * tl * wn**2 + 2 * zeta * wn * (2 * tl + ts) + 2)
    a1 = lam * (2 * wn**2 * tl + 2 * wn**2 * ts + 4 * zeta * wn) - wn**2 * ts
    a0 = Poly([2 * wn**2])
    roots = (a3 * a2 * a1 - a4 * a1**2 - a0 * a3**2).roots()
    real = sorted(r.real for r in roots if abs(r.imag) < 1e-12 and 0.0 < r.real < 1.0)
    return real[-1]


@pytest.mark.parametrize(("loop", "expected"), [
    (PAPER, 3.0 / 31.0),  # 0.0968, paper Fig. 5 (~0.1)
    ((120.0, 1.0, 0.02, 0.1), 0.139),
    ((60.0, 0.7, 0.005, 0.05), 0.181),
    (FLOWN, 0.244),
])
def test_lambda_crit_matches_the_routh_hurwitz_boundary(loop: tuple[float, ...], expected: float) -> None:
    lc = st.lambda_crit(*loop)
    assert lc == pytest.approx(_routh_hurwitz_lambda_crit(*loop), abs=1e-9)
    assert lc == pytest.approx(expected, abs=5e-4)


# --- the model-based U0 ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("loop", [PAPER, FLOWN, (60.0, 0.7, 0.005, 0.05)])
@pytest.mark.parametrize("u0_tau", [math.inf, 0.2, 0.0])
def test_model_based_u0_with_the_model_right_is_eq9(loop: tuple[float, ...], u0_tau: float) -> None:
    wn, zeta, _, _ = loop
    assert st.lambda_crit_model_u0(*loop, wn, zeta, u0_tau) == pytest.approx(st.lambda_crit(*loop), abs=1e-9)
    num, den = st.model_u0_coefficients(0.5, *loop, wn, zeta, u0_tau)
    assert num[-1] / den[-1] == pytest.approx(1.0)  # H(0) = 1


def test_model_based_u0_measurement_alone_is_eq9_with_the_true_actuators() -> None:
    wp = 0.6 * FLOWN[0]
    assert st.lambda_crit_model_u0(*FLOWN, wp, 1.0, 0.0) == pytest.approx(st.lambda_crit(wp, 1.0, *FLOWN[2:]))


def _ss(num: list[float], den: list[float]) -> tuple[np.ndarray, ...]:
    return tuple(np.atleast_2d(m) for m in signal.tf2ss(num, den))


def _assembled_loop(lam: float, wm: float, zm: float, ts: float, tl: float, wp: float, zp: float,
                    c: float) -> np.ndarray:
    """The closed loop of Fig. 4 with the model-based U0, block by block (scipy.signal.tf2ss), one mode of G_hat G^-1
    (G = 1, G_hat^-1 = 1/lam): the true actuator a = A(s) u; the sampled feedback y_f = L P a; the model observer
    p_hat' = r_hat + c (P a - p_hat), r_hat' = wm^2 (P u - p_hat) - 2 zm wm r_hat; U0 = L p_hat; u = U0 - y_f/lam."""
    blocks = {
        "A": _ss([wp**2], [1.0, 2 * zp * wp, wp**2]),
        "P1": _ss([-ts, 2.0], [ts, 2.0]), "L1": _ss([1.0], [tl, 1.0]),  # a -> P -> L -> y_f
        "P2": _ss([-ts, 2.0], [ts, 2.0]),  # u -> P (the command flown last tick, into the model)
        "P3": _ss([-ts, 2.0], [ts, 2.0]),  # a -> P (the measured actuators, into the correction)
        "L2": _ss([1.0], [tl, 1.0]),  # p_hat -> L -> U0
    }
    obs_a = np.array([[-c, 1.0], [-wm**2, -2 * zm * wm]])
    obs_b = np.array([[0.0, c], [wm**2, 0.0]])  # inputs (P u, P a)
    names = ["A", "P1", "L1", "P2", "P3", "L2"]
    sizes = {k: blocks[k][0].shape[0] for k in names} | {"OBS": 2}
    order = [*names, "OBS"]
    off: dict[str, int] = {}
    n = 0
    for k in order:
        off[k] = n
        n += sizes[k]

    def sl(k: str) -> slice:
        return slice(off[k], off[k] + sizes[k])

    # Outputs as rows over the state (every block output is a linear function of states and of u, which is itself
    # a function of states: u = C_L2 x_L2 - C_L1 x_L1 / lam, both filters strictly proper).
    def out(k: str, inp_row: np.ndarray) -> np.ndarray:
        a, b, cc, d = blocks[k]
        row = np.zeros(n)
        row[sl(k)] = cc[0]
        return row + d[0, 0] * inp_row

    u_row = np.zeros(n)
    u_row[sl("L2")] = blocks["L2"][2][0]
    u_row[sl("L1")] -= blocks["L1"][2][0] / lam
    a_row = out("A", u_row)
    pa_row, pu_row = out("P3", a_row), out("P2", u_row)
    p_hat_row = np.zeros(n)
    p_hat_row[off["OBS"]] = 1.0
    inputs = {"A": u_row, "P1": a_row, "L1": out("P1", a_row), "P2": u_row, "P3": a_row, "L2": p_hat_row}
    m = np.zeros((n, n))
    for k in names:
        a, b, _, _ = blocks[k]
        m[sl(k), sl(k)] += a
        m[sl(k), :] += np.outer(b[:, 0], inputs[k])
    m[sl("OBS"), sl("OBS")] += obs_a
    m[sl("OBS"), :] += np.outer(obs_b[:, 0], pu_row) + np.outer(obs_b[:, 1], pa_row)
    return m


@pytest.mark.parametrize(("factor", "u0_tau"), [(0.6, math.inf), (1.4, math.inf), (0.6, 0.2), (1.0, 0.2)])
@pytest.mark.parametrize("lam", [0.2, 0.3, 0.5, 1.0])
def test_model_u0_polynomial_against_the_loop_assembled_from_blocks(factor: float, u0_tau: float, lam: float) -> None:
    wm, zm, ts, tl = FLOWN
    wp = factor * wm
    c = 0.0 if math.isinf(u0_tau) else 1.0 / u0_tau
    eig = np.linalg.eigvals(_assembled_loop(lam, wm, zm, ts, tl, wp, zm, c))
    _, den = st.model_u0_coefficients(lam, wm, zm, ts, tl, wp, zm, u0_tau)
    # The assembled loop's characteristic polynomial is the derived one times the duplicated Pade and low-pass
    # copies, (s + 2/tau_s)^2 (s + 1/tau_L); coefficients compared (repeated roots make root-by-root comparisons
    # ill-conditioned), then the dominant pole.
    extra = np.polymul(np.polymul([1.0, 2.0 / ts], [1.0, 2.0 / ts]), [1.0, 1.0 / tl])
    expected = np.polymul(den / den[0], extra)
    assert np.real(np.poly(eig)) == pytest.approx(expected, rel=1e-9)
    roots = st.model_u0_poles(lam, wm, zm, ts, tl, wp, zm, u0_tau)
    assert float(eig.real.max()) == pytest.approx(float(roots[0].real), abs=1e-3)  # double roots at lam = 1


def test_model_u0_lambda_crit_over_a_40_percent_actuator_mismatch() -> None:
    wm, zm, ts, tl = FLOWN
    nominal = st.lambda_crit(*FLOWN)
    for factor in (0.6, 0.8, 1.2, 1.4):
        lc = st.lambda_crit_model_u0(*FLOWN, factor * wm, zm)
        c_max = lambda lam, f=factor: float(np.linalg.eigvals(_assembled_loop(lam, wm, zm, ts, tl, f * wm, zm,
                                                                              0.0)).real.max())
        assert c_max(lc * 1.001) < 0.0 < c_max(lc * 0.999)  # the assembled loop crosses there too
        assert nominal < lc < 1.05 * nominal  # the mismatch moves lambda_crit up, by under 5 % (docs/stability.md)


# --- the sampled loop --------------------------------------------------------------------------------------------
def test_sampled_force_mode_against_scipy_zero_order_hold() -> None:
    """Measured U0, force mode: lam (1 - L_d A_d) + L_d A_d = 0 with A_d the ZOH discretisation of A(s) (scipy) and
    L_d = alpha z / (z - (1 - alpha)); its lambda_crit is the tick recursion's."""
    wn, zeta, ts, tl = FLOWN
    num_a, den_a, _ = signal.cont2discrete(([wn**2], [1.0, 2 * zeta * wn, wn**2]), ts, method="zoh")
    num_a = np.trim_zeros(np.ravel(num_a), "f")
    alpha = 1.0 - math.exp(-ts / tl)
    num_l, den_l = np.array([alpha, 0.0]), np.array([1.0, alpha - 1.0])

    def rho(lam: float) -> float:
        open_num, open_den = np.polymul(num_l, num_a), np.polymul(den_l, den_a)
        char = np.polyadd(lam * open_den, (1.0 - lam) * open_num)
        return float(np.max(np.abs(np.roots(char)))) - 1.0

    lam_z = optimize.brentq(rho, 0.02, 0.5, xtol=1e-12)
    lam_sampled = sampled_loop.sampled_lambda_crit(wn, zeta, 1.0 / ts, tl, "force", u0_source="measured")
    assert lam_sampled == pytest.approx(lam_z, abs=1e-8)
    # With the model right, the model-based U0 is the same loop.
    assert sampled_loop.sampled_lambda_crit(wn, zeta, 1.0 / ts, tl, "force") == pytest.approx(lam_z, abs=1e-8)


@pytest.mark.parametrize("extra_ticks", [1, 2])
def test_a_link_delay_of_whole_ticks_against_scipy_zero_order_hold(extra_ticks: int) -> None:
    """A command flown extra_ticks later (a real-time link): the force mode with measured U0 is
    lam (1 - L_d A_d z^-d) + L_d A_d z^-d = 0, i.e. lam den z^d + (1 - lam) num = 0 over the open loop L_d A_d (scipy's
    ZOH discretisation, as above); the tick recursion with link_delay_ticks has the same lambda_crit, and so has the
    model-based U0 told which command flew (the model right)."""
    wn, zeta, ts, tl = FLOWN
    num_a, den_a, _ = signal.cont2discrete(([wn**2], [1.0, 2 * zeta * wn, wn**2]), ts, method="zoh")
    num_a = np.trim_zeros(np.ravel(num_a), "f")
    alpha = 1.0 - math.exp(-ts / tl)
    open_num = np.polymul([alpha, 0.0], num_a)
    open_den = np.polymul(np.polymul([1.0, alpha - 1.0], den_a), np.r_[1.0, np.zeros(extra_ticks)])  # z^d

    def rho(lam: float) -> float:
        return float(np.max(np.abs(np.roots(np.polyadd(lam * open_den, (1.0 - lam) * open_num))))) - 1.0

    lam_z = optimize.brentq(rho, 0.05, 0.9, xtol=1e-12)
    one_tick = sampled_loop.sampled_lambda_crit(wn, zeta, 1.0 / ts, tl, "force", u0_source="measured")
    got = sampled_loop.sampled_lambda_crit(wn, zeta, 1.0 / ts, tl, "force", u0_source="measured",
                                           link_delay_ticks=extra_ticks)
    assert got == pytest.approx(lam_z, abs=1e-8)
    assert got > one_tick  # more delay, less of the K box is stable
    told = sampled_loop.sampled_lambda_crit(wn, zeta, 1.0 / ts, tl, "force", link_delay_ticks=extra_ticks)
    assert told == pytest.approx(lam_z, abs=1e-8)


def test_an_actuator_model_not_told_which_command_flew_loses_stability_higher() -> None:
    """Over a link one tick late, the model-based U0 advanced on the FC's own last command (not the one flown) is a
    wrong U0 every tick: its lambda_crit is above the told model's in both modes (docs/hil.md: 0.40 against 0.31,
    above the defaults' guaranteed eigenvalue 0.39); with no link delay the two are the same loop."""
    wn, zeta, ts, tl = FLOWN
    for ch in sampled_loop.CHANNELS:
        told = sampled_loop.sampled_lambda_crit(wn, zeta, 1.0 / ts, tl, ch, None, None, "model", 0.2,
                                                link_delay_ticks=1)
        blind = sampled_loop.sampled_lambda_crit(wn, zeta, 1.0 / ts, tl, ch, None, None, "model", 0.2,
                                                 link_delay_ticks=1, model_told=False)
        assert blind > 1.2 * told
        assert sampled_loop.sampled_lambda_crit(wn, zeta, 1.0 / ts, tl, ch, model_told=False) == pytest.approx(
            sampled_loop.sampled_lambda_crit(wn, zeta, 1.0 / ts, tl, ch), abs=1e-12)
    with pytest.raises(ValueError, match="link_delay_ticks"):
        sampled_loop.sampled_loop_matrix(0.5, wn, zeta, 1.0 / ts, tl, link_delay_ticks=-1)


@pytest.mark.parametrize("loop", [PAPER, FLOWN, (120.0, 1.0, 0.02, 0.02), (120.0, 1.0, 0.01, 0.005)])
def test_the_pade_lambda_crit_is_at_or_above_the_sampled_loops(loop: tuple[float, ...]) -> None:
    """The continuous analysis (a whole sample of delay, Pade) is the conservative one for the lockstep loop: the
    sampled rotational mode (backward difference of the filtered gyro) and force mode lose stability lower."""
    wn, zeta, ts, tl = loop
    pade = st.lambda_crit(*loop)
    rot = sampled_loop.sampled_lambda_crit(wn, zeta, 1.0 / ts, tl, "rotational")
    force = sampled_loop.sampled_lambda_crit(wn, zeta, 1.0 / ts, tl, "force")
    assert force < rot <= pade + 1e-3


def test_sampled_loop_time_domain_decays_above_and_grows_below() -> None:
    wn, zeta, ts, tl = FLOWN
    lc = sampled_loop.sampled_lambda_crit(wn, zeta, 1.0 / ts, tl, "rotational", 0.6 * wn, zeta, "model", 0.2)
    for lam, grows in ((lc * 1.02, False), (lc * 0.98, True)):
        m = sampled_loop.sampled_loop_matrix(lam, wn, zeta, 1.0 / ts, tl, "rotational", 0.6 * wn, zeta, "model", 0.2)
        x = np.zeros(7)
        x[4] = 1.0  # a unit command held from the last tick
        norms = []
        for _ in range(3000):
            x = m @ x
            norms.append(float(np.linalg.norm(x)))
        assert (norms[-1] > norms[1000]) == grows


# --- the stated margin --------------------------------------------------------------------------------------------
def _fake(values: Any) -> StabilityFloor:
    return StabilityFloor(lambda_crit=0.1, min_eigenvalue=float(values["INDI_K_MIN"]))


def test_margin_rule_boundary_with_a_fake_floor() -> None:
    reg = ParamRegistry.from_defaults(stability_check=_fake)
    assert reg["INDI_LAM_MARGIN"] == pytest.approx(1.5)
    res = reg.set("INDI_K_MIN", 0.14)  # 1.4 x lambda_crit: stable, but inside the margin
    assert not res.accepted and reg["INDI_K_MIN"] == pytest.approx(0.5)
    assert "stability margin 1.40 < INDI_LAM_MARGIN 1.5" in res.reason
    assert reg.set("INDI_K_MIN", 0.16).accepted
    res = reg.set("INDI_LAM_MARGIN", 2.0)  # a stricter margin that the value in force does not meet
    assert not res.accepted and "INDI_LAM_MARGIN" in res.reason and reg["INDI_LAM_MARGIN"] == pytest.approx(1.5)
    assert reg.set("INDI_LAM_MARGIN", 1.0).accepted and reg.set("INDI_K_MIN", 0.11).accepted  # 1: stability only
    status = reg.stability_status()
    assert status is not None and status.margin == pytest.approx(1.1) and status.required_margin == 1.0


def _preset_registry() -> ParamRegistry:
    """The flown configuration: the defaults (docs/model.md, "The default configuration"), with the floor of the
    values in force computed (as the FC's worker does at start)."""
    reg = ParamRegistry.from_defaults()
    values = reg.as_dict()
    reg.store_floor(values, reg.compute_floor(values))
    return reg


def test_the_flown_configuration_is_accepted_and_nearby_settings_are_judged() -> None:
    """The real floor (workspace sweep): the defaults' 0.02 s filter with the model-based U0 and the flown gain
    (lambda* 0.4, floor 0.4: the flown box [0.4, 1]) pass at 1.60x; the settings docs/stability.md lists as refused are
    refused, the ones it lists as accepted are accepted. The flown gain uses most of the headroom: the faster rate,
    lighter actuator damping and shorter filter that K_hat's own box (the paper's INDI_LAM_REF 1) accepts at 2.00x are
    refused now, and accepted again with lambda* 1."""
    reg = _preset_registry()
    status = reg.stability_status()
    assert status is not None and status.lambda_crit == pytest.approx(0.2440, abs=1e-4)
    assert status.margin == pytest.approx(1.597, abs=2e-3) and status.meets_margin
    for name, value in (("INDI_LPF_TAU", 0.03), ("INDI_LPF_TAU", 0.2), ("ACT_WN", 40.0), ("INDI_K_MIN", 0.4)):
        assert reg.validate(name, value) is None, (name, value)
    near = (("INDI_LPF_TAU", 0.005), ("INDI_RATE_HZ", 50), ("ACT_ZETA", 0.7))
    for name, value in (*near, ("ACT_ZETA", 0.5), ("INDI_RATE_HZ", 40), ("INDI_K_MIN", 0.35), ("INDI_KFL_MIN", 0.35),
                        ("INDI_LAM_MARGIN", 2.1)):
        reason = reg.validate(name, value)
        assert reason is not None and "stability margin" in reason, (name, value, reason)
    assert reg.set("INDI_LAM_REF", 1.0).accepted and reg.set("INDI_KFL_MIN", 0.0).accepted  # K_hat's box
    status = reg.stability_status()
    assert status is not None and status.margin == pytest.approx(2.004, abs=2e-3)
    for name, value in near:
        assert reg.validate(name, value) is None, (name, value)
    for name, value in (("ACT_ZETA", 0.5), ("INDI_RATE_HZ", 40), ("INDI_K_MIN", 0.35)):
        assert reg.validate(name, value) is not None, (name, value)


def test_a_param_set_inside_the_margin_is_refused_over_mavlink_with_the_reason_and_the_old_value() -> None:
    veh = mavlink2.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
    gcs = mavlink2.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)
    reg = _preset_registry()
    proto = ParamProtocol(reg, veh)

    def send(msg: Any) -> list[Any]:
        return [gcs.decode(bytearray(m.pack(veh))) for m in proto.handle(veh.decode(bytearray(msg.pack(gcs))), 0.0)]

    out = send(gcs.param_set_encode(1, 1, b"INDI_RATE_HZ", decode_int_as_float(40), INT32))
    (pv,) = [m for m in out if m.get_type() == "PARAM_VALUE"]
    assert pv.param_id == "INDI_RATE_HZ" and decode_param_value(pv.param_value, pv.param_type) == 100
    text = "".join(m.text for m in out if m.get_type() == "STATUSTEXT")
    assert text.startswith("INDI_RATE_HZ: refused: stability margin 1.17 < INDI_LAM_MARGIN 1.5"), text
    assert "lambda_crit 0.334" in text and reg["INDI_RATE_HZ"] == 100
    out = send(gcs.param_set_encode(1, 1, b"INDI_LPF_TAU", 0.03, REAL32))  # further from lambda_min: accepted
    (pv,) = [m for m in out if m.get_type() == "PARAM_VALUE"]
    assert pv.param_value == pytest.approx(0.03) and not [m for m in out if m.get_type() == "STATUSTEXT"]


def decode_int_as_float(value: int) -> float:
    from navig8_fc.gcs.params import encode_param_value

    return encode_param_value(value, INT32)


# --- live telemetry at the GCS service's output ----------------------------------------------------------------
def test_lam_crit_and_lam_margin_stream_and_follow_a_parameter_change() -> None:
    from test_gcs_service import GCS, Rig

    rig = Rig()
    rig.step(5)
    t = [10.0]

    def named() -> dict[str, float]:
        rig.outbox.sent.clear()
        for _ in range(6):
            t[0] += 0.25
            rig.gcs.poll(t[0])
        return {m.name: m.value for _, m in rig.outbox.pop("NAMED_VALUE_FLOAT")}

    v = named()
    assert v["LAM_CRIT"] == pytest.approx(0.2440, abs=1e-4)  # the defaults: the 0.02 s filter
    assert v["LAM_MARGIN"] == pytest.approx(1.597, abs=2e-3)  # the flown box [0.4, 1]: min eig 0.3897
    status = rig.gcs.stability
    assert status is not None and status.margin == pytest.approx(v["LAM_MARGIN"], rel=1e-6)
    rig.send(rig.client.param_set_encode(1, 1, b"INDI_LPF_TAU", 0.1, REAL32), GCS)  # the paper's filter
    ((_, pv),) = rig.outbox.pop("PARAM_VALUE")
    assert pv.param_value == pytest.approx(0.1)
    rig.step(1)  # the stack applies the change (and recomputes its lambda_crit) at its next step
    v = named()
    assert v["LAM_CRIT"] == pytest.approx(3.0 / 31.0, abs=1e-6)
    assert v["LAM_MARGIN"] == pytest.approx(0.38970 * 31.0 / 3.0, rel=1e-3)


# --- navig8-stability on the configuration flown ---------------------------------------------------------------
def test_report_configuration_reads_params_and_set_through_the_one_parser() -> None:
    from navig8_tools import stability_report as sr

    conf = sr.configuration([], ["INDI_RATE_HZ=40"])
    assert conf.values["INDI_LPF_TAU"] == 0.02 and conf.values["INDI_U0_SRC"] == 1 and conf.values["INDI_RATE_HZ"] == 40
    assert conf.overrides["INDI_RATE_HZ"] == 40.0
    assert conf.verdict is not None and conf.verdict.startswith("refused: stability margin 1.17")
    assert sr.configuration([]).verdict is None
    assert sr.configuration([PAPER_PRESET]).values["INDI_LPF_TAU"] == 0.1
    with pytest.raises(ValueError, match="NAME=VALUE"):
        sr.configuration([], ["INDI_RATE_HZ"])
    with pytest.raises(ValueError, match="outside"):
        sr.configuration([], ["INDI_LPF_TAU=5"])


def test_report_json_for_the_flown_configuration(capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from navig8_tools import stability_report as sr
    from navig8_tools.stability_text import render_text

    assert sr.main(["--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["configuration"]["values"]["INDI_LPF_TAU"] == 0.02 and r["configuration"]["verdict"] is None
    assert r["lambda_crit"] == pytest.approx(0.2440, abs=1e-4)
    assert r["reference"]["lambda_crit"] == pytest.approx(3.0 / 31.0, abs=1e-9)  # the paper's column
    m = r["margin"]
    assert m["margin"] == pytest.approx(1.597, abs=2e-3) and m["required_margin"] == 1.5 and m["meets_margin"]
    rows = {row["plant_wn_factor"]: row for row in r["model_u0"]["mismatch"]}
    assert set(rows) >= {0.6, 1.0, 1.4} and rows[1.0]["model_u0"] == pytest.approx(r["lambda_crit"], abs=1e-9)
    assert max(row["model_u0"] for row in rows.values()) < 1.05 * r["lambda_crit"]
    rt = m["realtime_link"]  # a real-time link's extra tick: the defaults keep less than the rule's margin
    assert rt["sampled_lambda_crit"]["rotational"] == pytest.approx(0.3137, abs=1e-4)
    assert rt["sampled_lambda_crit_blind"]["rotational"] > m["guaranteed_min_eigenvalue"]  # unstable at the worst
    assert rt["margin"] == pytest.approx(m["guaranteed_min_eigenvalue"] / 0.3137, rel=1e-3) and not rt["meets_margin"]
    text = render_text(r)
    assert "paper Sec. 3 (reference)" in text and "a PARAM_SET to this configuration is accepted" in text
    assert "over a real-time link" in text and "required >= 1.5: NO" in text
