"""The estimator's gyroscopic moment (core/gyroscopic.py, CKF_GYRO): w x (I w) against numpy's cross product with the
full tensor, and its low-passed window increments (lpf_increments' gyroscopic channels, the law's filter) against the
closed forms of a step and of the running-mean start."""

from __future__ import annotations

import numpy as np
import pytest

from navig8_fc.core.gyroscopic import gyroscopic_moment
from navig8_fc.core.law_filters import LAW_OUT, LAW_STATE, LO_READY, lpf_increments


def test_moment_is_the_cross_product() -> None:
    """Random rates and planar inertia tensors (I_xy = I_yz = 0): equal to np.cross(w, I w) to 1e-12 N m."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        w = rng.normal(scale=2.0, size=3)
        ixx, iyy, izz = rng.uniform(0.1, 2.0, size=3)
        ixz = rng.uniform(-0.5, 0.5)
        tensor = np.array([[ixx, 0.0, ixz], [0.0, iyy, 0.0], [ixz, 0.0, izz]])
        got = gyroscopic_moment(*w.tolist(), ixx, iyy, izz, ixz)
        assert np.allclose(got, np.cross(w, tensor @ w), rtol=0.0, atol=1e-12)


def test_moment_vanishes_about_a_principal_axis() -> None:
    """Spinning about a principal axis of a diagonal tensor needs no moment (closed form)."""
    assert gyroscopic_moment(0.0, 0.0, 3.0, 0.3, 0.5, 0.7, 0.0) == (0.0, 0.0, 0.0)
    # with a product of inertia, a yaw spin needs a pitch moment: M_y = I_xz r^2
    assert gyroscopic_moment(0.0, 0.0, 2.0, 0.3, 0.5, 0.7, -0.2)[1] == pytest.approx(-0.2 * 4.0, abs=1e-15)


@pytest.mark.parametrize("n_window", [1.0, 25.0])
def test_increments_of_a_step_are_the_closed_form(n_window: float) -> None:
    """The law's filter (lpf_increments' gyroscopic channels) fed a step from m0 to m1 after its first sample: the
    low-pass is m1 - (m1 - m0)(1 - a)^k, so the window closing at step k reads (m1 - m0)((1 - a)^(k - n) - (1 - a)^k)
    (to 1e-12 N m); nothing on the first sample nor between windows."""
    alpha = 1.0 - np.exp(-0.01 / 0.7)
    st, out = LAW_STATE.zeros(), LAW_OUT.zeros()
    views = LAW_OUT.views(out)
    z5 = np.zeros(5)
    m0, m1 = np.array([0.2, -0.1, 0.05]), np.array([-0.3, 0.4, 0.1])
    lpf_increments(st, alpha, n_window, z5, z5, 0.0, m0, 0.0, 0.0, out, 0.0)
    assert out[LO_READY] == 0.0 and not views.delta_gyro.any()
    n_ready = 0
    for k in range(1, 301):
        lpf_increments(st, alpha, n_window, z5, z5, 0.0, m1, 0.0, 0.0, out, 0.0)
        if k % int(n_window):
            assert out[LO_READY] == 0.0 and not views.delta_gyro.any(), k
            continue
        n_ready += 1
        want = (m1 - m0) * ((1.0 - alpha) ** (k - n_window) - (1.0 - alpha) ** k)
        np.testing.assert_allclose(views.delta_gyro, want, rtol=0.0, atol=1e-12)
        assert not views.delta_acc.any()  # its own channels: U and Acc_m read nothing of it
    assert n_ready == int(300 // n_window)


def test_the_running_mean_start_reads_the_mean() -> None:
    """With the running-mean start (CKF_LPF_SEED) the low-pass of the first n samples is their mean while 1/n > a, and
    the window starts at the first sample: the first window (10 steps after it) reads the mean of the 11 minus the
    first."""
    alpha = 0.01
    rng = np.random.default_rng(5)
    st, out = LAW_STATE.zeros(), LAW_OUT.zeros()
    views = LAW_OUT.views(out)
    z5 = np.zeros(5)
    xs = rng.normal(scale=0.3, size=(11, 3))
    for x in xs:
        lpf_increments(st, alpha, 10.0, z5, z5, 0.0, x, 0.0, 0.0, out, 1.0)
    assert out[LO_READY] == 1.0
    np.testing.assert_allclose(views.delta_gyro, xs.mean(axis=0) - xs[0], rtol=0.0, atol=1e-12)


def test_a_restart_sets_the_filter_from_its_first_sample() -> None:
    """The law's reset zeroes the state: the next sample sets the low-pass again (no increment), and the next window
    reads only what came after it."""
    st, out = LAW_STATE.zeros(), LAW_OUT.zeros()
    views = LAW_OUT.views(out)
    z5 = np.zeros(5)
    lpf_increments(st, 0.5, 1.0, z5, z5, 0.0, np.array([1.0, 2.0, 3.0]), 0.0, 0.0, out, 0.0)
    lpf_increments(st, 0.5, 1.0, z5, z5, 0.0, np.array([5.0, 5.0, 5.0]), 0.0, 0.0, out, 0.0)
    assert tuple(views.delta_gyro) == (2.0, 1.5, 1.0)
    st[:] = 0.0
    lpf_increments(st, 0.5, 1.0, z5, z5, 0.0, np.array([10.0, 10.0, 10.0]), 0.0, 0.0, out, 0.0)
    assert out[LO_READY] == 0.0
    lpf_increments(st, 0.5, 1.0, z5, z5, 0.0, np.array([10.0, 10.0, 10.0]), 0.0, 0.0, out, 0.0)
    assert tuple(views.delta_gyro) == (0.0, 0.0, 0.0)
