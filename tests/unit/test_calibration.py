"""PREFLIGHT_CALIBRATION and INJECT_FAILURE at the GCS service's boundary (navig8_fc.gcs.calibration,
navig8_fc.gcs.failure_injection, navig8_fc.flight.sensor_cal): commands in, COMMAND_ACK and the `[cal]` STATUSTEXTs
out, on a real FlightStack fed sensors with a gyro bias and the plant's noise (docs/plant.md: 0.01 rad/s gyro, 0.5
m/s^2 accelerometer per sample at 100 Hz)."""

from __future__ import annotations

import math
from io import BytesIO
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as M

from navig8_fc.core import vehicle as vm
from navig8_fc.core.controller import FcSensors
from navig8_fc.core.rotation import euler_to_quat
from navig8_fc.flight import FlightStack
from navig8_fc.gcs.calibration import GYRO_CAL_S
from navig8_fc.gcs.failure_injection import FailureInjection
from navig8_fc.params.registry import ParamRegistry
from navig8_fc.shell.gcs_service import GcsService

API = ("api", ("127.0.0.1", 14540))
BIAS = (0.02, -0.015, 0.01)  # rad/s: a gyro offset of a few hundredths, as MEMS gyros have
GYRO_SIGMA, ACCEL_SIGMA = 0.01, 0.5
# the offset is the mean of GYRO_CAL_S * 100 samples: 3 sigma of that mean
GYRO_TOL_RAD_S = 3 * GYRO_SIGMA / math.sqrt(GYRO_CAL_S * 100)


class Outbox:
    def __init__(self, mav: Any) -> None:
        self.sent: list[Any] = []
        self.mav = mav
        self.rx = M.MAVLink(BytesIO(), srcSystem=255, srcComponent=190)

    def broadcast(self, msgs: list[Any], exclude: frozenset[Any] = frozenset()) -> None:
        self.sent += [self.rx.decode(bytearray(m.pack(self.mav))) for m in msgs]

    def reply(self, source: Any, msgs: list[Any]) -> None:
        self.broadcast(msgs)


class Rig:
    """A FlightStack on the ground fed 100 Hz sensors (a gyro bias, the plant's noise, `roll_deg` of tilt), its
    GcsService polled after every step, as navig8-fc runs them."""

    def __init__(self, bias: tuple[float, float, float] = BIAS, roll_deg: float = 0.0, seed: int = 1) -> None:
        self.registry = ParamRegistry.from_defaults()
        vehicle = vm.VehicleConfig.load()
        self.stack = FlightStack(vehicle, self.registry)
        self.mav = M.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
        self.out = Outbox(self.mav)
        self.gcs = GcsService(self.mav, 1, self.stack.state, self.stack, self.out, self.registry, vehicle,
                              trusted_sources=[API])
        self.client = M.MAVLink(BytesIO(), srcSystem=245, srcComponent=190)
        self.rng = np.random.default_rng(seed)
        self.bias, self.roll = bias, math.radians(roll_deg)
        self.rate = (0.0, 0.0, 0.0)  # a true body rate (motion): yaw turns with its z
        self.yaw = 0.0
        self.t_us = 0

    def step(self, n: int) -> list[FcSensors]:
        seen = []
        for _ in range(n):
            g = self.rng.normal(0.0, GYRO_SIGMA, 3) + np.add(self.bias, self.rate)
            a = self.rng.normal(0.0, ACCEL_SIGMA, 3) + (0.0, 9.81 * math.sin(self.roll), -9.81 * math.cos(self.roll))
            s = FcSensors(self.t_us * 1e-6, tuple(g), tuple(a), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),  # type: ignore[arg-type]
                          euler_to_quat(self.roll, 0.0, self.yaw), (0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                          (0.0, 0.0, 0.0))
            self.yaw += self.rate[2] * 0.01
            self.stack.step(s, True, self.t_us)
            self.gcs.poll(self.t_us * 1e-6)
            seen.append(self.stack.state().sensors)
            self.t_us += 10_000
        return seen

    def command(self, cmd: int, *p: float) -> int:
        params = list(p) + [0.0] * (7 - len(p))
        msg = self.mav.decode(bytearray(self.client.command_long_encode(1, 1, cmd, 0, *params).pack(self.client)))
        self.gcs.handle([(msg, API)], self.t_us * 1e-6)
        (ack,) = [m for m in self.out.sent if m.get_type() == "COMMAND_ACK"]
        self.out.sent.remove(ack)
        return int(ack.result)

    def texts(self) -> list[str]:
        got = [m.text for m in self.out.sent if m.get_type() == "STATUSTEXT"]
        self.out.sent = [m for m in self.out.sent if m.get_type() != "STATUSTEXT"]
        return got


def test_gyro_calibration_measures_the_offset_and_the_controller_flies_without_it() -> None:
    rig = Rig()
    assert rig.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 1) == M.MAV_RESULT_ACCEPTED
    rig.step(round(GYRO_CAL_S * 100) + 5)
    texts = rig.texts()
    assert texts[0] == "[cal] calibration started: 2 gyro" and texts[-1] == "[cal] calibration done: gyro", texts
    assert [t for t in texts if t.startswith("[cal] progress")][:2] == ["[cal] progress <10>", "[cal] progress <20>"]
    offsets = [rig.registry.get(n) for n in ("CAL_GYRO0_XOFF", "CAL_GYRO0_YOFF", "CAL_GYRO0_ZOFF")]
    assert all(abs(o - b) <= GYRO_TOL_RAD_S for o, b in zip(offsets, BIAS, strict=True)), (offsets, GYRO_TOL_RAD_S)
    announced = {m.param_id: m.param_value for m in rig.out.sent if m.get_type() == "PARAM_VALUE"}
    assert announced["CAL_GYRO0_XOFF"] == np.float32(offsets[0])  # every GCS is told
    after = np.array([s.gyro_frd_rad_s for s in rig.step(300)])  # what the controller now gets
    assert np.all(np.abs(after.mean(axis=0)) <= 2 * GYRO_TOL_RAD_S), after.mean(axis=0)


def test_calibration_is_refused_armed_or_busy_and_cancels_and_fails_on_motion() -> None:
    rig = Rig()
    rig.step(60)  # past the estimator's warm-up
    assert rig.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, 21196) == M.MAV_RESULT_ACCEPTED
    assert rig.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 1) == M.MAV_RESULT_TEMPORARILY_REJECTED
    assert "Calibration denied: armed" in rig.texts()
    assert rig.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 21196) == M.MAV_RESULT_ACCEPTED
    assert rig.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 1) == M.MAV_RESULT_ACCEPTED
    assert rig.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 0, 1) == M.MAV_RESULT_TEMPORARILY_REJECTED
    assert rig.command(M.MAV_CMD_PREFLIGHT_CALIBRATION) == M.MAV_RESULT_ACCEPTED  # all zero: cancel
    rig.step(2)
    assert "[cal] calibration cancelled" in rig.texts()
    assert rig.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 1) == M.MAV_RESULT_ACCEPTED
    rig.rate = (0.0, 0.0, 0.3)
    rig.step(50)
    rig.rate = (0.0, 0.0, 0.0)  # turned during the first quarter of the first try, then still
    rig.step(1000)
    texts = rig.texts()
    assert texts.count("[cal] motion, retrying..") == 1 and texts[-1] == "[cal] calibration done: gyro", texts
    rig.rate = (0.0, 0.0, 0.3)  # turning throughout: every try fails, nothing applied
    before = rig.registry.get("CAL_GYRO0_ZOFF")
    assert rig.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 1) == M.MAV_RESULT_ACCEPTED
    rig.step(round(3 * GYRO_CAL_S * 100) + 20)
    rig.rate = (0.0, 0.0, 0.0)
    rig.step(300)
    assert rig.texts()[-1] == "[cal] calibration failed: gyro: motion"
    assert rig.registry.get("CAL_GYRO0_ZOFF") == before
    assert rig.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 1) == M.MAV_RESULT_UNSUPPORTED  # barometer: none


def test_level_accel_and_mag_end_as_px4_does_on_this_vehicle() -> None:
    rig = Rig(bias=(0.0, 0.0, 0.0), roll_deg=2.0)
    assert rig.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 0, 2) == M.MAV_RESULT_ACCEPTED
    rig.step(110)
    assert rig.texts()[-1] == "[cal] calibration done: level"
    assert abs(rig.registry.get("SENS_BOARD_X_OFF") - 2.0) < 0.01 and abs(rig.registry.get("SENS_BOARD_Y_OFF")) < 0.01
    level = rig.step(5)[-1]
    assert abs(level.quat_wxyz[1]) < 1e-3 and abs(level.accel_frd_m_s2[1]) < 3 * ACCEL_SIGMA  # flown level
    assert rig.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 0, 1) == M.MAV_RESULT_ACCEPTED
    rig.step(2000)
    texts = rig.texts()
    assert "[cal] down orientation detected" in texts and texts.count("[cal] down side already completed") == 5
    assert texts[-1] == "[cal] calibration failed: timeout: no motion", texts[-8:]
    assert rig.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 1) == M.MAV_RESULT_ACCEPTED
    rig.step(2)
    assert rig.texts() == ["[cal] calibration started: 2 mag", "No mags found", "[cal] calibration failed: mag"]


def test_failure_injection_needs_sys_failure_en_and_turns_the_gps_off_and_on() -> None:
    rig = Rig()
    rig.step(10)
    gps = (M.MAV_CMD_INJECT_FAILURE, M.FAILURE_UNIT_SENSOR_GPS)
    assert rig.command(*gps, M.FAILURE_TYPE_OFF) == M.MAV_RESULT_DENIED
    assert "INJECT_FAILURE denied: set SYS_FAILURE_EN to 1" in rig.texts()
    rig.registry.set("SYS_FAILURE_EN", 1)
    assert rig.command(M.MAV_CMD_INJECT_FAILURE, M.FAILURE_UNIT_SENSOR_GYRO, M.FAILURE_TYPE_OFF) == \
        M.MAV_RESULT_UNSUPPORTED
    assert rig.command(*gps, M.FAILURE_TYPE_STUCK) == M.MAV_RESULT_UNSUPPORTED
    assert rig.command(*gps, M.FAILURE_TYPE_OFF) == M.MAV_RESULT_ACCEPTED
    rig.out.sent.clear()
    rig.step(150)  # GPS_RAW_INT at 5 Hz, SYS_STATUS at 1 Hz (wall time = sim time here)
    raw = [m for m in rig.out.sent if m.get_type() == "GPS_RAW_INT"]
    status = [m for m in rig.out.sent if m.get_type() == "SYS_STATUS"]
    assert raw and all(m.fix_type == M.GPS_FIX_TYPE_NO_FIX and m.satellites_visible == 0 for m in raw)
    assert status and not status[-1].onboard_control_sensors_health & M.MAV_SYS_STATUS_SENSOR_GPS
    assert rig.command(*gps, M.FAILURE_TYPE_OK) == M.MAV_RESULT_ACCEPTED
    rig.out.sent.clear()
    rig.step(150)
    assert [m.fix_type for m in rig.out.sent if m.get_type() == "GPS_RAW_INT"][-1] == M.GPS_FIX_TYPE_3D_FIX


def test_a_gps_failure_in_the_air_lands() -> None:
    landed: list[bool] = []
    fi = FailureInjection(lambda: True, lambda: True, lambda: (landed.append(True) or True, ""))
    assert fi.command((M.FAILURE_UNIT_SENSOR_GPS, M.FAILURE_TYPE_OFF, 0)) == (
        M.MAV_RESULT_ACCEPTED, None, "GPS lost (failure injected): landing")
    assert landed == [True] and fi.gps_off
