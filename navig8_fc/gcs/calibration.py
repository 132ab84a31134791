"""MAV_CMD_PREFLIGHT_CALIBRATION as PX4's Commander answers it and its calibration routines report it (PX4
src/modules/commander: Commander.cpp, gyro_calibration.cpp, accelerometer_calibration.cpp (do_level_calibration),
mag_calibration.cpp, calibration_routines.cpp; the `[cal]` STATUSTEXTs QGroundControl and MAVSDK's
calibration_statustext_parser read). docs/gcs.md, "Calibration".

- Armed, or a calibration running: TEMPORARILY_REJECTED (with the reason). All parameters 0: cancels the running one
  ("[cal] calibration cancelled"), else ACCEPTED (PX4's "RC calibration ended"). Anything but the four below:
  UNSUPPORTED.
- Gyro (p1 = 1): ACCEPTED; "[cal] calibration started: 2 gyro", GYRO_CAL_S of sim time of the still vehicle's gyro
  with "[cal] progress <n>" every 10 %, a motion check (the means of four quarters within GYRO_MOTION_RAD_S of the
  whole's and the attitude turned at most GYRO_MOTION_DEG; else "[cal] motion, retrying.." up to GYRO_TRIES
  times), then the offsets (the mean, on top of those in
  force) into CAL_GYRO0_XOFF/YOFF/ZOFF, applied and saved like any parameter, "[cal] calibration done: gyro".
- Level (p5 = 2): the mean roll and pitch over LEVEL_CAL_S into SENS_BOARD_X_OFF/Y_OFF (deg); beyond
  LEVEL_MAX_DEG: "[cal] calibration failed: level" after PX4's "excess pitch/roll offset".
- Accelerometer (p5 = 1): PX4's six-orientation routine on the accelerometer. A vehicle standing on the ground
  rests right side up: its "down" side is measured, then every further rest is that side again ("[cal] down side
  already completed"); the fifth such failure ends it as PX4 does: "[cal] calibration failed: timeout: no
  motion". The simulated vehicle cannot be turned over, so nothing is applied.
- Magnetometer (p2 = 1): this vehicle has none (its heading comes from motion capture): PX4's answer without a
  magnetometer, "No mags found" and "[cal] calibration failed: mag".
The routines run on the sensor samples the vehicle publishes (one per control step, on sim time); no sample for
SENSOR_TIMEOUT_S of wall time ends one with "[cal] calibration failed: reading sensor". Pure: the caller gives the
samples, the time and a way to apply parameters.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator, Sequence
from typing import Any

from navig8_fc.core.controller import FcSensors
from navig8_fc.core.rotation import attitude_error_angle, quat_to_euler
from navig8_fc.gcs.statustext import StatusTextEncoder

SEVERITY_CRITICAL, SEVERITY_INFO = 2, 6
MAV_RESULT_ACCEPTED, MAV_RESULT_TEMPORARILY_REJECTED, MAV_RESULT_UNSUPPORTED = 0, 1, 3
GYRO_CAL_S = 2.0  # sim s of samples: 200 at 100 Hz, the mean within 0.7 mrad/s (1 sigma) of the offset
GYRO_MOTION_RAD_S = 0.01  # a quarter's mean this far from the whole's: the vehicle moved (7 sigma of the noise)
GYRO_MOTION_DEG = 1.0  # the attitude turned this far during the samples: the vehicle moved
GYRO_TRIES = 3
LEVEL_CAL_S = 1.0
LEVEL_MAX_DEG = 10.0  # SENS_BOARD_*_OFF's range
LEVEL_MOTION_DEG = 0.5
ACCEL_BLOCK_S = 0.25  # the accelerometer's rest detector: means over this long ...
ACCEL_STILL_M_S2 = 0.5  # ... within this of each other: at rest (the 0.5 m/s^2 noise is 0.1 over a block)
ACCEL_STILL_S = 1.3  # PX4's still time before a side is taken (detect_orientation)
ACCEL_SIDE_S = 1.0  # a side's measurement
ACCEL_MAX_FAILURES = 4  # PX4: more than this many failed detections end the calibration
SENSOR_TIMEOUT_S = 5.0
SIDES = ("back", "front", "left", "right", "up", "down")  # PX4's detect_orientation_str order
GYRO_PARAMS = ("CAL_GYRO0_XOFF", "CAL_GYRO0_YOFF", "CAL_GYRO0_ZOFF")
LEVEL_PARAMS = ("SENS_BOARD_X_OFF", "SENS_BOARD_Y_OFF")

Text = tuple[int, str]
Outcome = tuple[list[Text], dict[str, float] | None]  # the closing texts, the parameters to apply
Worker = Generator[list[Text], FcSensors, Outcome]


def _started(kind: str) -> Text:
    return SEVERITY_INFO, f"[cal] calibration started: 2 {kind}"


def _failed(why: str) -> Text:
    return SEVERITY_CRITICAL, f"[cal] calibration failed: {why}"


def _mean(rows: Sequence[Sequence[float]]) -> tuple[float, ...]:
    return tuple(sum(c) / len(rows) for c in zip(*rows, strict=True))


def _still(rows: Sequence[Sequence[float]], tol: float) -> bool:
    """The means of four quarters within `tol` of the whole's on every axis."""
    whole, q = _mean(rows), len(rows) // 4
    return q > 0 and all(abs(a - b) <= tol for k in range(4) for a, b in zip(_mean(rows[k * q:(k + 1) * q]), whole,
                                                                              strict=True))


def _collect(s: FcSensors, duration_s: float, pick: Callable[[FcSensors], Sequence[float]],
             out: list[Text]) -> Generator[list[Text], FcSensors, tuple[list[Sequence[float]], FcSensors]]:
    """`duration_s` of samples from `s` on, with "[cal] progress <n>" every 10 %."""
    rows: list[Sequence[float]] = []
    t0, shown = s.t_s, 0
    while s.t_s - t0 < duration_s:
        rows.append(pick(s))
        pct = int(100.0 * (s.t_s - t0) / duration_s) // 10 * 10
        if pct > shown:
            shown = pct
            out.append((SEVERITY_INFO, f"[cal] progress <{pct}>"))
        s = yield out
        out = []
    return rows, s


def gyro_worker(old_rad_s: Sequence[float]) -> Worker:
    out: list[Text] = [_started("gyro")]
    s = yield out
    for _ in range(GYRO_TRIES):
        q0 = s.quat_wxyz
        rows, s = yield from _collect(s, GYRO_CAL_S, lambda x: x.gyro_frd_rad_s, [])
        # a steady turn looks like an offset to the gyro: the attitude says whether the vehicle stood still
        turned_rad = attitude_error_angle(s.quat_wxyz, q0)
        if _still(rows, GYRO_MOTION_RAD_S) and turned_rad <= math.radians(GYRO_MOTION_DEG):
            offsets = [o + m for o, m in zip(old_rad_s, _mean(rows), strict=True)]
            return [(SEVERITY_INFO, "[cal] progress <100>"), (SEVERITY_INFO, "[cal] calibration done: gyro")], \
                dict(zip(GYRO_PARAMS, offsets, strict=True))
        s = yield [(SEVERITY_CRITICAL, "[cal] motion, retrying..")]
    return [_failed("gyro: motion")], None


def level_worker(old_deg: Sequence[float]) -> Worker:
    s = yield [_started("level")]
    rows, s = yield from _collect(s, LEVEL_CAL_S, lambda x: [math.degrees(a) for a in quat_to_euler(x.quat_wxyz)[:2]],
                                  [])
    if not _still(rows, LEVEL_MOTION_DEG):
        return [_failed("level: motion")], None
    roll, pitch = (o + m for o, m in zip(old_deg, _mean(rows), strict=True))
    if abs(roll) > LEVEL_MAX_DEG or abs(pitch) > LEVEL_MAX_DEG:
        return [(SEVERITY_CRITICAL, "excess pitch/roll offset"), _failed("level")], None
    return [(SEVERITY_INFO, "[cal] progress <100>"), (SEVERITY_INFO, "[cal] calibration done: level")], \
        dict(zip(LEVEL_PARAMS, (roll, pitch), strict=True))


def _side(accel: Sequence[float], g: float = 9.80665, tol: float = 5.0) -> str | None:
    """PX4's detect_orientation: the axis carrying the specific force of gravity (FRD; at rest it points up)."""
    for axis in range(3):
        for sign, names in ((1.0, ("back", "left", "up")), (-1.0, ("front", "right", "down"))):
            if all(abs(accel[k] - (sign * g if k == axis else 0.0)) < tol for k in range(3)):
                return names[axis]
    return None


def accel_worker() -> Worker:
    s = yield [_started("accel")]
    done: list[str] = []
    failures = 0
    while failures <= ACCEL_MAX_FAILURES:
        pending = " ".join(n for n in SIDES if n not in done)
        out = [(SEVERITY_INFO, f"[cal] pending: {pending}"),
               (SEVERITY_INFO, "[cal] hold vehicle still on a pending side")]
        still_since, ref, block, t_block = None, None, [], s.t_s
        while still_since is None or s.t_s - still_since < ACCEL_STILL_S:
            block.append(s.accel_frd_m_s2)
            if s.t_s - t_block >= ACCEL_BLOCK_S:
                mean, block, t_block = _mean(block), [], s.t_s
                if ref is not None and max(abs(a - b) for a, b in zip(mean, ref, strict=True)) > ACCEL_STILL_M_S2:
                    if still_since is not None:
                        out.append((SEVERITY_INFO, "[cal] detected motion, hold still..."))
                    still_since = None
                elif ref is not None and still_since is None:
                    still_since = s.t_s
                    out.append((SEVERITY_INFO, "[cal] detected rest position, hold still..."))
                ref = mean
            s = yield out
            out = []
        side = _side(ref or s.accel_frd_m_s2)
        if side is None or side in done:
            failures += 1
            s = yield [(SEVERITY_INFO, f"[cal] {side} side already completed" if side else
                        "[cal] detected motion, hold still...")]
            continue
        failures = 0
        rows, s = yield from _collect(s, ACCEL_SIDE_S, lambda x: x.accel_frd_m_s2,
                                      [(SEVERITY_INFO, f"[cal] {side} orientation detected"),
                                       (SEVERITY_INFO, f"[cal] Hold still, measuring {side} side")])
        m = _mean(rows)
        done.append(side)
        s = yield [(SEVERITY_INFO, f"[cal] {side} side result: [{m[0]:.4f} {m[1]:.4f} {m[2]:.4f}]"),
                   (SEVERITY_INFO, f"[cal] progress <{100 * len(done) // len(SIDES)}>"),
                   (SEVERITY_INFO, f"[cal] {side} side done, rotate to a different side")]
        if len(done) == len(SIDES):  # a vehicle that can be turned over: not this one (module docstring)
            return [_failed("accel: no six-side fit")], None
    return [_failed("timeout: no motion")], None


def mag_worker() -> Worker:
    yield []
    return [_started("mag"), (SEVERITY_CRITICAL, "No mags found"), _failed("mag")], None


class Calibration:
    """PREFLIGHT_CALIBRATION and the routine it started (module docstring)."""

    def __init__(self, text: StatusTextEncoder, param: Callable[[str], float],
                 apply: Callable[[dict[str, float]], tuple[str | None, list[Any]]]) -> None:
        """param(name): the value in force; apply(values): the parameters measured, applied and saved (the refusal's
        reason, the messages announcing them)."""
        self._text = text
        self._param = param
        self._apply = apply
        self._worker: Worker | None = None
        self._kind = ""
        self._out: list[Any] = []
        self._last_t_s = -math.inf
        self._last_wall_s: float | None = None

    @property
    def running(self) -> str:
        """The routine running ("" none)."""
        return self._kind

    def command(self, params: Sequence[float], armed: bool) -> tuple[int, str | None, str | None]:
        """(MAV_RESULT, reason, None) for PREFLIGHT_CALIBRATION p1..p7."""
        p = [int(v) if math.isfinite(v) else 0 for v in params]
        if not any(p[:6]):
            if self._worker is not None:
                self._end([(SEVERITY_CRITICAL, "[cal] calibration cancelled")], None)
            return MAV_RESULT_ACCEPTED, None, None
        if armed:
            return MAV_RESULT_TEMPORARILY_REJECTED, "Calibration denied: armed", None
        if self._worker is not None:
            return MAV_RESULT_TEMPORARILY_REJECTED, f"Calibration denied: {self._kind} calibration running", None
        if p[0] == 1:
            kind, worker = "gyro", gyro_worker([self._param(n) for n in GYRO_PARAMS])
        elif p[1] == 1:
            kind, worker = "mag", mag_worker()
        elif p[4] == 1:
            kind, worker = "accel", accel_worker()
        elif p[4] == 2:
            kind, worker = "level", level_worker([self._param(n) for n in LEVEL_PARAMS])
        else:
            return MAV_RESULT_UNSUPPORTED, ("PREFLIGHT_CALIBRATION: gyro (p1 1), mag (p2 1), accel (p5 1) or level "
                                            "(p5 2) only"), None
        self._worker, self._kind, self._last_wall_s = worker, kind, None
        self._say(next(worker))
        return MAV_RESULT_ACCEPTED, None, None

    def update(self, sensors: FcSensors | None, armed: bool, now_wall_s: float) -> list[Any]:
        """Feed the newest sample (each control step's once); the messages to broadcast."""
        w = self._worker
        if w is not None:
            if self._last_wall_s is None:
                self._last_wall_s = now_wall_s
            if armed:
                self._end([_failed(f"{self._kind}: armed")], None)
            elif sensors is not None and sensors.t_s > self._last_t_s:
                self._last_t_s, self._last_wall_s = sensors.t_s, now_wall_s
                try:
                    self._say(w.send(sensors))
                except StopIteration as done:
                    self._end(*done.value)
            elif now_wall_s - self._last_wall_s > SENSOR_TIMEOUT_S:
                self._end([_failed("reading sensor")], None)
        out, self._out = self._out, []
        return out

    def _say(self, texts: list[Text]) -> None:
        for severity, text in texts:
            self._out += self._text.encode(severity, text)

    def _end(self, texts: list[Text], values: dict[str, float] | None) -> None:
        if values is not None:
            why, msgs = self._apply(values)
            if why is not None:  # refused by the registry (out of range): the routine failed
                texts = [(SEVERITY_CRITICAL, f"Calibration not applied: {why}"), _failed(self._kind)]
            self._out += msgs
        self._say(texts)
        if self._worker is not None:
            self._worker.close()
        self._worker, self._kind = None, ""


__all__ = ["Calibration", "accel_worker", "gyro_worker", "level_worker", "mag_worker"]
