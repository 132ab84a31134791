"""roots.brentq is scipy.optimize.brentq without its import: the same root, bit for bit, and the same errors."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest
from scipy import optimize

from navig8_fc.core import sampled_loop, stability
from navig8_fc.core.roots import brentq

FUNCTIONS: list[tuple[Callable[[float], float], float, float]] = [
    (lambda x: x * x - 2.0, 0.0, 2.0),
    (lambda x: x * x - 2.0, 2.0, 0.0),  # the bracket given backwards
    (lambda x: math.cos(x) - x, 0.0, 1.0),
    (lambda x: x**3 - 2.0 * x - 5.0, 2.0, 3.0),
    (lambda x: math.exp(x) - 1e-3, -20.0, 5.0),
    (lambda x: 1.0 if x > 0.3 else -1.0, 0.0, 1.0),  # a step: bisection all the way
    (lambda x: (x - 1e-9) ** 3, -1.0, 1.0),  # a flat triple root
    (lambda x: math.atan(1e4 * (x - 0.7)), 0.0, 1.0),
    (lambda x: x - 0.5, 0.5, 2.0),  # a root at an end
    (lambda x: math.log(x) + 3.0, 1e-6, 1.0),
]


@pytest.mark.parametrize("i", range(len(FUNCTIONS)))
@pytest.mark.parametrize("tols", [(2e-12, 4 * np.finfo(float).eps), (1e-12, 1e-12), (1e-10, 1e-12), (1e-3, 1e-6)])
def test_the_root_is_scipys_bit_for_bit(i: int, tols: tuple[float, float]) -> None:
    f, a, b = FUNCTIONS[i]
    xtol, rtol = tols
    ours = brentq(f, a, b, xtol=xtol, rtol=rtol)
    theirs = optimize.brentq(f, a, b, xtol=xtol, rtol=rtol)
    assert ours.hex() == float(theirs).hex()


def test_the_errors_are_scipys() -> None:
    for fn in (brentq, optimize.brentq):
        with pytest.raises(ValueError, match="different signs"):
            fn(lambda x: x * x + 1.0, -1.0, 1.0)
        with pytest.raises(ValueError, match="NaN"):
            fn(lambda x: math.nan if x > 0.1 else -1.0, 0.0, 1.0)
        with pytest.raises(RuntimeError, match="converge"):
            fn(lambda x: math.cos(x) - x, 0.0, 1.0, maxiter=2)
        with pytest.raises(ValueError, match="xtol"):
            fn(lambda x: x, -1.0, 1.0, xtol=0.0)
        with pytest.raises(ValueError, match="rtol"):
            fn(lambda x: x, -1.0, 1.0, rtol=1e-17)


# (wn, zeta, ts, tl): the paper's loop, the notes' cases, a fast and a slow actuator, no low-pass, and a lightly
# damped one with a long delay (a finite λ_upper)
LOOPS = [(120.0, 1.0, 0.01, 0.1), (60.0, 0.7, 0.005, 0.05), (120.0, 1.0, 0.02, 0.1), (500.0, 0.7, 0.0025, 0.005),
         (40.0, 1.0, 0.01, 0.0), (120.0, 0.4, 0.05, 0.1), (500.0, 0.1, 0.05, 0.005)]


def _model_u0_edge(wn: float, zeta: float, ts: float, tl: float) -> float:
    try:
        return stability.lambda_crit_model_u0(wn, zeta, ts, tl, 0.8 * wn, zeta, 0.2)
    except ValueError:  # a loop unstable at lam = 1 (a model far off): refused by both alike
        return math.nan


def _edges() -> list[float]:
    out = []
    for wn, zeta, ts, tl in LOOPS:
        out.append(stability.lambda_crit(wn, zeta, ts, tl))
        out.append(stability.lambda_upper(wn, zeta, ts, tl))
        out.append(_model_u0_edge(wn, zeta, ts, tl))
    out.append(sampled_loop.link_lambda_crit(120.0, 1.0, 100.0, 0.1, "model", 0.2, 1, True))
    out.append(sampled_loop.link_lambda_crit(120.0, 1.0, 100.0, 0.1, "measured", 0.2, 2, False))
    return out


def test_the_stability_edges_are_the_ones_scipy_gives(monkeypatch: pytest.MonkeyPatch) -> None:
    """λ_crit and λ_upper (lockstep, model-based U0, a late link) over a grid of loops: identical floats."""
    ours = _edges()
    monkeypatch.setattr(stability, "brentq", optimize.brentq)
    theirs = _edges()
    assert [v.hex() for v in ours] == [float(v).hex() for v in theirs]
    assert any(math.isfinite(v) and v > 1.0 for v in ours)  # a λ_upper refined too, not only λ_crit
    assert sum(math.isnan(v) for v in ours) < len(LOOPS) // 2  # most model-based U0 loops have an edge
