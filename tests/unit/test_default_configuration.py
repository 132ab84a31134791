"""The default configuration is the one documented (docs/model.md, "The default configuration"): the robust
controller on the plausible (±60 N tail) vehicle, with the paper's method one preset away (params/presets/paper.parm).

The test fails when a default moves away from the table, when the table and the parameter file disagree, or when
paper.parm stops restoring the paper's value of a part the defaults changed."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from navig8_fc.core.vehicle import VehicleConfig
from navig8_fc.params.registry import ParamRegistry
from navig8_fc.params.store import read_parm_file

ROOT = Path(__file__).resolve().parents[2]

# (parameter, default, the paper's value): the controller parts of the table
ROBUST = (
    ("INDI_ACC_REF", 1, 0), ("INDI_ALLOC", 1, 0), ("INDI_ALLOC_W_YAW", 3.0, 0.3), ("INDI_ALLOC_DTILT", 1.0, 0.3),
    ("INDI_LPF_TAU", 0.02, 0.1), ("INDI_U0_SRC", 1, 0), ("INDI_ARM_FF", 1, 0), ("OL_JERK_MAX", 5.0, 0.0),
    ("OL_ATT_ACC_REF", 1.0, 0.0), ("OL_ATT_RATE_REF", 0.6, 1.0),
)
CHECKS_ON = (("ACT_ID", 1), ("ARM_SERVO_ID", 1), ("OL_FF", 1))
# the flown loop gain (lambda*, the flown floor): one row of the table
FLOWN_GAIN = (("INDI_LAM_REF", 0.4, 1.0), ("INDI_KFL_MIN", 0.4, 0.0))


def test_the_defaults_are_the_documented_robust_configuration() -> None:
    reg = ParamRegistry.from_defaults()
    for name, default, _ in ROBUST + FLOWN_GAIN:
        assert float(reg[name]) == pytest.approx(default), name
    for name, value in CHECKS_ON:
        assert int(reg[name]) == value, name


def test_paper_parm_restores_the_papers_method() -> None:
    paper = read_parm_file(ROOT / "params" / "presets" / "paper.parm")
    for name, _, value in ROBUST + FLOWN_GAIN:
        assert paper[name] == pytest.approx(value), name
    # applied one at a time in the file's order from the defaults (navig8-sim, MAVProxy's param load) and as a stored
    # set sorted by name (navig8-sitl --params, the FC's start): every value accepted, the paper's flown gain in force
    names = list(paper)
    assert names.index("INDI_LAM_REF") < names.index("INDI_KFL_MIN")
    reg = ParamRegistry.from_defaults()
    for name, value in paper.items():
        assert reg.set(name, value).accepted, name
    stored = ParamRegistry.from_defaults()
    assert all(r.accepted for r in stored.load_values({**stored.as_dict(), **paper}))
    for r in (reg, stored):
        assert (float(r["INDI_LAM_REF"]), float(r["INDI_KFL_MIN"])) == (1.0, 0.0)
    # and the adaptive law's settings as printed (Sec. 4): one-step increments, measured U, no gates
    for name, value in (("CKF_INC_N", 1), ("CKF_U_SRC", 0), ("CKF_SAT_GATE", 0), ("CKF_EXC_LIN", 0),
                        ("CKF_Q_IXX", 1e-4), ("CKF_Q_IYY", 5e-5), ("CKF_Q_IZZ", 1e-4), ("CKF_Q_M", 5e-4),
                        ("CKF_ACC_REF", 0), ("CKF_GC_REF", 0), ("CKF_GRIP_RST", 0), ("CKF_PRED_DJ", 0)):
        assert paper[name] == pytest.approx(value), name


def test_the_estimator_options_are_the_documented_ones() -> None:
    """The law's moment rows about the estimated CoM by default; forgetting and the model's drift only in
    identification.parm (docs/model.md, "Estimator", items 4-9: they identify better and fly worse, or, the pitch
    row in moment space, do not help without forgetting; the running-mean start and the delivered U were measured
    on the identification family only)."""
    reg = ParamRegistry.from_defaults()
    assert (int(reg["CKF_GC_REF"]), int(reg["CKF_GRIP_RST"]), int(reg["CKF_PRED_DJ"])) == (1, 0, 0)
    assert reg["CKF_R_PITCH"] == 0.0 and reg["CKF_CZ_SIG"] == 0.0
    assert (int(reg["CKF_LPF_SEED"]), int(reg["CKF_U_SRC"]), int(reg["CKF_IXZ_MOD"])) == (0, 1, 0)
    assert reg["CKF_GRIP_SIG"] == 0.0 and reg["CKF_M_SIG_OPEN"] == 0.0 and reg["CKF_IXZ_SIG"] == 0.0
    assert int(reg["CKF_CZ_DM"]) == 0 and int(reg["CKF_MOM_LPF"]) == 0 and int(reg["CKF_MOM_MREF"]) == 0
    assert int(reg["CKF_PROJ_IYY"]) == 0 and int(reg["CKF_CZ_FOLLOW"]) == 0
    assert reg["CKF_Q_IXX"] == reg["CKF_Q_IZZ"] == pytest.approx(1e-5)  # the preset's a quarter of it (item 20)
    assert reg["CKF_M_ABS_SIG"] == 0.0  # the force balance's mass needs the gripper's reports (item 21)
    assert int(reg["CKF_GYRO"]) == 0  # Eq. 24 as the paper writes it (the defaults fly K = 0.4 whatever K_hat)
    assert int(reg["CKF_SYNC"]) == 0  # item 24: neutral on the defaults' flight and estimate, measured
    assert reg["CKF_R_MOVE"] == 1.0  # item 25: a measurement's gate; the defaults' estimator is Eq. 24's
    ident = read_parm_file(ROOT / "params" / "presets" / "identification.parm")
    assert ident == {"CKF_GRIP_RST": 1, "CKF_PRED_DJ": 1, "CKF_R_PITCH": pytest.approx(0.01),
                     "CKF_CZ_SIG": pytest.approx(0.005), "CKF_LPF_SEED": 1, "CKF_U_SRC": 2, "CKF_IXZ_MOD": 2,
                     "CKF_GRIP_SIG": pytest.approx(1.0), "CKF_M_SIG_OPEN": pytest.approx(0.2),
                     "CKF_IXZ_SIG": pytest.approx(0.1), "CKF_CZ_DM": 1, "CKF_START_DLY": pytest.approx(0.75),
                     "CKF_MOM_LPF": 1, "CKF_MOM_MREF": 1, "CKF_MOM_MOVE": 1, "CKF_CZ_FOLLOW": 1, "CKF_PROJ_IYY": 1,
                     "CKF_Q_IXX": pytest.approx(2.5e-6), "CKF_Q_IZZ": pytest.approx(2.5e-6),
                     "CKF_M_ABS_SIG": pytest.approx(0.1), "CKF_GYRO": 1, "CKF_SYNC": 1,
                     "CKF_R_MOVE": pytest.approx(8.0)}


def test_the_documented_table_agrees_with_the_parameter_file() -> None:
    text = (ROOT / "docs" / "model.md").read_text()
    section = text[text.index("## The default configuration"):text.index("## Feed-forward that cannot hurt")]
    for name, default, paper in ROBUST[:7]:  # one row each (the shaping parameters share one)
        row = next(line for line in section.splitlines() if line.startswith(f"| `{name}` |"))
        cells = [c.strip() for c in row.strip("|").split("|")]
        got_default = float(re.match(r"[-0-9.e]+", cells[1]).group())
        got_paper = float(re.match(r"[-0-9.e]+", cells[2]).group())
        assert (got_default, got_paper) == pytest.approx((default, paper)), row
    row = next(line for line in section.splitlines() if line.startswith("| `INDI_LAM_REF`, `INDI_KFL_MIN` |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert [float(x) for x in cells[1].split(",")] == pytest.approx([d for _, d, _ in FLOWN_GAIN]), row
    assert [float(x) for x in cells[2].split(",")] == pytest.approx([p for _, _, p in FLOWN_GAIN]), row


def test_the_default_vehicle_has_a_plausible_tail() -> None:
    cfg = VehicleConfig.load()
    tail_n = cfg.k_thrust_tail * cfg.tail_speed_max**2
    duct_n = cfg.k_thrust_duct * cfg.duct_speed_max**2
    assert tail_n == pytest.approx(60.0)  # docs/model.md "Tail": the top of the plausible range
    assert tail_n < duct_n  # less than one duct
