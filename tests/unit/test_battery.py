"""Battery model: battery_step and open_circuit_voltage against a plain reference of the model's equations."""

from __future__ import annotations

import bisect
import math
import random
from dataclasses import fields

import pytest

from navig8_fc.flight.battery import (
    CELL_OCV_V,
    SOC_POINTS,
    BatteryConfig,
    BatteryState,
    battery_initial,
    battery_step,
    open_circuit_voltage,
)


def _ref_ocv(soc: float, config: BatteryConfig) -> float:
    s = min(max(soc, 0.0), 1.0)
    i = min(bisect.bisect_right(SOC_POINTS, s), len(SOC_POINTS) - 1)
    s0, s1 = SOC_POINTS[i - 1], SOC_POINTS[i]
    v0, v1 = CELL_OCV_V[i - 1], CELL_OCV_V[i]
    return config.cells * (v0 + (v1 - v0) * (s - s0) / (s1 - s0))


def _ref_step(state: BatteryState, power_w: float, dt_s: float, config: BatteryConfig | None = None) -> BatteryState:
    cfg = config or BatteryConfig()
    p = power_w if math.isfinite(power_w) and power_w > 0.0 else 0.0
    dt = dt_s if math.isfinite(dt_s) and dt_s > 0.0 else 0.0
    v_oc = _ref_ocv(state.soc, cfg)
    r = cfg.internal_resistance_ohm
    disc = v_oc * v_oc - 4.0 * r * p
    current = v_oc / (2.0 * r) if disc < 0.0 else (v_oc - math.sqrt(disc)) / (2.0 * r)
    if state.soc <= 0.0:
        current = 0.0
    v_term = v_oc - current * r
    charge_as = current * dt
    soc = max(state.soc - charge_as / (cfg.capacity_ah * 3600.0), 0.0)
    return BatteryState(soc, v_term, current, state.consumed_mah + charge_as / 3.6,
                        state.energy_j + v_term * current * dt)  # fmt: skip


def _bits(state: BatteryState) -> tuple[str, ...]:
    return tuple(float(getattr(state, f.name)).hex() for f in fields(BatteryState))


@pytest.mark.parametrize("soc", [-1.0, -0.0, 0.0, 0.01, 0.05, 0.1, 0.33, 0.5, 0.95, 0.999, 1.0, 1.5, math.nan])
def test_open_circuit_voltage_matches_reference(soc: float) -> None:
    for cfg in (BatteryConfig(), BatteryConfig(cells=3)):
        assert repr(open_circuit_voltage(soc, cfg)) == repr(_ref_ocv(soc, cfg))


def test_battery_step_matches_reference_bit_for_bit() -> None:
    rng = random.Random(7)
    odd = [0.0, -0.0, -5.0, math.nan, math.inf, -math.inf, 1e9]
    for cfg in (None, BatteryConfig(), BatteryConfig(cells=4, capacity_ah=0.02, internal_resistance_ohm=0.5)):
        fast = ref = battery_initial(cfg)
        for k in range(2000):
            p = rng.choice(odd) if k % 7 == 0 else rng.uniform(0.0, 3000.0)
            dt = rng.choice(odd) if k % 11 == 0 else rng.uniform(0.0, 0.05)
            fast, ref = battery_step(fast, p, dt, cfg), _ref_step(ref, p, dt, cfg)
            assert _bits(fast) == _bits(ref), (k, p, dt)
    assert battery_step(battery_initial(), 1500.0, 0.01) == battery_step(battery_initial(), 1500.0, 0.01,
                                                                         BatteryConfig())  # fmt: skip
