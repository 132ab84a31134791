"""The stability floor of the loop flown over a real-time link (docs/stability.md, "Over a real-time link"): the FC
measures how late the simulator flies its answers (shell.realtime.LinkDelayMeter, from the bridge's cmd_time_usec
echo) and the registry's floor in force (LAM_CRIT, LAM_MARGIN, /fc/stability) and its margin rule are those of that
loop (ParamRegistry.set_link).

Independent checks: the link's lambda_crit against the z-domain loop of scipy's zero-order-hold discretisation with
z^-d (the characteristic polynomial, not the tick recursion the registry uses), the spectral radius on both sides of
the edge, and the defaults' figures of docs/hil.md."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import optimize, signal

from navig8_fc.core import sampled_loop
from navig8_fc.params.registry import LINK_FLOOR_INPUTS, LOCKSTEP, LinkTiming, ParamRegistry
from navig8_fc.shell.realtime import LINK_DELAY_BLOCK, UNECHOED_LINK, LinkDelayMeter

PERIOD_US = 10_000.0  # 100 Hz


def _registry(link: LinkTiming = LOCKSTEP) -> ParamRegistry:
    reg = ParamRegistry.from_defaults()
    reg.set_link(link)
    values = reg.floor_values()
    reg.store_floor(values, reg.compute_floor(values))
    return reg


# --- the meter -------------------------------------------------------------------------------------------------
def _feed(meter: LinkDelayMeter, delays: list[int | None]) -> None:
    clock = 1_000_000
    for d in delays:
        clock += int(PERIOD_US)
        # the answer of d + 1 ticks ago flew (None: the simulator did not say)
        meter.add(None if d is None else clock - int((d + 1) * PERIOD_US), clock, PERIOD_US)


def _delay(meter: LinkDelayMeter) -> int | None:
    return None if meter.link is None else meter.link.delay_ticks


def test_the_meter_reads_lockstep_as_no_delay_and_a_late_line_as_one_tick() -> None:
    m = LinkDelayMeter()
    _feed(m, [0] * (LINK_DELAY_BLOCK - 1))
    assert m.link is None  # a block not yet full: the floor stays lockstep's
    _feed(m, [0])
    assert m.link == LinkTiming(0, True)
    _feed(m, [1] * LINK_DELAY_BLOCK)
    assert m.link == LinkTiming(1, True)


def test_the_meter_takes_the_delay_95_percent_of_a_block_met() -> None:
    m = LinkDelayMeter()
    n_late = int(0.02 * LINK_DELAY_BLOCK)  # the serial line: 1-3 % a period later still (docs/hil.md)
    _feed(m, [1] * (LINK_DELAY_BLOCK - n_late) + [2] * n_late)
    assert _delay(m) == 1
    n_late = int(0.10 * LINK_DELAY_BLOCK)
    _feed(m, [1] * (LINK_DELAY_BLOCK - n_late) + [2] * n_late)
    assert _delay(m) == 2
    # the next block decides again: the link got quicker
    _feed(m, [0] * LINK_DELAY_BLOCK)
    assert _delay(m) == 0


def test_a_simulator_that_never_says_which_answer_flew_is_taken_one_tick_late_and_blind() -> None:
    m = LinkDelayMeter()
    _feed(m, [None] * LINK_DELAY_BLOCK)
    assert m.link == UNECHOED_LINK == LinkTiming(1, False)
    # a few answers not remembered among echoed ones are not a silent simulator: measured from the echoed ones
    _feed(m, [None] * 20 + [0] * (LINK_DELAY_BLOCK - 20))
    assert m.link == LinkTiming(0, True)


def test_an_answer_stamped_by_the_tick_itself_counts_as_no_delay() -> None:
    m = LinkDelayMeter()
    for _ in range(LINK_DELAY_BLOCK):
        m.add(5_000_000, 5_000_000, PERIOD_US)  # cannot happen on a real link; never a negative delay
    assert _delay(m) == 0


# --- the registry's floor over the link --------------------------------------------------------------------------
def _scipy_link_lambda_crit(wn: float, zeta: float, ts: float, tl: float, d: int) -> float:
    """The force mode over a link d ticks late (measured U0, or the model told, the model right): the roots of
    lam den z^(1+d) + (1 - lam) num over the open loop of the ZOH actuators and the sampled low-pass."""
    num_a, den_a, _ = signal.cont2discrete(([wn**2], [1.0, 2 * zeta * wn, wn**2]), ts, method="zoh")
    num_a = np.trim_zeros(np.ravel(num_a), "f")
    alpha = 1.0 - math.exp(-ts / tl)
    open_num = np.polymul([alpha, 0.0], num_a)
    open_den = np.polymul(np.polymul([1.0, alpha - 1.0], den_a), np.r_[1.0, np.zeros(d)])

    def rho(lam: float) -> float:
        return float(np.max(np.abs(np.roots(np.polyadd(lam * open_den, (1.0 - lam) * open_num))))) - 1.0

    return optimize.brentq(rho, 0.02, 0.95, xtol=1e-12)


def test_over_a_late_link_the_floor_in_force_is_that_loops() -> None:
    """The defaults over a line one tick late (docs/hil.md): lambda_crit 0.3137 (the rotational modes), margin 1.24
    below the 1.5 required; the actuator model not told which answer flew: 0.4009, margin 0.97; lockstep: the Pade
    H(s)'s 0.244, margin 1.597."""
    lock = _registry().stability_status()
    assert lock is not None and lock.link_delay_ticks == 0
    assert lock.lambda_crit == pytest.approx(0.244, abs=5e-4) and lock.margin == pytest.approx(1.597, abs=1e-3)
    told = _registry(LinkTiming(1, True)).stability_status()
    assert told is not None and (told.link_delay_ticks, told.link_model_told) == (1, True)
    assert told.lambda_crit == pytest.approx(0.3137, abs=5e-4)
    assert told.min_eigenvalue == lock.min_eigenvalue  # the K box and the workspace do not change with the link
    assert told.margin == pytest.approx(1.242, abs=2e-3) and not told.meets_margin
    blind = _registry(LinkTiming(1, False)).stability_status()
    assert blind is not None and blind.lambda_crit == pytest.approx(0.4009, abs=5e-4) and blind.margin < 1.0


@pytest.mark.parametrize("delay", [1, 2])
def test_the_force_modes_edge_over_the_link_against_scipy(delay: int) -> None:
    """The registry's lambda_crit over the link is at or above the force mode's edge from scipy's z-domain loop (the
    rotational modes may set it higher), and the one-tick link's loop, built at its edge, sits on the unit circle."""
    wn, zeta, rate, tl = 120.0, 1.0, 100.0, 0.02
    reg = _registry(LinkTiming(delay, True))
    reg.set("INDI_U0_SRC", 0)  # measured U0: the loop of the closed form
    values = reg.floor_values()
    lam = reg.compute_floor(values).lambda_crit
    lam_force = _scipy_link_lambda_crit(wn, zeta, 1.0 / rate, tl, delay)
    assert lam >= lam_force - 1e-8
    for ch in sampled_loop.CHANNELS:
        m = sampled_loop.sampled_loop_matrix(lam * 1.001, wn, zeta, rate, tl, ch, u0_source="measured",
                                             link_delay_ticks=delay)
        assert np.max(np.abs(np.linalg.eigvals(m))) < 1.0  # stable just above the edge in every mode
    edge = [np.max(np.abs(np.linalg.eigvals(sampled_loop.sampled_loop_matrix(
        lam * 0.999, wn, zeta, rate, tl, ch, u0_source="measured", link_delay_ticks=delay)))) for ch in
        sampled_loop.CHANNELS]
    assert max(edge) > 1.0  # and unstable just below it in one


def test_over_a_late_link_the_margin_rule_judges_the_loop_flown() -> None:
    """INDI_KFL_MIN 0.45 keeps 1.5 in lockstep but not over the late line (refused, the margin in the reason); 0.49
    restores it there (docs/stability.md: 1.53)."""
    assert _registry().set("INDI_KFL_MIN", 0.45).accepted
    reg = _registry(LinkTiming(1, True))
    res = reg.set("INDI_KFL_MIN", 0.45)
    assert not res.accepted and res.value == pytest.approx(0.4) and "stability margin 1.40" in (res.reason or "")
    assert reg.set("INDI_KFL_MIN", 0.49).accepted
    status = reg.stability_status()
    assert status is not None and status.margin == pytest.approx(1.53, abs=0.01) and status.meets_margin


def test_the_real_time_link_preset_restores_the_margin_over_a_late_link() -> None:
    """params/presets/realtime_link.parm (the preset the FC's warning names) loads whole over a line one tick late and
    meets INDI_LAM_MARGIN there; the defaults do not."""
    from pathlib import Path

    from navig8_fc.params.store import read_parm_file

    values = read_parm_file(Path(__file__).resolve().parents[2] / "params" / "presets" / "realtime_link.parm")
    reg = _registry(LinkTiming(1, True))
    before = reg.stability_status()
    assert before is not None and not before.meets_margin
    assert values and all(reg.set(k, v).accepted for k, v in values.items())
    status = reg.stability_status()
    assert status is not None and status.meets_margin and status.margin >= 1.5, status


def test_over_a_late_link_u0s_parameters_need_the_floor() -> None:
    """Lockstep's H(s) does not read U0; the loop over a late link does, so its parameters go through the floor."""
    lock, late = _registry(), _registry(LinkTiming(1, True))
    for name in LINK_FLOOR_INPUTS:
        value = 0.5 if name == "INDI_U0_TAU" else 0
        assert lock.floor_needed(name, value) is None
        assert late.floor_needed(name, value) is not None
