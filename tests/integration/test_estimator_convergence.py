"""The adaptive law converges on the identification scenario (issue 10's "the estimate moves where the truth moves").

Plant and FlightStack in one process (as navig8-sim), the ident scenario (an unknown 2 kg object at q = 0, pitch
doublets from 2 s), one seed. The truth is independent of the filter: K_true,i = J_ii / I_true,ii and
K_true,4 = m_UAM / m_true from the plant's composite inertia about its true CoM (sim_bridge) and the controller's UAM
model, clipped to the Eq. 20 box [0.5, 1]. The paper's configuration (one-step increments of the measured U, Acc_m
at O, the paper's Q) is run on the same data to show that the check can fail.
"""

from __future__ import annotations

import numpy as np
import pytest

from navig8_fc.core.controller import warm_up_kernels
from navig8_fc.flight import FlightStack
from navig8_fc.params.registry import ParamRegistry
from navig8_tools.sim import _sensors_to_fc
from sim_bridge.messages import ActuatorCommand as PlantCommand
from sim_bridge.plant import Plant
from sim_bridge.world import load_world

EXCITATION_T_S = 2.0  # the first pitch doublet of params/scenarios/ident.yaml
CONVERGE_WITHIN_S = 10.0
TOL_K = 0.1
PAPER = {"CKF_INC_N": 1, "CKF_U_SRC": 0, "CKF_ACC_REF": 0, "CKF_SAT_GATE": 0, "CKF_Q_IXX": 1e-4,
         "CKF_Q_IYY": 5e-5, "CKF_Q_IZZ": 1e-4, "CKF_Q_M": 5e-4, "CKF_P0_SCALE": 100.0}


def _k_error(overrides: dict[str, float], duration_s: float, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(t, |K - clip(K_true, 0.5, 1)| per tick (n, 4)) for the ident scenario, proposed controller."""
    reg = ParamRegistry.from_defaults()
    for name, value in overrides.items():
        assert reg.set(name, value).accepted, name
    w = load_world("ident")
    plant = Plant(w.vehicle, w.plant, w.scenario, np.random.default_rng(seed))
    stack = FlightStack(w.fc_vehicle, reg, w.scenario.script)
    cfg = stack.core.config
    warm_up_kernels(w.fc_vehicle, cfg)
    n = int(round(duration_s / cfg.dt_s))
    ts, errs = [], []
    for k in range(n + 1):
        sb = plant.sense()
        s = _sensors_to_fc(sb)
        res = stack.step(s, True, sb.time_us)
        st, tr = res.status, plant.truth()
        j, i_true = st.inertia_uam_diag, np.asarray(tr.inertia_com_kgm2)
        k_true = np.array([j[0] / i_true[0, 0], j[1] / i_true[1, 1], j[2] / i_true[2, 2], st.mass_uam_kg / tr.mass_kg])
        ts.append(s.t_s)
        errs.append(np.abs(np.array(st.adapt.k) - np.clip(k_true, reg["INDI_K_MIN"], reg["INDI_K_MAX"])))
        if k == n:
            break
        plant.step(PlantCommand(tilt_rad=res.command.tilt_rad, speed_rad_s=res.command.speed_rad_s), cfg.dt_s)
    return np.array(ts), np.array(errs)


@pytest.fixture(scope="module")
def default_run() -> tuple[np.ndarray, np.ndarray]:
    return _k_error({}, EXCITATION_T_S + CONVERGE_WITHIN_S + 1.0)


def test_implied_k_converges_within_10_s_of_excitation(default_run) -> None:
    """Defaults: from 10 s after the first doublet on, every implied K is within 0.1 of the clipped truth
    (K_true ~ 0.31 / 0.34 / 0.99 / 0.77 -> 0.5 / 0.5 / 0.99 / 0.77), and it was not at the start (K = 1)."""
    t, err = default_run
    late = t >= EXCITATION_T_S + CONVERGE_WITHIN_S - 1e-9
    assert late.sum() >= 100
    assert np.all(err[late] <= TOL_K), err[late].max(axis=0)
    assert np.all(err[0, [0, 1, 3]] > 0.2)  # the truth is far from K = 1: converging is not trivial


def test_the_paper_configuration_does_not_converge() -> None:
    """The same check on the paper's settings (one-step increments, measured U, Acc_m at O, the paper's Q) fails:
    the test can tell a converging estimator from one that barely moves (docs/results.md)."""
    t, err = _k_error(PAPER, EXCITATION_T_S + CONVERGE_WITHIN_S + 0.05)
    late = t >= EXCITATION_T_S + CONVERGE_WITHIN_S - 1e-9
    assert np.any(err[late] > 0.3)
