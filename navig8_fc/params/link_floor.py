"""The automatic link floor (INDI_KFL_LINK 1, the default; docs/stability.md, "Over a real-time link").

Over a real-time link the FC's answers fly one or more ticks later than in lockstep, lambda_crit of the loop rises
(the defaults': 0.244 in lockstep, 0.3137 one tick late) and the margin the flown K box guarantees can fall below
INDI_LAM_MARGIN (the defaults': 1.24 < 1.5). The FC then flies a higher floor on the flown K of the rotational axes:
the least one that meets INDI_LAM_MARGIN at the measured delay, found with the registry's own stability check (the
floor in force's lambda_crit and the workspace sweep of the guaranteed smallest eigenvalue, run_floor), so the margin
it reports afterwards (LAM_MARGIN, /fc/stability) is that check's at that floor.

- The floor is searched on a LINK_FLOOR_STEP grid between INDI_KFL_MIN and INDI_K_MIN: the guaranteed eigenvalue
  rises with the floor only up to the Eq. 20 box's bottom (the mass axis flies K_hat4 in [INDI_K_MIN, INDI_K_MAX],
  the flown floor does not move it), and it never falls as the floor rises (the box analysed shrinks from below), so
  bisection finds the least grid point that meets the margin.
- When no floor in that range meets it (the defaults two ticks late: at most 1.33), the floor is the range's top,
  the greatest margin the box gives, and the result says it falls short (`meets` False).
- `governed_link_floor`: on the ground the floor follows the link (a quicker link lowers it again); armed it only
  rises, so a link that recovers or flickers between two delays never steps the gain down (or back and forth) in
  flight.

Pure: no clocks, no I/O; the shell runs `least_link_floor` on the stability-floor worker (navig8_fc/shell/
floor_worker.py) and announces what it changes (navig8_fc/shell/fc_process.py).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from navig8_fc.params.registry import (
    LINK_KFL_KEY,
    LinkTiming,
    ParamRegistry,
    StabilityCheck,
    StabilityFloor,
    floor_key,
    link_of,
    run_floor,
)

LINK_FLOOR_STEP = 0.001  # the grid the floor is chosen on: the least meeting point, not a float's last digit
AUTO_PARAM = "INDI_KFL_LINK"  # 1: the automatic link floor; 0: a warning only


@dataclass(frozen=True)
class LinkFloor:
    """The link floor for one configuration and link (least_link_floor)."""

    link: LinkTiming  # the link it is computed for
    k_own: float  # INDI_KFL_MIN: the floor the parameters alone fly
    margin_own: float  # the margin at k_own over this link
    k_floor: float  # the floor to fly: 0 when k_own meets the margin, else the least grid point that does (or the
    # range's top, the box's best, when none does)
    margin: float  # the margin at max(k_own, k_floor)
    lambda_crit: float  # of the loop over this link (the same at every floor)
    required: float  # INDI_LAM_MARGIN
    floor: StabilityFloor  # the registry's floor at max(k_own, k_floor): stored as the floor in force once flown

    @property
    def meets(self) -> bool:
        return self.margin >= self.required and self.floor.ok

    @property
    def k_flown(self) -> float:
        """The floor flown on the rotational axes' K: max(INDI_KFL_MIN, k_floor)."""
        return max(self.k_own, self.k_floor)


def _at(check: StabilityCheck, values: Mapping[str, Any], k: float) -> StabilityFloor:
    return run_floor(check, {**values, LINK_KFL_KEY: k})


def least_link_floor(check: StabilityCheck, values: Mapping[str, Any], step: float = LINK_FLOOR_STEP) -> LinkFloor:
    """The least floor on the flown K (a multiple of `step`) whose margin over the link `values` carry meets their
    INDI_LAM_MARGIN (module docstring); `values`: a registry's floor_values (any link floor they carry is left out:
    the search starts from INDI_KFL_MIN). Module-level and pure, so the floor worker can run it."""
    base = {k: v for k, v in values.items() if k != LINK_KFL_KEY}
    required = float(base["INDI_LAM_MARGIN"])
    k_own = float(base["INDI_KFL_MIN"])
    own = run_floor(check, base)

    def result(k_floor: float, floor: StabilityFloor) -> LinkFloor:
        return LinkFloor(link_of(base), k_own, own.margin, k_floor, floor.margin, own.lambda_crit, required, floor)

    if own.margin >= required and own.ok:
        return result(0.0, own)
    n_lo = math.floor(k_own / step + 1e-9) + 1  # the first grid point above INDI_KFL_MIN
    n_hi = math.ceil(float(base["INDI_K_MIN"]) / step - 1e-9)  # above the box's bottom the floor changes nothing
    if not math.isfinite(own.lambda_crit) or n_hi < n_lo:  # the analysis refuses these values, or nothing to raise
        return result(0.0, own)
    top = _at(check, base, n_hi * step)
    if not (top.margin >= required and top.ok):
        return result(n_hi * step, top)  # the box's best falls short
    found = top
    while n_lo < n_hi:  # invariant: n_hi meets, every point below n_lo does not
        mid = (n_lo + n_hi) // 2
        floor = _at(check, base, mid * step)
        if floor.margin >= required and floor.ok:
            n_hi, found = mid, floor
        else:
            n_lo = mid + 1
    return result(n_hi * step, found)


def governed_link_floor(current: float, target: float, armed: bool) -> float:
    """The link floor to fly now (module docstring): the target on the ground, never below the current one armed."""
    return max(current, target) if armed else target


def link_floor_values(registry: ParamRegistry) -> dict[str, Any] | None:
    """The values whose link floor the registry should fly (its floor_values without the link floor in force), or
    None when it wants none: INDI_KFL_LINK 0, or no delay measured (lockstep: nothing changes)."""
    if AUTO_PARAM not in registry or int(registry.get(AUTO_PARAM)) != 1 or registry.link.delay_ticks == 0:
        return None
    values = registry.floor_values()
    values.pop(LINK_KFL_KEY, None)
    return values


def link_floor_key(values: Mapping[str, Any]) -> tuple[float, ...]:
    """A cache key for least_link_floor(values): the stability floor's inputs and the margin required."""
    return (*floor_key(values), float(values["INDI_LAM_MARGIN"]))


__all__ = ["AUTO_PARAM", "LINK_FLOOR_STEP", "LinkFloor", "governed_link_floor", "least_link_floor",
           "link_floor_key", "link_floor_values"]
