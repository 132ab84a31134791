"""The force balance's mass (core/force_balance.py, CKF_M_ABS_SIG): its scalar update against the Gaussian
posterior in information form, and its measurement against closed forms (F = m f with a thrust model off by a
constant factor)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.core.force_balance import ForceBalanceMass, correct_mass
from navig8_fc.core.kf_nuisance import NZ_COV, NZ_SIZE, NZ_VAR, NZ_X


def _random_prior(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    a = rng.normal(size=(n, n))
    return rng.normal(size=n) + np.array([0.4, 0.9, 1.1, 7.0, 0.0, 0.0][:n]), a @ a.T + 0.1 * np.eye(n)


def _nuisance(x: float, var: float, cov: np.ndarray) -> np.ndarray:
    nu = np.zeros(NZ_SIZE)
    nu[NZ_X], nu[NZ_VAR], nu[NZ_COV:NZ_COV + 4] = x, var, cov
    return nu


@pytest.mark.parametrize("n_nuisance", [0, 1, 2])
def test_the_update_is_the_gaussian_posterior(n_nuisance: int) -> None:
    """x, P and the nuisances after correct_mass equal the posterior of the augmented Gaussian prior given z = m + v
    (information form, P+ = (P^-1 + H^T H / r)^-1, x+ = P+ (P^-1 x + H^T z / r)), to 1e-9; cov(c, d) is zero in
    the prior, and the update's is dropped (kf_nuisance's convention), so the check reads the blocks it keeps."""
    rng = np.random.default_rng(7)
    n = 4 + n_nuisance
    x0, p0 = _random_prior(rng, n)
    if n == 6:
        p0[4, 5] = p0[5, 4] = 0.0
        p0 += np.eye(6) * max(0.0, -np.linalg.eigvalsh(p0).min() + 0.1)
    z, r = 7.3, 0.01
    x, p = x0[:4].copy(), p0[:4, :4].copy()
    nz = _nuisance(x0[4], p0[4, 4], p0[:4, 4]) if n >= 5 else np.zeros(NZ_SIZE)
    nx = _nuisance(x0[5], p0[5, 5], p0[:4, 5]) if n == 6 else np.zeros(NZ_SIZE)
    correct_mass(x, p, nz, nx, z, r)

    h = np.zeros(n)
    h[3] = 1.0
    info = np.linalg.inv(p0) + np.outer(h, h) / r
    p_post = np.linalg.inv(info)
    x_post = p_post @ (np.linalg.solve(p0, x0) + h * z / r)
    assert x == pytest.approx(x_post[:4], abs=1e-9)
    assert p == pytest.approx(p_post[:4, :4], abs=1e-9)
    if n >= 5:
        assert nz[NZ_X] == pytest.approx(x_post[4], abs=1e-9)
        assert nz[NZ_VAR] == pytest.approx(p_post[4, 4], abs=1e-9)
        assert nz[NZ_COV:NZ_COV + 4] == pytest.approx(p_post[:4, 4], abs=1e-9)
    else:
        assert not nz.any()  # no object held: the nuisance stays zero
    if n == 6:
        assert nx[NZ_X] == pytest.approx(x_post[5], abs=1e-9)
        assert nx[NZ_COV:NZ_COV + 4] == pytest.approx(p_post[:4, 5], abs=1e-9)


def test_a_certain_measurement_sets_the_mass_and_leaves_the_uncorrelated_states() -> None:
    x = np.array([0.4, 0.9, 1.1, 6.5])
    p = np.diag([0.01, 0.02, 0.03, 0.2])
    nz, nx = np.zeros(NZ_SIZE), np.zeros(NZ_SIZE)
    correct_mass(x, p, nz, nx, 7.0, 1e-12)
    assert x == pytest.approx([0.4, 0.9, 1.1, 7.0], abs=1e-9)
    assert p[3, 3] == pytest.approx(0.0, abs=1e-9) and np.diag(p)[:3] == pytest.approx([0.01, 0.02, 0.03])


def _fly(fbm: ForceBalanceMass, m_kg: float, scale: float, n: int, rng: np.random.Generator) -> None:
    """n ticks of F = m f through a doublet-like motion; the model's F off by `scale` (the thrust coefficient)."""
    for _ in range(n):
        f = np.array([rng.normal(0.0, 1.0), -9.81 + rng.normal(0.0, 0.5)])
        fm = m_kg * f * scale
        fbm.update(float(fm[0]), float(fm[1]), float(f[0]), float(f[1]))


def test_the_measured_mass_is_the_held_mass_whatever_the_thrust_models_scale() -> None:
    """Closed form: with F_model = s F and F = m f, F.f / f.f reads s m; the ratio learned with the UAM's mass
    (m_UAM / (s m_UAM) = 1 / s) turns s m_held into m_held. A constant f (after the running mean, the low-passes
    of F and f are then exactly proportional)."""
    alpha = 1.0 - math.exp(-0.01 / 0.7)
    fbm = ForceBalanceMass(alpha, 0.1)
    m_uam, m_held, s = 6.5, 7.0, 1.1
    f = (0.3, -9.81)
    for _ in range(200):
        fbm.update(m_uam * s * f[0], m_uam * s * f[1], *f)
    assert math.isnan(fbm.measured_mass_kg())  # not calibrated yet
    for _ in range(20):
        fbm.calibrate(m_uam)
    for _ in range(2000):  # the held object: F steps, f stays (hover)
        fbm.update(m_held * s * f[0], m_held * s * f[1], *f)
    assert fbm.measured_mass_kg() == pytest.approx(m_held, rel=1e-9)


def test_through_noisy_motion_the_measured_mass_is_within_its_noise() -> None:
    """The same with f moving and noisy per tick (F follows f exactly): the low-passed ratio is within 1 % of the
    held mass (each low-pass averages ~140 ticks of 0.5-1 m/s^2 noise on 9.8)."""
    rng = np.random.default_rng(3)
    fbm = ForceBalanceMass(1.0 - math.exp(-0.01 / 0.7), 0.1)
    _fly(fbm, 6.5, 0.9, 300, rng)
    for _ in range(20):
        fbm.calibrate(6.5)
    _fly(fbm, 7.5, 0.9, 500, rng)
    assert fbm.measured_mass_kg() == pytest.approx(7.5, rel=0.01)


def test_in_free_fall_there_is_no_balance_to_read() -> None:
    fbm = ForceBalanceMass(0.1, 0.1)
    fbm.update(0.0, 0.0, 0.0, 0.0)
    assert math.isnan(fbm.ratio_kg())
    for _ in range(20):
        fbm.calibrate(6.5)  # ignored: nothing to calibrate on
    fbm.update(0.0, -65.0, 0.0, -10.0)
    assert math.isnan(fbm.measured_mass_kg())


class _Recorder:
    def __init__(self) -> None:
        self.z: list[float] = []

    def correct_mass(self, z_kg: float, r_kg2: float) -> None:
        self.z.append(z_kg)


@pytest.mark.parametrize("restart", [True, False])
def test_a_grasp_restarts_the_low_passes(restart: bool) -> None:
    """Through tick(): after the gripper closes and the law calls restart(), the first window's measurement reads the
    held mass alone, not a mix weighted exp(-t / tau) toward the UAM's (without the restart: e^-1 of the step still
    missing, 6.5 + 0.5 (1 - (1 - alpha)^71) kg). G_C's force rows are identity on U's last two entries, so the model
    force is U[3:]."""
    alpha = 1.0 - math.exp(-0.01 / 0.7)
    fbm, kf = ForceBalanceMass(alpha, 0.1), _Recorder()
    gc = np.eye(5)
    f = (0.3, -9.81)
    m_uam, m_held = 6.5, 7.0

    def tick(m: float, correct: bool, closed: bool) -> None:
        u = np.array([0.0, 0.0, 0.0, m * f[0], m * f[1]])
        acc = np.array([0.0, 0.0, 0.0, *f])
        fbm.tick(gc, u, acc, correct, closed, m_uam, kf)

    for k in range(500):
        tick(m_uam, k % 25 == 0, False)  # open: 20 calibration windows
    if restart:
        fbm.restart()  # the grasp, as the law detects it
    tick(m_held, False, True)  # the object's weight from this tick on
    for _ in range(69):  # one filter constant's hold
        tick(m_held, False, True)
    tick(m_held, True, True)
    want = m_held if restart else m_uam + (m_held - m_uam) * (1.0 - (1.0 - alpha) ** 71)  # 71 held samples
    assert kf.z == [pytest.approx(want, rel=1e-12)]
