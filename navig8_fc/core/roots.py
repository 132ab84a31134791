"""Brent's bracketing root finder (Brent 1973, ch. 4), step for step as scipy.optimize.brentq does it.

Why not scipy.optimize: importing it costs ~0.4 s of CPU (it loads scipy.linalg, scipy.sparse and their docstring
machinery), and its only use here is refining λ_crit (stability.edge_from_nominal), which every FC and its
stability-floor worker compute at start. The steps below repeat scipy's (its Zeros/brentq.c) operation for operation in
IEEE double arithmetic, so the root is the same float, bit for bit (tests/unit/test_roots.py compares the two);
the errors are scipy's too: ValueError for a bracket without a sign change or a NaN value, RuntimeError when
`maxiter` iterations do not converge.
"""

from __future__ import annotations

import math
from collections.abc import Callable

XTOL = 2e-12  # scipy.optimize.brentq's defaults
RTOL = 4.0 * 2.220446049250313e-16
MAXITER = 100


def _value(f: Callable[[float], float], x: float) -> float:
    fx = float(f(x))
    if math.isnan(fx):
        raise ValueError(f"the function value at x={x:.17g} is NaN; solver cannot continue.")
    return fx


def _negative(v: float) -> bool:
    """C's signbit: True for -0.0 too (a bracket's sign test must treat -0.0 as scipy does)."""
    return math.copysign(1.0, v) < 0.0


def brentq(f: Callable[[float], float], a: float, b: float, xtol: float = XTOL, rtol: float = RTOL,
           maxiter: int = MAXITER) -> float:
    """A root of f in [a, b] (f(a), f(b) of opposite signs): |x - root| <= xtol + rtol |x|, within 2 x (that)."""
    if xtol <= 0.0:
        raise ValueError(f"xtol too small ({xtol:g} <= 0)")
    if rtol < RTOL:
        raise ValueError(f"rtol too small ({rtol:g} < {RTOL:g})")
    # pre: the previous estimate, cur: the best one, blk: the point that keeps the root bracketed with cur
    x_pre, x_cur = float(a), float(b)
    f_pre, f_cur = _value(f, x_pre), _value(f, x_cur)
    if f_pre == 0.0:
        return x_pre
    if f_cur == 0.0:
        return x_cur
    if _negative(f_pre) == _negative(f_cur):
        raise ValueError("f(a) and f(b) must have different signs")
    x_blk = f_blk = s_pre = s_cur = 0.0
    for _ in range(maxiter):
        if f_pre != 0.0 and f_cur != 0.0 and _negative(f_pre) != _negative(f_cur):
            x_blk, f_blk = x_pre, f_pre
            s_pre = s_cur = x_cur - x_pre
        if abs(f_blk) < abs(f_cur):  # cur must be the better end
            x_pre, x_cur, x_blk = x_cur, x_blk, x_cur
            f_pre, f_cur, f_blk = f_cur, f_blk, f_cur
        delta = (xtol + rtol * abs(x_cur)) / 2.0
        s_bis = (x_blk - x_cur) / 2.0
        if f_cur == 0.0 or abs(s_bis) < delta:
            return x_cur
        s_pre, s_cur = _next_step(x_pre, x_cur, x_blk, f_pre, f_cur, f_blk, s_pre, s_cur, s_bis, delta)
        x_pre, f_pre = x_cur, f_cur
        x_cur += s_cur if abs(s_cur) > delta else (delta if s_bis > 0.0 else -delta)
        f_cur = _value(f, x_cur)
    raise RuntimeError(f"Failed to converge after {maxiter} iterations, value is {x_cur!r}.")


def _next_step(x_pre: float, x_cur: float, x_blk: float, f_pre: float, f_cur: float, f_blk: float, s_pre: float,
               s_cur: float, s_bis: float, delta: float) -> tuple[float, float]:
    """(s_pre, s_cur) after this iteration: the secant (two points) or inverse quadratic (three) step while it is
    short enough and |f| keeps falling, else bisection."""
    if abs(s_pre) > delta and abs(f_cur) < abs(f_pre):
        if x_pre == x_blk:  # two distinct points: linear interpolation
            s_try = -f_cur * (x_cur - x_pre) / (f_cur - f_pre)
        else:  # three: inverse quadratic extrapolation
            d_pre = (f_pre - f_cur) / (x_pre - x_cur)
            d_blk = (f_blk - f_cur) / (x_blk - x_cur)
            s_try = -f_cur * (f_blk * d_blk - f_pre * d_pre) / (d_blk * d_pre * (f_blk - f_pre))
        if 2.0 * abs(s_try) < min(abs(s_pre), 3.0 * abs(s_bis) - delta):
            return s_cur, s_try
    return s_bis, s_bis
