"""The estimator's gyroscopic moment (core/gyroscopic.py, CKF_GYRO): w x (I w) against numpy's cross product with the
full tensor, and its low-passed window increments against lpf_increments' (the law's own filter, a separate
implementation) fed the same signal."""

from __future__ import annotations

import numpy as np
import pytest

from navig8_fc.core.adaptive_law import LAW_OUT, LAW_STATE, LO_READY, lpf_increments
from navig8_fc.core.gyroscopic import GyroscopicIncrement, gyroscopic_moment


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


@pytest.mark.parametrize("mean_start", [False, True])
@pytest.mark.parametrize("n_window", [1.0, 25.0])
def test_increments_match_the_laws_filter(mean_start: bool, n_window: float) -> None:
    """Fed through acc_m's first three channels of lpf_increments, the same moments give the same window increments
    on the same steps (to 1e-12), with and without the running-mean start."""
    rng = np.random.default_rng(5)
    alpha = 1.0 - np.exp(-0.01 / 0.7)
    gi = GyroscopicIncrement(alpha, mean_start)
    st, out = LAW_STATE.zeros(), LAW_OUT.zeros()
    views = LAW_OUT.views(out)
    u = np.zeros(5)
    n_ready = 0
    for k in range(300):
        moment = tuple(rng.normal(scale=0.3, size=3).tolist())
        acc = np.array([*moment, 0.0, 0.0])
        lpf_increments(st, alpha, n_window, u, acc, 0.0, 0.0, 0.0, out, 1.0 if mean_start else 0.0)
        ready = out[LO_READY] != 0.0
        got = gi.tick(moment, ready)
        if ready:
            n_ready += 1
            assert got is not None
            assert np.allclose(got, views.delta_acc[:3], rtol=0.0, atol=1e-12), k
        else:
            assert got is None
    assert n_ready == int(299 // n_window)


def test_reset_restarts_the_filter() -> None:
    """After reset the first sample sets the low-pass again: no increment, and the next window reads only what came
    after it."""
    gi = GyroscopicIncrement(0.5, False)
    gi.tick((1.0, 2.0, 3.0), False)
    assert gi.tick((5.0, 5.0, 5.0), True) == (2.0, 1.5, 1.0)
    gi.reset()
    assert gi.tick((10.0, 10.0, 10.0), True) is None
    assert gi.tick((10.0, 10.0, 10.0), True) == (0.0, 0.0, 0.0)
