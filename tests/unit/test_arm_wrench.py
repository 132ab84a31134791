"""CKF_ARM_WRENCH: the arm's reaction pitch moment in the adaptive law's measurement.

- The kernel's h' (MP.HDC / UO.HDC: d/dt of the bodies' pitch angular momentum relative to the body, about the
  composite CoM) against a central time difference of tools/authority_excursion.py's h (written separately with
  numpy) along q(t) = q0 + q' t + q'' t^2 / 2.
- The law on noise-free synthetic signals that satisfy G_C U = G_I,true Acc + [0, h', 0, 0, 0] exactly, with
  h' correlated with Q-dot (as the arm's reaction is during a reversal): with the term the estimate reaches the
  true Iyy; without it (the paper's Eq. 24) it settles elsewhere. A small R makes the filter converge within
  the test (the paper's R = 1500^2.. is for noisy data; the bias is the same).
"""

from __future__ import annotations

import numpy as np
import pytest

from navig8_fc.core import g_c
from navig8_fc.core.adaptive_law import AdaptiveLaw, AdaptiveLawConfig
from navig8_fc.core.ckf_config import CkfConfig
from navig8_fc.core.vehicle import UamModel, VehicleConfig, inertia_matrix_gi, model_geometry
from navig8_tools.authority_excursion import arm_momentum_y


@pytest.fixture(scope="module")
def cfg() -> VehicleConfig:
    return VehicleConfig.load()


def test_hdc_against_time_difference_of_h(cfg: VehicleConfig) -> None:
    rng = np.random.default_rng(11)
    geo = model_geometry(cfg)
    for _ in range(8):
        q0, qd, qdd = rng.uniform(-1, 1, 3), rng.uniform(-4, 4, 3), rng.uniform(-40, 40, 3)
        mo = float(rng.choice([0.0, rng.uniform(0.1, 2.0)]))
        mp = g_c.MP.zeros()
        g_c.mass_props(q0, qd, qdd, mo, geo, np.empty((3, 3)), np.empty((3, 3)), mp)
        eps = 1e-5

        hs = []
        for t in (eps, -eps):
            q, v = q0 + qd * t + 0.5 * qdd * t * t, qd + qdd * t
            hs.append(float(arm_momentum_y(cfg, q[None, :], v[None, :], mo)[0]))
        fd = (hs[0] - hs[1]) / (2 * eps)
        assert mp[g_c.MP.HDC] == pytest.approx(fd, rel=1e-6, abs=1e-6)
        # the controller's model: the same with the estimated object
        uo = g_c.UO.zeros()
        model = UamModel(cfg)
        g_c.uam_model(q0, qd, qdd, mo, geo, model.force_per_input, model.moment_o_per_input, np.empty((3, 3)),
                    np.empty((3, 3)), np.empty((5, 5)), np.empty((5, 5)), uo)
        assert uo[g_c.UO.HDC] == pytest.approx(mp[g_c.MP.HDC], rel=1e-12, abs=1e-12)


def _fly_synthetic(cfg: VehicleConfig, arm_wrench: bool) -> float:
    model = UamModel(cfg)
    q = np.radians([20.0, 20.0, 20.0])
    st = model.evaluate(q, (0.0, 0.0, 0.0))
    gc_inv = np.ascontiguousarray(np.linalg.inv(st.gc))
    k2_true = 0.7
    inertia_true = st.inertia_com.copy()
    inertia_true[1, 1] /= k2_true
    gi_true = inertia_matrix_gi(inertia_true, st.mass_kg)
    ckf = CkfConfig(r_diag=(1.0,) * 5, q_diag=(1e-8, 1e-6, 1e-8, 1e-8), start_delay_s=0.5)
    law = AdaptiveLaw(AdaptiveLawConfig(ckf, 0.5, 1.0, arm_wrench))
    t = np.arange(0.0, 30.0, 0.01)
    # pitch excitation; the arm's h' in phase with Q-dot (the reaction that drives the pitch) plus its own part:
    # read as inertia it adds 0.5 Iyy_UAM, i.e. an apparent K2 = 1 / (1 / 0.7 + 0.5) = 0.52
    qdot = 6.0 * np.sin(2 * np.pi * 0.8 * t) + 3.0 * np.sin(2 * np.pi * 2.1 * t)
    hd = 0.5 * st.inertia_com[1, 1] * qdot + 0.5 * np.sin(2 * np.pi * 0.3 * t)
    x = None
    for i, ti in enumerate(t):
        acc = np.array([0.3 * np.sin(1.7 * ti), qdot[i], 0.2 * np.sin(2.3 * ti), 0.5 * np.sin(0.9 * ti),
                        -9.8 + 0.5 * np.sin(1.3 * ti)])
        wrench = gi_true @ acc + np.array([0.0, hd[i], 0.0, 0.0, 0.0])
        u = gc_inv @ wrench
        _, _, status = law.step_arrays(ti, u, acc, gc_inv, st.inertia_com, st.mass_kg, np.zeros((3, 3)),
                                       float(hd[i]))
        x = status.k
    assert x is not None
    return x[1]


def test_arm_term_removes_the_bias(cfg: VehicleConfig) -> None:
    k2_with = _fly_synthetic(cfg, True)
    k2_without = _fly_synthetic(cfg, False)
    assert k2_with == pytest.approx(0.7, abs=0.02)
    assert k2_without < 0.6  # the paper's Eq. 24 reads h' as inertia (apparent K2 0.52)
