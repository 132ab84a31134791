"""The FC's model of its actuators (paper Sec. 3.2, Eq. 10): each of the five (alpha1, alpha3, w1, w2, w3) is
x'' = wn^2 (u - x) - 2 zeta wn x', the command held over each control period (zero-order hold), discretised
exactly: [x, x']_{k+1} = Ad [x, x']_k + Bd u_k, by the matrix exponential of the augmented system.

Used by the INDI's model-based U0 (INDI_U0_SRC = 1, `_kernels.indi_measure`) and by the PX4 simulator interface
when no actuator measurements arrive (navig8_fc.mavlink.px4sim). The step itself is one numba kernel
(`_kernels.actuator_model_step`), shared by both. Pure: no I/O.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.linalg import expm

from navig8_fc.core import _kernels as _k

N_ACTUATORS = 5


def actuator_discretisation(wn_rad_s: float, zeta: float, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(Ad as [a00, a01, a10, a11], Bd as [b0, b1]) of the second-order lag under a zero-order-hold command."""
    if not (wn_rad_s > 0.0 and zeta > 0.0 and dt_s > 0.0):
        raise ValueError(f"actuator model needs wn, zeta, dt > 0, got {wn_rad_s}, {zeta}, {dt_s}")
    a = np.array([[0.0, 1.0, 0.0], [-wn_rad_s**2, -2.0 * zeta * wn_rad_s, wn_rad_s**2], [0.0, 0.0, 0.0]])
    m = expm(a * dt_s)
    return np.ascontiguousarray(m[:2, :2].ravel()), np.ascontiguousarray(m[:2, 2])


class ActuatorModel:
    """The five actuators' (position, rate) state, advanced one period per `step(command)`."""

    def __init__(self, wn_rad_s: float, zeta: float, dt_s: float, initial: Sequence[float]) -> None:
        self._ad, self._bd = actuator_discretisation(wn_rad_s, zeta, dt_s)
        self._x = np.zeros(2 * N_ACTUATORS)  # positions, then rates (the kernel's layout)
        self._x[:N_ACTUATORS] = np.asarray(initial, dtype=float)

    def step(self, command: Sequence[float]) -> tuple[float, ...]:
        """Advance one period under `command`; the positions after it."""
        _k.actuator_model_step(self._x, 0, self._ad, self._bd, np.asarray(command, dtype=float), 0)
        return self.positions

    @property
    def positions(self) -> tuple[float, ...]:
        return tuple(self._x[:N_ACTUATORS].tolist())

    @property
    def rates(self) -> tuple[float, ...]:
        return tuple(self._x[N_ACTUATORS:].tolist())


__all__ = ["N_ACTUATORS", "ActuatorModel", "actuator_discretisation"]
