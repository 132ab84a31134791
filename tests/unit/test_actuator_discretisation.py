"""The actuator model's exact discretisation (core/actuator_model.actuator_discretisation, the FC's and the plant's one
copy) against scipy.linalg.expm of the augmented system [[A, B], [0, 0]] dt (Pade with scaling and squaring, an
independent method), across damping (underdamped, critical, overdamped, and next to critical on both sides), and
against the step response's closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from navig8_fc.core.actuator_model import actuator_discretisation


def _scipy(wn: float, zeta: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([[0.0, 1.0, 0.0], [-wn * wn, -2.0 * zeta * wn, wn * wn], [0.0, 0.0, 0.0]])
    m = expm(a * dt)
    return m[:2, :2].ravel(), m[:2, 2]


@pytest.mark.parametrize("zeta", [0.05, 0.3, 0.7, 1.0 - 1e-9, 1.0, 1.0 + 1e-9, 1.5, 4.0])
@pytest.mark.parametrize("wn_dt", [(120.0, 0.01), (60.0, 0.0025), (30.0, 0.00125), (900.0, 0.01)])
def test_equals_scipys_matrix_exponential(zeta: float, wn_dt: tuple[float, float]) -> None:
    """Ad, Bd equal scipy's to 1e-12 (relative to their scale: Ad's second row carries wn)."""
    wn, dt = wn_dt
    ad, bd = actuator_discretisation(wn, zeta, dt)
    ad_s, bd_s = _scipy(wn, zeta, dt)
    scale = np.array([1.0, dt, wn * wn * dt, 1.0])
    np.testing.assert_allclose(ad / scale, ad_s / scale, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(bd / [1.0, wn * wn * dt], bd_s / [1.0, wn * wn * dt], rtol=0.0, atol=1e-12)


def test_critical_damping_is_the_closed_form_step_response() -> None:
    """zeta = 1 from rest under a unit step: y(t) = 1 - (1 + wn t) e^(-wn t), y'(t) = wn^2 t e^(-wn t)."""
    wn, dt = 120.0, 0.01
    _, bd = actuator_discretisation(wn, 1.0, dt)
    x = wn * dt
    assert bd[0] == pytest.approx(1.0 - (1.0 + x) * math.exp(-x), abs=1e-15)
    assert bd[1] == pytest.approx(wn * x * math.exp(-x), rel=1e-14)


def test_refuses_a_model_without_dynamics() -> None:
    for wn, zeta, dt in ((0.0, 1.0, 0.01), (120.0, 0.0, 0.01), (120.0, 1.0, 0.0)):
        with pytest.raises(ValueError):
            actuator_discretisation(wn, zeta, dt)
