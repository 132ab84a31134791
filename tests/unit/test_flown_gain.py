"""The flown loop gain (INDI_LAM_REF, INDI_KFL_MIN; docs/results.md "Adapting with a flown gain"): the INDI flies
K_flown,i = max(lambda* K_hat,i, floor) on the rotational axes, K4 as estimated. Checked against an independent
computation: the eigenvalues of G_hat G^-1 with G from the vehicle's truth (vehicle.effectiveness_pair, Eq. 14) equal
lambda* K_hat / K_true; and the stability floor (registry, navig8-stability) analyses the flown box, not K_hat's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navig8_fc.core import k_xi
from navig8_fc.core.controller import ControllerConfig, FcSensors, FlightControllerCore
from navig8_fc.core.outer_loop import Setpoint
from navig8_fc.core.vehicle import VehicleConfig, effectiveness_pair, mass_properties
from navig8_fc.params.registry import ParamRegistry, flown_k_bounds

K_PIN = (0.8, 0.9, 0.7, 0.95)  # K_hat (pinned mode: the estimate is this constant)
LAM_REF, K_FLOOR = 0.6, 0.45  # K_flown = (0.48, 0.54, max(0.42, 0.45) = 0.45, 0.95)
Q_RAD = (0.3, -0.2, 0.4)


def _core(lam_ref: float, k_floor: float) -> tuple[VehicleConfig, FlightControllerCore]:
    vehicle = VehicleConfig.load()
    reg = ParamRegistry.from_defaults(check_stability=False)
    sets = {"CKF_MODE": 3, "CKF_K_PIN1": K_PIN[0], "CKF_K_PIN2": K_PIN[1], "CKF_K_PIN3": K_PIN[2],
            "CKF_K_PIN4": K_PIN[3], "INDI_KFL_MIN": k_floor, "INDI_LAM_REF": lam_ref}
    for name, value in sets.items():
        assert reg.set(name, value).accepted, name
    return vehicle, FlightControllerCore(vehicle, ControllerConfig.from_params(reg.as_dict(), vehicle))


def _gi_hat_after_ticks(core: FlightControllerCore, n: int = 3) -> tuple[np.ndarray, np.ndarray, tuple[float, ...]]:
    s = FcSensors(t_s=0.0, gyro_frd_rad_s=(0.0, 0.0, 0.0), accel_frd_m_s2=(0.0, 0.0, -9.81), pos_ned_m=(0.0, 0.0, -2.0),
                  vel_ned_m_s=(0.0, 0.0, 0.0), quat_wxyz=(1.0, 0.0, 0.0, 0.0), duct_tilt_rad=(0.0, 0.0),
                  prop_speed_rad_s=(300.0, 300.0, 0.0), joint_pos_rad=Q_RAD, joint_rate_rad_s=(0.0, 0.0, 0.0))
    st = None
    for i in range(n):
        s = FcSensors(**{**s.__dict__, "t_s": i * core.config.dt_s})
        _, st = core.step(s, Setpoint((0.0, 0.0, -2.0)), engaged=True)
    assert st is not None
    return np.array(st.gi_hat).reshape(5, 5), np.array(st.q_est_rad), st.adapt.k


def test_flown_k_and_its_box() -> None:
    assert k_xi.flown_k((0.8, 0.9, 0.7, 0.95), 0.6, 0.45) == pytest.approx((0.48, 0.54, 0.45, 0.95))
    assert k_xi.flown_k((0.8, 0.9, 0.7, 0.95), 1.0, 0.0) == (0.8, 0.9, 0.7, 0.95)
    assert k_xi.flown_k_box(0.5, 1.0, 1.0, 0.0) == (0.5, 1.0)  # the defaults: the Eq. 20 box itself
    assert k_xi.flown_k_box(0.5, 1.0, 0.5, 0.4) == (0.4, 1.0)  # rotational [0.4, 0.5], mass [0.5, 1]
    assert k_xi.flown_k_box(0.3, 1.0, 1.5, 0.0) == (0.3, 1.5)


@pytest.mark.parametrize("object_mass_kg", [0.0, 1.0])
def test_eigenvalues_of_g_hat_g_inv_are_lambda_ref_k_hat_over_k_true(object_mass_kg: float) -> None:
    """Independent of flown_gi_hat's column scaling: the controller's G_hat_I against the truth's G (Eq. 14) with the
    object at the gripper. No object: every eigenvalue is K_flown (K_true = 1). With one: the pitch eigenvalue is
    K_flown,2 / K_true,2 with K_true,2 = I_yy,UAM / I_yy,true (Eq. 17), the force pair K4 / K_true,4; the lateral
    pair is the eigenvalues of diag(K_flown,1, K_flown,3) Xi_lat."""
    vehicle, core = _core(LAM_REF, K_FLOOR)
    gi_hat, q, k_hat = _gi_hat_after_ticks(core)
    assert k_hat == pytest.approx(K_PIN)  # the estimate is untouched
    pair = effectiveness_pair(vehicle, q, object_mass_kg)
    g_hat = np.linalg.inv(gi_hat) @ pair.gc_uam  # Acc = G U, G = G_I^-1 G_C (Eq. 3-4), G_hat with G_hat_I
    g_true = np.linalg.inv(pair.gi_true) @ pair.gc_true
    lam = np.linalg.eigvals(g_hat @ np.linalg.inv(g_true))
    k_flown = (LAM_REF * K_PIN[0], LAM_REF * K_PIN[1], max(LAM_REF * K_PIN[2], K_FLOOR), K_PIN[3])
    uam, true = mass_properties(vehicle, q, 0.0), mass_properties(vehicle, q, object_mass_kg)
    k2_true = uam.inertia_com[1, 1] / true.inertia_com[1, 1]
    k4_true = uam.mass_kg / true.mass_kg
    if object_mass_kg == 0.0:
        want = np.array(k_flown[:3] + (k_flown[3], k_flown[3]))
    else:
        xi_lat = pair.xi[np.ix_((0, 2), (0, 2))]
        lat = np.linalg.eigvals(np.diag((k_flown[0], k_flown[2])) @ xi_lat)
        want = np.concatenate([lat, [k_flown[1] / k2_true, k_flown[3] / k4_true, k_flown[3] / k4_true]])
        assert k_flown[1] / k2_true == pytest.approx(LAM_REF * K_PIN[1] / k2_true)  # lambda* K_hat / K_true
    assert np.sort_complex(lam) == pytest.approx(np.sort_complex(want.astype(complex)), rel=1e-6, abs=1e-9)  # REAL32


def test_defaults_fly_k_hat_bit_for_bit() -> None:
    _, flown = _core(1.0, 0.0)
    _, again = _core(1.0, 0.0)
    a, _, _ = _gi_hat_after_ticks(flown)
    b, _, _ = _gi_hat_after_ticks(again)
    assert np.array_equal(a, b)
    # K_flown = K_hat: G_hat_I's diagonal is J / K_hat
    _, with_gain = _core(LAM_REF, K_FLOOR)
    c, _, _ = _gi_hat_after_ticks(with_gain)
    ratio = np.diag(c) / np.diag(a)
    k_flown3 = max(LAM_REF * K_PIN[2], K_FLOOR)
    assert ratio == pytest.approx([1 / LAM_REF, 1 / LAM_REF, K_PIN[2] / k_flown3, 1.0, 1.0])


def test_the_stability_floor_analyses_the_flown_box() -> None:
    reg = ParamRegistry.from_defaults()  # the defaults fly lambda* 0.4 with the floor 0.4: the flown box [0.4, 1]
    assert flown_k_bounds(reg.as_dict()) == (pytest.approx(0.4), pytest.approx(1.0))
    res = reg.set("INDI_KFL_MIN", 0.0)  # the paper's order reversed: K_hat at 0.5 flies 0.2, below lambda_crit 0.244
    assert not res.accepted and "stability floor" in (res.reason or "")
    assert reg.set("INDI_LAM_REF", 1.0).accepted  # lambda* 1 first (paper.parm's order) ...
    assert reg.set("INDI_KFL_MIN", 0.0).accepted  # ... then no floor: K_hat's own box
    assert flown_k_bounds(reg.as_dict()) == (pytest.approx(0.5), pytest.approx(1.0))
    res = reg.set("INDI_LAM_REF", 0.6)  # K_hat at 0.5 flies 0.3: margin ~1.19 < 1.5
    assert not res.accepted and "stability margin" in (res.reason or "")
    assert reg.set("INDI_KFL_MIN", 0.4).accepted  # the flown floor first ...
    assert reg.set("INDI_LAM_REF", 0.5).accepted  # ... then lambda*: the flown box [0.4, 1], margin ~1.6
    st = reg.stability_status()
    assert st is not None and st.min_eigenvalue == pytest.approx(0.3897, abs=2e-3)
    assert not reg.set("INDI_KFL_MIN", 0.3).accepted  # flown K 0.3 (K_hat 0.5 x 0.5 = 0.25 below it)
    assert math.isclose(float(reg["INDI_KFL_MIN"]), 0.4, rel_tol=1e-6)


def test_a_stored_set_valid_as_a_whole_loads_whatever_its_sorted_order() -> None:
    # load_values (a stored parameter file, navig8-sitl --params) applies the entries sorted by name, one at a time:
    # the paper's INDI_KFL_MIN 0 comes before its INDI_LAM_REF 1 and is refused on its own from the defaults; the
    # registry tries it again once lambda* is 1. A set that is invalid as a whole is still refused.
    reg = ParamRegistry.from_defaults()
    res = reg.load_values({"INDI_KFL_MIN": 0.0, "INDI_LAM_REF": 1.0})
    assert [r.name for r in res] == ["INDI_KFL_MIN", "INDI_LAM_REF"] and all(r.accepted for r in res)
    assert float(reg["INDI_LAM_REF"]) == 1.0 and float(reg["INDI_KFL_MIN"]) == 0.0
    reg = ParamRegistry.from_defaults()
    res = reg.load_values({"INDI_KFL_MIN": 0.0, "INDI_LAM_REF": 0.5})
    assert [r.accepted for r in res] == [False, True] and "stability floor" in (res[0].reason or "")
    assert math.isclose(float(reg["INDI_KFL_MIN"]), 0.4, rel_tol=1e-6)
