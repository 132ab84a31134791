"""Unit tests for navig8_fc.core.filters (first-order low-pass, backward difference)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.core.filters import BackwardDifference, LowPass1, lpf_alpha


def test_alpha_exact_discretisation() -> None:
    assert lpf_alpha(0.7, 0.01) == pytest.approx(1.0 - math.exp(-0.01 / 0.7), rel=1e-15)
    assert lpf_alpha(0.0, 0.01) == 1.0
    with pytest.raises(ValueError):
        lpf_alpha(-1.0, 0.01)
    with pytest.raises(ValueError):
        lpf_alpha(0.1, 0.0)


@pytest.mark.parametrize("tau_s,dt_s", [(0.7, 0.01), (0.1, 0.01), (0.05, 0.002)])
def test_lpf_step_response_matches_continuous(tau_s: float, dt_s: float) -> None:
    """Unit step from rest: y(k dt) = 1 - exp(-k dt / tau) at every sample time (to 1e-12)."""
    f = LowPass1(tau_s, dt_s, n=3)
    f.reset([0.0, 0.0, 0.0])
    for k in range(1, 400):
        y = f.step([1.0, 2.0, -3.0])
        expected = 1.0 - math.exp(-k * dt_s / tau_s)
        assert y[0] == pytest.approx(expected, abs=1e-12)
        assert y[1] == pytest.approx(2.0 * expected, abs=1e-12)
        assert y[2] == pytest.approx(-3.0 * expected, abs=1e-12)


def test_lpf_initialises_on_first_sample_and_reset() -> None:
    f = LowPass1(0.5, 0.01, n=2)
    assert not f.initialised and f.value is None
    assert f.step([3.0, -1.0]) == [3.0, -1.0]
    y = f.step([4.0, -1.0])
    assert y[0] == pytest.approx(3.0 + f.alpha * 1.0, rel=1e-15)
    f.reset()
    assert f.step(np.array([7.0, 8.0])) == [7.0, 8.0]


def test_lpf_output_is_not_aliased() -> None:
    f = LowPass1(0.5, 0.01, n=2)
    y = f.step([1.0, 1.0])
    y[0] = 100.0
    assert f.value == [1.0, 1.0]


def test_lpf_wrong_length_raises() -> None:
    f = LowPass1(0.5, 0.01, n=2)
    with pytest.raises(ValueError):
        f.step([1.0])
    f.step([1.0, 2.0])
    with pytest.raises(ValueError):
        f.step([1.0, 2.0, 3.0])


def test_lpf_zero_tau_is_pass_through() -> None:
    f = LowPass1(0.0, 0.01, n=1)
    for v in (1.0, -2.0, 5.5):
        assert f.step([v]) == [v]


def test_differentiator_of_ramp() -> None:
    """x = a + b t sampled at dt: the backward difference is exactly b after the first sample."""
    dt = 0.01
    d = BackwardDifference(dt, n=2)
    slopes = (2.5, -0.75)
    for k in range(50):
        t = k * dt
        y = d.step([1.0 + slopes[0] * t, -3.0 + slopes[1] * t])
        if k == 0:
            assert y == [0.0, 0.0]
        else:
            assert y[0] == pytest.approx(slopes[0], rel=1e-9)
            assert y[1] == pytest.approx(slopes[1], rel=1e-9)


def test_differentiator_reset_with_previous() -> None:
    d = BackwardDifference(0.1, n=1)
    d.reset([1.0])
    assert d.step([1.5]) == [pytest.approx(5.0)]
    d.reset()
    assert d.step([10.0]) == [0.0]


def test_numpy_input_gives_plain_floats() -> None:
    f = LowPass1(0.5, 0.01, n=2)
    d = BackwardDifference(0.01, n=2)
    for v in (np.array([1.0, 2.0]), np.array([2.0, 3.0])):
        y = f.step(v)
        dy = d.step(v)
        assert all(type(e) is float for e in y + dy)
