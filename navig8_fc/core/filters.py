"""Small discrete-time filters for the control loop: a first-order low-pass and a backward difference.

Pure Python on purpose. The signals in this controller have 1-5 components, and for vectors that
short plain floats in a list are about twice as fast as numpy (numpy's per-call overhead dominates):
one 5-element low-pass step costs ~0.5 us with lists and ~1.2 us with in-place numpy arithmetic
(CPython 3.11). Inputs may be any sequence of floats or a 1-D numpy array (converted with tolist()).

Both filters initialise on their first sample after construction or ``reset()``:
- the low-pass returns the first sample itself (no start-up transient from zero);
- the differentiator returns zeros on its first sample (there is no previous sample).

Outputs are new lists; the caller may keep them (the filter never mutates a list it returned).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = ["BackwardDifference", "LowPass1", "lpf_alpha"]


def lpf_alpha(tau_s: float, dt_s: float) -> float:
    """Smoothing factor of the exactly discretised first-order low-pass 1/(tau s + 1) (Eq. 11).

    y[k] = y[k-1] + alpha (x[k] - y[k-1]) with alpha = 1 - exp(-dt/tau): the step response at the
    sample times equals the continuous one, 1 - exp(-t/tau) (zero-order-hold input). tau = 0 gives
    alpha = 1 (pass-through).
    """
    if not (dt_s > 0.0 and math.isfinite(dt_s)):
        raise ValueError(f"dt_s must be positive and finite, got {dt_s}")
    if not (tau_s >= 0.0 and math.isfinite(tau_s)):
        raise ValueError(f"tau_s must be non-negative and finite, got {tau_s}")
    if tau_s == 0.0:
        return 1.0
    return -math.expm1(-dt_s / tau_s)


class _VectorFilter:
    """What both filters share: a fixed number of components and the check of an input against it."""

    __slots__ = ("_n",)

    def __init__(self, n: int) -> None:
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        self._n = int(n)

    @property
    def n(self) -> int:
        return self._n

    def _checked(self, x: Sequence[float] | np.ndarray) -> list[float]:
        v = [float(xi) for xi in (x.tolist() if isinstance(x, np.ndarray) else x)]
        if len(v) != self._n:
            raise ValueError(f"expected {self._n} components, got {len(v)}")
        return v


class LowPass1(_VectorFilter):
    """Vector first-order low-pass filter, time constant ``tau_s``, sample time ``dt_s``.

    ``step(x)`` returns the filtered vector. The first sample after construction or ``reset()``
    initialises the state to that sample, unless ``reset(value)`` gave an explicit initial state.
    """

    __slots__ = ("_alpha", "_y", "tau_s", "dt_s")

    def __init__(self, tau_s: float, dt_s: float, n: int = 1) -> None:
        super().__init__(n)
        self.tau_s = float(tau_s)
        self.dt_s = float(dt_s)
        self._alpha = lpf_alpha(self.tau_s, self.dt_s)
        self._y: list[float] | None = None

    @property
    def alpha(self) -> float:
        return self._alpha

    @property
    def initialised(self) -> bool:
        return self._y is not None

    @property
    def value(self) -> list[float] | None:
        """Current output (a copy), or None before the first sample."""
        return None if self._y is None else list(self._y)

    def reset(self, value: Sequence[float] | None = None) -> None:
        """Forget the state; with ``value``, start from it instead of from the next sample."""
        self._y = None if value is None else self._checked(value)

    def step(self, x: Sequence[float] | np.ndarray) -> list[float]:
        if isinstance(x, np.ndarray):
            x = x.tolist()  # plain floats: faster arithmetic and a list of float out, not of np.float64
        y = self._y
        if y is None:
            y = self._checked(x)
        else:
            a = self._alpha
            y = [yi + a * (xi - yi) for yi, xi in zip(y, x, strict=True)]
        self._y = y
        return list(y)


class BackwardDifference(_VectorFilter):
    """Vector backward-difference differentiator: y[k] = (x[k] - x[k-1]) / dt_s.

    The first sample after construction or ``reset()`` gives zeros. Its transfer function
    (1 - z^-1)/dt approximates s with half a sample of delay.
    """

    __slots__ = ("_inv_dt", "_prev", "dt_s")

    def __init__(self, dt_s: float, n: int = 1) -> None:
        if not (dt_s > 0.0 and math.isfinite(dt_s)):
            raise ValueError(f"dt_s must be positive and finite, got {dt_s}")
        super().__init__(n)
        self.dt_s = float(dt_s)
        self._inv_dt = 1.0 / self.dt_s
        self._prev: list[float] | None = None

    @property
    def initialised(self) -> bool:
        return self._prev is not None

    def reset(self, previous: Sequence[float] | None = None) -> None:
        """Forget the previous sample; with ``previous``, difference the next sample against it."""
        self._prev = None if previous is None else self._checked(previous)

    def step(self, x: Sequence[float] | np.ndarray) -> list[float]:
        cur = self._checked(x)
        prev = self._prev
        self._prev = cur
        if prev is None:
            return [0.0] * self._n
        k = self._inv_dt
        return [(c - p) * k for c, p in zip(cur, prev, strict=True)]
