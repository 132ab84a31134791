"""navig8_tools.estimator_convergence's window figures: the largest |K - K_true| and the mean K - K_true (its bias
part) over A <= t < B, against closed forms of a ramp and a sine."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_tools.estimator_convergence import window_max_error, window_mean_error


def test_a_ramps_window_mean_is_its_midpoint_and_its_max_its_last_sample() -> None:
    t = np.arange(0, 1001) * 0.01  # 0..10 s
    err = np.column_stack([0.01 * t, -0.02 * t])  # K - K_true: a rising and a falling ramp
    # 2 <= t < 4: samples 2.00 .. 3.99, mean at their midpoint 2.995 s
    assert window_mean_error(t, err, 2.0, 4.0) == pytest.approx([0.02995, -0.0599], abs=1e-12)
    assert window_max_error(t, np.abs(err), 2.0, 4.0) == pytest.approx([0.0399, 0.0798], abs=1e-12)


def test_a_sine_over_whole_periods_has_no_bias_but_its_amplitude_as_max() -> None:
    t = np.arange(0, 2000) * 0.001
    err = (0.03 + 0.05 * np.sin(2 * math.pi * t))[:, None]  # a 0.03 bias under a 0.05 oscillation
    assert abs(window_mean_error(t, err, 0.0, 2.0)[0] - 0.03) < 1e-12
    assert abs(window_max_error(t, np.abs(err), 0.0, 2.0)[0] - 0.08) < 1e-6


def test_an_empty_window_is_nan() -> None:
    t = np.arange(0, 10) * 0.1
    assert all(math.isnan(x) for x in window_mean_error(t, np.ones((10, 2)), 5.0, 6.0))

