"""The automatic link floor (INDI_KFL_LINK; navig8_fc/params/link_floor.py, docs/stability.md "Over a real-time link"):
over a late link whose margin falls below INDI_LAM_MARGIN the FC flies the least floor on the rotational axes' flown K
that meets it, without rewriting INDI_KFL_MIN.

Independent checks: the margin at the chosen floor recomputed from the analysis itself (the workspace sweep of
k_xi.min_eigenvalue_over_workspace over k_xi.flown_k_box, divided by sampled_loop.link_lambda_crit), not through the
registry's check, its caches or the search: at the floor >= INDI_LAM_MARGIN, one grid step below < it; and the
registry's own stability report at that floor."""

from __future__ import annotations

import math

import pytest

from navig8_fc.core import k_xi
from navig8_fc.core.sampled_loop import link_lambda_crit
from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.params.link_floor import (
    LINK_FLOOR_STEP,
    governed_link_floor,
    least_link_floor,
    link_floor_key,
    link_floor_values,
)
from navig8_fc.params.registry import LOCKSTEP, LinkTiming, ParamRegistry
from navig8_fc.shell.fc_process import link_fault_reason, link_floor_text, link_margin_warning

ONE_TICK, TWO_TICKS, BLIND = LinkTiming(1, True), LinkTiming(2, True), LinkTiming(1, False)


def _registry(link: LinkTiming = LOCKSTEP) -> ParamRegistry:
    reg = ParamRegistry.from_defaults()
    reg.set_link(link)
    return reg


def _margin(k_floor: float, link: LinkTiming) -> float:
    """The defaults' margin with the rotational axes' flown K floored at k_floor, over `link`, from the analysis."""
    lo, hi = k_xi.flown_k_box(0.5, 1.0, 0.4, max(0.4, k_floor))
    min_eig = k_xi.min_eigenvalue_over_workspace(VehicleConfig.load(None), lo, hi)
    return min_eig / link_lambda_crit(120.0, 1.0, 100.0, 0.02, "model", 0.2, link.delay_ticks, link.model_told)


def test_one_tick_late_the_defaults_fly_the_least_floor_that_meets_the_margin() -> None:
    """The defaults one tick late: margin 1.24 at INDI_KFL_MIN 0.4; the floor 0.482 meets 1.5 (1.502), 0.481 does
    not (docs/stability.md)."""
    reg = _registry(ONE_TICK)
    values = link_floor_values(reg)
    assert values is not None
    lf = least_link_floor(reg.stability_check, values)
    assert lf.link == ONE_TICK and lf.k_own == pytest.approx(0.4) and lf.margin_own == pytest.approx(1.242, abs=2e-3)
    assert lf.k_floor == pytest.approx(0.482) and lf.meets and lf.margin == pytest.approx(1.502, abs=2e-3)
    assert lf.lambda_crit == pytest.approx(0.3137, abs=5e-4)
    # independent: the analysis at the floor and one grid step below
    assert _margin(lf.k_floor, ONE_TICK) >= 1.5 > _margin(lf.k_floor - LINK_FLOOR_STEP, ONE_TICK)
    assert lf.margin == pytest.approx(_margin(lf.k_floor, ONE_TICK), rel=1e-6)  # float32 parameters
    # the registry's stability report at that floor: the required margin, INDI_KFL_MIN as set
    reg.set_link_k_floor(lf.k_floor)
    values_in_force = reg.floor_values()
    reg.store_floor(values_in_force, reg.compute_floor(values_in_force))
    status = reg.stability_status()
    assert status is not None and status.meets_margin and status.margin == pytest.approx(lf.margin, rel=1e-12)
    assert status.link_k_floor == pytest.approx(0.482) and status.link_delay_ticks == 1
    assert reg.get("INDI_KFL_MIN") == pytest.approx(0.4) and reg.as_dict()["INDI_KFL_MIN"] == pytest.approx(0.4)
    assert reg.flown_values()["INDI_KFL_MIN"] == pytest.approx(0.482)


def test_when_no_floor_in_the_box_meets_the_margin_the_box_best_is_flown() -> None:
    """Two ticks late (or the actuator model blind) no floor meets 1.5: above INDI_K_MIN the mass axis's K_hat4 keeps
    the box's bottom, so the floor stops at 0.5 with the box's best margin (1.33; blind 1.22), said to fall short."""
    for link, best in ((TWO_TICKS, 1.331), (BLIND, 1.220)):
        reg = _registry(link)
        values = link_floor_values(reg)
        assert values is not None
        lf = least_link_floor(reg.stability_check, values)
        assert lf.k_floor == pytest.approx(0.5) and not lf.meets
        assert lf.margin == pytest.approx(best, abs=2e-3) and lf.margin < lf.required
        # independent: nothing higher in the box does better
        assert _margin(1.0, link) == pytest.approx(_margin(0.5, link), rel=1e-9) == pytest.approx(lf.margin, rel=1e-6)


def test_a_configuration_that_meets_the_margin_over_the_link_gets_no_floor() -> None:
    reg = _registry(ONE_TICK)
    assert reg.set("INDI_KFL_MIN", 0.49).accepted  # the preset: 1.53 over one tick
    values = link_floor_values(reg)
    assert values is not None
    lf = least_link_floor(reg.stability_check, values)
    assert lf.k_floor == 0.0 and lf.meets and lf.k_flown == pytest.approx(0.49)


def test_lockstep_and_warn_only_want_no_floor() -> None:
    """No delay measured (lockstep: the non-real-time flights), or INDI_KFL_LINK 0: nothing to search, the controller's
    values are the parameters'."""
    reg = _registry(LOCKSTEP)
    assert link_floor_values(reg) is None
    assert reg.flown_values() == reg.as_dict()
    reg = _registry(ONE_TICK)
    assert reg.set("INDI_KFL_LINK", 0).accepted
    assert link_floor_values(reg) is None


def test_the_search_key_follows_what_the_floor_depends_on() -> None:
    reg = _registry(ONE_TICK)
    a = link_floor_values(reg)
    assert a is not None
    reg.set_link(TWO_TICKS)
    b = link_floor_values(reg)
    assert b is not None and link_floor_key(a) != link_floor_key(b)
    reg.set_link(ONE_TICK)
    reg.set_link_k_floor(0.482)  # the floor in force is not an input of its own search
    c = link_floor_values(reg)
    assert c is not None and link_floor_key(c) == link_floor_key(a)


def test_in_flight_the_floor_only_rises() -> None:
    assert governed_link_floor(0.0, 0.482, armed=True) == 0.482
    assert governed_link_floor(0.482, 0.5, armed=True) == 0.5
    assert governed_link_floor(0.5, 0.482, armed=True) == 0.5  # the link recovered in flight: kept
    assert governed_link_floor(0.5, 0.0, armed=True) == 0.5
    assert governed_link_floor(0.5, 0.482, armed=False) == 0.482  # on the ground it follows the link
    assert governed_link_floor(0.482, 0.0, armed=False) == 0.0


def test_the_link_floor_is_not_a_parameter_and_bad_values_change_nothing() -> None:
    reg = _registry(ONE_TICK)
    gen = reg.generation
    reg.set_link_k_floor(0.482)
    assert reg.generation == gen + 1 and reg.link_k_floor == pytest.approx(0.482)
    reg.set_link_k_floor(0.482)
    assert reg.generation == gen + 1  # no change, no new generation
    for bad in (-0.1, math.nan, math.inf, 1.5):
        with pytest.raises(ValueError):
            reg.set_link_k_floor(bad)
        assert reg.link_k_floor == pytest.approx(0.482) and reg.generation == gen + 1
    assert reg.get("INDI_KFL_MIN") == pytest.approx(0.4)


def test_the_margin_rule_judges_changes_at_the_floor_flown() -> None:
    """With the link floor in force a ground station may set INDI_KFL_MIN below it (the floor flown stays the link's:
    the margin holds); without it, one tick late, the same value is refused."""
    reg = _registry(ONE_TICK)
    res = reg.set("INDI_KFL_MIN", 0.45)
    assert not res.accepted and "stability margin 1.40" in (res.reason or "")
    reg.set_link_k_floor(0.482)
    res = reg.set("INDI_KFL_MIN", 0.45)
    assert res.accepted and reg.flown_values()["INDI_KFL_MIN"] == pytest.approx(0.482)


def test_the_announcements() -> None:
    reg = _registry(ONE_TICK)
    values = link_floor_values(reg)
    assert values is not None
    lf = least_link_floor(reg.stability_check, values)
    severity, text = link_floor_text(lf, 0.0, lf.k_floor, 0.4)
    assert severity == 5 and text == ("Link 1 tick late: margin 1.24 < INDI_LAM_MARGIN 1.5 at INDI_KFL_MIN 0.4; "
                                      "flown K floor 0.4 -> 0.482 (margin 1.50, lambda_crit 0.314)")
    reg.set_link(TWO_TICKS)
    values = link_floor_values(reg)
    assert values is not None
    short = least_link_floor(reg.stability_check, values)
    severity, text = link_floor_text(short, 0.482, short.k_floor, 0.4)
    assert severity == 4 and "flown K floor 0.482 -> 0.5, the K box's best: margin 1.33 still < 1.5" in text
    severity, text = link_floor_text(lf, 0.5, 0.482, 0.4)
    assert severity == 6 and "lowered 0.5 -> 0.482" in text
    assert link_floor_text(None, 0.482, 0.0, 0.4) == (6, "Link floor off: flown K floor 0.482 -> INDI_KFL_MIN 0.4")


def test_the_warning_and_the_pre_arm_failure() -> None:
    """INDI_KFL_LINK 0 warns as before; with it on the link floor's own text says it. Arming is refused while even
    the floor flown leaves less than INDI_LAM_MARGIN (the box's best two ticks late: 1.33), not once it meets it."""
    reg = _registry(ONE_TICK)
    values = reg.floor_values()
    reg.store_floor(values, reg.compute_floor(values))
    status = reg.stability_status()
    assert status is not None and not status.meets_margin
    assert link_margin_warning(status, auto=True) is None
    text = link_margin_warning(status, auto=False)
    assert text is not None and text.startswith("Stability margin 1.24 over this link < INDI_LAM_MARGIN 1.5")
    assert link_fault_reason(status, auto=False) is None  # warn only
    reg.set_link_k_floor(0.482)
    values = reg.floor_values()
    reg.store_floor(values, reg.compute_floor(values))
    status = reg.stability_status()
    assert status is not None and status.meets_margin and link_fault_reason(status, auto=True) is None
    reg.set_link(TWO_TICKS)
    reg.set_link_k_floor(0.5)
    values = reg.floor_values()
    reg.store_floor(values, reg.compute_floor(values))
    status = reg.stability_status()
    assert status is not None and not status.meets_margin
    assert link_fault_reason(status, auto=True) == ("stability margin 1.33 over this link (2 ticks late) < "
                                                    "INDI_LAM_MARGIN 1.5 at the K box's best floor 0.5")
    assert link_fault_reason(status, auto=False) is None
    lockstep = _registry(LOCKSTEP)
    values = lockstep.floor_values()
    lockstep.store_floor(values, lockstep.compute_floor(values))
    status = lockstep.stability_status()
    assert status is not None and link_fault_reason(status, auto=True) is None
