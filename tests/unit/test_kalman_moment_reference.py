"""The pitch row's low-passed moment re-referred when its reference point moves (CKF_MOM_MREF; docs/model.md,
"Estimator" item 17): kf_nuisance.refer_moment against the same filter run wholly about the final point, the moment
about it computed from the moment about O and the forces (M_c = M_O - (c_z F_x - c_x F_z), the y row of M_O - c x F)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.core.kf_nuisance import refer_moment


def _about(m_o: np.ndarray, f: np.ndarray, c: tuple[float, float]) -> np.ndarray:
    return m_o - (c[1] * f[:, 0] - c[0] * f[:, 1])


@pytest.mark.parametrize("seed", range(20))
def test_re_referred_filter_equals_the_filter_about_the_new_point(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, j, alpha = 60, int(rng.integers(2, 58)), float(rng.uniform(0.01, 0.5))
    m_o = rng.normal(0.0, 3.0, n)  # pitch moment about O (N m)
    f = np.column_stack([rng.normal(40.0, 5.0, n), rng.normal(-60.0, 5.0, n)])  # F_x, F_z (N)
    c_a = (float(rng.normal(0.0, 0.05)), float(rng.normal(0.1, 0.05)))
    c_b = (c_a[0] + float(rng.normal(0.0, 0.03)), c_a[1] + float(rng.normal(0.0, 0.03)))
    m_a, m_b = _about(m_o, f, c_a), _about(m_o, f, c_b)
    st = [m_a[0], m_a[0], f[0, 0], f[0, 1]]
    ref = m_b[0]  # the independent filter: about c_b throughout
    for k in range(1, n):
        moved = k == j
        mom = m_b[k] if k >= j else m_a[k]
        dc = (c_b[0] - c_a[0], c_b[1] - c_a[1]) if moved else (0.0, 0.0)
        refer_moment(st, f[k, 0], f[k, 1], alpha, *dc)
        st[0] += alpha * (mom - st[0])
        ref += alpha * (m_b[k] - ref)
        if k >= j:
            assert st[0] == pytest.approx(ref, abs=1e-9)
    assert st[2] == pytest.approx(_lpf(f[:, 0], alpha)) and st[3] == pytest.approx(_lpf(f[:, 1], alpha))


def test_without_a_move_only_the_forces_are_filtered() -> None:
    st = [1.5, 0.5, 40.0, -60.0]
    refer_moment(st, 50.0, -50.0, 0.1, 0.0, 0.0)
    assert st[:2] == [1.5, 0.5] and st[2:] == pytest.approx([41.0, -59.0])


def test_the_window_start_moves_with_the_state() -> None:
    """A move alone changes no increment: the state and the window's start shift alike (-(dc_z F_x,f - dc_x F_z,f))."""
    st = [1.5, 0.5, 40.0, -60.0]
    refer_moment(st, 40.0, -60.0, 0.1, 0.01, 0.02)
    shift = -(0.02 * 40.0 - 0.01 * -60.0)
    assert st[0] == pytest.approx(1.5 + shift) and st[1] == pytest.approx(0.5 + shift)
    assert st[0] - st[1] == pytest.approx(1.0)


def _lpf(x: np.ndarray, alpha: float) -> float:
    y = x[0]
    for v in x[1:]:
        y += alpha * (v - y)
    return float(y)


@pytest.mark.parametrize("move", [False, True])
def test_the_low_passed_moment_only_while_the_arm_moves(move: bool) -> None:
    """CKF_MOM_MOVE: the pitch row reads the low-passed moment (a finite pitch_y) while the arm moves or has not
    rested for PITCH_EVENT_HOLD_TAU filter constants and a window (AdaptiveLaw.arm_rested), G_C[M, :] Delta U (nan)
    at rest; without it the low-passed moment throughout."""
    from navig8_fc.core.adaptive_law import ARM_REST_IYY_DOT, PITCH_EVENT_HOLD_TAU, AdaptiveLaw, AdaptiveLawConfig
    from navig8_fc.core.ckf_config import CkfConfig

    ckf = CkfConfig(pitch_r_nm2=0.01, moment_lpf=True, moment_arm_moving=move, inc_window=25, lpf_tau_s=0.7,
                    dt_s=0.01, start_delay_s=0.0)
    law = AdaptiveLaw(AdaptiveLawConfig(ckf))
    seen: list[tuple[float, float]] = []
    step = law.kf.step
    t = [0.0]

    def spy(*a, **kw):  # the pitch row's y as the law passes it
        seen.append((t[0], kw["pitch_y"]))
        return step(*a, **kw)

    law.kf.step = spy
    gc_inv = np.ascontiguousarray(np.linalg.inv(np.diag([2.0, 2.0, 2.0, 0.1, 0.1])))
    inertia = np.diag([0.4, 0.6, 0.3])
    rng = np.random.default_rng(0)
    wait_s = PITCH_EVENT_HOLD_TAU * 0.7 + 0.25
    for k in range(800):
        t[0] = 0.01 * k
        rate = np.zeros((3, 3))
        if 2.0 <= t[0] < 3.0:
            rate[1, 1] = 2.0 * ARM_REST_IYY_DOT  # the arm moves for 1 s
        law.step_arrays(t[0], rng.normal(0.0, 1.0, 5), rng.normal(0.0, 0.1, 5), gc_inv, inertia, 6.5, rate)
    moving = [y for ts, y in seen if ts < wait_s or 2.0 <= ts < 3.0 + wait_s - 0.011]
    resting = [y for ts, y in seen if wait_s + 0.011 < ts < 2.0 or ts > 3.0 + wait_s + 0.011]
    corrected = [y for y in moving if not math.isnan(y)]
    assert len(corrected) > 5  # windows closed while the arm moved read the low-passed moment
    rest_read = [y for y in resting if not math.isnan(y)]
    if move:
        assert not rest_read
    else:
        assert len(rest_read) > 5
