"""The adaptive law converges on the identification scenario ("the estimate moves where the truth moves").

Plant and FlightStack in one process (as navig8-sim), the ident scenario (an unknown 2 kg object at q = 0, pitch
doublets from 2 s, yaw doublets between them from 4 s). The truth is independent of the filter: K_true,i = J_ii /
I_true,ii and K_true,4 = m_UAM / m_true from the plant's composite inertia about its true CoM (sim_bridge) and the
controller's UAM model, clipped to the Eq. 20 box [0.5, 1]. The paper's configuration (one-step increments of the
measured U, Acc_m at O, the paper's Q) is run on the same data to show that the check can fail.

K2 (pitch) converges since the law takes its moment rows about the estimated composite CoM (CKF_GC_REF = 1; about the
UAM's CoM it stayed at 0.7-1.0 against the clipped truth 0.5: docs/model.md, "Estimator" item 4). All four converge.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from shared_trace import k_trace

from sim_bridge.world import world_documents

EXCITATION_T_S = 2.0  # the first pitch doublet of params/scenarios/ident.yaml
CONVERGE_WITHIN_S = 10.0
TOL_K = 0.1
SEEDS = range(1, 11)
IDENT_DURATION_S = 30.0
PAPER = {"CKF_INC_N": 1, "CKF_U_SRC": 0, "CKF_ACC_REF": 0, "CKF_SAT_GATE": 0, "CKF_Q_IXX": 1e-4,
         "CKF_Q_IYY": 5e-5, "CKF_Q_IZZ": 1e-4, "CKF_Q_M": 5e-4, "CKF_P0_SCALE": 100.0}


def _k_error(overrides: dict[str, float], duration_s: float, seed: int = 1,
             scenario: str | Path = "ident", fly_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(t, |K - clip(K_true, 0.5, 1)| per tick (n, 4)) for the ident scenario, proposed controller (fly_s:
    shared_trace.k_trace's)."""
    t, k, k_true = k_trace(overrides, duration_s, seed, scenario, fly_s=fly_s)
    return t, np.abs(k - k_true)


@pytest.fixture(scope="module")
def default_run() -> tuple[np.ndarray, np.ndarray]:
    # seed 1's first 13 s of the flight test_every_k_converges_in_10_of_10_seeds reads whole (flown once)
    return _k_error({}, EXCITATION_T_S + CONVERGE_WITHIN_S + 1.0, fly_s=IDENT_DURATION_S)


CONVERGING = [0, 1, 2, 3]  # K1..K4


def test_implied_k_converges_within_10_s_of_excitation(default_run) -> None:
    """Defaults: from 10 s after the first doublet on, K1..K4 are within 0.1 of the clipped truth
    (K_true ~ 0.31 / 0.34 / 0.99 / 0.77 -> 0.5 / 0.5 / 0.99 / 0.77), and K1, K4 were not at the start (K = 1)."""
    t, err = default_run
    late = t >= EXCITATION_T_S + CONVERGE_WITHIN_S - 1e-9
    assert late.sum() >= 100
    assert np.all(err[late][:, CONVERGING] <= TOL_K), err[late].max(axis=0)
    assert np.all(err[0, [0, 3]] > 0.2)  # the truth is far from K = 1: converging is not trivial


def test_the_paper_configuration_does_not_converge() -> None:
    """The same check on the paper's settings (one-step increments, measured U, Acc_m at O, the paper's Q) fails:
    the test can tell a converging estimator from one that barely moves (docs/results.md)."""
    t, err = _k_error(PAPER, EXCITATION_T_S + CONVERGE_WITHIN_S + 0.05)
    late = t >= EXCITATION_T_S + CONVERGE_WITHIN_S - 1e-9
    assert np.any(err[late] > 0.3)


def test_every_k_converges_in_10_of_10_seeds() -> None:
    """Seeds 1-10, defaults, the whole 30 s: K1, K3 (the yaw doublets' point) and K4 (the mass gate's,
    CKF_EXC_LIN) are within 0.1 of the clipped truth from 12 s to the end in every seed, K2 within 0.15
    (docs/results.md, "Estimator": worst seeds 0.020 / 0.103 / 0.034 / 0.096; K2 beyond 0.1 in 1 of 10)."""
    worst = np.zeros(4)
    for seed in SEEDS:
        t, err = _k_error({}, IDENT_DURATION_S, seed)
        late = t >= EXCITATION_T_S + CONVERGE_WITHIN_S - 1e-9
        worst = np.maximum(worst, err[late].max(axis=0))
    assert np.all(worst[[0, 2, 3]] <= TOL_K) and worst[1] <= 0.15, worst


def test_without_yaw_doublets_k3_wanders(tmp_path: Path) -> None:
    """The same scenario with its yaw steps removed: yaw is not excited and K3's worst error after 12 s over seeds 6
    and 8 is about three times what it is with the doublets (0.093 against 0.032 measured): the yaw doublets are
    what makes K3 converge."""
    doc = world_documents("ident")["scenario"]
    steps = []
    for step in doc["setpoints"]["steps"]:
        kept = {k: v for k, v in step.items() if k != "yaw_deg"}
        if len(kept) > 1:
            steps.append(kept)
    assert len(steps) < len(doc["setpoints"]["steps"])  # there were yaw-only steps to remove
    doc["setpoints"]["steps"] = steps
    path = tmp_path / "ident_no_yaw.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    worst_k3, worst_k3_doublets = 0.0, 0.0
    for seed in (6, 8):
        t, err = _k_error({}, 27.0, seed, path)
        worst_k3 = max(worst_k3, float(err[t >= EXCITATION_T_S + CONVERGE_WITHIN_S - 1e-9, 2].max()))
        t, err = _k_error({}, 27.0, seed, fly_s=IDENT_DURATION_S)  # test_every_k_converges_in_10_of_10_seeds's flight
        worst_k3_doublets = max(worst_k3_doublets, float(err[t >= EXCITATION_T_S + CONVERGE_WITHIN_S - 1e-9, 2].max()))
    assert worst_k3 > 0.08 and worst_k3 > 2.0 * worst_k3_doublets, (worst_k3, worst_k3_doublets)
