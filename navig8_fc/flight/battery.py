"""A simple simulated battery for SYS_STATUS/BATTERY_STATUS (pure: state in, state out).

Model: a LiPo pack of `cells` in series, open-circuit voltage from state of charge through a typical LiPo
discharge curve (piecewise linear, per cell), a series internal resistance, and coulomb counting. The load
is given as electrical power (the shell estimates it from the propeller speeds); the current follows from
P = V_terminal I with V_terminal = V_oc - I R:

    I = (V_oc - sqrt(V_oc^2 - 4 R P)) / (2 R)

(past the maximum-power point, V_oc^2 < 4 R P, the pack delivers its maximum, I = V_oc / 2R). Default: 6S,
10 Ah, 20 mOhm, i.e. ~222 Wh; at the ~1.5 kW an 8.5 kg vehicle of this kind needs to hover that is about
8-9 minutes. Enough for GCS battery indicators and failsafe tests; it is not a thermal or ageing model.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

# Typical LiPo open-circuit voltage per cell (V) against state of charge (0..1).
SOC_POINTS = (0.0, 0.05, 0.10, 0.20, 0.30, 0.40, 0.50, 0.60, 0.70, 0.80, 0.90, 1.00)
CELL_OCV_V = (3.27, 3.61, 3.69, 3.73, 3.77, 3.79, 3.82, 3.87, 3.92, 3.98, 4.06, 4.20)


@dataclass(frozen=True)
class BatteryConfig:
    cells: int = 6
    capacity_ah: float = 10.0
    internal_resistance_ohm: float = 0.020  # whole pack
    low_remaining_pct: float = 20.0  # MAV_BATTERY_CHARGE_STATE_LOW below this
    critical_remaining_pct: float = 10.0  # ..._CRITICAL below this

    def __post_init__(self) -> None:
        if self.cells < 1 or not self.capacity_ah > 0.0 or not self.internal_resistance_ohm > 0.0:
            raise ValueError("BatteryConfig needs cells >= 1, capacity_ah > 0, internal_resistance_ohm > 0")


@dataclass(frozen=True)
class BatteryState:
    soc: float  # state of charge 0..1
    voltage_v: float  # terminal voltage under the last load
    current_a: float  # discharge current (>= 0)
    consumed_mah: float  # since start
    energy_j: float  # delivered since start

    @property
    def remaining_pct(self) -> int:
        return int(round(100.0 * min(max(self.soc, 0.0), 1.0)))


_DEFAULT_CONFIG = BatteryConfig()  # frozen: one shared default instead of one per step
_INF = math.inf
_sqrt = math.sqrt
_bisect_right = bisect.bisect_right
_LAST = len(SOC_POINTS) - 1
# Indexed like the tables by the segment's upper end i: (soc0, cell V0, V1 - V0, soc1 - soc0) of [i - 1, i].
_SEGMENTS = tuple(
    (SOC_POINTS[i - 1], CELL_OCV_V[i - 1], CELL_OCV_V[i] - CELL_OCV_V[i - 1], SOC_POINTS[i] - SOC_POINTS[i - 1])
    for i in range(_LAST + 1)
)
def open_circuit_voltage(soc: float, config: BatteryConfig) -> float:
    """Pack open-circuit voltage (V) at state of charge `soc` (clamped to 0..1)."""
    s = soc
    if s < 0.0:  # min(max(soc, 0.0), 1.0), NaN passes through
        s = 0.0
    elif s > 1.0:
        s = 1.0
    s0, v0, dv, ds = _SEGMENTS[min(_bisect_right(SOC_POINTS, s), _LAST)]
    return config.cells * (v0 + dv * (s - s0) / ds)


def battery_initial(config: BatteryConfig | None = None, soc: float = 1.0) -> BatteryState:
    cfg = config or BatteryConfig()
    return BatteryState(soc=soc, voltage_v=open_circuit_voltage(soc, cfg), current_a=0.0, consumed_mah=0.0,
                        energy_j=0.0)  # fmt: skip


def battery_step(state: BatteryState, power_w: float, dt_s: float, config: BatteryConfig | None = None) -> BatteryState:
    """Discharge at `power_w` (electrical, >= 0; NaN/negative count as 0) for `dt_s` seconds."""
    cfg = _DEFAULT_CONFIG if config is None else config
    p = power_w if 0.0 < power_w < _INF else 0.0  # NaN, Inf and <= 0 count as 0
    dt = dt_s if 0.0 < dt_s < _INF else 0.0
    soc0 = state.soc
    v_oc = open_circuit_voltage(soc0, cfg)
    r = cfg.internal_resistance_ohm
    disc = v_oc * v_oc - 4.0 * r * p
    current = v_oc / (2.0 * r) if disc < 0.0 else (v_oc - _sqrt(disc)) / (2.0 * r)
    if soc0 <= 0.0:
        current = 0.0  # reported empty; the plant is not limited by this model
    v_term = v_oc - current * r
    charge_as = current * dt
    soc = soc0 - charge_as / (cfg.capacity_ah * 3600.0)
    if soc < 0.0:  # max(soc, 0.0)
        soc = 0.0
    return BatteryState(soc, v_term, current, state.consumed_mah + charge_as / 3.6,
                        state.energy_j + v_term * current * dt)  # fmt: skip


# Induced power of one rotor, P = T^1.5 / sqrt(2 rho A) / FM (momentum theory with a figure of merit; sea-level
# air, the duct's disk area): the simulated pack's load (SimulatedPack) (docs/gcs.md, hover ~0.6 kW at 8 kg).
AIR_DENSITY_KG_M3 = 1.225
ROTOR_DISK_AREA_M2 = 0.07
FIGURE_OF_MERIT = 0.6
BATTERY_PERIOD_S = 0.1  # the pack model's update period (BATTERY_STATUS streams at 1 Hz)
_POWER_DIVISOR = math.sqrt(2 * AIR_DENSITY_KG_M3 * ROTOR_DISK_AREA_M2) * FIGURE_OF_MERIT


class SimulatedPack:
    """The simulated pack on sim time, loaded with the rotors' induced power (the constants above). The energy is
    summed every control step and the pack model advances every BATTERY_PERIOD_S with the mean power (its state
    moves by ~1e-5 of charge per period; a step each tick cost ~1.5 us, 3 % of the flight stack's)."""

    def __init__(self) -> None:
        self.state = battery_initial()
        self._t_s: float | None = None  # sim time the pack model has advanced to
        self._step_t_s: float | None = None  # the last step's sim time
        self._energy_j = 0.0  # drawn since _t_s

    def discharge(self, t_s: float, t1: float, t2: float, t3: float) -> None:
        """One control step at sim time t_s with rotor thrusts t1, t2, t3 (N)."""
        last = self._step_t_s
        self._step_t_s = t_s
        if last is None:
            self._t_s = t_s
            return
        if t_s > last:
            self._energy_j += (abs(t1) ** 1.5 + abs(t2) ** 1.5 + abs(t3) ** 1.5) / _POWER_DIVISOR * (t_s - last)
            if t_s - self._t_s >= BATTERY_PERIOD_S:  # type: ignore[operator]
                self.flush()

    def flush(self) -> BatteryState:
        """The pack advanced to the last step's time; its state."""
        t0, t1 = self._t_s, self._step_t_s
        if t0 is None or t1 is None or t1 <= t0:
            return self.state
        self.state = battery_step(self.state, self._energy_j / (t1 - t0), t1 - t0)
        self._t_s, self._energy_j = t1, 0.0
        return self.state
