"""PX4's simulator messages as the FC's sensor source (navig8_fc/mavlink/px4sim.py): frames packed by pymavlink
(the oracle, independent of the FC's codec), decoded by the codec, assembled into the FC's step; the actuator
model against the closed-form step response of a second-order system."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as m2  # noqa: E402

from navig8_fc.core.vehicle import VehicleConfig  # noqa: E402
from navig8_fc.links.sim_guard import REPAIR_SILENCE_S, SensorLimits, SimGuard  # noqa: E402
from navig8_fc.mavlink import codec  # noqa: E402
from navig8_fc.mavlink.px4sim import PX4_SIM_MESSAGES, ActuatorModel, Px4SimAssembler, ned_from_global  # noqa: E402
from navig8_fc.mission.geo import GeoOrigin  # noqa: E402


def _step_response(wn: float, zeta: float, t: float) -> float:
    """x(t) for x'' = wn^2 (1 - x) - 2 zeta wn x', x(0) = x'(0) = 0 (textbook closed forms)."""
    if zeta < 1.0:
        wd = wn * math.sqrt(1 - zeta**2)
        return 1 - math.exp(-zeta * wn * t) * (math.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * math.sin(wd * t))
    return 1 - math.exp(-wn * t) * (1 + wn * t)


@pytest.mark.parametrize("zeta", [0.5, 0.8, 1.0])
def test_actuator_model_matches_the_closed_form_step_response(zeta: float) -> None:
    wn, dt = 120.0, 0.01
    m = ActuatorModel(wn, zeta, dt, (0.0,) * 5)
    for k in range(1, 30):
        x = m.step((1.0, 2.0, 100.0, -50.0, 0.0))
        want = _step_response(wn, zeta, k * dt)
        assert x[0] == pytest.approx(want, abs=1e-9)
        assert x[2] == pytest.approx(100 * want, abs=1e-7) and x[3] == pytest.approx(-50 * want, abs=1e-7)
        assert x[4] == 0.0


def test_global_position_back_to_ned_within_the_wire_resolution() -> None:
    o = GeoOrigin()
    for ned in [(0.0, 0.0, 0.0), (3.2, -1.7, -2.0), (-12.0, 40.0, -10.5)]:
        lat, lon, alt = o.to_global(ned)
        got = ned_from_global(o, round(lat * 1e7), round(lon * 1e7), round(alt * 1000))
        assert np.allclose(got, ned, atol=0.012)  # 1e-7 deg is 1.1 cm north, 0.7 cm east here; 1 mm down


def _frames(stamp: int, ned: tuple[float, float, float], sensor_id: int = 0, extra: bytes = b"") -> bytes:
    mav = m2.MAVLink(None, srcSystem=1, srcComponent=51)
    lat, lon, alt = GeoOrigin().to_global(ned)
    q = (math.cos(0.1), 0.0, 0.0, math.sin(0.1))
    return (mav.hil_state_quaternion_encode(stamp, q, 0.01, 0.02, 0.03, round(lat * 1e7), round(lon * 1e7),
                                            round(alt * 1000), 12, -34, 56, 0, 0, 0, 0, -1000).pack(mav)
            + mav.hil_gps_encode(stamp, 3, round(lat * 1e7), round(lon * 1e7), round(alt * 1000), 30, 30, 36, 12,
                                 -34, 56, 65535, 12).pack(mav)
            + extra
            + mav.hil_sensor_encode(stamp, 0.1, -0.2, -9.8, 0.01, 0.02, 0.03, 0, 0, 0, 0, 0, 0, 0, 0b111111,
                                    sensor_id).pack(mav))


def test_px4_frames_make_the_fcs_step() -> None:
    c = codec.Codec(PX4_SIM_MESSAGES)
    asm = Px4SimAssembler(GeoOrigin(), ActuatorModel(120.0, 0.8, 0.01, (0.0,) * 5))
    counts = codec.ParseCounters()
    mav = m2.MAVLink(None, srcSystem=1, srcComponent=51)
    # a HIL_SENSOR before any pose makes no step
    lone = mav.hil_sensor_encode(1, 0, 0, -9.8, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0b111111, 0).pack(mav)
    assert [asm.add(m) for m in c.parse(lone, counts)] == [None] and asm.incomplete == 1
    got = [b for m in c.parse(_frames(10001, (1.0, -2.0, -3.0)), counts) if (b := asm.add(m)) is not None]
    assert counts.bad_frames == 0 and counts.garbage_bytes == 0 and len(got) == 1
    b = got[0]
    assert b.time_usec == 10001 and b.imu_fresh
    assert np.allclose(b.pos_ned_m, (1.0, -2.0, -3.0), atol=0.012)
    assert np.allclose(b.vel_ned_m_s, (0.12, -0.34, 0.56))
    assert np.allclose(b.quat_wxyz, (math.cos(0.1), 0, 0, math.sin(0.1)))
    assert np.allclose(b.accel_frd_m_s2, (0.1, -0.2, -9.8)) and np.allclose(b.gyro_frd_rad_s, (0.01, 0.02, 0.03))
    assert b.duct_tilt_rad == (0.0, 0.0) and b.joint_pos_rad == (0.0, 0.0, 0.0)  # modelled: nothing commanded yet
    assert asm.counters.gps == 1 and asm.counters.modelled_actuators == 1
    # after a command the model moves towards it; a second IMU (id 1) is ignored
    asm.command((0.1, 0.1), (500.0, 0.0, 500.0))
    got = [b for m in c.parse(_frames(20001, (1.0, -2.0, -3.0)), counts) if (b := asm.add(m)) is not None]
    assert 0.0 < got[0].prop_speed_rad_s[0] < 500.0 and got[0].prop_speed_rad_s[0] == got[0].prop_speed_rad_s[2]
    assert [asm.add(m) for m in c.parse(_frames(30001, (0, 0, 0), sensor_id=1), counts)][-1] is None
    assert asm.counters.other_imu == 1


def test_measured_actuator_and_arm_states_are_used_when_they_come_with_the_step() -> None:
    c = codec.Codec(PX4_SIM_MESSAGES)
    asm = Px4SimAssembler(GeoOrigin(), ActuatorModel(120.0, 0.8, 0.01, (0.0,) * 5))
    enc = codec.Encoder(c, 1, 25)
    extra = enc.frame("NAVIG8_ACTUATOR_STATE", (10001, 1, (0.2, -0.1), (600.0, 5.0, 610.0), 0))
    extra += enc.frame("NAVIG8_ARM_STATE", (10001, 1, (0.5, 0.1, 0.0), (0.0, 0.0, 0.0), 1))
    got = [b for m in c.parse(_frames(10001, (0, 0, -1), extra=extra), codec.ParseCounters())
           if (b := asm.add(m)) is not None]
    b = got[0]
    assert np.allclose(b.duct_tilt_rad, (0.2, -0.1)) and np.allclose(b.prop_speed_rad_s, (600.0, 5.0, 610.0))
    assert np.allclose(b.joint_pos_rad, (0.5, 0.1, 0.0)) and b.gripper_closed
    assert asm.counters.measured_actuators == 1


def test_the_simulator_is_pinned_and_its_steps_sequenced_and_validated() -> None:
    """PX4's simulator messages have no nonce: the guard pins the configured peer (or the first sender), refuses every
    other address, takes only newer stamps, and replaces a NaN gyro by the last good one (navig8_fc/links/sim_guard)."""
    sim, other = ("127.0.0.1", 4560), ("127.0.0.1", 4999)
    g = SimGuard(1, SensorLimits.from_vehicle(VehicleConfig.load()), lambda: 7, monotonic=True)
    assert not g.admit_simulator(other, 0.0, sim) and g.peer is None  # configured: nobody else, ever
    assert g.admit_simulator(sim, 0.0, sim) and g.counters.sessions == 1
    assert not g.admit_simulator(other, REPAIR_SILENCE_S + 1.0, sim)  # not even after silence
    first = SimGuard(1, SensorLimits.from_vehicle(VehicleConfig.load()), lambda: 7, monotonic=True)
    assert first.admit_simulator(other, 0.0, None) and not first.admit_simulator(sim, 1.0, None)
    assert first.counters.wrong_sender == 1
    assert first.admit_simulator(sim, 1.0 + REPAIR_SILENCE_S, None)  # the first one silent that long: a restart
    c = codec.Codec(PX4_SIM_MESSAGES)
    asm = Px4SimAssembler(GeoOrigin(), ActuatorModel(120.0, 0.8, 0.01, (0.0,) * 5))

    def step(stamp: int, **mutate: float) -> str:
        (b,) = [b for m in c.parse(_frames(stamp, (0.0, 0.0, -2.0)), codec.ParseCounters())
                if (b := asm.add(m)) is not None]
        if mutate:
            b = b._replace(gyro_frd_rad_s=(mutate["gyro"], 0.0, 0.0))
        inp = g.accept_bundle(b, dict(asm.completed))
        return inp.kind if not inp.bad_groups else f"{inp.kind} {inp.bad_groups} {inp.bundle.gyro_frd_rad_s[0]:.3f}"

    assert step(10001) == "step" and step(20001) == "step"
    assert step(15001) == "none" and g.counters.out_of_order == 1  # older than the last: never flown
    assert step(30001, gyro=math.nan) == "step ('imu',) 0.010" and g.counters.invalid_imu == 1  # the last good gyro
